"""The in-step impact resolver of ``pounding.fmu``: impacts located and integrated inside a step.

:class:`ImpactResolver` is a pure Python Dormand-Prince 5(4) integrator of the relative
motion in the impact's own scales, with located events (onset, maximum penetration,
re-approach, separation); :class:`StepOutcome` is what one communication step hands back.
The force of each branch is the contact law table's scaled kernel
(:meth:`fmu_src.contact_laws.LawSpec.kernel`); the separation rule is the table's too
(:meth:`~fmu_src.contact_laws.LawSpec.separation_function`).  Pure physics (SI units, no FMI).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

from scipy.optimize import brentq

from .contact_laws import MIN_IMPACT_SPEED, ContactLaw
from .host_observer import HostObserver

# Dormand-Prince 5(4) tableau (Dormand & Prince 1980; as in scipy's RK45).
_C2, _C3, _C4, _C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9
_A21 = 1 / 5
_A31, _A32 = 3 / 40, 9 / 40
_A41, _A42, _A43 = 44 / 45, -56 / 15, 32 / 9
_A51, _A52, _A53, _A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
_A61, _A62, _A63, _A64, _A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
_B1, _B3, _B4, _B5, _B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
_E1, _E3, _E4, _E5, _E6, _E7 = 71 / 57600, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40

#: scaled rate above which a restitution branch turns back into approach (the structure pushes the
#: bodies together again before they separate); a small positive threshold so that the event
#: cannot fire at the very point where the approach branch ended.
_REAPPROACH_RATE = 1e-9
#: guard against an endless impact/flight alternation inside one step (never reached in tests)
_MAX_IMPACTS_PER_STEP = 1000
#: branch switches (maximum penetration / re-approach) per step after which re-approach is no
#: longer detected in that step: a guard against chatter at delta_dot = 0 (a crvk contact held
#: between its branches sticks instead, ImpactResolver._stick; never reached in the tests)
_MAX_SWITCHES_PER_STEP = 200
#: energy the hand-over's timing may have given the host before it is taken back, as a part of
#: the impact's kinetic energy m v_imp^2 (rule 7)
_DEBT_TOLERANCE = 1e-4
#: timing energy left to the host by ImpactResolver._withhold, as a part of m v_imp^2 (0.2 % of
#: the impact's kinetic energy): the projection it acts on is a prediction, and at fine steps it
#: is off by more than this (1e-4, as _DEBT_TOLERANCE, in every episode of an
#: undeclared host, withheld enough at 1 ms to lose a grazing impact of the shear buildings in
#: three hosts; 5e-3 left 2.3 % of the initial energy at 10 ms in the buildings' Newmark/Jacobi cell)
_WITHHOLD_TOLERANCE = 0.001
#: steps over which ImpactResolver._withhold continues the resolver's own impact and the host's
#: delivery: the longest standard kernel (4 taps) after the last hand-over, and 2 more steps of impact
_WITHHOLD_HORIZON = 6
#: energy created on the host's side (ImpactResolver._passivity) left to the host, as a part of
#: m v_imp^2 (2 % of the impact's kinetic energy): the coming steps are a projection, off by
#: about this at 10 ms (0.1 %, as _WITHHOLD_TOLERANCE, withheld from the shear buildings in
#: symplectic Euler / Jacobi order enough to lose the 0.15 m/s impact at 1.15 s; 0.5 % too)
_PASSIVITY_TOLERANCE = 0.01


#: Brent's bounded search: the golden section's ratio, and the relative tolerance on the
#: abscissa (the square root of 2.2e-16, as scipy's)
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))
_SQRT_EPS = math.sqrt(2.2e-16)
#: how closely ImpactResolver._refine_peak locates a force maximum, as a part of the span it
#: searches: at a smooth maximum the force found is short of the peak by about
#: F'' dx^2 / 2, a part (1e-4)^2 = 1e-8 of the force's variation over the span, a hundredth of
#: the impact's own integration error (~1e-6 relative at rtol 1e-8); 1e-7 took 15 DP steps per
#: search, 1e-4 takes 7 % fewer DP steps in all (kasai_maison) and moves the peaks by < 2e-11
_PEAK_XATOL = 1e-4


def bounded_minimum(fun, upper: float, xatol: float, max_calls: int = 500) -> tuple[float, int]:
    """``(min fun(x) over 0 <= x <= upper, evaluations)``: Brent's bounded minimisation
    (Brent 1973, "Algorithms for minimization without derivatives", ch. 5: golden section
    steps, parabolic ones where a parabola through the last three points is trusted), stopping
    when the bracket around the best point is within ``xatol`` (absolute) plus ``_SQRT_EPS``
    relative.  It takes the same points, in the same floating-point arithmetic, as
    ``scipy.optimize.minimize_scalar(fun, bounds=(0, upper), method="bounded",
    options={"xatol": xatol})`` (tests/test_resolver_peak_search.py compares them bit for bit),
    without the 15-20 us of argument handling and result objects per call that made scipy's a
    third of pounding.fmu's peak refinement.  ``fun`` must be finite on the interval."""
    lo, hi = 0.0, upper
    best = second = third = lo + _GOLDEN * (hi - lo)   # best point, the previous best, the one before
    f_best = f_second = f_third = fun(best)
    calls = 1
    move = last_move = 0.0           # the latest step and the one before it
    mid = 0.5 * (lo + hi)
    tol = _SQRT_EPS * abs(best) + xatol / 3.0
    while abs(best - mid) > 2.0 * tol - 0.5 * (hi - lo):
        golden = True
        if abs(last_move) > tol:     # try the parabola through the three points
            r = (best - second) * (f_best - f_third)
            q = (best - third) * (f_best - f_second)
            p = (best - third) * q - (best - second) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            older, last_move = last_move, move
            if abs(p) < abs(0.5 * q * older) and q * (lo - best) < p < q * (hi - best):
                golden = False
                move = (p + 0.0) / q
                x = best + move
                if x - lo < 2.0 * tol or hi - x < 2.0 * tol:   # too close to an end: a minimal step
                    move = tol if mid >= best else -tol
        if golden:
            last_move = (lo if best >= mid else hi) - best
            move = _GOLDEN * last_move
        x = best + (-1.0 if move < 0.0 else 1.0) * max(abs(move), tol)
        fx = fun(x)
        calls += 1
        if fx <= f_best:
            if x >= best:
                lo = best
            else:
                hi = best
            third, f_third = second, f_second
            second, f_second = best, f_best
            best, f_best = x, fx
        else:
            if x < best:
                lo = x
            else:
                hi = x
            if fx <= f_second or second == best:
                third, f_third = second, f_second
                second, f_second = x, fx
            elif fx <= f_third or third == best or third == second:
                third, f_third = x, fx
        mid = 0.5 * (lo + hi)
        tol = _SQRT_EPS * abs(best) + xatol / 3.0
        if calls >= max_calls:
            break
    return f_best, calls


