"""Each contact's own trajectory, replayed from the steps its FMU took: force and penetration inside the steps.

A contact FMU hands the buildings one number per step (the mean force), so its force history
inside the steps (the force-penetration loop of an impact, the instant of its largest force) is
not in its outputs.  It is reproduced here by replaying the physics the FMU runs on the steps it
was given, which the run logs as it goes (:class:`cosim.master.steplog.LoggedContact`: start time,
step length and inputs of every ``fmi2DoStep``, whatever the coupling, the dormant contacts'
catch-ups, the long steps, the recorded set and the output interval; a rolled-back step is not
in it):

* ``resolve_impacts = true``: a fresh :class:`fmu_src.resolver.ImpactResolver` built from the
  same parameters (:func:`cosim.master.models.contact_law`) takes every logged step with the
  same ``delta = x1 - x2 - gap`` and ``delta_dot = v1 - v2`` (computed as the FMU does), step
  length and ``gap_open`` declaration; it records every accepted internal point.  The resolver is deterministic, so the
  replay is the FMU's own trajectory: its contacts, onsets and peak forces are the FMU's
  outputs bit for bit (tests/test_step_log.py).  Cost: the contact FMU's own arithmetic without the FMI calls.
* ``resolve_impacts = false``: a fresh :class:`fmu_src.plain_contact.PlainContact` takes the
  same steps: the force law at each step start, held over the step.

Why a replay rather than new FMU outputs: FMI 2.0 variables have a fixed size, so a trajectory of
a varying number of internal points cannot be an output.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.integrate import solve_ivp

from fmu_src.linear_response import Configuration
from fmu_src.plain_contact import PlainContact
from fmu_src.resolver import ImpactResolver

from .coupling import get_strategy
from .models import contact_law, shear_building
from .names import column, element_name

if TYPE_CHECKING:
    from .results import SimulationResult


@dataclass(frozen=True)
class ContactTrajectory:
    """One contact (impact or graze) of a contact instance: ``time`` (s), ``force`` (N, >= 0) and
    ``penetration`` (m) at the resolver's accepted internal points, onset to separation (plain
    law: at the starts of the steps in contact, the force held over each); ``t_peak``, ``F_peak``
    the contact's largest force as the FMU reports it (the resolver refines it between points)."""

    contact: str
    number: int
    t_onset: float
    time: np.ndarray
    force: np.ndarray
    penetration: np.ndarray
    t_peak: float = float("nan")
    F_peak: float = 0.0

    @property
    def peak_force(self) -> float:
        return float(np.max(self.force)) if self.force.size else 0.0


