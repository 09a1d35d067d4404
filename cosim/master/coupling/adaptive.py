"""Adaptive communication step with rollback.

:class:`Adaptive` is a :class:`~cosim.master.coupling.base.CouplingStrategy`: one call of
:meth:`Adaptive.step` makes one *accepted* Gauss-Seidel communication step (ground, contacts
from the buildings at t, buildings), of a length chosen per step:

* Step sizes are dyadic fractions ``h_max / 2**j`` of the base step (``j = 0 .. max_halvings``)
  and every step starts on a multiple of its own size, so time is an integer count of the
  finest step (no round-off drift) and the building FMU, which caches its exact propagator
  per step size, sees only ``max_halvings + 1`` sizes (plus the last, clipped one).
* *Apart*: for each contact level the master predicts the earliest possible closure of the
  gap from the floors' outputs, ``delta = x1 - x2 - gap < 0``, ``delta_dot = v1 - v2``
  (> 0 approaching), ``delta_ddot = a1 - a2`` (absolute accelerations: the ground motion
  cancels) and an acceleration bound ``A = accel_safety |delta_ddot| + pga``::

      delta + delta_dot s + A s^2 / 2 = 0   ->   s* (time to closure, s)

  and takes the largest aligned dyadic step not longer than ``s*``; the step grows back by
  at most a factor 2 per step when the floors are apart.
* *Quiet*: where every gap is proven open (:mod:`cosim.master.gap_bound`) for the step and one
  base step more, aligned steps of up to ``max_long_step`` (0.32 s): the buildings integrate
  the record's knots exactly across them (:mod:`cosim.master.knots`), the contacts sleep
  through them (:mod:`cosim.master.dormancy`).  Default scene: 411 steps instead of 4012.
* *In contact* (and for the step that closes the gap) the step is at most
  ``contact_fraction * T`` with ``T = L / v`` the impact's time scale,
  ``L = (m v^2 / k)^(1/(n+1))`` (:meth:`~fmu_src.contact_laws.ContactLaw.length_scale`),
  ``v`` the approach speed (predicted before the onset, latched after it).
* *Onset*: with resolved impacts the step that may close the gap and the contact's first step
  in contact are at most ``onset_fraction * T`` (half the contact step, :data:`ONSET_RATIO`),
  for an impact at least :data:`ONSET_SPEED_SHARE` as fast as the fastest so far: the host
  holds the step's mean contact force while the impact starts part-way through the step, and
  the contact FMU learns the structures' push one step late; both errors sit in these steps.
  Not for a contact law that sticks (:func:`takes_onset_steps`).
* *Rollback*: before a step in which the gap may close (``s* < risk_factor h``) and that is
  longer than the contact step at :data:`SAVE_SPEED_MARGIN` times the closing speed's bound
  (a shorter one is accepted whatever closes in it) every FMU's state is saved
  (``fmi2GetFMUstate``; a sleeping contact's is the one it fell asleep with, kept by
  :mod:`cosim.master.dormancy`); if the gap did close inside a step longer than the
  contact step, every FMU is restored (``fmi2SetFMUstate``) and the step is retried with the
  largest dyadic step not longer than the crossing time interpolated from the step's end
  points (not blind halving).  States are saved only for such steps because saving costs
  about as much as a step (pythonfmu deep-copies the slave: ~130 us for the four FMUs of
  the default scene).  A closure inside an unsaved step is accepted and counted in
  ``stats["missed_events"]``.

The scheme inside a step is Gauss-Seidel.  With ``resolve_impacts = true`` (the package's
default) the contact FMU integrates each impact inside its step, following the buildings'
motion, and hands over the impulse as a mean force: the master's steps then only need to
land near the onsets and follow the buildings through the contact (``contact_fraction``
1/2).  With ``resolve_impacts = false`` the contact FMU's force is held over the step (first
order in ``h``, ``contact_fraction`` 1/64); it converges to the monolithic solution
(:mod:`cosim.peers.reference`) and its energy bookkeeping is exact: the contact FMU's work
``F (delta_new - delta_old)`` is what the buildings receive.

The contacts are seen through :func:`cosim.master.guard.contact_levels`, the stability
guard's view.
"""
from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np

from ...fmus import POUNDING, fmu_spec
from ..dormancy import Dormancy
from ..gap_bound import GroundAhead, OpenGaps, constant_bound
from ..guard import contact_levels
from ..knots import GroundLookahead
from .base import CouplingStrategy

if TYPE_CHECKING:
    from ..system import System


def closure_time(delta: float, delta_dot: float, accel_bound: float) -> float:
    """Earliest ``s >= 0`` (s) with ``delta + delta_dot s + accel_bound s^2 / 2 >= 0``.

    ``delta`` < 0 is the open gap (m), ``delta_dot`` > 0 approaching (m/s), ``accel_bound``
    >= 0 (m/s^2) bounds how fast the approach can speed up.  ``inf`` if it cannot close.
    """
    if delta >= 0.0:
        return 0.0
    if accel_bound > 0.0:
        # the one positive root of A s^2 / 2 + v s + delta = 0 (delta < 0), without cancellation
        root = math.sqrt(delta_dot * delta_dot - 2.0 * accel_bound * delta)
        if delta_dot > 0.0:
            return -2.0 * delta / (delta_dot + root)
        return (root - delta_dot) / accel_bound
    if delta_dot > 0.0:
        return -delta / delta_dot
    return math.inf


