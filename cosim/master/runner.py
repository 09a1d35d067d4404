"""Running a scene from Python: :func:`run_scene` (the command line's ``run`` calls it).

    from cosim import run_scene
    run = run_scene("kobe", [Override.of("pounding.gap", 0.02)], out="out/kobe_2cm")
    run.summary.peak_force_N, run.cost.wall_time_s, run.result["pounding_3.F"], run.folder

Loads and checks the scene (:func:`cosim.master.loader.load_scene`), builds the system the
scene calls for, runs it (:func:`cosim.master.simulate.simulate`), summarises it and writes
``history.csv``, ``summary.json`` and the plots into ``out/<scene name>/`` (or ``out``),
complete or not at all.  The FMUs come from ``fmu_dir``, an already loaded ``catalog``, or
:func:`cosim.fmus.default_fmu_dir` (built there from the sources when missing or stale).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

from ..fmus import default_fmu_dir
from .loader import load_scene
from .output import write_results
from .provenance import provenance
from .results import ENERGY_CREATION_LIMIT, ENERGY_RESIDUAL_LIMIT, RunResult, summarize
from .scene import Override
from .simulate import simulate
from .system import Catalog, System

DEFAULT_SCENE = "default"


def settings(coupling: str | None = None, step: float | None = None,
             stop_time: float | None = None) -> list[Override]:
    """The top-level overrides of a run's settings (typed; None leaves the scene's)."""
    out = []
    if coupling is not None:
        out.append(Override(None, "coupling", str(coupling)))
    if step is not None:
        out.append(Override(None, "step", float(step)))
    if stop_time is not None:
        out.append(Override(None, "stop_time", float(stop_time)))
    return out


def run_scene(scene: str | Path | Mapping[str, Any] = DEFAULT_SCENE, overrides: Sequence[Override | str] = (), *,
              out: str | Path | None = None, coupling: str | None = None, step: float | None = None,
              stop_time: float | None = None, fmu_dir: str | Path | None = None,
              catalog: Catalog | None = None, write: bool = True, plots: bool = True,
              progress: bool | None = None, parquet: bool = False,
              energy_limit: float = ENERGY_RESIDUAL_LIMIT, creation_limit: float = ENERGY_CREATION_LIMIT,
              **strategy_options: Any) -> RunResult:
    """Load, validate and run a scene; write its results unless ``write=False``.

    ``overrides``: :class:`~cosim.master.scene.Override` objects (or their text form,
    ``"pounding.gap=0.02"``); ``coupling``, ``step`` (s), ``stop_time`` (s) replace the
    scene's; ``strategy_options`` go to the coupling strategy.  Raises
    :class:`~cosim.master.scene.SceneError` (invalid scene or override) or
    :class:`~cosim.master.fmi.FMUError` (an FMU refused a parameter or a step) before
    anything is written, :class:`~cosim.master.guard.InstabilityError` when the stability
    guard stops the run.  ``catalog`` reuses already loaded FMUs; ``parquet`` also writes
    ``history.parquet``; ``energy_limit``, ``creation_limit``: when the summary warns of lost
    accuracy (:func:`~cosim.master.results.accuracy_warnings`).
    """
    own_catalog = catalog is None
    if own_catalog:
        catalog = Catalog(fmu_dir if fmu_dir is not None else default_fmu_dir())
    try:
        loaded = load_scene(scene, list(overrides) + settings(coupling, step, stop_time), catalog)
        with System(loaded, catalog) as system:
            result = simulate(system, progress=progress, **strategy_options)
        made_with = provenance(loaded, catalog)
    finally:
        if own_catalog:
            catalog.close()
    summary = summarize(result, made_with, energy_limit=energy_limit, creation_limit=creation_limit)
    folder = None
    if write:
        folder = write_results(result, Path(out) if out else Path("out") / loaded.name, plots=plots,
                               summary=summary, parquet=parquet)
    return RunResult(loaded, result, summary, folder)