def replay_contact(result: "SimulationResult", contact: str) -> list[ContactTrajectory] | None:
    """Every contact of instance ``contact`` with its trajectory inside the steps, in order,
    replayed on the steps its FMU took (module docstring); None when the run did not log them."""
    steps = result.contact_steps.get(contact)
    if steps is None:
        return None
    spec = result.scene.instance(contact)
    gap = float(spec.value("gap"))
    # the FMU computes delta and its rate from its inputs in this order (x1 - x2 - gap, v1 - v2)
    delta = steps.input("x1") - steps.input("x2") - gap
    rate = steps.input("v1") - steps.input("v2")
    declared = steps.input("gap_open") != 0.0     # steps the master declared open (dormancy.py)
    t, h = steps.t, steps.h
    depth = float(spec.value("graze_depth"))
    if bool(spec.value("resolve_impacts")):
        # the host the coupling declared at initialization, unless the scene set one (System.initialize)
        host = str(spec.value("host")) if "host" in spec.parameters else get_strategy(result.strategy).host
        model = ImpactResolver(contact_law(spec), host=host, graze_depth=depth)
    else:
        model = PlainContact(contact_law(spec), graze_depth=depth)
    resolved = isinstance(model, ImpactResolver)
    trace: list[tuple[int, float, float, float]] = []
    if resolved:
        model.trace = trace
    onsets: dict[int, float] = {}
    peaks: dict[int, tuple[float, float]] = {}
    for k in range(len(steps)):
        started, points = model.started, len(trace)
        tk, dk = float(t[k]), float(delta[k])
        force = model.step(dk, float(rate[k]), float(h[k]), bool(declared[k]))
        if model.started != started:
            # several contacts beginning in one step: only the last one's onset is known exactly
            for number in range(started + 1, model.started + 1):
                onsets[number] = tk + model.onset_offset
        if not resolved and model.in_contact:     # the force held from this step's start
            trace.append((model.started, tk, force, dk))
        if len(trace) != points:      # as the FMU's outputs t_peak, F_peak after this step
            peaks[model.started] = (onsets[model.started] + model.peak_delay(), model.impact_peak)
    if not trace:
        return []
    data = np.array(trace)
    out = []
    for number in np.unique(data[:, 0]).astype(int):
        rows = data[data[:, 0] == number]
        t0 = onsets[number]
        t_peak, F_peak = peaks.get(number, (float("nan"), 0.0))
        # the resolver's points are timed from their onset, the plain law's at the step starts
        time = t0 + rows[:, 1] if resolved else rows[:, 1].copy()
        out.append(ContactTrajectory(contact, int(number), t0, time, rows[:, 2], rows[:, 3], t_peak, F_peak))
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
    ``t_peak``), and the steps are those the run logged because they hold a contact force
    (:class:`cosim.master.steplog.ContactWindows`: the buildings' states at both ends and their
    inputs over the step).  A quick estimate first: the absolute acceleration of floor ``i``
    (mass ``m``) is ``s + F / m`` with the structure's part ``s = -(K u + C v)_i / m`` taken
    linear between the step's ends (``a - F_held / m`` there).  The steps whose estimate comes
    within ``_CANDIDATE_MARGIN`` of the floor's largest are then solved exactly: the linear
    building from its state at the step start, under the ground acceleration it was given (held
    or the record's knots), the contact force inside the step (linear between the trajectory's
    points) and the other contacts' held forces (:func:`_exact_in_step`: the closed-form
    response to inputs linear between knots; ``solve_ivp`` for an undamped free mass).  Sign -1 on
    the left body, +1 on the right.  Yielding buildings keep the quick estimate.  A plain-law
    contact's force is held over each step, as the building holds it: its building's own
    in-step peak has it already.
    """
    scene = result.scene
    windows = result.contact_windows
    if windows is None or not len(windows) or not scene.levels:
        return {}
    late = result.strategy == "jacobi"             # a Jacobi building holds the force of the step before
    t0, t1 = windows.t0, windows.t1
    # the floor forces each pounding building held over each logged step and over the step before
    # (0 when that one is not logged: it is logged whenever a contact force is there, or was)
    follows = np.flatnonzero(t0[1:] == t1[:-1]) + 1
    held, before = {}, {}
    for building, inputs in windows.inputs.items():
        held[building] = inputs.held_forces(scene.n_storeys(building))
        before[building] = np.zeros_like(held[building])
        before[building][follows] = held[building][follows - 1]
    out: dict[str, dict[int, float]] = {}
    models: dict = {}            # building -> (ShearBuilding, its exact linear response)
    for level in scene.levels:
        if not bool(scene.instance(level.instance).value("resolve_impacts")):
            continue
        force_t, force = _force_polyline(replay_contact(result, level.instance) or [])
        # the logged step (t0, t1] holding each point; a point in no logged step acted on no building
        r = np.minimum(np.searchsorted(t1, force_t, side="left"), t0.size - 1)
        inside = (force_t <= t1[r]) & (force_t >= t0[r])
        tp, fp, r = force_t[inside], force[inside], r[inside]
        if not tp.size:
            continue
        F_column = column(level.instance, "F")
        mine = windows.at_start(F_column) if late else windows.at_end(F_column)
        w = np.clip((tp - t0[r]) / (t1[r] - t0[r]), 0.0, 1.0)
        for building, floor, sign in ((level.left, level.floor_left, -1.0), (level.right, level.floor_right, 1.0)):
            spec = scene.instance(building)
            m = float(spec.value(element_name("m", floor)))
            a = column(building, element_name("a", floor))
            f = floor - 1
            s0 = windows.at_start(a) - before[building][:, f] / m   # the structure's part at each end
            s1 = windows.at_end(a) - held[building][:, f] / m
            other = held[building][:, f] - sign * mine
            quick = np.abs((1.0 - w) * s0[r] + w * s1[r] + (sign * fp + other[r]) / m)
            value = float(np.max(quick))
            if _is_linear(spec):
                # the exact in-step values replace the estimate (which overshoots by up to 1.5 %:
                # the structure's part is not linear over a step that holds an impact)
                if building not in models:
                    model = shear_building(spec)
                    models[building] = (model, elastic_configuration(model))
                model, config = models[building]
                solve = _exact_in_step if config is not None else _integrated_in_step
                value = max(solve(windows, model, building, floor, int(k), force_t, force,
                                  sign, float(mine[k]), held[building][k], config)
                            for k in np.unique(r[quick >= (1.0 - _CANDIDATE_MARGIN) * value]))
            floors = out.setdefault(building, {})
            floors[floor] = max(floors.get(floor, 0.0), value)
    return out


def _is_linear(spec) -> bool:
    try:
        return str(spec.value("hysteresis")) == "linear"
    except KeyError:                  # a building.fmu without yielding storeys
        return True


def _force_polyline(trajectories: list[ContactTrajectory]) -> tuple[np.ndarray, np.ndarray]:
    """A contact's force (N) against time (s) over a run, linear between its points: each contact
    from 0 at its onset through the replayed points (the last is 0 at separation) with its
    refined peak ``F_peak`` at ``t_peak``; 0 outside the contacts."""
    times, forces = [], []
    for tr in trajectories:
        times += [np.array([tr.t_onset]), tr.time]
        forces += [np.zeros(1), tr.force]
        if tr.F_peak > 0.0:
            times.append(np.array([tr.t_peak]))
            forces.append(np.array([tr.F_peak]))
    if not times:
        return np.zeros(0), np.zeros(0)
    t, f = np.concatenate(times), np.concatenate(forces)
    order = np.argsort(t, kind="stable")
    return t[order], f[order]


def _step_inputs(windows, model, building: str, floor: int, k: int, force_t: np.ndarray, force: np.ndarray,
                 sign: float, mine_held: float, f_held: np.ndarray):
    """What a building was given over the logged step ``k`` (:func:`_exact_in_step`): the step's
    ends (s), its floors' displacements and velocities at the start, the ground acceleration
    (times, m/s^2), the contact force's polyline inside the step (its inner times, then knots
    with the step's ends, N) and the held floor forces without this contact's held mean (N)."""
    t0, t1 = float(windows.t0[k]), float(windows.t1[k])
    floors = range(1, model.n + 1)
    u0 = np.array([windows.start[k, windows.columns.index(column(building, element_name("x", i)))] for i in floors])
    v0 = np.array([windows.start[k, windows.columns.index(column(building, element_name("v", i)))] for i in floors])
    g_times, g_values = windows.inputs[building].ground(k, t0, t1)
    # the contact's force inside the step: its polyline, cut at the step's ends (a point on an
    # end belongs to both steps)
    inside = (force_t > t0) & (force_t < t1)
    tp = force_t[inside]
    knots_t = np.concatenate(([t0], tp, [t1]))
    knots_f = np.concatenate(([np.interp(t0, force_t, force, 0.0, 0.0)], force[inside],
                              [np.interp(t1, force_t, force, 0.0, 0.0)]))
    base = f_held.copy()
    base[floor - 1] -= sign * mine_held
    return t0, t1, u0, v0, g_times, g_values, tp, knots_t, knots_f, base


def _exact_in_step(windows, model, building: str, floor: int, k: int, force_t: np.ndarray, force: np.ndarray,
                   sign: float, mine_held: float, f_held: np.ndarray, config: Configuration | None = None) -> float:
    """Largest |absolute acceleration| of ``floor`` over the logged step ``k``: the linear
    building from its state at the step start, the contact force (sign ``sign`` on this floor)
    along its polyline (force_t, force) in place of its held mean ``mine_held`` (N), the other
    held forces ``f_held`` (N per floor), the ground acceleration the building was given.

    Exact to round-off: between consecutive knots of the two polylines both inputs are linear
    in time, and the building's response to a linear input is known in closed form
    (:class:`fmu_src.linear_response.Configuration`: ``z' = A z + b0 + b1 s`` in modal
    coordinates, ``config`` the building's elastic one, built here if not given); evaluated at
    ``_STEP_POINTS`` points of the step and at every knot."""
    n = model.n
    if config is None:
        config = elastic_configuration(model)
    t0, t1, u0, v0, g_times, g_values, tp, knots_t, knots_f, base = _step_inputs(
        windows, model, building, floor, k, force_t, force, sign, mine_held, f_held)
    minv = 1.0 / model.masses
    f = floor - 1
    # segments between every knot of either input; each input is linear inside a segment, read at
    # two inner points (a knot shared by a jump of the record is then taken from the right side)
    cuts = np.unique(np.concatenate((knots_t, g_times[(g_times > t0) & (g_times < t1)])))
    grid = np.unique(np.concatenate((np.linspace(t0, t1, _STEP_POINTS), tp, cuts)))
    z = np.concatenate((u0, v0))
    row_u, row_v = -model.K[f] * minv[f], -model.C[f] * minv[f]
    best = 0.0
    for a, b in zip(cuts[:-1], cuts[1:]):
        length = b - a
        if not length > 0.0:
            continue
        inner = (a + length / 3.0, a + 2.0 * length / 3.0)
        g1, g2 = np.interp(inner, g_times, g_values)
        c1, c2 = np.interp(inner, knots_t, knots_f)
        g_slope, c_slope = 3.0 * (g2 - g1) / length, 3.0 * (c2 - c1) / length
        g_a, c_a = g1 - g_slope * length / 3.0, c1 - c_slope * length / 3.0
        # z' = A z + b0 + b1 s: the floor forces (the contact's linear, the others held) and -ag
        p0 = base.copy()
        p0[f] += sign * c_a
        b0 = np.concatenate((np.zeros(n), minv * p0 - g_a))
        b1 = np.zeros(2 * n)
        b1[n:] = -g_slope
        b1[n + f] += minv[f] * sign * c_slope
        q0, beta0, beta1 = config.W @ z, config.W @ b0, config.W @ b1
        s = grid[(grid >= a) & (grid <= b)] - a
        states = config.state_at(q0, beta0, beta1, s)
        # absolute acceleration of the floor: (-(K u) - C v + forces) / m
        acc = row_u @ states[:n] + row_v @ states[n:] + minv[f] * (p0[f] + sign * c_slope * s)
        best = max(best, float(np.max(np.abs(acc))))
        z = config.state_at(q0, beta0, beta1, length)
    return best


def elastic_configuration(model) -> Configuration | None:
    """The exact linear response of a shear building (:class:`fmu_src.linear_response.Configuration`),
    None where its modal form is refused (a defective state matrix: an undamped free mass)."""
    try:
        return Configuration(model.masses, model.C, model.stiffnesses)
    except ValueError:
        return None


def _integrated_in_step(windows, model, building: str, floor: int, k: int, force_t: np.ndarray, force: np.ndarray,
                        sign: float, mine_held: float, f_held: np.ndarray, config=None) -> float:
    """:func:`_exact_in_step` by ``solve_ivp`` (DOP853, rtol 1e-10) where the closed form is
    refused (:func:`elastic_configuration`)."""
    n = model.n
    t0, t1, u0, v0, g_times, g_values, tp, knots_t, knots_f, base = _step_inputs(
        windows, model, building, floor, k, force_t, force, sign, mine_held, f_held)
    K, C, minv = model.K, model.C, 1.0 / model.masses

    def forces(tt):
        f = base.copy()
        f[floor - 1] += sign * float(np.interp(tt, knots_t, knots_f))
        return f

    def rhs(tt, y):
        u, v = y[:n], y[n:]
        return np.concatenate((v, minv * (-(K @ u) - C @ v + forces(tt)) - float(np.interp(tt, g_times, g_values))))

    sol = solve_ivp(rhs, (t0, t1), np.concatenate((u0, v0)), method="DOP853", rtol=1e-10, atol=1e-14,
                    dense_output=True)
    grid = np.unique(np.concatenate((np.linspace(t0, t1, _STEP_POINTS), tp)))
    y = sol.sol(grid)
    acc = [abs((-(K[floor - 1] @ y[:n, j]) - C[floor - 1] @ y[n:, j] + forces(grid[j])[floor - 1]) * minv[floor - 1])
           for j in range(grid.size)]
    return float(max(acc))