def row_step(row_interval: float, h_base: float) -> float:
    """Longest dyadic step (``h_base`` times a power of 2, s) whose aligned steps land on every
    multiple of ``row_interval`` (s): ``h_base`` times the largest power of 2 dividing
    ``row_interval / h_base``, or ``h_base`` when that is not a whole number."""
    n = round(row_interval / h_base)
    if n < 1 or abs(n * h_base - row_interval) > 1e-9 * row_interval:
        return h_base
    return h_base * (n & -n)


def proof_horizon(h: float, nominal: float, h_base: float) -> float:
    """The horizon (s) of a proof over a step of ``h`` (s) whose nominal length is ``nominal``
    (``h_base`` times a power of 2, s): ``nominal`` plus :data:`PROOF_SLACK` base steps, one
    value per dyadic level whatever round-off ``h`` carries, and never shorter than ``h`` (a
    proof over a longer horizon holds over the step: the bound is a bound from the step's start)."""
    H = nominal + PROOF_SLACK * h_base
    return H if H >= h else h


# -- the strategy ----------------------------------------------------------------------------------
#: base steps a piece of a waking contact's catch-up spans at most (:mod:`cosim.master.dormancy`).
#: The skipped interval itself is one step the master declares open (``gap_open``); pieces are
#: cut only from long steps among the last skipped steps, which the contact takes as it would
#: have, and in a replay: there the resolver predicts a step's flight from the structures' motion
#: over its previous step, which holds over a few base steps
CATCH_UP_STEPS = 4
#: and at most this long (s): the prediction's error grows with the piece's length in seconds, not
#: in base steps (before the declaration, 4 base steps of 20 ms, 0.08 s, started a spurious
#: impact on free_vibration when the whole interval was caught up in pieces; tests/test_dormancy.py)
MAX_CATCH_UP_SPAN = 0.04
#: base steps a proof with no contact force looks ahead (a proof costs about as much as an FMI
#: call or two; a longer horizon is valid longer where the gaps are wide, and no shorter where
#: they are not)
QUIET_HORIZON = 8
#: a long step's proof, after one that held over its whole horizon, looks this many long steps
#: ahead: where the gaps stayed wide one proof then serves the next long step too (a proof is the
#: motion's from the state the run reached, valid until its horizon ends while no force appears,
#: which it proves); if it falls short, the one-step proof is made as before.  Exact proofs
#: (cosim.master.gap_bound._ExactPair) hold over such horizons; the whole ground's bound did not
#: (measured: more proofs and steps).  Default scene 201 -> 164 proofs, kasai_maison 426 -> 395,
#: the same steps
LONG_PROOF_REACH = 2
#: round-off slack (in base steps) on a proof's end time when a long step is fitted inside it
PROOF_SLACK = 1e-9
#: a step's closing speed, as a multiple of the planner's bound on it (``max(delta_dot, 0) + A s*``),
#: up to which a closure inside the step is accepted without a rollback (:meth:`Adaptive._retry_step`
#: accepts a step no longer than the closing step at the speed found): states are saved only for
#: steps that could be rejected.  The bound already doubles the relative acceleration and adds the
#: record's peak; 1.5 more covers an approach speed half as fast again as that (the closing step
#: scales as ``v^(2/(n+1) - 1)``: 8 % shorter for Hertz's n = 3/2).  Saves on the default scene
#: 15 -> 3, kasai_maison 103 -> 0; no rollback and no missed event either way.
SAVE_SPEED_MARGIN = 1.5
#: contact step / impact time scale, by contact mode (chosen from docs/accuracy.md)
CONTACT_FRACTION_RESOLVED = 1.0 / 2.0
CONTACT_FRACTION_PLAIN = 1.0 / 64.0
#: the largest ``contact_fraction`` accepted, measured, not derived: a resolved impact is exact
#: inside one step however long (docs/accuracy.md, hard cases: 10 contact durations), but it
#: learns the buildings' push one communication step late, and a step of 2 T is still shorter
#: than an elastic impact (pi T with a linear spring, 3.22 T with Hertz's n = 3/2).  The accuracy
#: study's coarse family (base step 0.04 s) runs 2 and its five scenes keep the reference's
#: impacts; at 4 free_vibration counts 4 of its 5.  A coarse setting for the cost-accuracy front,
#: not a default (parkfield at that base step counts 10 impacts for 9, at 1 and 2 alike).  With
#: the plain force law a step over 1/4 of T stops the run (the stability guard) whatever this allows
CONTACT_FRACTION_MAX = 2.0
#: the onset steps (the step that may close a gap, and the contact's first step in contact) /
#: the contact step, with resolved impacts.  A resolved impact's peak-force error at the default
#: step comes from those steps (docs/contact_models.md, known limits): the host holds the step's
#: mean force while the impact starts part-way through the step, and the contact FMU learns the
#: structures' reaction to the impact one step late.  Measured (benchmarks/bench_scenes.py, every
#: scene, one run, 2026-11-24): peak force kasai_maison 0.68 -> 0.15 %, sanfernando 0.43 ->
#: 0.18 %, kasai_maison_inelastic 0.26 -> 0.05 %, default_inelastic 0.38 -> 0.10 %, kobe 0.07
#: -> 0.03 %, for 0.5-3 % more steps; the default scene 0.04 -> 0.21 % and parkfield 0.15 ->
#: 0.24 %, where the prediction's lag no longer cancels the host's share.  The closing step
#: alone left sanfernando at 0.44 % (its largest impact starts 0.03 ms before a communication
#: point: its error sits in the first step in contact); a ratio 1/4 took the default scene to
#: 0.33 % and parkfield to 0.32 %
ONSET_RATIO = 0.5
#: an impact's onset steps are shortened only if its approach speed is at least this share of
#: the fastest impact's so far (any contact level): the slower ones can hardly set the peak
#: force (Hertz, n = 3/2: 0.65 of it at 0.7 times the speed, same masses).  Measured on
#: kasai_maison's 39 impacts: 464 steps with every onset shortened, 431 with 0.5 and 424 with
#: 0.7 (+1.9 % on main's 416: its speed ratio to OpenSees has the least margin), the same peak
#: force (0.16, 0.146, 0.146 %); with 0.7 the other scenes' peak forces are those of 0.5 or
#: better (default_inelastic 0.10 % for 0.15 %) and their dissipated energies closer to main's
ONSET_SPEED_SHARE = 0.7


