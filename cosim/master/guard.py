"""The stability guard of every run and the error it raises.

:class:`StabilityGuard` runs after every accepted communication step of every coupling
strategy (hooked into :func:`cosim.master.simulate.simulate`) and raises
:class:`InstabilityError` with what to change when a run has stopped meaning anything:
non-finite outputs, a penetration deeper than all the energy in the system could compress
the contact spring, energy created by the coupling, a plain force-law contact stepped
past a quarter of its impact time scale, or work that explodes (refined communication steps
or a contact FMU's internal steps far beyond what any resolved impact needs, or more steps
than the run's limit).

:func:`contact_levels` is how the master sees each contact instance (where its signals live
in ``System.y`` and its contact law, from the contact law table); the adaptive strategy
plans its steps with the same view.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Container

import numpy as np

from fmu_src.contact_laws import MIN_IMPACT_SPEED, ContactLaw, law_for

from .names import column, element_name

if TYPE_CHECKING:
    from .system import System

# Slowest approach speed the time scale is evaluated at (m/s): below it T = L/v grows
# without physical meaning (a resting contact has no impact time scale); the contact laws'
# own floor on a latched impact speed.
_V_FLOOR = MIN_IMPACT_SPEED

#: Refined communication steps the master may take per impact (beyond the scene's own steps),
#: with resolved impacts and with the plain force law.  Measured: resolved impacts need 1-3
#: refinements each (default scene 12 for 11 impacts, Kobe 27 for 9); the plain law at 1/64 of
#: the impact time scale 585 each (default scene, CR 0.65), and its step shrinks up to 16 times
#: more as CR -> 1 (``_Level.in_contact_scale``): about 9400.  Far more than those (over 150
#: times and twice) is not an impact being resolved but a contact whose time scale has
#: collapsed (``pounding.zeta = 1e6``: a dashpot that holds the floors together took 137 000
#: steps of 0.6 us in 2 ms).
MAX_REFINED_STEPS_PER_IMPACT = {True: 500, False: 20_000}   # by resolve_impacts
#: Internal steps a contact FMU may take after an impact's onset, beyond
#: :data:`SUBSTEPS_PER_STEP` per communication step.  A resolved impact takes 40-90 internal
#: steps on every bundled scene (at most 16 in one doStep, measured); 5000 is 55 times the
#: most, an impact law whose in-step integration has become stiff or chatters (crvk at
#: CR 0.001 chattered at 600-700 per doStep while the floors stuck together, for seconds, before the
#: in-step resolver of issue 13; it now completes, and this bound stays the master's own protection).
MAX_SUBSTEPS_PER_IMPACT = 5_000
#: Internal steps per communication step a lasting contact may take without counting against
#: :data:`MAX_SUBSTEPS_PER_IMPACT` (four times the most seen in one doStep on the bundled scenes).
SUBSTEPS_PER_STEP = 64

#: ``ndarray.sum`` without its Python wrapper (checked after every step)
_SUM = np.add.reduce


class InstabilityError(RuntimeError):
    """A run produced numbers that cannot be trusted; the message says what to change.

    Attributes: ``t`` (s), ``instance`` (contact or building name, or ``""``), ``reason``
    (``"non-finite" | "penetration" | "energy" | "resolution" | "work"``).
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
    law: ContactLaw
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
    j_impacts: int = -1         # contact output impacts (index into System.ints; -1: none)
    j_substeps: int = -1        # contact output substeps (index into System.ints; -1: none)
    i_contact_time: int = -1    # contact output contact_time (s; -1: none)
    i_zeta_used: int = -1       # contact output zeta_used (-1: none)
    i_substeps_total: int = -1  # contact output substeps_total (index into System.y; -1: none, j_substeps read)

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


