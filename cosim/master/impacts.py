"""Each contact's own trajectory, replayed from a run's history: force and penetration inside the steps.

A contact FMU hands the buildings one number per step (the mean force), so its force history
inside the steps (the force-penetration loop of an impact, the instant of its largest force) is
not in the recorded outputs.  It is reproduced here by replaying the physics the FMU runs, from
the inputs it received:

* ``resolve_impacts = true``: a fresh :class:`fmu_src.resolver.ImpactResolver` built from the
  same parameters (:func:`cosim.master.models.contact_law`) is stepped over every accepted
  communication step of the run with the same inputs (the floors' recorded displacements and
  velocities at each step start) and step lengths; it records every accepted internal point.
  The resolver is deterministic, so the replay is the FMU's own trajectory (to the rounding of
  the step lengths recovered from the recorded times: its contacts, peak forces and energies
  agree with the FMU's outputs to 1e-9, tested).  Cost: the contact FMU's own arithmetic without
  the FMI calls (about 0.1 s for the default scene's 4012 steps).
* ``resolve_impacts = false``: the force law acts on the inputs at each step start; the
  recorded ``delta`` and ``F`` are that trajectory already.

Why a replay rather than new FMU outputs: FMI 2.0 variables have a fixed size, so a trajectory of
a varying number of internal points cannot be an output; the replay needs nothing from a host
but the history this master records anyway.  It needs every accepted step recorded.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.integrate import solve_ivp

from fmu_src.resolver import ImpactResolver

from .coupling import get_strategy
from .models import contact_law, shear_building
from .names import column, element_name

if TYPE_CHECKING:
    from .results import SimulationResult


@dataclass(frozen=True)
class ContactTrajectory:
    """One contact (impact or graze) of a contact instance: ``time`` (s), ``force`` (N, >= 0) and
    ``penetration`` (m) at the resolver's accepted internal points, onset to separation."""

    contact: str
    number: int
    t_onset: float
    time: np.ndarray
    force: np.ndarray
    penetration: np.ndarray

    @property
    def peak_force(self) -> float:
        return float(np.max(self.force)) if self.force.size else 0.0


def _inputs(result: "SimulationResult", contact: str):
    scene = result.scene
    level = next(lv for lv in scene.levels if lv.instance == contact)
    spec = scene.instance(contact)
    gap = float(spec.value("gap"))
    x1 = result[column(level.left, element_name("x", level.floor_left))]
    v1 = result[column(level.left, element_name("v", level.floor_left))]
    x2 = result[column(level.right, element_name("x", level.floor_right))]
    v2 = result[column(level.right, element_name("v", level.floor_right))]
    return spec, x1 - x2 - gap, v1 - v2


def replay_contact(result: "SimulationResult", contact: str) -> list[ContactTrajectory] | None:
    """Every contact of instance ``contact`` with its trajectory inside the steps, in order; None
    when the history does not hold every accepted step (a decimated recording)."""
    if result.time.size - 1 != result.cost.communication_steps:
        return None
    spec, delta, rate = _inputs(result, contact)
    t = result.time
    if not bool(spec.value("resolve_impacts")):
        return _plain_trajectories(result, contact, t)
    # the host the coupling declared at initialization, unless the scene set one (System.initialize)
    host = str(spec.value("host")) if "host" in spec.parameters else get_strategy(result.strategy).host
    resolver = ImpactResolver(contact_law(spec), host=host, graze_depth=float(spec.value("graze_depth")))
    trace: list[tuple[int, float, float, float]] = []
    resolver.trace = trace
    onsets: dict[int, float] = {}
    for k in range(t.size - 1):
        started = resolver.started
        # the FMU computes delta and its rate from its inputs in this order (x1 - x2 - gap, v1 - v2)
        resolver.step(float(delta[k]), float(rate[k]), float(t[k + 1] - t[k]))
        if resolver.started != started:
            # several contacts beginning in one step: only the last one's onset is known exactly
            for number in range(started + 1, resolver.started + 1):
                onsets[number] = t[k] + resolver.onset_offset
    if not trace:
        return []
    data = np.array(trace)
    out = []
    for number in np.unique(data[:, 0]).astype(int):
        rows = data[data[:, 0] == number]
        t0 = onsets[number]
        out.append(ContactTrajectory(contact, int(number), t0, t0 + rows[:, 1], rows[:, 2], rows[:, 3]))
    return out


