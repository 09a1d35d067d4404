"""The run loop: a coupling strategy advances a system, the guard watches, a recorder keeps every output.

:func:`simulate` initialises a :class:`~cosim.master.system.System`, steps it with a
coupling strategy (:mod:`cosim.master.coupling`) from t = 0 to the stop time, checks every
accepted step with the stability guard (:mod:`cosim.master.guard`) and returns a
:class:`~cosim.master.results.SimulationResult` (history and cost).
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .coupling import get_strategy
from .fmi import FMUError
from .guard import StabilityGuard
from .results import Cost, SimulationResult

if TYPE_CHECKING:
    from .system import System


class Recorder:
    """Preallocated history of (t, y, ints), grown by doubling for variable steps."""

    def __init__(self, system: "System", capacity: int):
        self.system = system
        self.n_y = system.y.size
        self.time = np.empty(max(capacity, 2))
        self.values = np.empty((max(capacity, 2), self.n_y + system.ints.size))
        self.count = 0

    def record(self, t: float) -> None:
        if self.count == self.time.size:
            self.time = np.resize(self.time, 2 * self.time.size)
            self.values = np.resize(self.values, (2 * self.values.shape[0], self.values.shape[1]))
        k = self.count
        self.time[k] = t
        row = self.values[k]
        row[:self.n_y] = self.system.y
        row[self.n_y:] = self.system.ints
        self.count += 1


def initial_outputs_finite(system: "System") -> None:
    """Raise :class:`~cosim.master.fmi.FMUError` naming the instance and output if an output is
    not finite after initialisation (before any step: the inputs wired from it would carry NaN
    into every instance, and the first one to check its inputs would be blamed)."""
    y = system.y
    if np.isfinite(y).all():
        return
    bad = system.columns[int(np.flatnonzero(~np.isfinite(y))[0])]
    instance, _, variable = bad.partition(".")
    value = float(y[system.columns.index(bad)])
    raise FMUError(instance, "fmi2ExitInitializationMode", 3,
                   [f"{instance}: output {variable} = {value!r} after initialisation: its parameters are beyond "
                    f"what its arithmetic supports (check the magnitudes of its masses, stiffnesses and periods)"])


def simulate(system: "System", strategy: str | type | None = None, stop_time: float | None = None,
             step: float | None = None, progress: bool | None = None,
             callback: Callable[[float], None] | None = None, check_stability: bool = True,
             max_steps: int | None = None, **options: Any) -> SimulationResult:
    """Initialise ``system`` and run it from t0 = 0 to ``stop_time`` with a coupling strategy.

    ``strategy``: a name from :data:`cosim.master.coupling.STRATEGIES` or a
    :class:`~cosim.master.coupling.base.CouplingStrategy` subclass (default: the scene's
    ``coupling``); ``step``: communication step (s, default: the scene's);
    ``progress``: tqdm bar (None = shown if the run lasts over 2 s).
    ``options`` go to the strategy's constructor.  ``check_stability``: after every
    step, :class:`cosim.master.guard.StabilityGuard` raises
    :class:`cosim.master.guard.InstabilityError` (saying what to change) when the run has
    produced non-finite values, a penetration beyond physical sense or created energy, or when
    its work explodes (more than ``max_steps`` accepted steps, or refinements and contact
    substeps far beyond any impact's needs).  The outputs at t0 (after initialisation) are
    checked before the first step: a non-finite one stops the run naming the instance.
    """
    scene = system.scene
    stop_time = scene.stop_time if stop_time is None else float(stop_time)
    step = scene.step if step is None else float(step)
    cls = get_strategy(strategy or scene.coupling)
    if system.initialized:
        system.reset()
    calls_before = system.fmu_calls()
    steps_before = system.do_steps()
    wall = time.perf_counter()
    system.initialize(0.0, stop_time, host=cls.host)
    solver = cls(system, 0.0, stop_time, step, **options)
    initial_outputs_finite(system)
    guard = None
    if check_stability:
        guard = StabilityGuard(system, max_steps=max_steps, base_step=step)
    recorder = Recorder(system, int(np.ceil(stop_time / step)) + 2)
    recorder.record(0.0)
    bar = None
    if progress is not False:
        from tqdm import tqdm

        bar = tqdm(total=stop_time, unit="s", delay=0.0 if progress else 2.0, leave=False,
                   desc=scene.name, bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.2f}/{total:g} s "
                                               "[{elapsed}<{remaining}]")
    shown = 0.0
    try:
        while solver.status == "running":
            solver.step()
            if guard is not None:
                guard.check(solver.t, getattr(solver, "h_last", solver.h))
            recorder.record(solver.t)
            if callback is not None:
                callback(solver.t)
            if bar is not None and solver.t - shown >= 0.01 * stop_time:
                bar.update(solver.t - shown)
                shown = solver.t
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - wall
    stats = dict(getattr(solver, "stats", {}))
    if guard is not None and guard.step_over_time_scale:
        stats["step_over_time_scale"] = dict(guard.step_over_time_scale)
    k = recorder.count
    cost = Cost(wall_time_s=wall, communication_steps=solver.communication_steps, rollbacks=solver.rollbacks,
                fmu_calls=system.fmu_calls() - calls_before,
                do_steps={n: v - steps_before.get(n, 0) for n, v in system.do_steps().items()})
    return SimulationResult(
        scene=scene, strategy=cls.name, time=recorder.time[:k].copy(), columns=list(system.columns),
        values=recorder.values[:k].copy(), cost=cost, instances=[n.name for n in system.nodes], stats=stats)
