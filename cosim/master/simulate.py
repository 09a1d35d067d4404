"""The run loop: a coupling strategy advances a system, the guard watches, a recorder keeps what is asked.

:func:`simulate` initialises a :class:`~cosim.master.system.System`, steps it with a
coupling strategy (:mod:`cosim.master.coupling`) from t = 0 to the stop time, checks every
accepted step with the stability guard (:mod:`cosim.master.guard`), keeps what
:mod:`cosim.master.recording` says (rows at the output interval, peaks and impact onsets of
every step, the final values), logs what the replays of the true peaks need
(:mod:`cosim.master.steplog`: every step each contact FMU took, the buildings around contacts)
and returns a :class:`~cosim.master.results.SimulationResult` (history, peaks, final values,
logs and cost).
"""
from __future__ import annotations

import functools
import time
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from .coupling import get_strategy
from .fmi import FMUError
from .guard import StabilityGuard
from .recording import Recorder, counter_signal_columns, impact_detail_columns, recorded_columns, tracked_columns
from .results import Cost, SimulationResult
from .steplog import ContactWindowLog, LoggedContact, window_columns

if TYPE_CHECKING:
    from .system import System


def _one_blas_thread(run):
    """Run with the BLAS libraries (numpy's and scipy's OpenBLAS) limited to one thread.

    The FMUs of a run compute on matrices of at most a few dozen rows, one after the other, in
    this process: a BLAS thread pool cannot gain on them, and waking its threads costs more than
    the product.  On a shared machine it costs much more: with two OpenBLAS threads a building's
    ``scipy.linalg.expm`` of a 4x4 matrix took 27 ms on average instead of 20 us (measured on the
    2-core machine at a load average of 7: ``free_vibration`` 0.48 s of CPU instead of 0.054 s,
    ``default`` 0.73 s instead of 0.33 s, bit-identical results).
    """
    @functools.wraps(run)
    def limited(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return run(*args, **kwargs)
    return limited


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


@_one_blas_thread
def simulate(system: "System", strategy: str | type | None = None, stop_time: float | None = None,
             step: float | None = None, progress: bool | None = None,
             callback: Callable[[float], None] | None = None, check_stability: bool = True,
             output_interval: float | None = None, record: str | Sequence[str] = "summary",
             max_steps: int | None = None, **options: Any) -> SimulationResult:
    """Initialise ``system`` and run it from t0 = 0 to ``stop_time`` with a coupling strategy.

    ``strategy``: a name from :data:`cosim.master.coupling.STRATEGIES` or a
    :class:`~cosim.master.coupling.base.CouplingStrategy` subclass (default: the scene's
    ``coupling``); ``step``: communication step (s, default: the scene's);
    ``progress``: tqdm bar (None = shown if the run lasts over 2 s).
    ``output_interval`` (s): at most one history row per interval (default: the scene's
    ``output_interval``, else its step; 0: every communication point); ``record``: the recorded
    columns, ``"summary"`` (what the summary and the plots use), ``"all"`` or a list
    (:mod:`cosim.master.recording`); peaks and impact onsets are taken from every step whatever
    is recorded.  ``options`` go to the strategy's constructor.  ``check_stability``: after every
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
    if output_interval is None:
        output_interval = getattr(scene, "output_interval", None)
    asked = output_interval is not None
    output_interval = step if output_interval is None else float(output_interval)
    cls = get_strategy(strategy or scene.coupling)
    if asked and output_interval > 0.0 and cls.takes_long_steps:
        # rows were asked for at this interval: every long step must end on them
        options.setdefault("row_interval", output_interval)
    if system.initialized:
        system.reset()
    calls_before = system.fmu_calls()
    steps_before = system.do_steps()
    wall = time.perf_counter()
    cpu = time.process_time()
    system.initialize(0.0, stop_time, host=cls.host)
    solver = cls(system, 0.0, stop_time, step, **options)
    initial_outputs_finite(system)
    guard = None
    if check_stability:
        guard = StabilityGuard(system, max_steps=max_steps, base_step=step)
    recorder = Recorder(system, stop_time, output_interval, recorded_columns(system, record))
    watched = set(solver.watched_columns()) | set(tracked_columns(system)) | set(impact_detail_columns(system)) | \
        set(counter_signal_columns(system)) | set(window_columns(system))
    if guard is not None:
        watched |= set(guard.watched_columns())
    system.watch(watched, set(recorder.columns))
    plan = system.plan

    def before_step(t_next: float) -> None:
        plan.rows = recorder.due(t_next)

    solver.on_step = before_step
    recorder.start(0.0)
    windows = ContactWindowLog(system)    # the steps that hold a contact force (true peaks)
    initial = dict(zip(system.columns, np.concatenate((system.y, system.ints)).tolist()))
    bar = None
    if progress is not False:
        from tqdm import tqdm

        bar = tqdm(total=stop_time, unit="s", delay=0.0 if progress else 2.0, leave=False,
                   desc=scene.name, bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.2f}/{total:g} s "
                                               "[{elapsed}<{remaining}]")
    shown = 0.0
    try:
        while solver.status == "running":
            t_start = solver.t
            plan.rows = True                   # a strategy that does not say where it steps reads all
            solver.step()
            # the contacts asleep through the step: not called, their outputs as they were (the
            # recorder and the guard pass over them)
            asleep = solver.sleeping()
            recorder.track(t_start, solver.t, asleep)  # first: it reads the counters the guard checks
            windows.track(t_start, solver.t)
            if guard is not None:
                guard.check(solver.t, getattr(solver, "h_last", solver.h), asleep)
            if plan.rows and recorder.due(solver.t):
                recorder.read_ints()
                recorder.record(solver.t)
            if callback is not None:
                callback(solver.t)
            if bar is not None and solver.t - shown >= 0.01 * stop_time:
                bar.update(solver.t - shown)
                shown = solver.t
        solver.finish()
        for node in system.nodes:              # the final value of every output
            node.push_all()
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - wall
    cpu = time.process_time() - cpu
    stats = dict(getattr(solver, "stats", {}))
    if guard is not None and guard.step_over_time_scale:
        stats["step_over_time_scale"] = dict(guard.step_over_time_scale)
    cost = Cost(wall_time_s=wall, communication_steps=solver.communication_steps, rollbacks=solver.rollbacks,
                fmu_calls=system.fmu_calls() - calls_before,
                do_steps={n: v - steps_before.get(n, 0) for n, v in system.do_steps().items()}, cpu_time_s=cpu)
    times, values = recorder.history()
    final = dict(zip(system.columns, np.concatenate((system.y, system.ints)).tolist()))
    return SimulationResult(
        scene=scene, strategy=cls.name, time=times, columns=list(recorder.columns), values=values, cost=cost,
        instances=[n.name for n in system.nodes], stats=stats, final=final, peaks=recorder.peaks(),
        onsets={name: list(v) for name, v in recorder.onsets.items()}, output_interval=output_interval,
        impact_rows=recorder.impact_rows, first_onsets=dict(recorder.first_onsets),
        initial=initial, contact_windows=windows.windows(),
        contact_steps={n.name: n.instance.steps() for n in system.contacts if isinstance(n.instance, LoggedContact)})
