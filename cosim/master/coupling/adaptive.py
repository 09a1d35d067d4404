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
(:mod:`cosim.peers.reference`) and its energy bookkeeping is exact: the contact FMU's work
``F (delta_new - delta_old)`` is what the buildings receive.

The contacts are seen through :func:`cosim.master.guard.contact_levels`, the stability
guard's view.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..guard import contact_levels
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

    def __init__(self, system: "System", t0: float, t_bound: float, step: float, *,
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
