"""Run a pounding scene: ``python cosim/run.py [SCENE] [--set instance.variable=value ...]``.

    python cosim/run.py                                   # scenes/default.toml -> out/default/
    python cosim/run.py kobe --set pounding.gap=0.02 --set pounding.CR=0.5 --out out/kobe_gap2
    python cosim/run.py my_scene.toml --coupling jacobi --step 0.005
    python cosim/run.py --list                            # bundled scenes

SCENE is a scene file or the name of a bundled scene (``scenes/<name>.toml``).
``--set`` overrides any FMU parameter by instance and name: ``pounding.X``
applies to every contact instance, ``pounding_3.X`` to one, ``left.m[1]`` to
one floor of building ``left``, ``ground.record``; ``stop_time=5`` sets a
top-level scene key.  The FMUs are built into ``build/fmus`` if missing or
out of date (``--fmu-dir`` uses another folder).

Writes ``history.csv``, ``summary.json`` and PNG plots into ``out/<scene>/``
(or ``--out``), complete or not at all, and prints the summary.  Exit code 0
on success, 2 for invalid input (scene, override, parameter, record), 1 if an
FMU fails during the run.

API: :func:`run_scene` does the same from Python and returns a
:class:`RunResult`.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

if __package__ in (None, ""):  # run as a script: make the package importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.coupling import STRATEGIES  # noqa: E402
from cosim.adaptive import InstabilityError  # noqa: E402
from cosim.fmi import FMUError  # noqa: E402
from cosim.master import Catalog, SimulationResult, System, simulate  # noqa: E402
from cosim.results import format_summary, summarize, write_results  # noqa: E402
from cosim.scene import ROOT, Scene, SceneError, bundled_scenes, load_scene  # noqa: E402

DEFAULT_SCENE = "default"


@dataclass
class RunResult:
    scene: Scene
    result: SimulationResult
    summary: dict[str, Any]
    folder: Path | None


from cosim.fmus import default_fmu_dir  # noqa: E402,F401  (moved: the library builds FMUs)


def run_scene(scene: str | Path | dict = DEFAULT_SCENE, overrides: Sequence[str] = (), *,
              out: str | Path | None = None, coupling: str | None = None, step: float | None = None,
              stop_time: float | None = None, fmu_dir: str | Path | None = None,
              catalog: Catalog | None = None, write: bool = True, plots: bool = True,
              progress: bool | None = None, **strategy_options: Any) -> RunResult:
    """Load, validate and run a scene; write its results unless ``write=False``.

    Raises :class:`~cosim.scene.SceneError` (invalid scene or override) or
    :class:`~cosim.fmi.FMUError` (an FMU refused a parameter or a step) before
    anything is written.  ``catalog`` reuses already loaded FMUs.
    """
    own_catalog = catalog is None
    if own_catalog:
        catalog = Catalog(fmu_dir if fmu_dir is not None else default_fmu_dir())
    try:
        extra = list(overrides)
        if coupling is not None:
            extra.append(f"coupling={coupling!r}".replace("'", '"'))
        if step is not None:
            extra.append(f"step={float(step)!r}")
        if stop_time is not None:
            extra.append(f"stop_time={float(stop_time)!r}")
        loaded = load_scene(scene, extra, catalog)
        with System(loaded, catalog) as system:
            result = simulate(system, progress=progress, **strategy_options)
    finally:
        if own_catalog:
            catalog.close()
    summary = summarize(result)
    folder = None
    if write:
        folder = write_results(result, Path(out) if out else Path("out") / loaded.name, plots=plots,
                               summary=summary)
    return RunResult(loaded, result, summary, folder)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python cosim/run.py", description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", nargs="?", default=DEFAULT_SCENE,
                        help="scene file or bundled scene name (default: %(default)s)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="INSTANCE.VAR=VALUE",
                        help="override an FMU parameter (repeatable), e.g. pounding.gap=0.02")
    parser.add_argument("--out", type=Path, help="result folder (default: out/<scene name>)")
    parser.add_argument("--coupling", choices=sorted(STRATEGIES), help="coupling strategy (default: the scene's)")
    parser.add_argument("--step", type=float, help="communication step in s (default: the scene's)")
    parser.add_argument("--stop-time", type=float, help="end time in s (default: the scene's)")
    parser.add_argument("--fmu-dir", type=Path, help="folder with the FMUs (default: build them into build/fmus)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    parser.add_argument("--list", action="store_true", help="list the bundled scenes and exit")
    parser.add_argument("--accuracy", action="store_true",
                        help="accuracy/time study: every coupling strategy over a range of steps against the "
                             "reference and OpenSees; writes accuracy.csv/.md/.png into --out")
    parser.add_argument("--export-ssp", type=Path, metavar="FILE.ssp",
                        help="write the scene as an SSP 1.0 package (FMUs included) and exit without running")
    args = parser.parse_args(argv)
    if args.list:
        for name in bundled_scenes():
            try:
                description = load_scene(name).description
            except SceneError as exc:
                description = f"(invalid: {exc})"
            print(f"{name:<16} {description}")
        return 0
    if args.export_ssp is not None:
        from cosim.ssp import export_cli

        return export_cli(args.scene, args.export_ssp, args.overrides, coupling=args.coupling, step=args.step,
                          stop_time=args.stop_time, fmu_dir=args.fmu_dir)
    if args.accuracy:
        from cosim.accuracy import main as accuracy_main

        try:
            return accuracy_main(args.scene, args.out, args.overrides, fmu_dir=args.fmu_dir,
                                 stop_time=args.stop_time)
        except SceneError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    try:
        run = run_scene(args.scene, args.overrides, out=args.out, coupling=args.coupling, step=args.step,
                        stop_time=args.stop_time, fmu_dir=args.fmu_dir, plots=not args.no_plots,
                        progress=False if args.no_progress else None)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except FMUError as exc:
        # parameters and records are checked at initialisation: that is bad input too
        print(f"error: {exc}", file=sys.stderr)
        return 1 if exc.function == "fmi2DoStep" else 2
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except InstabilityError as exc:  # the run went unphysical: nothing was written
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(format_summary(run.summary))
    print(f"results: {run.folder}")
    return 0


if __name__ == "__main__":
    from cosim.fmi import exit_process

    exit_process(main())
