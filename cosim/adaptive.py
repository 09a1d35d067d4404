"""Adaptive communication step with rollback, and the stability guard of every run.

:class:`Adaptive` is a :class:`~cosim.coupling.CouplingStrategy`: one call of
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
* *In contact* (and for the step that closes the gap) the step is at most
  ``contact_fraction * T`` with ``T = L / v`` the impact's time scale,
  ``L = (m v^2 / k)^(1/(n+1))`` (:meth:`~fmu_src.contact_laws.ContactLaw.length_scale`),
  ``v`` the approach speed (predicted before the onset, latched after it).
* *Rollback*: before a step in which the gap may close (``s* < risk_factor h``) every FMU's
  state is saved (``fmi2GetFMUstate``); if the gap did close inside a step longer than the
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
(:mod:`cosim.reference`) and its energy bookkeeping is exact: the contact FMU's work
``F (delta_new - delta_old)`` is what the buildings receive.

:class:`StabilityGuard` runs after every accepted step of every strategy (hooked into
:func:`cosim.master.simulate`) and raises :class:`InstabilityError` with what to change when
a run has stopped meaning anything: non-finite outputs, a penetration deeper than all the
energy in the system could compress the contact spring, or energy created by the coupling.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fmu_src.contact_laws import MIN_IMPACT_SPEED, law_for

from .coupling import STRATEGIES, CouplingStrategy
from .master import System

# Slowest approach speed the time scale is evaluated at (m/s): below it T = L/v grows
# without physical meaning (a resting contact has no impact time scale); the contact laws'
# own floor on a latched impact speed.
_V_FLOOR = MIN_IMPACT_SPEED


class InstabilityError(RuntimeError):
    """A run produced numbers that cannot be trusted; the message says what to change.

    Attributes: ``t`` (s), ``instance`` (contact or building name, or ``""``), ``reason``
    (``"non-finite" | "penetration" | "energy"``).
    """

    def __init__(self, message: str, t: float, instance: str = "", reason: str = ""):
        super().__init__(message)
        self.t = t
        self.instance = instance
        self.reason = reason


# -- per contact: indices into System.y and the contact's physics -------------------------------
@dataclass
class _Level:
    """One contact instance seen from the master: where its signals live in ``System.y``."""

    name: str
    law: object                 # fmu_src.contact_laws.ContactLaw
    gap: float                  # m
    resolved: bool              # resolve_impacts
    ix1: int
    iv1: int
    ia1: int
    ix2: int
    iv2: int
    ia2: int
    i_delta: int                # contact output delta (m)
    i_F: int                    # contact output F (N)
    i_vimp: int                 # contact output v_impact (m/s)
    i_Ediss: int                # contact output E_dissipated (J)
    CR: float = 0.65            # requested restitution

    def in_contact_scale(self, delta: float, delta_dot: float, v_imp: float, fraction: float) -> float:
        """Longest step (s) the explicit force-law coupling can take in contact now.

        ``fraction`` times the shortest of: the impact time scale (closing step:
        :meth:`time_scale`, in contact: ``L(v) / v``); the spring's
        ``sqrt(m / k_t)``, ``k_t = n k delta^(n-1)``; and ``8 m / c`` for the dashpot ``c =
        dF/d(delta_dot)`` (an explicit relaxation needs ``h c / m`` well below 1: CR -> 0 makes
        ``c`` huge).  The dissipated energy's error is a fixed fraction of the impact's kinetic
        energy per ``h / T``, so relative to what the impact dissipates it grows like
        ``1 / (1 - CR^2)``: the step shrinks by ``(1 - CR^2) / (1 - 0.65^2)`` (the default was
        set at CR = 0.65, concrete), at most 16 times.
        """
        law = self.law
        v = max(v_imp, abs(delta_dot), _V_FLOOR)
        if delta <= 0.0:                      # the step that closes the gap
            scale = self.time_scale(v)
        else:                                 # in contact: the spring's scale and the local ones
            scale = law.length_scale(v) / v
            k_t = law.n * law.k * delta ** (law.n - 1.0)
            if k_t > 0.0:
                scale = min(scale, math.sqrt(law.m / k_t))
            c = law.force_and_derivatives(delta, delta_dot, v)[2]
            if c > 0.0 and math.isfinite(c):
                scale = min(scale, 8.0 * law.m / c)
        energy = min(1.0, max(1.0 / 16.0, (1.0 - self.CR * self.CR) / (1.0 - 0.65 * 0.65)))
        return fraction * energy * scale

    def time_scale(self, v: float) -> float:
        """Impact time scale (s) at approach speed ``v`` (m/s): ``d* / v``.

        ``d*`` is the penetration scale ``L = (m v^2 / k)^(1/(n+1))``, or the distance the
        dashpot alone stops the bodies in, ``m v / c(d*)``, if shorter (a few fixed-point
        passes; CR -> 0 makes the dashpot stop the impact long before the spring would).
        """
        v = max(abs(v), _V_FLOOR)
        law = self.law
        d = law.length_scale(v)
        for _ in range(4):
            c = law.force_and_derivatives(d, v, v)[2]
            if not (c > 0.0 and math.isfinite(c)) or law.m * v / c >= d:
                break
            d = law.m * v / c
        return d / v

    def kinematics(self, y: np.ndarray) -> tuple[float, float, float]:
        """Host ``delta`` (m), ``delta_dot`` (m/s, > 0 approaching), ``delta_ddot`` (m/s^2)."""
        item = y.item
        return (item(self.ix1) - item(self.ix2) - self.gap, item(self.iv1) - item(self.iv2),
                item(self.ia1) - item(self.ia2))

    def approach_speed(self, y: np.ndarray) -> float:
        """Speed (m/s) an impact's time scale is taken at: the latched ``v_impact`` or the
        current closing rate, whichever is larger."""
        return max(y.item(self.i_vimp), abs(y.item(self.iv1) - y.item(self.iv2)))


def _parameter(node, name: str):
    if name in node.spec.parameters:
        return node.spec.parameters[name]
    return node.instance.fmu.variables[name].start


def contact_levels(system: System) -> list[_Level]:
    """The contact levels of ``system`` with the output indices the master needs."""
    index = {c: i for i, c in enumerate(system.columns[:system.y.size])}
    levels = []
    for node in system.contacts:
        p = {k: _parameter(node, k) for k in ("gap", "k", "n", "model", "m1", "m2", "CR", "zeta", "resolve_impacts")}
        law = law_for(p["model"], float(p["k"]), float(p["n"]), float(p["m1"]), float(p["m2"]),
                      float(p["CR"]), float(p["zeta"]))
        source = {}
        for row, name in enumerate(node.inputs.names):   # x1, v1, x2, v2: one source column each
            j = int(np.flatnonzero(node.A[row])[0])
            source[name] = j
        accel = {}
        for body in ("1", "2"):
            column = system.columns[source["x" + body]]          # e.g. "left.x[3]"
            accel[body] = index[column.replace(".x[", ".a[")]
        out = node.name + "."
        levels.append(_Level(node.name, law, float(p["gap"]), bool(p["resolve_impacts"]),
                             source["x1"], source["v1"], accel["1"], source["x2"], source["v2"], accel["2"],
                             index[out + "delta"], index[out + "F"], index[out + "v_impact"],
                             index[out + "E_dissipated"], float(p["CR"])))
    return levels


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


# -- the guard -------------------------------------------------------------------------------------
class StabilityGuard:
    """Stop a run whose numbers cannot be trusted (see module docstring).

    Checks after every accepted step, with ``E_avail = E_initial + max over time of sum E_input``
    (J): no mechanical state can hold more energy than was ever put in.

    * non-finite output;
    * a contact penetration (the contact FMU's ``delta``) beyond ``penetration_factor``
      times ``((n+1) E_avail / k)^(1/(n+1))``, the penetration at which the contact spring
      alone would hold all of ``E_avail``;
    * energy created: a contact's ``E_dissipated < -energy_tol E_avail``, or the contacts'
      net work on the buildings ``sum E_external > energy_tol E_avail``, or the buildings'
      ``E_kinetic + E_strain > (1 + energy_tol) E_avail``.

    * a plain-law contact (``resolve_impacts = false``) stepped at more than
      ``max_step_over_time_scale`` times the impact time scale ``T`` (:meth:`_sampling`); the
      largest ratio seen is kept in :attr:`step_over_time_scale` for the run's summary.

    ``energy_tol = 0.01``: a coupling that creates 1 % of the energy in the system has
    changed the response by more than any accuracy a user asks of a pounding study.
    """

    #: plain-law step / impact time scale beyond which a run stops (its energy error ~ the ratio)
    max_step_over_time_scale = 0.25

    def __init__(self, system: System, penetration_factor: float = 2.0, energy_tol: float = 0.01):
        self.system = system
        self.penetration_factor = float(penetration_factor)
        self.energy_tol = float(energy_tol)
        self.levels = contact_levels(system)
        index = {c: i for i, c in enumerate(system.columns[:system.y.size])}
        names = [b.name for b in system.buildings]
        # plain int lists: the checks run after every step on a handful of scalars, where
        # y.item(i) is several times cheaper than numpy fancy indexing
        self._i_input = [index[f"{b}.E_input"] for b in names]
        self._i_external = [index[f"{b}.E_external"] for b in names]
        self._i_mech = [index[f"{b}.{v}"] for b in names for v in ("E_kinetic", "E_strain")]
        # energy stored at t0 in contacts that start closed (allow_initial_overlap): it is in
        # the system, and a contact that releases it reports it as negative dissipation
        self._stored0 = [lv.law.elastic_energy(lv.kinematics(system.y)[0]) for lv in self.levels]
        self.E_initial = sum(system.y.item(i) for i in self._i_mech) + sum(self._stored0)
        self.E_avail = self.E_initial
        self._limits = [0.0] * len(self.levels)
        self._update_limits()
        #: largest communication step / impact time scale seen in contact, per plain-law contact
        self.step_over_time_scale = {lv.name: 0.0 for lv in self.levels if not lv.resolved}

    def _update_limits(self) -> None:
        E = self.E_avail
        self._limits = [self.penetration_factor * ((lv.law.n + 1.0) * E / lv.law.k) ** (1.0 / (lv.law.n + 1.0))
                        + 1e-12 for lv in self.levels]

    def penetration_limit(self) -> list[float]:
        """Deepest credible penetration of each contact now (m)."""
        return list(self._limits)

    def problem(self, t: float, h: float) -> InstabilityError | None:
        """The first problem found after the step that ended at ``t`` (step ``h``), or None."""
        y = self.system.y
        if not math.isfinite(y.sum()):      # one reduction; a non-finite entry makes the sum non-finite
            bad = self.system.columns[int(np.flatnonzero(~np.isfinite(y))[0])] if not np.isfinite(y).all() \
                else "(sum of outputs)"
            return InstabilityError(f"t = {t:.6g} s: output {bad} is not finite: {self._advice(None, h)}",
                                    t, bad.split(".")[0], "non-finite")
        item = y.item
        E_in = self.E_initial
        for i in self._i_input:
            E_in += item(i)
        if E_in > self.E_avail:
            self.E_avail = E_in
            self._update_limits()
        tol = self.energy_tol * self.E_avail + 1e-9
        for lv, limit, stored0 in zip(self.levels, self._limits, self._stored0):
            delta = item(lv.i_delta)
            if delta > limit:
                return InstabilityError(
                    f"{lv.name}: t = {t:.6g} s: penetration {delta:.3g} m is beyond physical sense "
                    f"(all {self.E_avail:.3g} J in the system would compress the contact only "
                    f"{limit / self.penetration_factor:.3g} m): {self._advice(lv, h)}", t, lv.name, "penetration")
            if delta > 0.0 and not lv.resolved:
                error = self._sampling(lv, t, h)
                if error is not None:
                    return error
            if item(lv.i_Ediss) < -tol - stored0:
                return InstabilityError(
                    f"{lv.name}: t = {t:.6g} s: the contact created {-item(lv.i_Ediss) - stored0:.3g} J "
                    f"(> {100 * self.energy_tol:g} % of the {self.E_avail:.3g} J put in): {self._advice(lv, h)}",
                    t, lv.name, "energy")
        if self.levels:
            work = -sum(self._stored0)
            for i in self._i_external:
                work += item(i)
            if work > tol:
                lv = max(self.levels, key=lambda lv: item(lv.i_F))
                return InstabilityError(
                    f"t = {t:.6g} s: the contact forces did {work:.3g} J of net work on the buildings "
                    f"(> {100 * self.energy_tol:g} % of the {self.E_avail:.3g} J put in): {self._advice(lv, h)}",
                    t, lv.name, "energy")
        mech = 0.0
        for i in self._i_mech:
            mech += item(i)
        if mech > self.E_avail + tol:
            lv = max(self.levels, key=lambda lv: item(lv.i_F)) if self.levels else None
            return InstabilityError(
                f"t = {t:.6g} s: the buildings hold {mech:.3g} J, more than the {self.E_avail:.3g} J ever put "
                f"in: {self._advice(lv, h)}", t, lv.name if lv else "", "energy")
        return None

    def _sampling(self, level: _Level, t: float, h: float) -> InstabilityError | None:
        """Track ``h / T`` of a plain-law contact in contact, ``T = L / v`` the spring's impact
        time scale (``L = (m v^2 / k)^(1/(n+1))``, ``v`` the approach speed); an error once it
        exceeds :attr:`max_step_over_time_scale`.

        The plain force law is held over each step (first order in ``h``): the accuracy tables
        (docs/accuracy.md, Jankowski law at CR 0.65) show its dissipated-energy error close to
        ``h / T`` itself (0.8-1.2 times it on the default and Kobe scenes), so past a quarter of
        the time scale the run no longer says anything about the impacts, stable or not.  (At
        low CR the dashpot stops the bodies sooner, but nearly all the energy is dissipated
        whatever the step; at high CR the same absolute error is a larger part of the little
        that is dissipated: the warning says so.)
        """
        v = level.approach_speed(self.system.y)
        if v <= _V_FLOOR:                      # resting contact: no impact to resolve
            return None
        ratio = h * v / level.law.length_scale(v)
        if ratio > self.step_over_time_scale[level.name]:
            self.step_over_time_scale[level.name] = ratio
        if ratio <= self.max_step_over_time_scale:
            return None
        return InstabilityError(
            f"{level.name}: t = {t:.6g} s: a step of {ratio:.2g} impact time scales would leave the dissipated "
            f"energy off by about {min(ratio, 1.0):.0%}: {self._advice(level, h)}", t, level.name, "resolution")

    def check(self, t: float, h: float) -> None:
        error = self.problem(t, h)
        if error is not None:
            raise error

    def _advice(self, level: _Level | None, h: float) -> str:
        if level is None:
            return f"the communication step {h:.3g} s is too long for this scene; use a shorter step"
        T = level.time_scale(level.approach_speed(self.system.y))
        step = 0.02 * T  # the plain law's dissipated-energy error is about h / T: 2 % (docs/accuracy.md)
        if level.resolved:
            return (f"the communication step {h:.3g} s is too long for the resolved impacts to hand their "
                    f"impulse to the buildings; use a step below {step:.2g} s")
        return (f"plain force-law contact (resolve_impacts=false) cannot follow an impact of time scale "
                f"{T:.2g} s with a communication step of {h:.3g} s; use resolve_impacts=true, "
                f"coupling=\"adaptive\", or a step below {step:.2g} s")


# -- the strategy ----------------------------------------------------------------------------------
#: contact step / impact time scale, by contact mode (chosen from docs/accuracy.md)
CONTACT_FRACTION_RESOLVED = 1.0 / 2.0
CONTACT_FRACTION_PLAIN = 1.0 / 64.0


def default_contact_fraction(levels) -> float:
    """1/2 if every contact resolves its impacts, else 1/64 (see :class:`Adaptive`)."""
    if levels and all(lv.resolved for lv in levels):
        return CONTACT_FRACTION_RESOLVED
    return CONTACT_FRACTION_PLAIN


class Adaptive(CouplingStrategy):
    """Gauss-Seidel with dyadic adaptive communication steps and rollback (module docstring).

    Parameters (besides the base class's; ``step`` is the largest step ``h_max``, s)
    ----------
    contact_fraction : float, optional
        Step in contact (and for the step that closes a gap) as a fraction of the impact's
        time scale ``T = L / v`` (:meth:`_Level.in_contact_scale`).  Default
        (:func:`default_contact_fraction`): 1/2 when every contact FMU resolves its impacts
        (``resolve_impacts = true``: the FMU integrates the impact, the master only follows
        the buildings through it), 1/64 with the plain force law (first order: peak force
        and dissipated energy of the default scene within 1 % and 2 % of the reference).
        Both from the accuracy study, docs/accuracy.md.
    max_halvings : int
        Smallest step ``h_max / 2**max_halvings`` (default 16).
    accel_safety : float
        Factor on the current relative acceleration in the closure bound (default 2).
    risk_factor : float
        States are saved before a step if the gap may close within ``risk_factor`` steps.

    Counters: ``communication_steps`` (accepted), ``rollbacks`` (rejected and retried),
    ``stats`` (``saved_states``, ``missed_events``, ``h_min_used``, ``h_max_used``).
    """

    name = "adaptive"
    host = "zoh"        # Gauss-Seidel: building.fmu holds F exactly over the step it was computed for

    def __init__(self, system: System, t0: float, t_bound: float, step: float, *,
                 contact_fraction: float | None = None, max_halvings: int = 16, accel_safety: float = 2.0,
                 risk_factor: float = 2.0):
        super().__init__(system, t0, t_bound, step)
        self.levels = contact_levels(system)
        if contact_fraction is None:
            contact_fraction = default_contact_fraction(self.levels)
        if not (0.0 < contact_fraction <= 1.0):
            raise ValueError(f"contact_fraction = {contact_fraction!r} must be in (0, 1]")
        if not (isinstance(max_halvings, int) and 0 <= max_halvings <= 40):
            raise ValueError(f"max_halvings = {max_halvings!r} must be an integer in 0..40")
        self.contact_fraction = float(contact_fraction)
        self.max_halvings = max_halvings
        self.accel_safety = float(accel_safety)
        self.risk_factor = float(risk_factor)
        self.h_max = self.h
        self.h_min = self.h_max / 2 ** max_halvings
        self._tick = 0                                     # time = t0 + tick * h_min
        self._end_tick = max(1, math.ceil((self.t_bound - self.t0) / self.h_min - 1e-9))
        self._level = 0                                    # level of the last step (0: h_max)
        self._order = system.ground + system.contacts + system.buildings
        self._i_pga = None
        if system.ground:
            self._i_pga = system.columns.index(f"{system.ground[0].name}.pga")
        self.h_last = self.h_max
        self.stats = dict(saved_states=0, missed_events=0, h_min_used=math.inf, h_max_used=0.0)

    # -- step choice -------------------------------------------------------------------------
    def _dyadic_level(self, h_target: float) -> int:
        """Smallest level ``j`` with ``h_max / 2**j <= h_target`` (capped at ``max_halvings``)."""
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

    def _plan(self) -> tuple[float, bool]:
        """``(h_target, risky)``: the longest safe step (s) and whether a closure may fall in it."""
        y = self.system.y
        a_extra = y.item(self._i_pga) if self._i_pga is not None else 0.0
        h_target = self.h_max
        closures = []
        for lv in self.levels:
            d, dd, ddd = lv.kinematics(y)
            if d > 0.0 or y.item(lv.i_F) > 0.0 or y.item(lv.i_delta) > 0.0:     # in contact
                h_target = min(h_target, lv.in_contact_scale(d, dd, y.item(lv.i_vimp), self.contact_fraction))
                continue
            A = self.accel_safety * abs(ddd) + a_extra
            s = closure_time(d, dd, A)
            if s < math.inf:
                v_closing = max(dd, 0.0) + A * s                    # fastest possible approach at closure
                h_contact = lv.in_contact_scale(0.0, v_closing, v_closing, self.contact_fraction)
                h_target = min(h_target, max(s, h_contact))
                closures.append(s)
        return h_target, closures

    # -- one accepted step ---------------------------------------------------------------------
    def step(self) -> None:
        if self.status != "running":
            raise RuntimeError("the strategy has already finished")
        system = self.system
        cap = math.inf
        finest = 0                                               # a retry must be finer than the rejected step
        saved = None
        while True:
            h_target, closures = self._plan()
            level = max(self._dyadic_level(min(h_target, cap)), finest)
            level = max(level, self._level - 1)                  # grow by at most a factor 2
            level = self._aligned(level)
            n_ticks = 1 << (self.max_halvings - level)
            end_tick = min(self._tick + n_ticks, self._end_tick)
            t = self.t0 + self._tick * self.h_min
            t_next = self.t_bound if end_tick >= self._end_tick else self.t0 + end_tick * self.h_min
            h = t_next - t
            risky = level < self.max_halvings and any(s < self.risk_factor * h for s in closures)
            if risky and saved is None:
                saved = self._save()
            start = [lv.kinematics(system.y) for lv in self.levels]
            self._advance(t, h)
            retry = self._retry_step(start, h)
            if retry is None:
                break
            if saved is not None:
                self._restore(saved)
                self.rollbacks += 1
                cap = retry
                finest = min(level + 1, self.max_halvings)
                continue
            self.stats["missed_events"] += 1
            break
        if saved is not None:
            self._free(saved)
        self._tick = end_tick
        self._level = level
        self.h_last = h
        self.stats["h_min_used"] = min(self.stats["h_min_used"], h)
        self.stats["h_max_used"] = max(self.stats["h_max_used"], h)
        self.communication_steps += 1
        self.t = t_next
        if end_tick >= self._end_tick:
            self.status = "finished"

    def _advance(self, t: float, h: float) -> None:
        y = self.system.y
        for node in self._order:
            node.step(y, t, h)

    def _retry_step(self, start, h: float) -> float | None:
        """After a step of ``h``: the step to retry with (s) if a gap closed inside a step
        longer than that contact's contact step, else None."""
        y = self.system.y
        retry = None
        for lv, (d0, dd0, _) in zip(self.levels, start):
            if d0 > 0.0:
                continue
            d1, dd1, _ = lv.kinematics(y)
            if d1 <= 0.0:
                continue
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
        return ([n.instance.get_state() for n in system.nodes], system.y.copy(), system.ints.copy())

    def _restore(self, saved) -> None:
        states, y, ints = saved
        system = self.system
        for node, state in zip(system.nodes, states):
            node.instance.set_state(state)
        system.y[:] = y
        system.ints[:] = ints

    def _free(self, saved) -> None:
        for node, state in zip(self.system.nodes, saved[0]):
            node.instance.free_state(state)


STRATEGIES[Adaptive.name] = Adaptive