def _plain_trajectories(result: "SimulationResult", contact: str, t: np.ndarray) -> list[ContactTrajectory]:
    """Plain force law: the force of step k acts on the inputs at its start (recorded at its end)."""
    force = result[column(contact, "F")][1:]
    delta = result[column(contact, "delta")][1:]
    on = (delta > 0.0) | (force > 0.0)
    out = []
    edges = np.flatnonzero(np.diff(np.concatenate(([0], on.astype(int), [0]))))
    for number, (a, b) in enumerate(zip(edges[::2], edges[1::2]), 1):
        out.append(ContactTrajectory(contact, number, float(t[a]), t[a:b].copy(), force[a:b].copy(),
                                     delta[a:b].copy()))
    return out


#: a step is solved exactly when its quick estimate is within this fraction of the floor's largest
#: quick estimate: the quick estimate (structure's part linear over the step) is within 2 % of
#: the exact in-step value on the default scene, so 5 % keeps every step that can hold the peak
_CANDIDATE_MARGIN = 0.05
#: points per step at which the exact in-step solution is evaluated, besides the contact's own
_STEP_POINTS = 64


def contact_floor_accelerations(result: "SimulationResult") -> dict[str, dict[int, float]]:
    """Peak absolute acceleration (m/s^2) of every pounding floor while its contacts push it,
    located inside the steps with the contact's own force: ``{building: {floor: value}}``.

    A building FMU holds each contact's *mean* force over a step, so its own in-step peak misses
    the force's peak (8 % low on the default scene).  Here the force inside the steps is the
    contact's replayed trajectory (:func:`replay_contact`, plus its refined peak ``F_peak`` at
    ``t_peak``).  A quick estimate first: the absolute acceleration of floor ``i`` (mass ``m``)
    is ``s + F / m`` with the structure's part ``s = -(K u + C v)_i / m`` taken linear between
    the step's ends (``a - F_held / m`` there).  The steps whose estimate comes within
    ``_CANDIDATE_MARGIN`` of the floor's largest are then solved exactly: the linear building
    from its recorded state at the step start, under the ground acceleration it held
    (``ag_mean``), the contact force inside the step (linear between the trajectory's points)
    and the other contacts' held forces (``solve_ivp``, DOP853, rtol 1e-10).  Sign -1 on the
    left body, +1 on the right.  Yielding buildings keep the quick estimate.
    """
    scene = result.scene
    if not scene.levels or not result.has(column(scene.levels[0].instance, "t_peak")):
        return {}
    late = result.strategy == "jacobi"             # a Jacobi building holds the force of the step before
    t = result.time

    def held_force(level):
        force = result[column(level.instance, "F")]
        return np.concatenate(([0.0], force[:-1])) if late else force

    held: dict[tuple[str, int], np.ndarray] = {}
    for level in scene.levels:
        for building, floor, sign in ((level.left, level.floor_left, -1.0), (level.right, level.floor_right, 1.0)):
            held[(building, floor)] = held.get((building, floor), 0.0) + sign * held_force(level)
    out: dict[str, dict[int, float]] = {}
    for level in scene.levels:
        peak = result[column(level.instance, "F_peak")]
        when = result[column(level.instance, "t_peak")]
        new = np.flatnonzero((peak[1:] > 0.0) & ((peak[1:] != peak[:-1]) | (when[1:] != when[:-1]))) + 1
        times, forces = [when[new]], [peak[new]]
        for trajectory in replay_contact(result, level.instance) or []:
            times.append(trajectory.time)
            forces.append(trajectory.force)
        tp, fp = np.concatenate(times), np.concatenate(forces)
        if not tp.size:
            continue
        order = np.argsort(tp, kind="stable")
        tp, fp = tp[order], fp[order]
        mine = held_force(level)
        j = np.clip(np.searchsorted(t, tp), 1, t.size - 1)       # the step (t[j-1], t[j]] holding each point
        w = np.clip((tp - t[j - 1]) / (t[j] - t[j - 1]), 0.0, 1.0)
        for building, floor, sign in ((level.left, level.floor_left, -1.0), (level.right, level.floor_right, 1.0)):
            spec = scene.instance(building)
            m = float(spec.value(element_name("m", floor)))
            a = result[column(building, element_name("a", floor))]
            s = a - held[(building, floor)] / m           # the structure's part at each communication point
            other = held[(building, floor)][j] - sign * mine[j]
            quick = np.abs((1.0 - w) * s[j - 1] + w * s[j] + (sign * fp + other) / m)
            value = float(np.max(quick))
            if _is_linear(spec):
                # the exact in-step values replace the estimate (which overshoots by up to 1.5 %:
                # the structure's part is not linear over a step that holds an impact)
                model = shear_building(spec)
                value = max(_exact_in_step(result, model, building, floor, int(step), tp[j == step],
                                           fp[j == step], sign, held)
                            for step in np.unique(j[quick >= (1.0 - _CANDIDATE_MARGIN) * value]))
            floors = out.setdefault(building, {})
            floors[floor] = max(floors.get(floor, 0.0), value)
    return out


