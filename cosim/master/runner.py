"""Running a scene from Python: :func:`run_scene` (the command line's ``run`` calls it).

    from cosim import run_scene
    run = run_scene("kobe", [Override.of("pounding.gap", 0.02)], out="out/kobe_2cm")
    run.summary.peak_force_N, run.cost.wall_time_s, run.result["pounding_3.F"], run.folder

Loads and checks the scene (:func:`cosim.master.loader.load_scene`), checks the run's size
(:func:`cosim.master.limits.check_run_size`) and claims the result folder by the output rule
(:mod:`cosim.files`) before anything runs, then builds the system the scene calls for, runs it
(:func:`cosim.master.simulate.simulate`), summarises it and writes ``history.csv``,
``summary.json`` and the plots into ``out/<scene name>/`` (numbered ``-2``, ``-3``... when taken)
or ``out``, complete or not at all.  The FMUs come from ``fmu_dir``, an already loaded
``catalog``, or :func:`cosim.fmus.default_fmu_dir` (built there from the sources when missing
or stale).
"""
from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any, Mapping, Sequence

from ..files import output_target, written_folder
from ..fmus import default_fmu_dir
from .limits import DEFAULT_MAX_STEPS, check_run_size
from .loader import load_scene
from .output import write_into
from .provenance import provenance
from .results import ENERGY_CREATION_LIMIT, ENERGY_RESIDUAL_LIMIT, RunResult, summarize
from .scene import Override
from .simulate import simulate
from .system import Catalog, System

DEFAULT_SCENE = "default"


def settings(coupling: str | None = None, step: float | None = None,
             stop_time: float | None = None, output_interval: float | None = None) -> list[Override]:
    """The top-level overrides of a run's settings (typed; None leaves the scene's)."""
    out = []
    if output_interval is not None:
        out.append(Override(None, "output_interval", float(output_interval),
                            origin=f"--output-interval {output_interval!r}"))
    if coupling is not None:
        out.append(Override(None, "coupling", str(coupling), origin=f"--coupling {coupling}"))
    if step is not None:
        out.append(Override(None, "step", float(step), origin=f"--step {step!r}"))
    if stop_time is not None:
        out.append(Override(None, "stop_time", float(stop_time), origin=f"--stop-time {stop_time!r}"))
    return out


def run_scene(scene: str | Path | Mapping[str, Any] = DEFAULT_SCENE, overrides: Sequence[Override | str] = (), *,
              out: str | Path | None = None, overwrite: bool = False, coupling: str | None = None,
              step: float | None = None, stop_time: float | None = None, fmu_dir: str | Path | None = None,
              catalog: Catalog | None = None, write: bool = True, plots: bool = True,
              progress: bool | None = None, output_interval: float | None = None,
              record: str | Sequence[str] = "summary", max_steps: int = DEFAULT_MAX_STEPS, parquet: bool = False,
              energy_limit: float = ENERGY_RESIDUAL_LIMIT, creation_limit: float = ENERGY_CREATION_LIMIT,
              **strategy_options: Any) -> RunResult:
    """Load, validate and run a scene; write its results unless ``write=False``.

    ``overrides``: :class:`~cosim.master.scene.Override` objects (or their text form,
    ``"pounding.gap=0.02"``); ``coupling``, ``step`` (s), ``stop_time`` (s) replace the
    scene's; ``output_interval`` (s) and ``record`` say what the history keeps
    (:func:`cosim.master.simulate.simulate`); ``strategy_options`` go to the coupling strategy.
    ``out``: the result folder (default ``out/<scene name>``, numbered when taken); an earlier
    run's folder is replaced only with ``overwrite`` (:mod:`cosim.files`).  ``max_steps`` bounds
    the communication steps, planned and refined.  Raises, before anything runs or is written:
    :class:`~cosim.master.scene.SceneError` (invalid scene or override;
    :class:`~cosim.master.limits.LimitError` for a run beyond its bounds),
    :class:`cosim.files.OutputError` (the folder is refused or not writable, too little space);
    while running: :class:`~cosim.master.fmi.FMUError` (an FMU refused a parameter or a step),
    :class:`~cosim.master.guard.InstabilityError` (the stability guard stopped the run);
    nothing is written then.  ``catalog`` reuses already loaded FMUs; ``parquet`` also writes
    ``history.parquet``; ``energy_limit``, ``creation_limit``: when the summary warns of lost
    accuracy (:func:`~cosim.master.results.accuracy_warnings`).
    """
    own_catalog = catalog is None
    if own_catalog:
        catalog = Catalog(fmu_dir if fmu_dir is not None else default_fmu_dir())
    try:
        loaded = load_scene(scene, list(overrides) + settings(coupling, step, stop_time, output_interval), catalog)
        size = check_run_size(loaded, max_steps, record=record)
        claim: Any = contextlib.nullcontext()
        if write:
            default = out is None
            target = output_target(Path("out") / loaded.name if default else Path(out), overwrite=overwrite,
                                   default=default)
            claim = written_folder(target, "run", overwrite=overwrite, default=default,
                                   expected_bytes=size.output_bytes(plots))
        with claim as pending:
            with System(loaded, catalog) as system:
                result = simulate(system, progress=progress, record=record, max_steps=max_steps,
                                  **strategy_options)
            made_with = provenance(loaded, catalog)
            summary = summarize(result, made_with, energy_limit=energy_limit, creation_limit=creation_limit)
            if pending is not None:
                write_into(pending.path, result, plots, summary, parquet=parquet)
    finally:
        if own_catalog:
            catalog.close()
    return RunResult(loaded, result, summary, pending.target if pending is not None else None)