def takes_onset_steps(level) -> bool:
    """True if a contact level's impacts get the onset steps: it resolves its impacts and its
    law cannot stick (:attr:`fmu_src.contact_laws.LawSpec.sticks`: crvk).  In a stick the
    contact holds the structures' push at a fixed penetration while the host's floors, moved by
    the held mean force, drift from it (rule 4's offset released under load,
    docs/contact_models.md), and the work of that drift, which the contact does not dissipate,
    depends on where the stick starts: with onset steps crvk at CR 0.001 on the default scene
    ended with an energy residual of -1.24 % of the input instead of -0.15 % (-0.3 -> -1.1 % on
    three other records and PGAs), past the 1 % the guard treats as created by the coupling
    (tests/test_attacks.py); at CR 0.002 to 0.65 within 0.5 % either way."""
    law = level.law
    return level.resolved and not (law.spec.sticks and law.zeta > 0.0)


def default_contact_fraction(levels) -> float:
    """1/2 if every contact resolves its impacts, else 1/64 (see :class:`Adaptive`)."""
    if levels and all(lv.resolved for lv in levels):
        return CONTACT_FRACTION_RESOLVED
    return CONTACT_FRACTION_PLAIN


def default_onset_fraction(levels, contact_fraction: float) -> float:
    """``ONSET_RATIO * contact_fraction`` if every contact resolves its impacts, else
    ``contact_fraction`` (the plain force law's steps are all short: no onset step of its own).
    Each level takes it only if :func:`takes_onset_steps`."""
    if levels and all(lv.resolved for lv in levels):
        return ONSET_RATIO * contact_fraction
    return contact_fraction


