"""One case in one process, and the checks before a study runs.

:class:`CaseRunner` keeps the FMUs loaded and one system reused (reset between cases);
:func:`case_row` turns a run's typed summary into a row of the results table with a status;
:func:`validate_study` tries every value of every axis through the scene loader and the FMUs
before any case runs.
"""
from __future__ import annotations

import math
import os
import threading
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

from ...master.fmi import FMUError
from ...master.guard import InstabilityError
from ...master.loader import load_scene
from ...master.results import Summary, summarize
from ...master.scene import Override, SceneError
from ...master.simulate import simulate
from ...master.system import Catalog, System
from .results_io import BUILDING_COLUMNS, one_line
from .spec import DEFAULT_ENERGY_TOLERANCE, Study, StudyError


def case_row(summary: Summary, energy_tolerance: float) -> dict[str, Any]:
    """Flatten a run's summary (:class:`cosim.master.results.Summary`) into study columns, with a status."""
    cost = summary.cost
    row: dict[str, Any] = dict(
        peak_force_N=summary.peak_force_N, impacts=summary.impacts, dissipated_energy_J=summary.dissipated_energy_J,
        max_penetration_m=summary.max_penetration_m, peak_impact_velocity_m_s=summary.peak_impact_velocity_m_s,
        first_impact_s=summary.first_impact_s, energy_input_J=summary.energy_input_J,
        energy_residual_relative=summary.energy_residual_relative, stop_time_s=summary.stop_time_s,
        communication_steps=cost.communication_steps, rollbacks=cost.rollbacks, wall_time_s=cost.wall_time_s)
    for name, b in summary.buildings.items():
        for c in BUILDING_COLUMNS:
            row[f"{name}.{c}"] = getattr(b, c)
    numbers = [v for v in row.values() if isinstance(v, float)]
    if not all(math.isfinite(v) for v in numbers):
        row.update(status="unstable", error="non-finite result: " + ", ".join(
            k for k, v in row.items() if isinstance(v, float) and not math.isfinite(v)))
    elif summary.energy_residual_relative < -energy_tolerance:
        # a negative residual is energy the system has and was never given: the coupling created it
        row.update(status="unstable", error=f"energy created: {-summary.energy_residual_relative:.3g} "
                                            f"of the energy input (tolerance {energy_tolerance:g})")
    else:
        row.update(status="ok", error="")
    return row


#: how long (s) :meth:`CaseRunner.close` waits for a running case before leaving its FMUs loaded
CLOSE_WAIT_S = 2.0


class CaseRunner:
    """Runs cases in one process: FMUs loaded once, one :class:`~cosim.master.System` reused.

    The system of the previous case is ``reset`` (fmi2Reset + the new start
    values) when the new case has the same instances and connections, rebuilt
    otherwise, and dropped after a failure (an FMU that refused a step is not
    trusted again).  A lock serialises cases if a worker has several threads.
    """

    def __init__(self, fmu_dir: str | Path):
        self.catalog = Catalog(fmu_dir)
        self.system = None
        self.lock = threading.Lock()
        self.cases_run = 0
        self.systems_built = 0

    def _system_for(self, scene):
        if self.system is not None:
            try:
                self.system.reset(scene)
                return self.system
            except ValueError:
                self._drop_system()
        self.system = System(scene, self.catalog)
        self.systems_built += 1
        return self.system

    def _drop_system(self) -> None:
        if self.system is not None:
            try:
                self.system.close()
            except Exception:  # noqa: BLE001 - freeing a broken instance must not hide the case's error
                pass
            self.system = None

    def run(self, scene_raw: Mapping[str, Any], overrides: Sequence[Override | str],
            energy_tolerance: float = DEFAULT_ENERGY_TOLERANCE) -> dict[str, Any]:
        """Run one case; always returns a row (failures become ``status = "failed"``)."""
        with self.lock:
            start = time.perf_counter()
            try:
                scene = load_scene(scene_raw, overrides, self.catalog)
                system = self._system_for(scene)
                result = simulate(system, progress=False)
                row = case_row(summarize(result), energy_tolerance)
            except (SceneError, FMUError) as exc:
                self._drop_system()
                row = dict(status="failed", error=one_line(exc))
            except InstabilityError as exc:  # the master's run-time monitor stopped the run
                self._drop_system()
                # guard: the guard's reason (not a CSV column; the report retries such cases)
                row = dict(status="unstable", error=one_line(f"{type(exc).__name__}: {exc}"),
                           guard=exc.reason or "unstable")
            except Exception as exc:  # noqa: BLE001 - any failure of one case is recorded, the study goes on
                self._drop_system()
                row = dict(status="failed", error=one_line(f"{type(exc).__name__}: {exc}"))
            self.cases_run += 1
            row["case_time_s"] = time.perf_counter() - start
            row["worker"] = f"{os.uname().nodename}:{os.getpid()}"
            return row

    def close(self, wait_s: float = CLOSE_WAIT_S) -> bool:
        """Free the FMUs, once no case runs; True if they were freed.

        A Dask worker tears its plugin down from its event-loop thread while a cancelled case may
        still run in its task thread (a thread cannot be stopped): freeing the instances under a
        running doStep corrupted the heap ("malloc_consolidate(): unaligned fastbin chunk
        detected" on a study's Ctrl-C, about one run in 30).  So close waits at most ``wait_s``
        for the case to end, and otherwise leaves the FMUs to the ending process."""
        if not self.lock.acquire(timeout=wait_s):
            return False
        try:
            self._drop_system()
            self.catalog.close()
        finally:
            self.lock.release()
        return True


def validate_study(study: Study, catalog) -> list[str]:
    """Check every variable and every value against the scene and the FMUs, before anything runs.

    Each value of each axis is tried with the other axes at their first
    value: the scene loader checks the names (a variable no FMU of the scene
    has) and types, then the FMUs are initialised with those start values, so
    the FMU's own range checks run and their message reaches the user.
    Returns the names of the scene's buildings (their columns in the table).
    """
    first = [axis.values[0] for axis in study.axes]
    trials: list[list[str]] = []
    for a, axis in enumerate(study.axes):
        for point in axis.values if a == 0 else axis.values[1:]:
            values: dict[str, Any] = {}
            for b, other in enumerate(study.axes):
                values.update(zip(other.variables, point if b == a else first[b]))
            trials.append([Override.of(k, v) for k, v in values.items()])
    where = f"{study.path or study.name}"
    scenes = []
    for overrides in trials:
        try:
            scenes.append(load_scene(study.scene, study.fixed + overrides, catalog))
        except SceneError as exc:
            raise StudyError(f"{where}: {_listed(overrides)}: {exc}") from None
    system = System(scenes[0], catalog)
    try:
        for number, (scene, overrides) in enumerate(zip(scenes, trials)):
            try:
                if number:
                    system.reset(scene)
            except ValueError:  # another structure (e.g. n_storeys varied): its own instances
                system.close()
                system = System(scene, catalog)
            try:
                system.initialize(0.0, scene.stop_time)
            except FMUError as exc:
                raise StudyError(f"{where}: {_listed(overrides)}: the FMU refused it: {exc}") from None
    finally:
        system.close()
    return [b.name for b in scenes[0].buildings]


def _listed(overrides: Sequence[Override]) -> str:
    from .cases import fixed_text

    return ", ".join(fixed_text(o) for o in overrides)