@dataclass
class StepOutcome:
    """What one :meth:`ImpactResolver.step` hands back (SI units)."""

    impulse: float = 0.0          # N s over the step
    mean_force: float = 0.0       # N, impulse / h
    peak_force: float = 0.0       # N, largest instantaneous force in the step
    substeps: int = 0             # accepted internal integration steps
    nfev: int = 0                 # force evaluations
    impacts_started: int = 0
    impacts_completed: int = 0


class ImpactResolver:
    """Locate and integrate impacts inside a communication step, at the impact's own time scale.

    The host supplies ``delta`` [m] and ``delta_dot`` [m/s] at the start of each step and applies
    the returned mean force over the step.  Inside the step the relative motion obeys
    ``delta_ddot = a_ext(s) - F / m``: the contact force on the effective mass plus the
    *external* relative acceleration ``a_ext`` of the structures the bodies belong to (storey
    springs and dampers; zero for free masses).  Rules (docs/contact_models.md, "in-step rules"):

    1. *Following the host* (:class:`HostObserver`).  ``a_ext`` is learnt from the host's
       velocity increments only, once our own force is taken out of them with the host's
       identified delivery kernel (or when none of our force can be in them), and extrapolated
       linearly over the next step.  Position increments, which depend on the host's
       integrator, are never learnt from.
    2. *Whose state.*  Out of contact, once every impulse handed over has reached the host, the
       host's state is the truth (rule 4 for a residual overlap).  Through a contact and until
       its impulse has reached the host, the resolver's own state is: it is corrected only by
       the difference between the clean structural increment and the one assumed.  For free
       masses that difference is zero whatever the host integrator, so an impact of free
       masses is exact at any step.
    3. *Onset*: out of contact, a new impact starts where the prediction
       ``delta_eff + delta_dot s + int int a_ext`` crosses zero while approaching.
       A step that starts overlapping (a crossing the prediction missed) moves the overlap
       into ``offset``; the impact starts at once if the bodies approach.
    4. *During contact* the impact is integrated (Dormand-Prince 5(4), scaled by
       ``L = (m v^2/k)^(1/(n+1))`` and ``T = L / v``) with located events at maximum
       penetration (``delta_dot = 0``), re-approach (``delta_dot`` rising again while loaded,
       the structure pushing back: same impact), stick (a push between the two branches of a
       law whose force drops at ``delta_dot = 0``: held, :meth:`_stick`) and separation (``delta = 0``, or the raw
       force reaching zero for laws with a dashpot in restitution); it may straddle any number
       of steps, and several impacts may occur in one step.
    5. *After separation* the host, moved by a held mean force, may still overlap while
       separating.  Such an apparent overlap is kept as ``offset`` (>= 0, cleared once the
       host's ``delta <= 0``); a force separation with ``delta > 0`` moves the remaining
       overlap into the offset as well.
    6. *Impulse and energy*: the impulse is ``int F dt`` of the internal force history,
       ``mean_force = impulse / h``.  ``E_dissipated`` is the work of the dissipative part of the
       force, ``int (F - k delta^n) delta_dot dt`` >= 0, integrated along the internal trajectory
       (plus, at a force separation, the elastic energy left in the overlap): it never decreases,
       and it does not depend on how the host holds the force, so the host's energy balance
       shows the coupling error instead of hiding it.
    7. *Hand-over* (:meth:`_hand_over`): a host that delivers our force ``lead`` steps late on
       average (the kernel's mean delay) gets the impulse that much early, so that it acts on
       the host's structures when it acts on the resolver's own bodies; momentum is exact over
       an episode (``ahead``).  The energy a late hand-over gave the host (``int C A dt``,
       :meth:`HostObserver._book_timing`) is taken back by shifting the next hand-over.  In an
       episode that began before the host's kernel was known (the first impact of a host that
       declared nothing) what the timing will still give the host after the last hand-over is
       projected and taken back by withholding impulse for good (:meth:`_withhold`): the host's
       bodies separate a little slower; energy is taken rather than created.  So is what the
       host's own rates show created for every host timing not yet excluded
       (:meth:`_passivity`): with several contacts on a structure ``int C A dt`` misses most of it.
    8. *A step declared open* (``gap_open``, :meth:`open_step`): a host that has proven the gap
       open over the coming step (``x1 - x2 < gap`` throughout) may say so; when the contact has
       nothing in progress (:meth:`can_skip`) it then does no onset search and no prediction of
       the flight over the step, whatever its length: no force, no impact.  The structures'
       motion is learnt from the host's increments as after any step; the next step starts from
       the host's state.

    ``follow_host=False`` restores the free-mass model (``a_ext = 0``, no corrections).
    The instance holds plain numbers, its observer, an optional trace list and what
    ``__init__`` builds from the law and never changes (the law, frozen; the kernels):
    :meth:`snapshot` saves its state.
    """

    def __init__(self, law: ContactLaw, rtol: float = 1e-8, follow_host: bool = True,
                 extrapolate: bool = True, host: str = "any", graze_depth: float = 0.0):
        self.law = law
        self.graze_depth = graze_depth   # m: a contact shallower than this is a graze, not an impact
        self.rtol = rtol
        self.follow_host = follow_host
        self.observer = HostObserver(law.m, extrapolate, host)
        spec = law.spec   # the law's entry of the contact law table: kernels and separation rule
        self._kernels = {True: spec.kernel(law.zeta, law.n, True), False: spec.kernel(law.zeta, law.n, False)}
        # restitution ends at d = 0 or, for a law whose raw force can reach 0 first, there; the
        # Hertz-damp factor 1 + zeta u only while an external force pulls (used with al < 0)
        self._separations = (spec.separation_function(law.zeta, law.n),
                             spec.separation_function(law.zeta, law.n, pulled=True))
        self._separation = self._separations[0]
        self._sticks = spec.sticks and law.zeta > 0.0   # a push between the branches holds it (rule 4)
        self.in_contact = False
        self.approaching = False
        self.sticking = False       # held at delta_dot = 0 between the law's two branches (rule 4)
        self.v_imp = 0.0            # latched approach speed of the latest impact, m/s
        self.d = 0.0                # internal scaled penetration (in contact)
        self.u = 0.0                # internal scaled rate (in contact)
        self.e = 0.0                # scaled energy dissipated by the current impact (unit m v_imp^2)
        self.e_top = 0.0            # largest e - margin so far (reported while in contact: never decreases)
        self.offset = 0.0           # m, apparent overlap left by a resolved impact
        self.delta_end = 0.0        # m, internal penetration at the end of the last step
        self.delta_dot_end = 0.0    # m/s
        self.stepped = False        # a step has been taken
        self.ahead = 0.0            # N s, impulse handed over ahead of the internal trajectory (rule 7)
        self.rate0 = 0.0            # m/s, the resolver's own rate at the start of the current step
        self.just_separated = False
        self.after_open = False     # the last step was skipped as declared open (rule 8)
        self.dtau = 1e-3            # next internal step, scaled
        self.a0 = 0.0               # m/s^2, external relative acceleration at the step start
        self.a1 = 0.0               # m/s^3, its rate over the step
        self.correction = (0.0, 0.0)  # (m, m/s) last correction applied to the internal state
        self.impacts = 0            # contacts that reached graze_depth (counted when they do)
        self.grazes = 0             # completed contacts that never reached graze_depth
        self.started = 0            # contacts begun
        self.ended = 0              # contacts completed (impacts and grazes)
        self.counted = False        # the current/latest contact is counted as an impact
        self.onset_offset = 0.0     # s into its step at which the latest contact began
        self.peak_tau = 0.0         # scaled time from the onset to impact_peak
        #: None, or a list that receives (contact number, s since its onset, force N, penetration m)
        #: at every accepted internal point: a contact's own trajectory (the master's replays)
        self.trace = None
        self.E_completed = 0.0      # J, all completed impacts
        self.F_max = 0.0            # N
        self.impact_peak = 0.0      # N, current/latest impact
        self.impact_time = 0.0      # s, elapsed contact time of current/latest impact
        self.delta_max = 0.0        # m, current/latest impact
        self.last_CR = math.nan     # achieved CR of the latest completed impact
        self.last_E = 0.0           # J dissipated by the latest completed impact
        self._prev = ()             # last two force samples for peak interpolation
        self._sep = (0.0, 0.0)      # (m, m/s) state at the latest separation, shifted to delta <= 0
        self._scaled = (None,)      # _scales() of the latest v_imp, and that v_imp first

    def snapshot(self) -> "ImpactResolver":
        """A copy as independent as ``copy.deepcopy`` gives, for an FMU state, at a tenth of its
        cost: what can change in place (the observer's notices, the trace) is copied; the law
        (frozen) and the kernel tables built by ``__init__`` are shared, being never changed
        (tests/test_contact_snapshots.py walks both copies for anything else shared)."""
        new = copy.copy(self)
        new.observer = self.observer.snapshot()
        if self.trace is not None:
            new.trace = list(self.trace)
        return new

    # -- derived outputs -------------------------------------------------------------------
    def _scales(self):
        """(v_imp [m/s], L [m], T [s], F0 [N]): the latest impact's scales, computed once per
        approach speed (a power; asked for at every step, t_peak's included)."""
        v = self.v_imp
        cached = self._scaled
        if cached[0] == v:
            return cached
        L = self.law.length_scale(v)
        self._scaled = scales = (v, L, L / v, self.law.m * v * v / L)
        return scales

    def peak_delay(self) -> float:
        """Time (s) from the onset of the latest contact to its largest force (at the sample where
        it was found, within one internal step of the refined peak)."""
        return self.peak_tau * self._scales()[2] if self.v_imp > 0.0 else 0.0

    def dissipated_energy(self) -> float:
        """Energy dissipated by all impacts so far, the current one up to now [J]; never decreases."""
        if not self.in_contact:
            return self.E_completed
        # same floating-point expression as in _finish: the total cannot drop by a rounding
        return self.E_completed + self.law.m * self.v_imp * self.v_imp * self.e_top

    # -- external acceleration -------------------------------------------------------------
    def _ext_rate(self, t: float, r: float) -> float:
        """Rate change [m/s] from the external acceleration over [t, t + r] of the step."""
        return self.a0 * r + self.a1 * (t * r + 0.5 * r * r)

    def _ext_position(self, t: float, r: float) -> float:
        """Position change [m] from the external acceleration over [t, t + r], from rest."""
        return 0.5 * self.a0 * r * r + self.a1 * (0.5 * t * r * r + r * r * r / 6.0)

    def _follow(self, delta: float, delta_dot: float, h: float) -> None:
        """Rule 1-2: learn the structures' motion, correct the resolver's own state by the
        difference between the clean structural increment and the one assumed."""
        if not self.follow_host:
            self.a0 = self.a1 = 0.0
            return
        observer = self.observer
        cx, cu = observer.observe(delta, delta_dot, h)
        cx, cu = float(cx), float(cu)
        self.a0, self.a1 = float(observer.a0), float(observer.a1)
        self.correction = (cx, cu)
        if cx == 0.0 and cu == 0.0:
            return
        if self.in_contact:
            v, L = self._scales()[:2]
            self.d += cx / L
            self.u += cu / v
        self.delta_end += cx
        self.delta_dot_end += cu

    # -- one communication step ------------------------------------------------------------
    def step(self, delta: float, delta_dot: float, h: float, gap_open: bool = False) -> StepOutcome:
        """Advance over ``h`` [s] from the host's ``delta`` [m], ``delta_dot`` [m/s] at the step start.

        ``gap_open``: the host declares the gap open over the whole step (rule 8); the step is then
        skipped if the bodies are apart at its start and the contact can skip it (:meth:`can_skip`),
        else taken as an ordinary one."""
        if not (h > 0.0 and math.isfinite(h)):
            raise ValueError(f"communication step h = {h!r} s is outside the allowed range h > 0")
        delta, delta_dot = float(delta), float(delta_dot)
        if gap_open and delta <= 0.0 and self.can_skip():
            return self.open_step(delta, delta_dot, h)
        out = StepOutcome()
        self._follow(delta, delta_dot, h)
        d0, v0 = (0.0, 0.0) if self.in_contact else self._flight_start(delta, delta_dot)
        self.rate0 = self.u * self.v_imp if self.in_contact else v0   # m/s, own rate at the step start
        self._advance(0.0, h, d0, v0, out)
        # the force law is compressive; a quadrature of a force that fades to zero at
        # separation can sum to -1e-29 N s, which must not reach the host as tension
        internal = own = max(out.impulse, 0.0)
        lead = self.observer.lead if self.follow_host else 0.0
        if lead > 0.0 or self.ahead != 0.0 or (self.follow_host and self.observer.owed() > 0.0):
            out.impulse, internal = self._hand_over(internal, lead, h)
        else:
            out.impulse = internal
        out.mean_force = out.impulse / h
        if self.follow_host:
            self.observer.record(out.mean_force, h, internal, (own, self.rate0, self.delta_dot_end))
        self.stepped = True
        return out

    def can_skip(self) -> bool:
        """True when a step declared open may be skipped (rule 8): out of contact, with every
        impulse handed over delivered to the host (nothing ahead, none on its way)."""
        if self.in_contact or self.ahead != 0.0:
            return False
        return not self.follow_host or self.observer.quiet_steps >= self.observer.support

    def open_step(self, delta: float, delta_dot: float, h: float) -> StepOutcome:
        """A step of ``h`` [s] the host declared open, from the host's ``delta`` [m], ``delta_dot``
        [m/s] at its start (rule 8; the caller checked :meth:`can_skip`): the structures' motion
        learnt as after any step, no force, no onset, no flight predicted.  ``delta_end``,
        ``delta_dot_end`` are the host's values at the step start; the next step starts from the
        host's state."""
        self._follow(delta, delta_dot, h)
        if self.follow_host:
            self.observer.record(0.0, h, 0.0, (0.0, delta_dot, delta_dot))
        self.offset = 0.0
        self.just_separated = False
        self.after_open = True
        self.delta_end, self.delta_dot_end = delta, delta_dot
        self.rate0 = delta_dot
        self.stepped = True
        return StepOutcome()

    def _probe(self, h: float, span: float) -> float:
        """Impulse [N s] the resolver's own bodies will receive over ``span`` s after this step."""
        probe = copy.copy(self)
        probe.trace = None          # a look ahead, not the trajectory (a shallow copy shares the list)
        out = StepOutcome()
        probe._advance(h, h + span, probe.delta_end, probe.delta_dot_end, out)
        return max(out.impulse, 0.0)

    def _hand_over(self, internal: float, lead: float, h: float) -> tuple[float, float]:
        """Rule 7: the impulse [N s] to hand over this step, and the internal one to book.

        The host delivers our force ``lead`` steps late on average: hand it over that much
        early, so that it reaches the host's structures when it acts on the resolver's own
        bodies (``ahead`` keeps the difference; momentum is exact over an episode).  While the
        timing has given the host energy (the host's kernel was not yet known), hand over
        early or late by the step that takes it back: ``int C A dt`` (HostObserver._book_timing)
        changes by ``dJ A h`` when ``dJ`` is handed over one step early.
        """
        target = self._probe(h, lead * h) if lead > 0.0 else 0.0
        debt = self.observer.owed()
        a_next = self.a0 + self.a1 * h
        if debt > _DEBT_TOLERANCE * self.law.m * self.v_imp * self.v_imp and a_next != 0.0 \
                and (self.in_contact or target > 0.0):
            shift = -debt / (a_next * h)
            if shift > 0.0:                       # early: at most the next step's impulse
                shift = min(shift, self._probe(h, (lead + 1.0) * h) - target)
            target += shift
        emitted = max(internal + target - self.ahead, 0.0)
        withheld = self._withhold(emitted, internal, h) if self.follow_host and self.observer.untimed else 0.0
        self.ahead += emitted - internal
        emitted, internal = emitted - withheld, internal - withheld
        if not self.in_contact and target <= 0.0 and self.ahead > 0.0:
            # handed over for an impact the resolver's own motion did not make after all:
            # the host has it, so the bodies have it (momentum)
            self.delta_dot_end -= self.ahead / self.law.m
            internal += self.ahead
            self.ahead = 0.0
        return emitted, internal

    def _withhold(self, emitted: float, internal: float, h: float) -> float:
        """Impulse [N s] of this step's hand-over ``emitted`` to keep from the host for good, so
        that the energy a late host gains before its timing is known is taken back at once.

        Before the first impact has shown the host's kernel the hand-over is timed for the
        provisional one, and a host later than that gains ``int C A dt`` (rule 7), mostly after
        the last impulse has been handed over, when no shift of the hand-over can take it back
        (the two oscillators of the host matrix in HHT-alpha, Jacobi order, at 10 ms: 9 % of
        the system's energy in a first impact of three steps).  Called only in such an episode
        (``HostObserver.untimed``).  The energy is projected to the end of the episode
        (:meth:`HostObserver.projected_debt`: the host timed as the standard host the rows fit
        best, the resolver's own impact continued over the coming steps and handed over as
        rule 7 times it), and what exceeds the tolerance is
        taken back by handing over ``dJ`` less: the host's relative rate is then ``dJ / m``
        higher, which takes ``g dJ + dJ^2 / (2 m)`` from its relative kinetic energy, ``g``
        the host's separation speed while it would have received ``dJ`` (the resolver's own
        minus ``C / m``, weighted by the kernel).  A host the kernel times right gains
        nothing, and nothing is withheld; where the projection is off the host loses some
        contact energy instead (the criterion is one-sided: energy created is forbidden, a
        contact energy error within 15 % is allowed).  Then, measured on the host's side
        (:meth:`_passivity`), as much more as the smallest projection over the host timings the
        rows do not exclude still shows created beyond ``_PASSIVITY_TOLERANCE``, found by
        bisection on that projection, and only while the host's bodies separate.  The host's bodies receive ``dJ`` less relative impulse than the
        resolver's own: their total momentum is unchanged (the force pair is equal and
        opposite), and out of contact the host's state is the truth again (rule 2).
        """
        obs, m = self.observer, self.law.m
        if not emitted > 0.0:
            return 0.0
        probe = copy.copy(self)
        probe.trace = None          # a look ahead, not the trajectory (a shallow copy shares the list)
        future, rates = [], [self.delta_dot_end]    # impulses [N s]; rates [m/s] at the step ends
        for j in range(1, _WITHHOLD_HORIZON + 1):
            out = StepOutcome()
            probe._advance(j * h, (j + 1) * h, probe.delta_end, probe.delta_dot_end, out)
            future.append(max(out.impulse, 0.0))
            rates.append(probe.delta_dot_end)
        # the coming hand-overs as rule 7 times them: by the end of coming step j, what the own
        # bodies receive up to ``lead`` steps later (the cumulative impulse interpolated linearly)
        cumulative = [0.0]
        for J in future:
            cumulative.append(cumulative[-1] + J)
        lead = min(obs.lead, float(len(future)))
        handed = self.ahead + emitted - internal   # N s, handed over beyond the own bodies' so far
        emissions = [emitted]
        for j in range(1, len(future) + 1):
            x = min(j + lead, float(len(future)))
            i = min(int(x), len(future) - 1)
            due = cumulative[i] + (x - i) * future[i] if x < len(future) else cumulative[-1]
            emissions.append(max(due - handed, 0.0))
            handed = max(handed, due)
        emissions = emissions[:len(future)]
        debt, C = obs.projected_debt(emissions, [internal] + future, h)
        tolerance = _WITHHOLD_TOLERANCE * m * self.v_imp * self.v_imp
        excess = debt - obs.repaid - tolerance
        # the host's relative rate while it receives this step's impulse: the resolver's own
        # minus C / m (C at the step's middle), weighted by the kernel
        kernel = obs.delivery_kernel()
        C.append(C[-1])
        g = -sum(w * (0.5 * (rates[max(i - 1, 0)] + rates[i]) - 0.5 * (C[i] + C[i + 1]) / m)
                 for i, w in enumerate(kernel))
        dJ = 0.0
        if excess > 0.0 and g > 0.0:
            dJ = min(m * (math.sqrt(g * g + 2.0 * excess / m) - g), emitted)
            obs.repaid += g * dJ + 0.5 * dJ * dJ / m
        impulses, boundaries = [internal] + future, [self.rate0] + rates

        # the same, measured on the host's side (_passivity): what every plausible host timing
        # shows created beyond the tolerance is withheld too, while the host separates (withheld
        # from bodies that still approach, an impulse gives them energy)
        tolerance = _PASSIVITY_TOLERANCE * m * self.v_imp * self.v_imp

        def created(x):
            return self._passivity([emitted - x] + emissions[1:], impulses, boundaries, h)[0]

        before, g_host = self._passivity([emitted - dJ] + emissions[1:], impulses, boundaries, h) \
            if obs.last is not None else (0.0, 0.0)
        if before > tolerance and g_host > 0.0 and created(emitted) < before:
            lo, hi = dJ, emitted          # all of it when even that leaves more than the tolerance
            if created(hi) <= tolerance:
                for _ in range(40):           # the impulse to 1e-12 of this step's
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if created(mid) > tolerance else (lo, mid)
            dJ = hi
        return dJ

    def _passivity(self, emissions, impulses, rates, h: float) -> tuple[float, float]:
        """Energy [J] this episode will have created in the host, for the host timing the rows do
        not exclude that shows least (:meth:`HostObserver.passivity`), and the host's separation
        speed [m/s] while it receives this step's impulse in that timing.  ``emissions`` [N s]:
        this step's hand-over, then the coming ones; ``impulses`` [N s], ``rates`` [m/s]: the
        resolver's own, from this step on (rates at the steps' boundaries)."""
        obs = self.observer
        least, g = math.inf, 0.0
        for kernel in obs.plausible_kernels():
            created, rates_host = obs.passivity(kernel, (impulses, emissions, rates), h)
            if created < least:
                least, g = created, -sum(w * r for w, r in zip(kernel, rates_host))
        return least, g

    def _advance(self, t: float, t_end: float, d0: float, v0: float, out: StepOutcome) -> None:
        """Flight and impacts from ``t`` to ``t_end`` [s] into the step (d0, v0: flight state at t)."""
        for _ in range(_MAX_IMPACTS_PER_STEP):
            if self.in_contact:
                t = self._integrate(t, t_end, out)
                if self.in_contact:
                    return
                d0, v0 = self._sep
            s = self._onset(d0, v0, t, t_end - t)
            if s is None:
                r = t_end - t
                self.delta_end = d0 + v0 * r + self._ext_position(t, r)
                self.delta_dot_end = v0 + self._ext_rate(t, r)
                return
            v_on = v0 + self._ext_rate(t, s)
            t += s
            self._start(v_on)
            self.onset_offset = t
            out.impacts_started += 1

    def _flight_start(self, delta: float, delta_dot: float):
        """Internal (penetration, rate) out of contact at the step start; sets ``offset`` (rule 5)."""
        # after a step skipped as declared open (rule 8) the host's state is the truth, as at a run's start
        followed = self.follow_host and self.stepped and not self.after_open
        self.after_open = False
        if followed and self.observer.pending():
            # part of an impulse is still on its way to the host: the resolver's own flight
            d0, v0 = self.delta_end, self.delta_dot_end
            self.offset = max(0.0, delta - d0) if delta > 0.0 else 0.0
            if d0 > 0.0:
                self.offset, d0 = self.offset + d0, 0.0
            return d0, v0
        if followed:
            inner = self.delta_end               # internal flight, predicted over the last step
        else:
            inner = self.delta_end if self.just_separated else delta - self.offset
        self.just_separated = False
        v0 = delta_dot
        offset = delta - inner
        if delta <= 0.0 or offset < 0.0:         # host open, or the host is behind the internal state
            offset = 0.0
        d0 = delta - offset
        if d0 > 0.0:                             # overlap the prediction missed: into the offset
            offset += d0
            d0 = 0.0
        self.offset = offset
        return d0, v0

    def _onset(self, d0: float, v0: float, t: float, r: float):
        """First time in (0, r] [s] at which the flight ``d0 + v0 s + ext`` crosses 0 upward, or None."""
        if not r > 0.0:
            return None
        a0, a1 = self.a0 + self.a1 * t, self.a1

        def g(s):
            return d0 + v0 * s + 0.5 * a0 * s * s + a1 * s * s * s / 6.0

        # monotone pieces between the zeros of g' = v0 + a0 s + a1 s^2 / 2
        cuts = [0.0, r]
        if a1 != 0.0:
            disc = a0 * a0 - 2.0 * a1 * v0
            if disc >= 0.0:
                q = math.sqrt(disc)
                cuts += [(-a0 + q) / a1, (-a0 - q) / a1]
        elif a0 != 0.0:
            cuts.append(-v0 / a0)
        cuts = sorted(c for c in cuts if 0.0 <= c <= r)
        g_lo = d0
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            g_hi = g(hi)
            if g_lo <= 0.0 < g_hi:
                if g_lo == 0.0:
                    return lo
                return brentq(g, lo, hi, xtol=1e-15 * r, rtol=1e-15)
            g_lo = g_hi
        return None

    def _start(self, v: float) -> None:
        self.in_contact = True
        self.approaching = True
        self.sticking = False
        self.v_imp = max(v, MIN_IMPACT_SPEED)
        self.d, self.u, self.e, self.e_top = 0.0, 1.0, 0.0, 0.0
        self.started += 1
        self.counted = False
        self.impact_peak = 0.0
        self.peak_tau = 0.0
        self.impact_time = 0.0
        self.delta_max = 0.0
        self._prev = ()
        self.dtau = 1e-3
        self._count_if_deep()

    def _count_if_deep(self) -> None:
        """Count the current contact as an impact once its penetration reaches ``graze_depth``
        (at once when that is 0)."""
        if not self.counted and self.delta_max >= self.graze_depth:
            self.counted = True
            self.impacts += 1

    def _finish(self, d: float, u: float, L: float, v: float) -> None:
        """Book a completed impact that separated at scaled (d, u)."""
        n, m = self.law.n, self.law.m
        # a force separation with d > 0 leaves the spring energy of the overlap behind: lost
        e = max(self.e_top, self.e) + (d ** (n + 1.0) / (n + 1.0) if d > 0.0 else 0.0)
        self._count_if_deep()
        if not self.counted:
            self.grazes += 1
        self.ended += 1
        if self.trace is not None:        # the separation point (impact_time: the whole contact)
            self.trace.append((self.started, self.impact_time, 0.0, d * L))
        self.in_contact = False
        self.just_separated = True
        self.last_CR = max(0.0, -u)
        self.last_E = m * self.v_imp * self.v_imp * e
        self.E_completed += self.last_E
        self._sep = (min(d, 0.0) * L, u * v)   # the overlap at a force separation goes to the offset

    def _integrate(self, t: float, h: float, out: StepOutcome) -> float:
        """Integrate the current impact from ``t`` [s] into the step; returns the time reached."""
        v, L, T, F0 = self._scales()
        m = self.law.m
        # external acceleration in scaled units: alpha(tau) = al0 + al1 tau from time t
        al0 = (self.a0 + self.a1 * t) * T / v
        al1 = self.a1 * T * T / v
        tau = 0.0
        tau_end = (h - t) / T
        # 1e-10: a pull below 1e-10 of the impact's force scale cannot clip the force before
        # round-off in 1 + zeta u does (LawSpec.separation_function, pulled)
        self._separation = self._separations[1 if min(al0, al0 + al1 * tau_end) < -1e-10 else 0]
        u_ref = self.u                            # impulse = m (ext rate change - internal rate change)
        d, u = self.d, self.u
        # branch consistent with the (possibly corrected) state
        if self.sticking:
            u = 0.0                               # held: a correction of the rate goes into the force
        elif self.approaching and u <= 0.0:
            self._switch_to_restitution(d, u, L)
        elif not self.approaching and u > _REAPPROACH_RATE:
            self.approaching = True
        f = self._kernels[self.approaching]
        if not self.approaching and self._separation(d, u) <= 0.0:
            self._finish(d, u, L, v)
            out.impacts_completed += 1
            return t
        fs = f(d, u)
        acc = al0 - fs
        nfev = 1
        base = self.impact_time / T               # scaled contact time at the step start
        if not self._prev:
            nfev += self._sample(base, fs, d, u, acc, al0, al1, self.approaching, out, F0)
        atol = rtol = self.rtol
        dtau = self.dtau
        e, e_top = self.e, self.e_top
        # the identity drifts by the integration error (~rtol) where the true power is 0: the
        # reported value trails it by this margin, so that booking the completed impact's own
        # value (exact for free masses) never lowers the total
        margin = 10.0 * self.rtol
        separated = False
        switches = 0
        substeps = 0
        # the loop's callees and bounds as locals: it runs ~5 times per communication step
        dp_step, sample, separation, dissipated = self._dp_step, self._sample, self._separation, self._dissipated
        stop = tau_end * (1.0 - 1e-15)
        while tau < stop:
            if self.sticking:
                tau = self._stick(d, al0, al1, tau, tau_end, base, out, F0)
                if self.sticking:
                    break
                f = self._kernels[self.approaching]
                fs = f(d, 0.0)
                acc = al0 + al1 * tau - fs
                continue
            rest = tau_end - tau
            hs = rest if rest < dtau else dtau        # min(dtau, rest), without the builtin's call
            last = hs >= rest
            al_t = al0 + al1 * tau
            stepped = dp_step(f, al_t, al1, d, u, acc, hs, atol, rtol)
            d1, u1, acc1, f1, err = stepped
            nfev += 6
            if err > 1.0:
                dtau = hs * max(0.2, 0.9 * err ** -0.2)
                continue
            substeps += 1
            event = None
            if self.approaching:
                if u1 <= 0.0:
                    event = "max_penetration"
            else:
                if separation(d1, u1) <= 0.0:
                    event = "separation"
                if u1 > _REAPPROACH_RATE and switches < _MAX_SWITCHES_PER_STEP:
                    event = "reapproach" if event is None else self._first_event(
                        f, al_t, al1, d, u, acc, hs, stepped, atol, rtol)
            if event is not None:
                switches += 1
                g = self._event_function(event)
                hs, d1, u1, _, _, n_ev = self._locate(f, al_t, al1, d, u, acc, hs, stepped, g, atol, rtol)
                nfev += n_ev
                # the located step, from its accepted start: where a peak before the event is searched
                located = ((base + tau, 0.0, d, u, acc, self.approaching, al_t, al1), hs)
                tau += hs
                e += self._dissipated(d, u, d1, u1, al_t, al1, hs)
                e_top = e - margin if e - margin > e_top else e_top
                d, u = d1, u1
                if event == "separation":
                    separated = True
                    break
                self.e, self.e_top = e, e_top
                if event == "max_penetration":
                    u = 0.0
                    f_end = f(d, 0.0)
                    nfev += self._sample(base + tau, f_end, d, u, al0 + al1 * tau - f_end, al0 + al1 * tau, al1,
                                         True, out, F0, located, branch_end=True)
                    self._switch_to_restitution(d, u, L)
                    self.sticking = self._holds(d, al0 + al1 * tau)
                else:                                     # re-approach: the dashpot acts again ...
                    self.approaching = True
                    if self._holds(d, al0 + al1 * tau):   # ... unless its force would push back at once
                        self.approaching, self.sticking, u = False, True, 0.0
                if self.sticking:
                    continue
                f = self._kernels[self.approaching]
                fs = f(d, u)
                acc = al0 + al1 * tau - fs
                nfev += 1 + self._sample(base + tau, fs, d, u, acc, al0 + al1 * tau, al1, self.approaching,
                                         out, F0)
                dtau = hs if hs > 0.0 else dtau
                continue
            # the accepted step, from its start: where the force's peak is searched (_sample)
            accepted = ((base + tau, 0.0, d, u, acc, self.approaching, al_t, al1), hs)
            tau += hs
            e += dissipated(d, u, d1, u1, al_t, al1, hs)
            e_top = e - margin if e - margin > e_top else e_top
            d, u, acc = d1, u1, acc1
            nfev += sample(base + tau, f1, d, u, acc, al0 + al1 * tau, al1, self.approaching, out, F0, accepted)
            if not last:
                # min(5.0, 0.9 * max(err, 1e-10) ** -0.2): the same values (NaN included)
                grow = 0.9 * (1e-10 if 1e-10 > err else err) ** -0.2
                dtau = hs * (grow if grow < 5.0 else 5.0)
        out.substeps += substeps
        self.dtau = dtau
        t_used = tau * T
        self.impact_time += t_used
        # impulse = m * (change of rate due to the external acceleration - change of the rate)
        out.impulse += m * (v * (u_ref - u) + self._ext_rate(t, t_used))
        out.nfev += nfev
        self.d, self.u, self.e, self.e_top = d, u, e, e_top
        if separated:
            self._finish(d, u, L, v)
            out.impacts_completed += 1
            return t + t_used
        self.delta_end = d * L
        self.delta_dot_end = u * v
        self.delta_max = max(self.delta_max, d * L)
        self._count_if_deep()
        return h

    def _holds(self, d: float, alpha: float) -> bool:
        """True if the contact sticks at scaled penetration ``d`` under the scaled external
        acceleration ``alpha``: pushed together harder than the restitution branch holds at zero
        rate, less than the approach branch does (crvk's force drop).  Neither branch is then
        consistent; the solution is Filippov's sliding motion, as in cosim/peers/reference.py.
        Only a law that :attr:`~.contact_laws.LawSpec.sticks` (for the others the two forces
        are equal at zero rate, and the band is empty)."""
        if not self._sticks:
            return False
        f_approach = self._kernels[True](d, 0.0)
        f_restitution = self._kernels[False](d, 0.0)
        return f_restitution < alpha < f_approach

    def _stick(self, d, al0, al1, tau, tau_end, base, out, F0) -> float:
        """Hold the penetration from ``tau`` while ``alpha(s) = al0 + al1 s`` stays between the
        branches' forces at ``d``; returns where it leaves (into approach above the upper one,
        restitution below the lower one) or ``tau_end``.  The force is ``alpha``: no work, no
        dissipation; the impulse is the external rate change (_integrate's bookkeeping)."""
        upper = self._kernels[True](d, 0.0)
        lower = self._kernels[False](d, 0.0)
        end = tau_end
        if al1 > 0.0:
            end = min(end, (upper - al0) / al1)
        elif al1 < 0.0:
            end = min(end, (lower - al0) / al1)
        end = max(end, tau)
        for s in (tau, end):                      # the force is linear in time: peaks at the ends
            F = (al0 + al1 * s) * F0
            out.peak_force = max(out.peak_force, F)
            self.impact_peak = max(self.impact_peak, F)
            self.F_max = max(self.F_max, F)
        if end < tau_end:
            self.sticking = False
            self.approaching = al1 > 0.0
        self._prev = ()
        return end

    def _dissipated(self, d, u, d1, u1, al, al1, hs) -> float:
        """Scaled energy dissipated over one internal step from (d, u) to (d1, u1), length ``hs``.

        Energy identity of ``u' = alpha - f``: ``int f u = int alpha u - [u^2 / 2]``, minus the
        energy stored in the spring, ``[d^(n+1) / (n+1)]``.  With ``alpha = al + al1 s``,
        ``int alpha u = [alpha d] - al1 int d`` (``int d`` by the Hermite rule, exact to h^5).
        For free masses (alpha = 0) the sum over an impact telescopes to
        ``(1 - u_out^2) / 2``: the kinetic energy the host loses, to round-off.
        """
        n1 = self.law.n + 1.0
        s0 = d ** n1 / n1 if d > 0.0 else 0.0
        s1 = d1 ** n1 / n1 if d1 > 0.0 else 0.0
        work = 0.0
        if al != 0.0 or al1 != 0.0:
            work = (al + al1 * hs) * d1 - al * d - al1 * hs * (0.5 * (d + d1) + hs * (u - u1) / 12.0)
        return 0.5 * (u * u - u1 * u1) + (s0 - s1) + work

    def _switch_to_restitution(self, d: float, u: float, L: float) -> None:
        self.approaching = False
        self.delta_max = max(self.delta_max, d * L)
        self._count_if_deep()

    def _event_function(self, event: str):
        if event == "max_penetration":
            return lambda dd, uu: uu
        if event == "reapproach":
            return lambda dd, uu: _REAPPROACH_RATE - uu
        return self._separation

    def _first_event(self, f, al_t, al1, d, u, acc, hs, stepped, atol, rtol) -> str:
        """Separation and re-approach both inside one step (``stepped``: its DP step): the one
        located first."""
        t_sep = self._locate(f, al_t, al1, d, u, acc, hs, stepped, self._separation, atol, rtol)[0]
        t_re = self._locate(f, al_t, al1, d, u, acc, hs, stepped, self._event_function("reapproach"), atol, rtol)[0]
        return "separation" if t_sep <= t_re else "reapproach"

    def _sample(self, tau, fs, d, u, acc, al, al1, approaching, out, F0, step=None,
                branch_end=False) -> int:
        """Track the peak force at an accepted point; returns the force evaluations spent.

        ``step``: the accepted Dormand-Prince step that ended here, as (its start, as a sample
        tuple, and its scaled length), None at a branch's first point; a step that ends at the
        end of the approach branch (maximum penetration) is the located one.  Where the
        samples of a branch show a local maximum, the force is maximised along the two
        accepted steps around it, end to end (one bounded Brent search, :func:`bounded_minimum`,
        :meth:`_refine_across`), each re-integrated from its own accepted start with the
        external acceleration it used: the trajectory the resolver actually took, after any
        correction at a communication step's start (rule 2).  So is the step that rises into
        the end of the approach branch.  The peak is never below the largest sample, and it
        does not depend on where samples fall.  (The search this replaced ran one DP step from
        the sample before the maximum: at a step's boundary that is the previous step's end
        state, before the correction, with the previous step's external acceleration.)
        """
        peak = fs
        nfev = 0
        prev = self._prev
        sample = (tau, fs, d, u, acc, approaching, al, al1, step)
        # the earlier samples on the same branch, in order (at most the last two)
        if len(prev) == 2:
            first, second = prev
            if first[5] != approaching:
                same = (second,) if second[5] == approaching else ()
            else:
                same = prev if second[5] == approaching else (first,)
        else:
            same = prev if prev and prev[0][5] == approaching else ()
        if len(same) == 2 and same[1][1] >= same[0][1] and same[1][1] >= fs:
            # the maximum lies on the step into the middle sample or on the one out of it:
            # one search along both, end to end
            peak = max(peak, same[1][1])
            p, n_ev = self._refine_across(same[1][8], step)
            peak, nfev = max(peak, p), nfev + n_ev
        if branch_end and step is not None and same and fs >= same[-1][1]:
            p, n_ev = self._refine_peak(*step)   # rising into the branch's end: along the located step
            peak, nfev = max(peak, p), nfev + n_ev
        self._prev = (prev[-1], sample) if prev else (sample,)
        if self.trace is not None:
            _, L, T, _ = self._scales()
            self.trace.append((self.started, tau * T, fs * F0, d * L))
        F = peak * F0
        if F > out.peak_force:
            out.peak_force = F
        if F > self.impact_peak:
            self.impact_peak = F
            self.peak_tau = tau
        if F > self.F_max:
            self.F_max = F
        return nfev

    def _refine_across(self, first, second):
        """Largest scaled force along two consecutive accepted steps, each ``(start, length)``
        or None (:meth:`_sample`), taken end to end: one bounded search over their joined
        length, each point on the step it falls in, re-integrated from that step's start (the
        second's start may differ from the first's end by a correction, rule 2)."""
        if first is None or second is None:
            accepted = first if second is None else second
            return self._refine_peak(*accepted) if accepted is not None else (0.0, 0)
        (s1, span1), (s2, span2) = first, second
        if not (span1 > 0.0 and span2 > 0.0):
            (p1, n1), (p2, n2) = self._refine_peak(s1, span1), self._refine_peak(s2, span2)
            return max(p1, p2), n1 + n2
        rtol, dp_step = self.rtol, self._dp_step
        f1, f2 = self._kernels[s1[5]], self._kernels[s2[5]]
        _, _, d1, u1, acc1, _, al1, al11 = s1[:8]
        _, _, d2, u2, acc2, _, al2, al21 = s2[:8]

        def minus_force(x):
            if x <= span1:
                return -dp_step(f1, al1, al11, d1, u1, acc1, x, rtol, rtol)[3]
            return -dp_step(f2, al2, al21, d2, u2, acc2, x - span1, rtol, rtol)[3]

        span = span1 + span2
        lowest, calls = bounded_minimum(minus_force, span, _PEAK_XATOL * span)
        return -lowest, 6 * calls

    def _refine_peak(self, sample, span):
        """Largest scaled force along a DP step of length in (0, span] from ``sample`` (the
        accepted start of a step, a sample tuple)."""
        _, f0, d, u, acc, approaching, al, al1 = sample[:8]
        if not span > 0.0:
            return f0, 0
        f = self._kernels[approaching]
        rtol = self.rtol

        def minus_force(x):
            return -self._dp_step(f, al, al1, d, u, acc, x, rtol, rtol)[3]   # f at the step's end

        lowest, calls = bounded_minimum(minus_force, span, _PEAK_XATOL * span)
        return -lowest, 6 * calls

    @staticmethod
    def _dp_step(f, al, al1, d, u, a1, hs, atol, rtol):
        """One Dormand-Prince step of ``d' = u, u' = al + al1 s - f(d, u)``; returns (d, u, u',
        force, error norm).  The dissipated energy is booked from the step's ends
        (:meth:`_dissipated`), not integrated here: the kernels return the force alone."""
        # stage states (d_i, u_i) and derivatives (u_i, a_i); hs * _A21 * x is (hs * _A21) * x
        h21 = hs * _A21
        d2 = d + h21 * u
        u2 = u + h21 * a1
        f2 = f(d2, u2)
        a2 = al + al1 * _C2 * hs - f2
        d3 = d + hs * (_A31 * u + _A32 * u2)
        u3 = u + hs * (_A31 * a1 + _A32 * a2)
        f3 = f(d3, u3)
        a3 = al + al1 * _C3 * hs - f3
        d4 = d + hs * (_A41 * u + _A42 * u2 + _A43 * u3)
        u4 = u + hs * (_A41 * a1 + _A42 * a2 + _A43 * a3)
        f4 = f(d4, u4)
        a4 = al + al1 * _C4 * hs - f4
        d5 = d + hs * (_A51 * u + _A52 * u2 + _A53 * u3 + _A54 * u4)
        u5 = u + hs * (_A51 * a1 + _A52 * a2 + _A53 * a3 + _A54 * a4)
        f5 = f(d5, u5)
        a5 = al + al1 * _C5 * hs - f5
        d6 = d + hs * (_A61 * u + _A62 * u2 + _A63 * u3 + _A64 * u4 + _A65 * u5)
        u6 = u + hs * (_A61 * a1 + _A62 * a2 + _A63 * a3 + _A64 * a4 + _A65 * a5)
        f6 = f(d6, u6)
        a6 = al + al1 * hs - f6
        dn = d + hs * (_B1 * u + _B3 * u3 + _B4 * u4 + _B5 * u5 + _B6 * u6)
        un = u + hs * (_B1 * a1 + _B3 * a3 + _B4 * a4 + _B5 * a5 + _B6 * a6)
        fn = f(dn, un)
        an = al + al1 * hs - fn
        ed = hs * (_E1 * u + _E3 * u3 + _E4 * u4 + _E5 * u5 + _E6 * u6 + _E7 * un)
        eu = hs * (_E1 * a1 + _E3 * a3 + _E4 * a4 + _E5 * a5 + _E6 * a6 + _E7 * an)
        # max(abs(a), abs(b)) written out (the same values: max keeps its first argument unless
        # the second is larger): two builtin calls fewer per norm, a tenth of the step's cost
        a, b = (d if d >= 0.0 else -d), (dn if dn >= 0.0 else -dn)
        sd = atol + rtol * (b if b > a else a)
        a, b = (u if u >= 0.0 else -u), (un if un >= 0.0 else -un)
        su = atol + rtol * (b if b > a else a)
        a, b = (ed if ed >= 0.0 else -ed) / sd, (eu if eu >= 0.0 else -eu) / su
        return dn, un, an, fn, (b if b > a else a)

    def _locate(self, f, al, al1, d, u, acc, hs, stepped, g, atol, rtol):
        """Step length in (0, hs] where ``g`` of the DP step's end state reaches 0 (Illinois);
        ``stepped``: the DP step of length ``hs`` itself, already taken.

        Returns (length, d, u, u', force, force evaluations).
        """
        a, ga = 0.0, g(d, u)
        b = hs
        gb = g(stepped[0], stepped[1])
        best = (b,) + stepped[:4]
        nfev = 0
        side = 0
        for _ in range(60):
            if gb == 0.0 or (b - a) <= 1e-14 * max(hs, 1e-300):
                break
            c = (a * gb - b * ga) / (gb - ga) if gb != ga else 0.5 * (a + b)
            if not (a < c < b):
                c = 0.5 * (a + b)
            step = self._dp_step(f, al, al1, d, u, acc, c, atol, rtol)
            nfev += 6
            gc = g(step[0], step[1])
            if gc > 0.0:
                a, ga = c, gc
                if side == -1:
                    gb *= 0.5
                side = -1
            else:
                b, gb = c, gc
                best = (c,) + step[:4]
                if side == 1:
                    ga *= 0.5
                side = 1
            if abs(gc) < 1e-15:
                best = (c,) + step[:4]
                break
        return best + (nfev,)