class Adaptive(CouplingStrategy):
    """Gauss-Seidel with dyadic adaptive communication steps and rollback (module docstring).

    Parameters (besides the base class's; ``step`` is the base step ``h_base``, s: the longest
    step near a possible contact)
    ----------
    contact_fraction : float, optional
        Step in contact (and for the step that closes a gap) as a fraction of the impact's
        time scale ``T = L / v`` (:meth:`_Level.in_contact_scale`).  Default
        (:func:`default_contact_fraction`): 1/2 when every contact FMU resolves its impacts
        (``resolve_impacts = true``: the FMU integrates the impact, the master only follows
        the buildings through it), 1/64 with the plain force law (first order: peak force
        and dissipated energy of the default scene within 1 % and 2 % of the reference).
        Both from the accuracy study, docs/accuracy.md.  In (0, :data:`CONTACT_FRACTION_MAX`].
    onset_fraction : float, optional
        The step that may close a gap and a contact's first step in contact, as a fraction of
        ``T``, for an impact at least :data:`ONSET_SPEED_SHARE` times as fast as the fastest
        so far.  Default (:func:`default_onset_fraction`): half ``contact_fraction`` when every
        contact resolves its impacts, else ``contact_fraction``.  In (0, ``contact_fraction``].
        A level whose law sticks (:func:`takes_onset_steps`) keeps ``contact_fraction``.
    max_halvings : int
        Smallest step ``h_base / 2**max_halvings`` (default 16).
    accel_safety : float
        Factor on the current relative acceleration in the closure bound (default 2).
    risk_factor : float
        States are saved before a step if the gap may close within ``risk_factor`` steps.
    knots : bool
        Hand the buildings the ground motion's knots (exact for the record over any step) with
        the ground motion read ahead in chunks (:mod:`cosim.master.knots`); default True (when
        the FMUs have knots).  False: the ground steps with every step and the buildings hold
        its step mean ``ag_mean``.
    dormancy : bool
        No call to a contact FMU over a step in which its gap provably stays open
        (:mod:`cosim.master.dormancy`); default True.
    long_steps : bool, optional
        Steps of up to ``max_long_step`` where every gap provably stays open for the step and
        one base step more; default: with ``dormancy`` (the contacts sleep through long steps
        and their catch-up declares the skipped interval open, cutting only the last skipped steps into
        pieces of at most ``catch_up_span``), else when every
        contact FMU takes such steps (:attr:`cosim.fmus.FmuSpec.long_quiet_steps`, or
        ``resolve_impacts = false``).
    max_long_step : float
        Longest step (s), rounded down to ``h_base`` times a power of 2 (default 0.32 s: 32
        samples of a 100 Hz record, what the FMUs' 33 knots carry).
    row_interval : float, optional
        History rows asked for at every multiple of it (s): long steps are then at most
        :func:`row_step` long, so that every row time is a communication point.

    Counters: ``communication_steps`` (accepted), ``rollbacks`` (rejected and retried),
    ``stats`` (``saved_states``, ``missed_events``, ``h_min_used``, ``h_max_used``, ``long_steps``,
    ``proofs``, ``dormant_steps``, ``catch_ups``, ``catch_up_steps``, ``catch_up_replays``,
    ``ground_steps``).
    """

    name = "adaptive"
    takes_long_steps = True
    host = "zoh"        # Gauss-Seidel: building.fmu holds F exactly over the step it was computed for

    def __init__(self, system: "System", t0: float, t_bound: float, step: float, *,
                 contact_fraction: float | None = None, onset_fraction: float | None = None,
                 max_halvings: int = 16, accel_safety: float = 2.0,
                 risk_factor: float = 2.0, knots: bool = True, dormancy: bool = True,
                 long_steps: bool | None = None, max_long_step: float = 0.32, catch_up_span: float | None = None,
                 row_interval: float | None = None):
        super().__init__(system, t0, t_bound, step)
        self.levels = contact_levels(system)
        if contact_fraction is None:
            contact_fraction = default_contact_fraction(self.levels)
        if not (0.0 < contact_fraction <= CONTACT_FRACTION_MAX):
            raise ValueError(f"contact_fraction = {contact_fraction!r} must be in (0, {CONTACT_FRACTION_MAX:g}]")
        if onset_fraction is None:
            onset_fraction = default_onset_fraction(self.levels, contact_fraction)
        if not (0.0 < onset_fraction <= contact_fraction):
            raise ValueError(f"onset_fraction = {onset_fraction!r} must be in (0, contact_fraction = {contact_fraction!r}]")
        if not (isinstance(max_halvings, int) and 0 <= max_halvings <= 40):
            raise ValueError(f"max_halvings = {max_halvings!r} must be an integer in 0..40")
        if not (max_long_step > 0.0 and math.isfinite(max_long_step)):
            raise ValueError(f"max_long_step = {max_long_step!r} s must be > 0")
        self.contact_fraction = float(contact_fraction)
        self.onset_fraction = float(onset_fraction)
        # each level's onset steps' fraction (its contact fraction for a law that sticks)
        self._onset_fractions = [self.onset_fraction if takes_onset_steps(lv) else self.contact_fraction
                                 for lv in self.levels]
        self.max_halvings = max_halvings
        self.accel_safety = float(accel_safety)
        self.risk_factor = float(risk_factor)
        self.h_max = self.h                                 # the base step
        self.h_min = self.h_max / 2 ** max_halvings
        self._tick = 0                                     # time = t0 + tick * h_min
        self._end_tick = max(1, math.ceil((self.t_bound - self.t0) / self.h_min - 1e-9))
        self._level = 0                                    # level of the last step (0: h_max, < 0: long)
        self._i_pga = None
        if system.ground:
            self._i_pga = system.columns.index(f"{system.ground[0].name}.pga")
        self.h_last = self.h_max
        self.stats = dict(saved_states=0, missed_events=0, h_min_used=math.inf, h_max_used=0.0, long_steps=0,
                          proofs=0, ground_steps=0)
        # the ground motion as knots, read ahead
        self._look = None
        capacity = self._knot_capacity() if knots else 0
        if capacity:
            self._look = GroundLookahead(system.ground[0], capacity, self.h_max,
                                         self.h_max * 2 ** max(0, int(math.floor(math.log2(max_long_step / self.h_max)
                                                                                  + 1e-9))), self.t_bound)
            self._look.start(self.t0)
            system.use_knots(capacity)
        else:
            system.use_knots(0)
        # the proof that gaps stay open, dormant contacts, long steps
        self._gaps = OpenGaps.build(system, self.levels) if (dormancy or long_steps is not False) else None
        if catch_up_span is None:
            catch_up_span = min(CATCH_UP_STEPS * self.h_max, MAX_CATCH_UP_SPAN)
        self._dormancy = Dormancy(system, self.stats, catch_up_span) if (dormancy and self._gaps is not None) else None
        if long_steps is None:
            # asleep, a contact never takes a long step itself (the catch-up cuts it, dormancy.py)
            long_steps = (self._dormancy is not None or all(not lv.resolved for lv in self.levels)
                          or fmu_spec(POUNDING).long_quiet_steps)
        self.long_levels = 0
        if long_steps and self._gaps is not None and (self._look is not None or not system.ground):
            # rows asked for: no longer than a step that lands on every row (the ground motion is
            # still read ahead in chunks of max_long_step)
            longest = max_long_step if row_interval is None else min(max_long_step, row_step(row_interval, self.h))
            self.long_levels = max(0, int(math.floor(math.log2(longest / self.h_max) + 1e-9)))
        # each level's floors (x1, x2, v1, v2, a1, a2) and contact outputs (F, delta) in System.y,
        # gathered in one fancy index per try (_levels_now): the kinematics of every
        # level with the same arithmetic as _Level.kinematics, without a call and six reads each
        self._level_reads = np.array([(lv.ix1, lv.ix2, lv.iv1, lv.iv2, lv.ia1, lv.ia2, lv.i_F, lv.i_delta)
                                for lv in self.levels], dtype=np.intp).reshape(-1)
        self._level_gaps = [lv.gap for lv in self.levels]
        self._proven = [-math.inf] * len(self.levels)      # s: each gap proven open until then (F = 0)
        self._kinematics: list = []                        # each level's (delta, rate, its rate) at the step start
        self._now_active: list = []                        # each contact has something to do at the step start (_levels_now)
        # a closure predicted later than this (s) changes neither the step (at most h_max) nor the
        # saving of states (a closure within risk_factor steps): _plan skips its time scales
        self._far = 2.0 * max(1.0, self.risk_factor) * self.h_max
        self._nominal = self.h_max                         # the current step's nominal length (s, step())
        self._last_full = False                            # the last long step's proof held over its horizon
        # each level in contact at the start of the step being planned (_plan; the last try's), and
        # at the start of the last accepted step: a level in contact then is past its first step
        self._no_contact = (False,) * len(self.levels)
        self._in_contact = self._was_in_contact = self._no_contact
        self._v_fastest = 0.0                              # m/s, the fastest impact's approach speed so far

    def _knot_capacity(self) -> int:
        """Knots the ground FMU gives and every building takes (0: no knots)."""
        system = self.system
        if not system.ground or not system.buildings:
            return 0
        ground = system.ground[0].instance

        def size(instance, name, causality):
            count = 0
            while True:
                try:
                    instance.variable(f"{name}[{count + 1}]", causality)
                except (KeyError, ValueError):
                    return count
                count += 1
        try:
            ground.variable("n_knots", "output")
            for b in system.buildings:
                b.instance.variable("n_knots", "input")
        except (KeyError, ValueError):
            return 0
        capacity = size(ground, "t_knot", "output")
        for b in system.buildings:
            capacity = min(capacity, size(b.instance, "t_knot", "input"))
        return capacity if capacity >= 2 else 0

    def watched_columns(self) -> list[str]:
        """The coupling's sources, each contact level's floors (x, v, a) and contact outputs (F,
        delta, v_impact), and every floor's x, v for the proof that gaps stay open."""
        system = self.system
        cols = system.columns
        out = [c for c in system.coupling_sources() if not (self._look is not None and c.startswith(
            system.ground[0].name + "."))]
        for lv in self.levels:
            out += [cols[i] for i in (lv.ix1, lv.iv1, lv.ia1, lv.ix2, lv.iv2, lv.ia2, lv.i_F, lv.i_delta, lv.i_vimp)]
        if self._gaps is not None:
            out += self._gaps.columns(system)
        return out

    # -- step choice -------------------------------------------------------------------------
    def _dyadic_level(self, h_target: float) -> int:
        """Smallest level ``j >= 0`` with ``h_max / 2**j <= h_target`` (capped at ``max_halvings``)."""
        if h_target >= self.h_max:
            return 0
        if h_target <= self.h_min:
            return self.max_halvings
        return min(self.max_halvings, math.ceil(math.log2(self.h_max / h_target) - 1e-12))

    def _aligned(self, level: int) -> int:
        """Refine ``level`` until the current time is a multiple of its step."""
        while level < self.max_halvings and self._tick % (1 << (self.max_halvings - level)):
            level += 1
        return level

    def _levels_now(self) -> tuple[list, list]:
        """Each level's kinematics ``(delta, rate, its rate)`` now (:meth:`_Level.kinematics`)
        and whether its contact has something to do: a force, a closed gap (its own, or the
        host's).  One loop over the levels, each read once per try."""
        it = iter(self.system.y[self._level_reads].tolist())
        kinematics, active = [], []
        # zip over one iterator eight times: each level's eight reads in order, no slice made
        for gap, x1, x2, v1, v2, a1, a2, F, delta in zip(self._level_gaps, it, it, it, it, it, it, it, it):
            d = x1 - x2 - gap
            kinematics.append((d, v1 - v2, a1 - a2))
            active.append(F != 0.0 or delta >= 0.0 or d >= 0.0)
        return kinematics, active

    def _plan(self) -> tuple[float, bool]:
        """``(h_target, closures)``: the longest safe step (s) and, for each gap that may close,
        ``(s*, h_keep)``: the earliest closure (s) and a function of no argument giving the
        longest step (s) accepted whatever closes in it (no state to save for it; evaluated by
        :meth:`step` only for a closure within its risk), from each level's kinematics now
        (``_kinematics``, read by :meth:`step`).  A closure later than ``_far`` is left out: it
        could change neither.  A time scale costs a few contact-law evaluations: each is
        computed only where it can change the answer."""
        proven = self.t0 + self._tick * self.h_min + self.h_max   # a gap proven open until then: nothing to plan
        if min(self._proven, default=proven) >= proven:            # every gap (most steps): no loop
            self._in_contact = self._no_contact
            return self.h_max, []
        in_contact = self._in_contact = [False] * len(self.levels)
        y = self.system.y
        a_extra = y.item(self._i_pga) if self._i_pga is not None else 0.0
        h_target = self.h_max
        closures = []
        far = self._far
        for k, (lv, until, (d, dd, ddd)) in enumerate(zip(self.levels, self._proven, self._kinematics)):
            if until >= proven:
                continue
            onset = self._onset_fractions[k]
            if d > 0.0 or y.item(lv.i_F) > 0.0 or y.item(lv.i_delta) > 0.0:     # in contact
                in_contact[k] = True
                v_imp = y.item(lv.i_vimp)
                if v_imp > self._v_fastest:
                    self._v_fastest = v_imp
                fraction = self.contact_fraction
                if not self._was_in_contact[k] and v_imp >= ONSET_SPEED_SHARE * self._v_fastest:
                    fraction = onset                                # its first step in contact
                h_target = min(h_target, lv.in_contact_scale(d, dd, v_imp, fraction))
                continue
            A = self.accel_safety * abs(ddd) + a_extra
            s = closure_time(d, dd, A)
            if s <= far:
                v_closing = max(dd, 0.0) + A * s                    # fastest possible approach at closure
                if s < h_target:                # else max(s, h_contact) >= h_target: no change
                    # the onset step for an impact that may matter (ONSET_SPEED_SHARE), at the
                    # approach speed now; the rollback (_retry_step) and the saving of states
                    # keep the contact step: a longer step holding the onset is accepted as before
                    fraction = onset if dd >= ONSET_SPEED_SHARE * self._v_fastest else self.contact_fraction
                    h_contact = lv.in_contact_scale(0.0, v_closing, v_closing, fraction)
                    h_target = min(h_target, max(s, h_contact))
                # a step no longer than the closing step at SAVE_SPEED_MARGIN times that speed is
                # accepted even if the gap closes in it (_retry_step): no rollback can follow it
                v_save = SAVE_SPEED_MARGIN * v_closing
                closures.append((s, functools.partial(lv.in_contact_scale, 0.0, v_save, v_save,
                                                      self.contact_fraction)))
        return h_target, closures

    # -- the proof that gaps stay open ---------------------------------------------------------------
    def _ground_bound(self, t: float, H: float):
        """``|ag|`` bound ahead (:func:`~cosim.master.gap_bound.running_max_abs`): from the knots
        read ahead, else the record's peak (the ground's ``pga`` output), else 0.  The ground
        is read ahead now; the bound is a function, evaluated only if a proof needs it
        (:meth:`~cosim.master.gap_bound.OpenGaps.horizons`)."""
        if self._look is None:
            return constant_bound(self.system.y.item(self._i_pga) if self._i_pga is not None else 0.0)
        look = self._look
        look.cover(t + H)
        times, values = look.times, look.values     # replaced, never changed in place, by the look-ahead
        return GroundAhead(times, values, t, H)

    def _prove_quiet(self, t: float, H: float) -> float:
        """With no contact active: how long (s, <= H) every gap provably stays open from ``t``
        with no contact force; each contact's proof is then valid until ``t`` plus that."""
        ground = self._ground_bound(t, H)
        if ground is None:
            return 0.0
        self.stats["proofs"] += 1
        s = min(self._gaps.horizons(self.system.y, H, ground), default=H)
        self._proven = [t + s] * len(self.levels)
        return s

    def _long_level(self, t: float) -> int:
        """The longest aligned long level (< 0) whose step and one base step more stay inside
        every gap's proof, or 0."""
        aligned = [lvl for lvl in range(-self.long_levels, 0)
                   if self._tick % (1 << (self.max_halvings - lvl)) == 0]
        if not aligned:
            return 0
        remaining = self.t_bound - t
        H = min(self.h_max * 2 ** -aligned[0], remaining) + self.h_max
        # a proof until t + H allows the longest aligned step: compared with a round-off slack
        # (proven times are sums of floats: a proof that ends exactly at t + H would otherwise
        # be taken as a hair short, and the step halved twice; measured on the default scene)
        slack = PROOF_SLACK * self.h_max
        if min(self._proven, default=math.inf) < t + H - slack:
            reach = LONG_PROOF_REACH if self._last_full else 1
            span = min(reach * (H - self.h_max), remaining) + self.h_max
            self._last_full = self._prove_quiet(t, span) >= span
            if reach > 1 and not self._last_full and min(self._proven, default=math.inf) < t + H - slack:
                self._last_full = self._prove_quiet(t, H) >= H
        safe = min(self._proven, default=math.inf) - t - self.h_max + slack
        capacity = self._look.capacity if self._look is not None else None
        for lvl in aligned:
            h = self.h_max * 2 ** -lvl
            if h > remaining + self.h_min:
                continue
            if h <= safe and (capacity is None or self._look.knots_in(t, min(t + h, self.t_bound)) <= capacity):
                return lvl
        return 0

    # -- one accepted step ---------------------------------------------------------------------
    def step(self) -> None:
        if self.status != "running":
            raise RuntimeError("the strategy has already finished")
        system = self.system
        cap = math.inf
        finest = 0                                               # a retry must be finer than the rejected step
        saved = None
        while True:
            # each level's kinematics and whether it has something to do, once per try (the
            # floors do not move before the buildings step, a contact's outputs not before it does)
            self._kinematics, self._now_active = self._levels_now()
            start = self._kinematics
            h_target, closures = self._plan()
            level = max(self._dyadic_level(min(h_target, cap)), finest)
            level = max(level, max(self._level, 0) - 1)          # grow by at most a factor 2 (below h_base)
            level = self._aligned(level)
            t = self.t0 + self._tick * self.h_min
            if (level == 0 and self.long_levels and cap == math.inf
                    and not any(self._now_active)):
                level = self._long_level(t)
            n_ticks = 1 << (self.max_halvings - level)
            end_tick = min(self._tick + n_ticks, self._end_tick)
            t_next = self.t_bound if end_tick >= self._end_tick else self.t0 + end_tick * self.h_min
            h = t_next - t
            # a long step (level < 0) is proven free of closures; a step that _retry_step would
            # accept whatever closes in it needs no saved state
            risky = bool(closures) and 0 <= level < self.max_halvings and any(
                s < self.risk_factor * h and h > h_keep() * (1.0 + 1e-9) for s, h_keep in closures)
            if risky and saved is None:
                saved = self._save()
            self._before(t_next)
            # the proofs over this step take its nominal length (the clipped last step its own)
            self._nominal = self.t_bound - t if end_tick >= self._end_tick else self.h_max * 2.0 ** -level
            self._advance(t, h)
            retry = self._retry_step(start, h)
            if retry is None:
                break
            if saved is not None:
                self._restore(saved)
                self.rollbacks += 1
                cap = retry
                finest = min(max(level, 0) + 1, self.max_halvings)
                continue
            self.stats["missed_events"] += 1
            break
        if saved is not None:
            self._free(saved)
        self._was_in_contact = self._in_contact            # the accepted try's plan (never changed after it)
        if self._dormancy is not None:
            self._dormancy.commit()
        self._tick = end_tick
        self._level = level
        self.h_last = h
        stats = self.stats
        if level < 0:
            stats["long_steps"] += 1
        if h < stats["h_min_used"]:
            stats["h_min_used"] = h
        if h > stats["h_max_used"]:
            stats["h_max_used"] = h
        self.communication_steps += 1
        self.t = t_next
        if end_tick >= self._end_tick:
            self.status = "finished"

    def _advance(self, t: float, h: float) -> None:
        system = self.system
        y = system.y
        look = self._look
        if look is not None:
            look.drop_before(t)
            look.cover(t + h)
            self.stats["ground_steps"] = look.ground_steps
        else:
            for node in system.ground:
                node.step(y, t, h)
        if self._dormancy is None:
            for node in system.contacts:
                node.step(y, t, h)
        else:
            self._step_contacts(t, h)
        if look is not None:
            knots = look.cut(t, t + h)
            for node in system.buildings:
                node.pull_with_knots(y, knots)
                node.instance.do_step(t, h)
                node.push()
        else:
            for node in system.buildings:
                node.step(y, t, h)

    def _step_contacts(self, t: float, h: float) -> None:
        """Step every contact that may have something to do over ``[t, t + h]``; the others
        sleep (:mod:`cosim.master.dormancy`), proven open with the forces of those that step."""
        system, y, dormancy = self.system, self.system.y, self._dormancy
        contacts = system.contacts
        t1 = t + h
        active = self._now_active
        if True in active:
            pending = []
            sleeping = dormancy.sleeping
            for k, node in enumerate(contacts):
                if active[k]:
                    if node.name in sleeping:
                        dormancy.wake(node)
                    node.step(y, t, h)
                else:
                    pending.append(k)
        else:                               # nothing to do anywhere (most steps): every contact pending
            pending = list(range(len(contacts)))
        if not pending:                     # every contact stepped: nothing to prove or to skip
            return
        # a proof over this step spans its nominal length: t + h is a difference of sums of
        # floats that comes in several round-off variants of one dyadic step, each of which would
        # build its own tables (ModalBound._cached; 5 variants of 0.01 s on kasai_maison, ~1.4 ms
        # a run); the nominal length plus a round-off slack covers every one of them
        H = proof_horizon(h, self._nominal, self.h_max)
        proven = self._proven
        if len(pending) == len(proven) and min(proven) < t1:
            # no force anywhere: one proof for every gap, over a few base steps ahead (it holds
            # as long as it says: no gap closes before it ends, so no force appears)
            self._prove_quiet(t, min(max(H, QUIET_HORIZON * self.h_max), self.t_bound - t))
            proven = self._proven           # a new list
        while pending:
            doubtful = [k for k in pending if proven[k] < t1]
            if not doubtful:
                break
            ground = self._ground_bound(t, H)
            if ground is None:
                wake = doubtful
            else:
                self.stats["proofs"] += 1
                horizons = self._gaps.horizons(y, H, ground, self._forces(pending), doubtful)
                wake = [k for k, s in zip(doubtful, horizons) if s < h]
                for k, s in zip(doubtful, horizons):
                    if s >= h:
                        proven[k] = t1              # proven for this step only (with these forces)
            if not wake:
                break
            for k in wake:
                node = contacts[k]
                dormancy.wake(node)
                node.step(y, t, h)
                pending.remove(k)
        dormancy.skip([contacts[k] for k in pending], t, h)

    def _forces(self, sleeping: list[int]) -> dict:
        """Floor forces (N) of the contacts that stepped, per building, held over the step."""
        y = self.system.y
        forces: dict = {}
        asleep = set(sleeping)
        for k, lv in enumerate(self.levels):
            if k in asleep:
                continue
            F = y.item(lv.i_F)
            if F == 0.0:
                continue
            left, fl, right, fr, _ = self._gaps.levels[k]
            for b, f, sign in ((left, fl, -1.0), (right, fr, 1.0)):
                vec = forces.get(b)
                if vec is None:
                    vec = forces[b] = np.zeros(self._gaps.buildings[b][0].n)
                vec[f] += sign * F
        return forces

    def sleeping(self):
        """The sleeping contacts (:mod:`cosim.master.dormancy`), by name."""
        return self._dormancy.sleeping if self._dormancy is not None else ()

    def finish(self) -> None:
        if self._dormancy is not None:
            self._dormancy.wake_all()
            self._dormancy.commit()

    def _retry_step(self, start, h: float) -> float | None:
        """After a step of ``h``: the step to retry with (s) if a gap closed inside a step
        longer than that contact's contact step, else None."""
        item = self.system.y.item
        retry = None
        for lv, (d0, dd0, _) in zip(self.levels, start):
            if d0 > 0.0:
                continue
            d1 = item(lv.ix1) - item(lv.ix2) - lv.gap          # lv.kinematics(y), the same arithmetic
            if d1 <= 0.0:
                continue
            dd1 = item(lv.iv1) - item(lv.iv2)
            v = max(dd0, dd1)
            h_contact = lv.in_contact_scale(0.0, v, v, self.contact_fraction)
            if h <= h_contact * (1.0 + 1e-9) or h <= self.h_min * (1.0 + 1e-9):
                continue
            s = h * (-d0) / (d1 - d0)                          # crossing, linear in the step
            if s >= h * (1.0 - 1e-9):                           # landed on the onset (round-off)
                continue
            candidate = max(s, h_contact)
            retry = candidate if retry is None else min(retry, candidate)
        return retry

    # -- FMU states ----------------------------------------------------------------------------
    def _save(self):
        self.stats["saved_states"] += 1
        system = self.system
        look = self._look
        # a sleeping contact has not been called since it fell asleep: its state is the one its
        # sleep holds (restored from there if it wakes in the step, see _restore)
        dormancy = self._dormancy
        return ([None if dormancy is not None and dormancy.asleep(n) else n.instance.get_state()
                 for n in system.nodes], system.y.copy(), system.ints.copy(),
                self._dormancy.snapshot() if self._dormancy is not None else None, list(self._proven),
                [n.knots_set for n in system.buildings],
                (look.t_end, look.times, look.values, look.width, look.chunks) if look is not None else None)

    def _restore(self, saved) -> None:
        states, y, ints, sleeping, proven, knots, look = saved
        system = self.system
        for node, state in zip(system.nodes, states):
            if state is None:               # asleep at the save: back to its sleep's state if it woke since
                then = sleeping[node.name].state
                now = self._dormancy.sleeping.get(node.name)
                if now is None or now.state is not then:
                    node.instance.set_state(then)
                continue
            node.instance.set_state(state)
        system.y[:] = y
        system.ints[:] = ints
        if sleeping is not None:
            self._dormancy.restore(sleeping)
        self._proven = list(proven)
        for node, count in zip(system.buildings, knots):
            node.knots_set = count
        if look is not None:
            self._look.t_end, self._look.times, self._look.values, self._look.width, self._look.chunks = look

    def _free(self, saved) -> None:
        for node, state in zip(self.system.nodes, saved[0]):
            if state is not None:
                node.instance.free_state(state)