def contact_levels(system: "System") -> list[_Level]:
    """The contact levels of ``system`` with the output indices the master needs.

    The contact's parameters as its instance has them (set by the scene, else the FMU's
    default: :meth:`cosim.master.scene.InstanceSpec.value`); the floors' signals from the
    scene's contact levels.
    """
    index = {c: i for i, c in enumerate(system.columns[:system.y.size])}
    ints = {c: j for j, c in enumerate(system.columns[system.y.size:])}
    where = {level.instance: level for level in system.scene.levels}
    levels = []
    for node in system.contacts:
        p = {k: node.spec.value(k) for k in ("gap", "k", "n", "model", "m1", "m2", "CR", "zeta", "resolve_impacts")}
        law = law_for(p["model"], float(p["k"]), float(p["n"]), float(p["m1"]), float(p["m2"]),
                      float(p["CR"]), float(p["zeta"]))
        level = where[node.name]
        floors = ((level.left, level.floor_left), (level.right, level.floor_right))
        x1, v1, a1, x2, v2, a2 = (index[column(b, element_name(var, f))] for b, f in floors for var in "xva")
        out = node.name + "."
        levels.append(_Level(node.name, law, float(p["gap"]), bool(p["resolve_impacts"]), x1, v1, a1, x2, v2, a2,
                             index[out + "delta"], index[out + "F"], index[out + "v_impact"],
                             index[out + "E_dissipated"], float(p["CR"]), ints.get(out + "impacts", -1),
                             ints.get(out + "substeps", -1), index.get(out + "contact_time", -1),
                             index.get(out + "zeta_used", -1), index.get(out + "substeps_total", -1)))
    return levels


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

    * work that explodes (:meth:`_work`): more accepted communication steps than ``max_steps``;
      more than :data:`MAX_REFINED_STEPS_PER_IMPACT` refined steps per impact beyond the scene's
      own steps (``base_step``); a contact FMU's internal steps (its ``substeps`` output) since
      its latest impact's onset beyond :data:`MAX_SUBSTEPS_PER_IMPACT` plus
      :data:`SUBSTEPS_PER_STEP` per communication step.  The message names the contact and the
      time scale that collapsed.

    ``energy_tol = 0.01``: a coupling that creates 1 % of the energy in the system has
    changed the response by more than any accuracy a user asks of a pounding study.
    """

    #: plain-law step / impact time scale beyond which a run stops (its energy error ~ the ratio)
    max_step_over_time_scale = 0.25

    def __init__(self, system: "System", penetration_factor: float = 2.0, energy_tol: float = 0.01,
                 max_steps: int | None = None, base_step: float | None = None):
        self.system = system
        self.max_steps = max_steps
        self.base_step = float(base_step) if base_step else system.scene.step
        self.steps = 0                       # accepted communication steps checked so far
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
        self._work0 = -sum(self._stored0)        # the net work's start (J), summed once, not per step
        self._resolved = all(lv.resolved for lv in self.levels)
        self.E_initial = sum(system.y.item(i) for i in self._i_mech) + sum(self._stored0)
        self.E_avail = self.E_initial
        self._limits = [0.0] * len(self.levels)
        self._limits_stale = False      # E_avail grew since the limits were made (made when next needed)
        self._update_limits()
        # the levels by name, and all of them: each check loops over the awake levels only
        # (_awake: on kasai_maison 1-2 of 8 at most steps)
        self._names = [lv.name for lv in self.levels]
        self._everyone = list(range(len(self.levels)))
        #: largest communication step / impact time scale seen in contact, per plain-law contact
        self.step_over_time_scale = {lv.name: 0.0 for lv in self.levels if not lv.resolved}
        # per contact: impacts seen, internal steps and communication steps since the latest onset,
        # and when it began (s)
        self._impacts = [0] * len(self.levels)
        self._total_impacts = 0                       # sum of _impacts
        self._substeps = [0] * len(self.levels)
        self._since = [0] * len(self.levels)          # steps before the one of the latest onset
        self._onset = [0.0] * len(self.levels)
        self._touching = [False] * len(self.levels)   # in contact after the previous step
        # substeps_total after the previous step (the step's internal steps are the difference)
        self._total_seen = [system.y.item(lv.i_substeps_total) if lv.i_substeps_total >= 0 else 0.0
                            for lv in self.levels]

    def watched_columns(self) -> list[str]:
        """The Real outputs the guard reads after every step."""
        cols = self.system.columns
        out = [cols[i] for i in self._i_input + self._i_external + self._i_mech]
        for lv in self.levels:
            out += [cols[i] for i in (lv.i_delta, lv.i_F, lv.i_vimp, lv.i_Ediss, lv.iv1, lv.iv2)]
            if lv.i_contact_time >= 0:       # named by the message of exploding work (_stuck)
                out.append(cols[lv.i_contact_time])
            if lv.i_substeps_total >= 0:     # the internal steps, without an fmi2GetInteger (_work)
                out.append(cols[lv.i_substeps_total])
        return out

    def _update_limits(self) -> None:
        self._limits_stale = False
        E = self.E_avail
        self._limits = [self.penetration_factor * ((lv.law.n + 1.0) * E / lv.law.k) ** (1.0 / (lv.law.n + 1.0))
                        + 1e-12 for lv in self.levels]

    def penetration_limit(self) -> list[float]:
        """Deepest credible penetration of each contact now (m)."""
        if self._limits_stale:
            self._update_limits()
        return list(self._limits)

    def problem(self, t: float, h: float, asleep: Container[str] = ()) -> InstabilityError | None:
        """The first problem found after the step that ended at ``t`` (step ``h``), or None.

        ``asleep``: contacts not called since before the step (:mod:`cosim.master.dormancy`), passed
        over: each fell asleep proven open (``F = 0``, ``delta < 0``: nothing to sample, no
        internal step) with the outputs this guard checked after the step before, and they have
        not changed since; every limit they are checked against only loosens as ``E_avail``
        grows (the penetration limit, the energy tolerance), so their checks hold as they did.
        Every contact is checked after the first step (none has been checked awake before)."""
        self.steps += 1
        if self.steps == 1:
            asleep = ()
        y = self.system.y
        if not math.isfinite(_SUM(y)):      # one reduction; a non-finite entry makes the sum non-finite
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
            self._limits_stale = True
        tol = self.energy_tol * self.E_avail + 1e-9
        awake = self._awake(asleep)
        if awake and self._limits_stale:       # only an awake level is checked against them
            self._update_limits()
        levels, limits, stored = self.levels, self._limits, self._stored0
        for k in awake:
            lv, limit, stored0 = levels[k], limits[k], stored[k]
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
            work = self._work0
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
        return self._work(t, h, asleep, awake)

    def _awake(self, asleep: Container[str]) -> list[int]:
        """The levels (indices, in order) not in ``asleep``."""
        if not asleep:
            return self._everyone
        return [k for k, name in enumerate(self._names) if name not in asleep]

    # -- work ------------------------------------------------------------------------------------
    def _work(self, t: float, h: float, asleep: Container[str] = (),
              awake: list[int] | None = None) -> InstabilityError | None:
        """Work that explodes (see the class docstring), or None (``asleep`` as :meth:`problem`;
        ``awake``: the levels not in it, :meth:`_awake`, if known)."""
        if self.max_steps is not None and self.steps > self.max_steps:
            return InstabilityError(
                f"t = {t:.6g} s: the run has taken {self.steps:,} communication steps, more than the limit of "
                f"{self.max_steps:,} (--max-steps; the scene plans {self.system.scene.stop_time / self.base_step:.3g} "
                f"at step {self.base_step:g} s, the rest are refinements near impacts): raise --max-steps on "
                f"purpose, or lengthen the step", t, "", "work")
        ints = self.system.ints
        item = self.system.y.item
        total_impacts = self._total_impacts
        levels = self.levels
        for i in (self._awake(asleep) if awake is None else awake):
            lv = levels[i]
            if lv.j_impacts < 0:
                continue
            impacts = ints.item(lv.j_impacts)
            if impacts != self._impacts[i]:       # a new impact began in this step
                total_impacts += impacts - self._impacts[i]
                self._impacts[i] = impacts
                self._substeps[i] = 0
                self._since[i] = self.steps - 1
                self._onset[i] = t
            if lv.i_substeps_total >= 0:
                # the internal steps of the step (of every doStep since the previous check: a
                # contact woken from dormancy adds its catch-up steps), from the Real running
                # total read with the step; steps that neither began nor ended in contact take
                # none in the resolver (it counts only steps in contact) and add nothing
                total = item(lv.i_substeps_total)
                taken = total - self._total_seen[i]
                self._total_seen[i] = total
            elif lv.j_substeps >= 0:
                # an FMU without substeps_total: its Integer ``substeps``, current after a step that
                # began or ended in contact (Recorder.track reads the counters then, before the guard)
                taken = ints.item(lv.j_substeps)
            else:
                continue
            touching = item(lv.i_F) != 0.0 or item(lv.i_delta) >= 0.0
            if touching or self._touching[i]:
                self._substeps[i] += int(taken)
            self._touching[i] = touching
            steps_since = self.steps - self._since[i]     # communication steps since the onset's
            allowed = MAX_SUBSTEPS_PER_IMPACT + SUBSTEPS_PER_STEP * steps_since
            if self._substeps[i] > allowed:
                self._total_impacts = total_impacts
                return InstabilityError(
                    f"{lv.name}: t = {t:.6g} s: the contact FMU has taken {self._substeps[i]:,} internal steps in "
                    f"{steps_since} communication steps since its impact at t = {self._onset[i]:.6g} s "
                    f"(limit {MAX_SUBSTEPS_PER_IMPACT:,} + {SUBSTEPS_PER_STEP} per step; a resolved impact takes "
                    f"40-90): {self._stuck(lv)}", t, lv.name, "work")
        self._total_impacts = total_impacts
        refined = self.steps - t / self.base_step
        if self.levels:
            per_impact = MAX_REFINED_STEPS_PER_IMPACT[self._resolved]
            if refined > per_impact * (total_impacts + 1):
                lv = max(self.levels, key=lambda lv: self.system.y.item(lv.i_delta))
                return InstabilityError(
                    f"{lv.name}: t = {t:.6g} s: the coupling has taken {refined:,.0f} refined communication steps "
                    f"for {total_impacts} impact(s) (limit {per_impact:,} per impact), the last {h:.2g} s long: "
                    f"{self._collapse(lv)}", t, lv.name, "work")
        return None

    def _law_text(self, level: _Level) -> str:
        y = self.system.y
        zeta = y.item(level.i_zeta_used) if level.i_zeta_used >= 0 else level.law.zeta
        return f"{level.law.model} at CR = {level.CR:g} (zeta = {zeta:.3g}, k = {level.law.k:.3g}, n = {level.law.n:g})"

    def _stuck(self, level: _Level) -> str:
        """What a contact whose in-step work exploded looks like, and what to change."""
        y = self.system.y
        delta, delta_dot, _ = level.kinematics(y)
        v = max(level.approach_speed(y), _V_FLOOR)
        T = level.time_scale(v)
        held = y.item(level.i_contact_time) if level.i_contact_time >= 0 else float("nan")
        return (f"{self._law_text(level)}: the floors have been in contact for {held:.3g} s, "
                f"{held / T:.3g} impact time scales (T = {T:.2g} s at {v:.2g} m/s), closing at {delta_dot:.2g} m/s: "
                f"the law holds them together and its in-step integration chatters; raise CR or lower zeta")

    def _collapse(self, level: _Level) -> str:
        """Which of the contact's time scales collapsed, in numbers, and what to change."""
        law = level.law
        y = self.system.y
        delta, delta_dot, _ = level.kinematics(y)
        v = max(level.approach_speed(y), _V_FLOOR)
        impact = law.length_scale(v) / v
        d = max(delta, 1e-3 * law.length_scale(v))
        scales = {"the impact time scale L/v": impact}
        k_t = law.n * law.k * d ** (law.n - 1.0)
        if k_t > 0.0:
            scales["the spring's sqrt(m/k_t)"] = math.sqrt(law.m / k_t)
        c = law.force_and_derivatives(d, max(abs(delta_dot), _V_FLOOR), v)[2]
        if c > 0.0 and math.isfinite(c):
            scales["the dashpot's 8 m/c"] = 8.0 * law.m / c
        name, shortest = min(scales.items(), key=lambda kv: kv[1])
        text = f"{self._law_text(level)}: {name} = {shortest:.2g} s, against an impact time scale of {impact:.2g} s"
        if name == "the dashpot's 8 m/c":
            return (text + ": the damping holds the floors together and the coupling must follow it in steps this "
                           "short; lower zeta, or raise CR (CR -> 0 makes the dashpot stiff)")
        return text + ": check the contact's k, n and masses, or lengthen the step"

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

    def check(self, t: float, h: float, asleep: Container[str] = ()) -> None:
        error = self.problem(t, h, asleep)
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