def _is_linear(spec) -> bool:
    try:
        return str(spec.value("hysteresis")) == "linear"
    except KeyError:                  # a building.fmu without yielding storeys
        return True


def _exact_in_step(result, model, building: str, floor: int, step: int, tp: np.ndarray, fp: np.ndarray,
                   sign: float, held: dict) -> float:
    """Largest |absolute acceleration| of ``floor`` over the step (t[step-1], t[step]]: the linear
    building from its recorded state, the contact force through the points (tp, fp)."""
    t = result.time
    t0, t1 = float(t[step - 1]), float(t[step])
    n = model.n
    floors = range(1, n + 1)
    u0 = np.array([result[column(building, element_name("x", i))][step - 1] for i in floors])
    v0 = np.array([result[column(building, element_name("v", i))][step - 1] for i in floors])
    ag = float(result[column("ground", "ag_mean")][step]) if result.scene.ground is not None else 0.0
    f_held = np.zeros(n)
    for (b, i), force in held.items():
        if b == building:
            f_held[i - 1] += force[step]
    mine_held = sign * float(result[column(_level_of(result, building, floor), "F")][step])
    # the contact's force through its points; at the step's ends continued flat from the nearest
    knots_t = np.concatenate(([t0], tp, [t1]))
    knots_f = np.concatenate(([fp[0]], fp, [fp[-1]]))
    K, C, minv = model.K, model.C, 1.0 / model.masses

    def forces(tt):
        f = f_held.copy()
        f[floor - 1] += sign * float(np.interp(tt, knots_t, knots_f)) - mine_held
        return f

    def rhs(tt, y):
        u, v = y[:n], y[n:]
        return np.concatenate((v, minv * (-(K @ u) - C @ v + forces(tt)) - ag))

    sol = solve_ivp(rhs, (t0, t1), np.concatenate((u0, v0)), method="DOP853", rtol=1e-10, atol=1e-14,
                    dense_output=True)
    grid = np.unique(np.concatenate((np.linspace(t0, t1, _STEP_POINTS), tp)))
    y = sol.sol(grid)
    acc = [abs((-(K[floor - 1] @ y[:n, k]) - C[floor - 1] @ y[n:, k] + forces(grid[k])[floor - 1]) * minv[floor - 1])
           for k in range(grid.size)]
    return float(max(acc))


def _level_of(result, building: str, floor: int) -> str:
    for level in result.scene.levels:
        if (level.left, level.floor_left) == (building, floor) or (level.right, level.floor_right) == (building, floor):
            return level.instance
    raise KeyError((building, floor))
