"""The command line of the package: ``pounding-cosim <command> ...`` (the only module with argparse).

    pounding-cosim run [SCENE] [--set INSTANCE.VAR=VALUE ...] [--out DIR] ...   # default scene -> out/default/
    pounding-cosim list                                  # bundled scenes and studies
    pounding-cosim study STUDY [--workers N] [--resume] ...; pounding-cosim study plot RESULTS.csv --x ... --y ...
    pounding-cosim study compare RESULTS.csv --x ... --pair ... --y ... --out DIR
    pounding-cosim calibrate --model crvk --m1 200 --m2 200 --k 1.8974e11 --v 10 --cr 0.4
    pounding-cosim report --out docs/reproduction [--quick]
    pounding-cosim accuracy SCENE [--out DIR]
    pounding-cosim spectrum RECORD [RECORD ...] [--damping 0.05] [--periods 0.02:10:100] [--out DIR]
    pounding-cosim separation SCENE [--records R ...] [--pga G] [--no-check] [--out DIR]
    pounding-cosim build-fmus [--out DIR] [--force] [NAME ...]
    pounding-cosim export-ssp SCENE FILE.ssp;  pounding-cosim cr-table;  pounding-cosim fmu-docs;  pounding-cosim opensees SCENE
    pounding-cosim --version

``python cosim/run.py``, ``python cosim/study.py``, ``python cosim/calibrate.py``,
``python cosim/report.py`` and ``python build_fmu.py`` are the same commands (thin shims), as
are ``python -m cosim`` and ``python -m cosim.cli``.

Exit codes, the same for every command (:func:`exit_code`): 0 success; 1 a run that failed
(an FMU refused a step, the stability guard stopped it, the disk filled up while writing);
2 bad input (scene, ``--set``, study, calibration target, a parameter an FMU refuses at
initialisation, a missing or corrupt file, an output path the rule refuses, a run beyond its
limits); 130 interrupted (Ctrl-C: "interrupted", nothing written).  Errors are one line on
standard error, ``error: ...``, never a traceback.

Output paths follow one rule (:mod:`cosim.files`): a new or empty folder, or one this package
wrote before and only with ``--overwrite``; a default path that is taken is numbered.  Text given to
``--set`` is parsed here, once (:func:`cosim.master.scene.parse_override`); everything below
this module takes typed values.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Callable, NoReturn, Sequence

from . import __version__

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


class BadInput(Exception):
    """A problem with the command line's input found by the command line itself (exit 2)."""


def _loaded(module: str, name: str) -> type | None:
    """Class ``name`` of ``module`` if that module is already imported, else None."""
    return getattr(sys.modules.get(module), name, None)


def exit_code(exc: BaseException) -> int:
    """The exit code of a command that raised ``exc`` (the one mapping of the package)."""
    from .files import OutputError, WriteError
    from .master import FMUError, InstabilityError, SceneError
    from .master.fmi import FMULoadError

    # the applications' own errors, if their module was loaded at all (an exception cannot come
    # from a module that never ran; importing the study application would load Dask, ~1 s)
    app_errors = tuple(cls for cls in (_loaded("cosim.apps.calibrate", "CalibrationError"),
                                       _loaded("cosim.apps.study.spec", "StudyError"),
                                       _loaded("cosim.peers.ssp", "NotExpressibleError")) if cls is not None)

    if isinstance(exc, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if isinstance(exc, WriteError):          # the work was done, the disk could not take it
        return EXIT_FAILED
    if isinstance(exc, (OutputError, FMULoadError)):
        return EXIT_BAD_INPUT
    if isinstance(exc, FMUError):
        # parameters and records are checked at initialisation: that is bad input too
        return EXIT_FAILED if exc.function == "fmi2DoStep" else EXIT_BAD_INPUT
    if isinstance(exc, InstabilityError):   # the run went unphysical: nothing was written
        return EXIT_FAILED
    cluster_lost = _loaded("cosim.apps.study.cluster", "ClusterLost")
    if cluster_lost is not None and isinstance(exc, cluster_lost):
        return EXIT_FAILED   # a study's scheduler (or every able worker) went away: rows kept
    if isinstance(exc, (BadInput, SceneError, FileNotFoundError, FileExistsError) + app_errors):
        return EXIT_BAD_INPUT
    raise exc


def _overrides(texts: Sequence[str]):
    from .master.scene import parse_override

    return [parse_override(t) for t in texts]


def _fmu_dir(path: Path | None) -> Path:
    from .fmus import default_fmu_dir

    return path if path is not None else default_fmu_dir()


# -- the commands ----------------------------------------------------------------------------------
def cmd_run(args) -> int:
    if args.list:
        return cmd_list(args, studies=False)
    if args.export_ssp is not None:
        args.file = args.export_ssp
        return cmd_export_ssp(args)
    if args.accuracy:
        return cmd_accuracy(args)
    from .master import format_summary, run_scene

    record = args.record
    if record not in ("summary", "all"):
        record = [c.strip() for c in record.split(",") if c.strip()]
    run = run_scene(args.scene, _overrides(args.overrides), out=args.out, overwrite=args.overwrite,
                    coupling=args.coupling, step=args.step, stop_time=args.stop_time, fmu_dir=args.fmu_dir,
                    plots=not args.no_plots, progress=False if args.no_progress else None,
                    output_interval=args.output_interval, record=record, max_steps=args.max_steps,
                    parquet=args.parquet, energy_limit=args.energy_limit, creation_limit=args.creation_limit)
    print(format_summary(run.summary))
    print(f"results: {run.folder}")
    return EXIT_OK


def cmd_list(args, studies: bool = True) -> int:
    from .master import SceneError, bundled_scenes, load_scene

    for name in bundled_scenes():
        try:
            description = load_scene(name).description
        except SceneError as exc:
            description = f"(invalid: {exc})"
        print(f"{name:<16} {description}")
    if studies:
        from .apps.study import StudyError, bundled_studies, load_study

        print("\nstudies:")
        for name in bundled_studies():
            try:
                study = load_study(name)
                text = f"{study.n_cases} cases of {study.scene.stem}: {study.description}".rstrip(": ")
            except StudyError as exc:
                text = f"(invalid: {exc})"
            print(f"{name:<28} {text}")
    return EXIT_OK


def cmd_accuracy(args) -> int:
    from .apps.accuracy import markdown, study_and_write

    t0 = time.perf_counter()
    study, folder = study_and_write(args.scene, args.out, _overrides(args.overrides), fmu_dir=args.fmu_dir,
                                    stop_time=args.stop_time, overwrite=args.overwrite, repeats=args.repeats)
    print(markdown(study))
    print(f"written: {folder} (study wall time {time.perf_counter() - t0:.0f} s)")
    return EXIT_OK


def cmd_spectrum(args) -> int:
    from .apps.spectra import period_grid, record_spectra, summary_lines, write_spectrum

    try:
        periods = period_grid(args.periods)
        spectra = record_spectra(args.records, periods, args.damping, fmt=args.format, dt=args.dt, units=args.units,
                                 target_pga_g=args.pga)
    except ValueError as exc:   # a record, a period or the damping: the input's fault
        raise BadInput(str(exc)) from None
    out = args.out if args.out is not None else Path("out") / "spectra"
    out.mkdir(parents=True, exist_ok=True)
    stem = "_".join(s.name for s in spectra) + f"_zeta{args.damping:g}"
    paths = write_spectrum(spectra, out, stem, plot=not args.no_plots)
    print("\n".join(summary_lines(spectra)))
    print("written: " + ", ".join(str(p) for p in paths))
    return EXIT_OK


def cmd_separation(args) -> int:
    from .apps.separation_scene import format_separations, scene_separations, write_separations
    from .files import output_target
    from .master import Catalog, load_scene

    overrides = _overrides(args.overrides)
    name = load_scene(args.scene, overrides).name
    default = args.out is None
    out = output_target(Path("out") / f"{name}_separation" if default else args.out, overwrite=args.overwrite,
                        default=default)   # refused before the runs, not after them
    with Catalog(_fmu_dir(args.fmu_dir)) as catalog:
        try:
            rows = scene_separations(args.scene, overrides, args.records, args.pga, check=not args.no_check,
                                     method=args.method, catalog=catalog)
        except ValueError as exc:   # SceneError, a record that cannot be read: the input's fault
            raise BadInput(str(exc)) from None
    print(format_separations(rows))
    folder = write_separations(rows, out, plots=not args.no_plots, overwrite=args.overwrite, default=default)
    print(f"results: {folder}")
    failed = [r for r in rows if r.check is not None and not r.check.passed]
    if failed:
        print(f"warning: {len(failed)} check(s) failed: the co-simulation did not confirm contact at 0.99 S and none "
              f"at 1.01 S", file=sys.stderr)
    return EXIT_OK


def cmd_export_ssp(args) -> int:
    from .master.runner import settings
    from .peers.ssp import export

    overrides = _overrides(args.overrides) + settings(args.coupling, args.step, args.stop_time)
    try:
        out, notes, scene = export(args.scene, args.file, overrides, fmu_dir=_fmu_dir(args.fmu_dir),
                                   overwrite=args.overwrite)
    except ValueError as exc:   # a scene or system SSP cannot hold (names, values): the input's fault
        raise BadInput(str(exc)) from None
    for note in notes:
        print(f"note: {note}")
    print(f"SSP 1.0 package: {out} ({len(scene.instances())} components, {len(scene.connections())} connections)")
    return EXIT_OK


def cmd_study_run(args) -> int:
    from .apps.study import StudyError, load_study, run_study, validate_study
    from .apps.study.cases import fixed_text
    from .master import Catalog, Override

    if args.max_cases < 1:
        raise StudyError(f"--max-cases {args.max_cases}: needs at least 1 case")
    study = load_study(args.study, _overrides(args.fixed), max_cases=args.max_cases)
    if args.dry_run:
        from .apps.study.cluster import ctrl_c_deferred

        with ctrl_c_deferred(), Catalog(_fmu_dir(args.fmu_dir)) as catalog:   # the FMUs run here
            validate_study(study, catalog)
        print(f"{study.name}: {study.n_cases} cases of scene {study.scene}, varying "
              + " x ".join("(" + ", ".join(a.variables) + f": {len(a)})" for a in study.axes))
        print(f"{'case':>6}  {'case_id':<12}  values")
        for case in study.cases():
            print(f"{case.index:>6}  {case.id:<12}  "
                  + "  ".join(fixed_text(Override.of(k, v)) for k, v in case.values.items()))
        return EXIT_OK
    if args.workers is not None and args.workers < 1:
        raise StudyError(f"--workers {args.workers}: needs at least 1 worker")
    try:
        result = run_study(study, args.out, workers=args.workers, scheduler=args.scheduler, resume=args.resume,
                           retry_failed=args.retry_failed, fmu_dir=args.fmu_dir, progress=not args.no_progress)
    except KeyboardInterrupt:
        print("interrupted: the finished cases are in the results; complete them with --resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    for worker in result.unfit_workers:
        print(f"note: a worker that joined cannot run the cases, its cases ran on the others: {worker}")
    if result.stale_lock:
        from .apps.study.lock import describe

        print(f"note: took over the lock of a study that no longer runs ({describe(result.stale_lock)})")
    print(f"{study.name}: {result.n_cases} cases, {result.skipped} already done, {result.ran} run now "
          + (f"({result.retried} of them failed or unstable before) " if result.retried else "")
          + f"({result.failed} failed or unstable)"
          + (f" in {result.elapsed_s:.1f} s on {result.workers} workers" if result.ran else ""))
    print(f"results: {result.csv}\n         {result.parquet}")
    return EXIT_OK


def cmd_study_plot(args) -> int:
    from .apps.study import plot_results

    path = plot_results(args.results, args.x, args.y, args.by, args.where, args.out, args.logy)
    print(f"plot: {path}")
    return EXIT_OK


def cmd_study_compare(args) -> int:
    from .apps.study.compare import write_comparison

    md, png = write_comparison(args.results, args.x, args.pair, args.panels, args.y, args.out)
    print(f"table: {md}\nplot: {png}")
    return EXIT_OK


def cmd_calibrate(args) -> int:
    import contextlib

    from .apps.calibrate import CalibrationError, calibrate, calibrate_stiffness, write_into
    from .files import output_target, written_folder

    if args.peak_force is not None and args.k is not None:
        raise CalibrationError("give either --k (calibrate zeta) or --peak-force (calibrate k), not both")
    if args.peak_force is None and args.k is None:
        raise CalibrationError("--k is required (contact stiffness in N/m^n), or --peak-force to calibrate it")
    claim = contextlib.nullcontext()
    if args.out is not None:   # claimed before the calibration runs: a refused path is known at once
        claim = written_folder(output_target(args.out, overwrite=args.overwrite), "calibration",
                               overwrite=args.overwrite)
    with claim as pending:
        if args.peak_force is not None:
            res = calibrate_stiffness(args.model, args.peak_force, args.cr, m1=args.m1, m2=args.m2,
                                      v_imp=args.v_imp, n=args.n, fmu=not args.no_fmu, fmu_dir=args.fmu_dir)
        else:
            res = calibrate(args.model, args.cr, m1=args.m1, m2=args.m2, k=args.k, v_imp=args.v_imp, n=args.n,
                            fmu=not args.no_fmu, zeta_bounds=tuple(args.zeta_bounds), fmu_dir=args.fmu_dir)
        if pending is not None:
            write_into(res, pending.path, plots=not args.no_plots)
    print(res.summary())
    if pending is not None:
        print(f"results: {pending.target}")
    return EXIT_OK


def cmd_report(args) -> int:
    from .apps.report import build_report

    t0 = time.perf_counter()
    folder = build_report(args.out, quick=args.quick, fmu_dir=args.fmu_dir, jobs=args.jobs, overwrite=args.overwrite)
    print(f"report: {folder / 'report.md'} ({time.perf_counter() - t0:.0f} s)")
    return EXIT_OK


def cmd_build_fmus(args) -> int:
    from .fmus import FMU_NAMES, build_all, fmu_folder

    unknown = set(args.names) - set(FMU_NAMES)
    if unknown:
        raise BadInput(f"unknown FMU {sorted(unknown)}; known: {sorted(FMU_NAMES)}")
    out = args.out if args.out is not None else fmu_folder()
    print(f"FMUs in {out}:")
    build_all(out, force=args.force, names=tuple(args.names) or None, quiet=False)
    return EXIT_OK


def cmd_cr_table(args) -> int:
    from .apps.cr_table import cr_table

    print(cr_table(ns=tuple(args.n)))
    return EXIT_OK


def cmd_fmu_docs(args) -> int:
    from .apps.fmu_docs import missing_fmus, tables

    folder = _fmu_dir(args.fmu_dir)
    missing = missing_fmus(folder)
    if missing:
        raise BadInput(f"{folder}: no {', '.join(missing)} (build them with "
                       f"`pounding-cosim build-fmus --out {folder}`, or omit FMU_DIR)")
    sys.stdout.write(tables(folder))
    return EXIT_OK


def cmd_opensees(args) -> int:
    from .master import load_scene
    from .peers.opensees import compare, opensees_available

    if not opensees_available():
        print("error: openseespy is not importable (pip install openseespy)", file=sys.stderr)
        return EXIT_FAILED
    print(compare(load_scene(args.scene, _overrides(args.overrides)), args.dt, args.material))
    return EXIT_OK


# -- the parser ------------------------------------------------------------------------------------
def _timing_repeats(text: str) -> int:
    """Timings per cheap run of the accuracy study (argparse type), 1 to MAX_TIMING_REPEATS."""
    from .apps.accuracy import MAX_TIMING_REPEATS

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer (allowed: 1 to {MAX_TIMING_REPEATS})") from None
    if not 1 <= value <= MAX_TIMING_REPEATS:
        raise argparse.ArgumentTypeError(f"{text} is outside the allowed range 1 to {MAX_TIMING_REPEATS}")
    return value


def _repeats_option(p: argparse.ArgumentParser) -> None:
    from .apps.accuracy import REPEAT_BELOW_S, TIMING_REPEATS

    p.add_argument("--repeats", type=_timing_repeats, default=TIMING_REPEATS, metavar="N",
                   help=f"accuracy study: time every run under {REPEAT_BELOW_S:g} s (the package's and OpenSees' "
                        "alike) N times and keep the fastest (default: %(default)s)")


def _fraction(text: str) -> float:
    """A fraction 0 < value < 1 (argparse type): refused with the value and the range otherwise."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (allowed: 0 < value < 1)") from None
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"{text} is outside the allowed range 0 < value < 1")
    return value


def _scene_options(p: argparse.ArgumentParser, run: bool = True) -> None:
    from .master.coupling import STRATEGIES

    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="INSTANCE.VAR=VALUE",
                   help="override an FMU parameter (repeatable), e.g. pounding.gap=0.02")
    p.add_argument("--coupling", choices=sorted(STRATEGIES), help="coupling strategy (default: the scene's)")
    p.add_argument("--step", type=float, help="communication step in s (default: the scene's)")
    p.add_argument("--stop-time", type=float, help="end time in s (default: the scene's)")
    p.add_argument("--fmu-dir", type=Path, help="folder with the FMUs (default: build them where the package "
                                                "keeps them: build/fmus in a checkout, else a per-user cache)")


def _overwrite_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of an earlier run of this package in --out (a folder holding "
                        "anything else is never replaced)")


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    """The parser and its subcommands' parsers (by name)."""
    from .apps.study.spec import MAX_CASES as STUDY_MAX_CASES
    from .fmus import FMU_NAMES
    from .master.results import ENERGY_CREATION_LIMIT, ENERGY_RESIDUAL_LIMIT
    from .master.limits import DEFAULT_MAX_STEPS
    from .master.runner import DEFAULT_SCENE
    from .peers.opensees import MATERIALS

    parser = argparse.ArgumentParser(prog="pounding-cosim", description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="exit codes: 0 ok, 1 failed run, 2 bad input, 130 interrupted")
    parser.add_argument("--version", action="version", version=f"pounding-cosim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    subs: dict[str, argparse.ArgumentParser] = {}

    def add(name: str, handler: Callable, help: str, **kwargs) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=help, **kwargs)
        p.set_defaults(handler=handler)
        subs[name] = p
        return p

    p = add("run", cmd_run, "run a scene: writes history.csv, summary.json and plots into out/<scene>/")
    p.add_argument("scene", nargs="?", default=DEFAULT_SCENE,
                   help="scene file or bundled scene name (default: %(default)s)")
    _scene_options(p)
    p.add_argument("--out", type=Path, help="result folder: new or empty (default: out/<scene name>, numbered "
                                            "-2, -3, ... when taken)")
    _overwrite_option(p)
    p.add_argument("--output-interval", type=float, metavar="SECONDS",
                   help="at most one history.csv row per interval (default: the scene's output_interval, else "
                        "its step; 0: every communication point); peaks are taken from every step")
    p.add_argument("--record", default="summary", metavar="SET",
                   help="columns of history.csv: 'summary' (what the summary and plots use, the default), "
                        "'all', or instance.variable names separated by commas")
    p.add_argument("--max-steps", type=int, default=DEFAULT_MAX_STEPS, metavar="N",
                   help="largest number of communication steps a run may take, planned or refined "
                        "(default %(default)s); raise it on purpose for a longer run")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--parquet", action="store_true",
                   help="also write history.parquet (units and descriptions in the column metadata)")
    p.add_argument("--energy-limit", type=_fraction, default=ENERGY_RESIDUAL_LIMIT, metavar="FRACTION",
                   help="warn when |energy residual| exceeds this fraction of the input energy (default: %(default)g)")
    p.add_argument("--creation-limit", type=_fraction, default=ENERGY_CREATION_LIMIT, metavar="FRACTION",
                   help="warn that the run created energy when the residual is below minus this fraction of the "
                        "input energy (default: %(default)g)")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.add_argument("--list", action="store_true", help="list the bundled scenes and exit")
    p.add_argument("--accuracy", action="store_true",
                   help="accuracy/time study (as the accuracy command): every coupling strategy over a range of "
                        "steps against the reference and OpenSees; writes accuracy.csv/.md/.png into --out")
    _repeats_option(p)
    p.add_argument("--export-ssp", type=Path, metavar="FILE.ssp",
                   help="write the scene as an SSP 1.0 package (FMUs included) and exit without running")

    add("list", cmd_list, "list the bundled scenes and studies")

    p = add("accuracy", cmd_accuracy, "accuracy/time study of a scene: every coupling strategy against the "
                                      "reference solver and OpenSees")
    p.add_argument("scene", help="scene file or bundled scene name")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="INSTANCE.VAR=VALUE",
                   help="override an FMU parameter (repeatable)")
    p.add_argument("--stop-time", type=float, help="end time in s (default: the scene's)")
    p.add_argument("--fmu-dir", type=Path, help="folder with the FMUs")
    p.add_argument("--out", type=Path, help="result folder: new or empty (default: out/<scene>_accuracy, numbered "
                                            "when taken)")
    _repeats_option(p)
    _overwrite_option(p)

    from fmu_src.ground_records import FORMATS, UNITS
    from fmu_src.response_spectrum import DEFAULT_DAMPING

    p = add("spectrum", cmd_spectrum, "elastic response spectra of records (displacement, pseudo-velocity, "
                                      "pseudo-acceleration): a CSV table and a log-log plot")
    p.add_argument("records", nargs="+", metavar="RECORD",
                   help="bundled record name (elcentro1940 kobe1995 sanfernando1971 parkfield1966) or a file")
    p.add_argument("--damping", type=float, default=DEFAULT_DAMPING, help="damping ratio (default %(default)s)")
    p.add_argument("--periods", nargs="+", metavar="T",
                   help="periods in s, or START:STOP:NUM log-spaced (default 0.02:10:100)")
    p.add_argument("--pga", type=float, metavar="G", help="scale each record to this PGA in g (default: as recorded)")
    p.add_argument("--format", choices=FORMATS, default="auto", help="file format (default %(default)s)")
    p.add_argument("--dt", type=float, help="sampling interval in s of a single-column file")
    p.add_argument("--units", choices=sorted(UNITS), default="g", help="units of the file's values (default g)")
    p.add_argument("--out", type=Path, help="folder for <records>_zeta<damping>.csv/.png (default out/spectra); "
                                            "existing files are never replaced")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plot")

    p = add("separation", cmd_separation,
            "the separation that avoids pounding at each level of a scene, per record, beside the code rules "
            "(ABS, SRSS, EC8 0.7 SRSS, DDC) from histories and spectra, checked by co-simulation at 0.99 and "
            "1.01 times it")
    p.add_argument("scene", help="scene file or bundled scene name")
    p.add_argument("--records", nargs="+", metavar="RECORD",
                   help="records to use instead of the scene's (bundled names or files; the scene's scaling applies)")
    p.add_argument("--pga", type=float, metavar="G", help="scale every record to this PGA in g")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="INSTANCE.VAR=VALUE",
                   help="scene override, as for run (repeatable)")
    p.add_argument("--method", choices=("exact", "bisection"),
                   help="exact (linear buildings at rest, the default where it applies) or bisection on the gap "
                        "with co-simulation runs (any building)")
    p.add_argument("--no-check", action="store_true", help="skip the co-simulation runs at 0.99 and 1.01 times the gap")
    p.add_argument("--fmu-dir", type=Path, help="folder with the FMUs")
    p.add_argument("--out", type=Path, help="result folder: new or empty (default: out/<scene>_separation, numbered "
                                            "when taken)")
    _overwrite_option(p)
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plot")

    p = add("export-ssp", cmd_export_ssp, "write a scene as an SSP 1.0 package (FMUs included)")
    p.add_argument("scene", help="scene file or bundled scene name")
    p.add_argument("file", type=Path, metavar="FILE.ssp")
    _scene_options(p)
    p.add_argument("--overwrite", action="store_true", help="replace FILE.ssp if it exists (never a folder)")

    p = add("study", cmd_study_run, "run a parameter study on Dask (`study plot ...` plots its results)",
            formatter_class=argparse.RawDescriptionHelpFormatter,
            epilog="plots: pounding-cosim study plot RESULTS.csv --x VAR --y COLUMN [--by VAR]")
    p.add_argument("study", help="study file (TOML) or bundled study name, e.g. fig8a_gap")
    p.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="use the Dask cluster at this address instead")
    p.add_argument("--out", type=Path, help="result folder (default: out/studies/<study name>)")
    p.add_argument("--resume", action="store_true", help="complete the results already in --out: run only the "
                                                         "cases without a row")
    p.add_argument("--retry-failed", action="store_true",
                   help="with --resume (implied): also run again the cases whose rows are failed or unstable "
                        "(their old rows are replaced)")
    p.add_argument("--max-cases", type=int, default=STUDY_MAX_CASES, metavar="N",
                   help="refuse a study of more than N cases (default %(default)s: about 70 min of one core "
                        "with full records); raise it on purpose")
    p.add_argument("--set", dest="fixed", action="append", default=[], metavar="INSTANCE.VAR=VALUE",
                   help="one more fixed override for every case (repeatable), e.g. stop_time=5")
    p.add_argument("--fmu-dir", type=Path, help="folder with the FMUs")
    p.add_argument("--dry-run", action="store_true",
                   help="check the study (every value on the FMUs) and print its cases, one line each "
                        "(number, case_id, values); run nothing, write nothing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    p = add("study-plot", cmd_study_plot, "plot a summary column of a study against a varied variable "
                                          "(also: study plot)")
    p.add_argument("results", type=Path, help="results.csv of a study")
    p.add_argument("--x", required=True, help="varied column on the abscissa, e.g. pounding.gap")
    p.add_argument("--y", required=True, help="summary column, e.g. peak_force_N")
    p.add_argument("--by", help="one curve per value of this column, e.g. ground.record")
    p.add_argument("--where", action="append", default=[], metavar="COLUMN=VALUE",
                   help="keep only these rows (repeatable)")
    p.add_argument("--logy", action="store_true", help="logarithmic y axis")
    p.add_argument("--out", type=Path, help="PNG file (default: next to the CSV)")

    p = add("study-compare", cmd_study_compare, "two variants of a study side by side: comparison.md (table) and "
                                                "comparison.png (also: study compare)")
    p.add_argument("results", type=Path, help="results.csv of a study")
    p.add_argument("--x", required=True, help="varied column on the abscissa, e.g. pounding.gap")
    p.add_argument("--pair", required=True, help="varied column with the two variants, e.g. left.hysteresis")
    p.add_argument("--panels", help="one row of panels per value of this column, e.g. ground.record")
    p.add_argument("--y", nargs="+", required=True, help="summary columns, e.g. peak_force_N impacts")
    p.add_argument("--out", type=Path, required=True, help="folder for comparison.md and comparison.png")

    from fmu_src.contact_laws import MODELS

    from .apps.calibrate import ZETA_MAX

    p = add("calibrate", cmd_calibrate, "calibrate a contact law's damping constant (or stiffness) through the "
                                        "FMUs, the seed paper's cyclic procedure",
            formatter_class=argparse.RawDescriptionHelpFormatter, epilog="models: " + " ".join(MODELS))
    p.add_argument("--model", required=True, help="contact model (see below)")
    p.add_argument("--m1", type=float, required=True, help="mass of body 1 [kg]")
    p.add_argument("--m2", type=float, required=True, help="mass of body 2 [kg]")
    p.add_argument("--k", type=float, help="contact stiffness [N/m^n] (not with --peak-force)")
    p.add_argument("--n", type=float, default=1.5, help="stiffness exponent (default %(default)s)")
    p.add_argument("--v", "--v-imp", dest="v_imp", type=float, required=True, help="impact velocity [m/s]")
    p.add_argument("--cr", type=float, required=True, help="target (or assumed) coefficient of restitution")
    p.add_argument("--peak-force", type=float, help="calibrate k to this measured peak force [N]")
    p.add_argument("--zeta-bounds", type=float, nargs=2, default=(0.0, ZETA_MAX), metavar=("LOW", "HIGH"),
                   help=f"search interval of the damping constant (default 0 {ZETA_MAX:g})")
    p.add_argument("--no-fmu", action="store_true", help="physics level only (no co-simulation)")
    p.add_argument("--fmu-dir", type=Path, help="folder with the FMUs")
    p.add_argument("--out", type=Path, help="write calibration.json, loop.png, force_time.png into this new or "
                                            "empty folder")
    _overwrite_option(p)
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")

    p = add("report", cmd_report, "regenerate the reproduction report of the seed paper")
    p.add_argument("--out", type=Path, default=Path("docs/reproduction"),
                   help="report folder: new, empty, or an earlier report's with --overwrite (default %(default)s)")
    _overwrite_option(p)
    p.add_argument("--quick", action="store_true", help="reduced grids and shortened records (tests)")
    p.add_argument("--fmu-dir", type=Path, help="folder with the FMUs")
    p.add_argument("--jobs", type=int, default=2, help="processes for the earthquake runs (default %(default)s)")

    p = add("build-fmus", cmd_build_fmus, "build the FMUs (skipped when they are up to date)")
    p.add_argument("--out", type=Path, help="output folder (default: build/fmus in a checkout, else a per-user cache)")
    p.add_argument("--force", action="store_true", help="rebuild even if sources are unchanged")
    p.add_argument("names", nargs="*", help=f"FMUs to build (default: all: {' '.join(FMU_NAMES)})")

    p = add("cr-table", cmd_cr_table, "the CR each contact law achieves with its published constant")
    p.add_argument("--n", type=float, nargs="*", default=[1.5], help="stiffness exponents for the table")

    p = add("fmu-docs", cmd_fmu_docs, "print the Markdown tables of the FMUs' variables (as in README.md)")
    p.add_argument("fmu_dir", nargs="?", type=Path, default=None, metavar="FMU_DIR",
                   help="folder holding the built FMUs (default: build them where the package keeps them)")

    p = add("opensees", cmd_opensees, "OpenSees against the reference solver on a scene, at several time steps")
    p.add_argument("scene", help="scene file or bundled scene name")
    p.add_argument("--dt", type=float, nargs="+", default=[1e-3, 5e-4, 2e-4, 1e-4], help="time steps (s)")
    p.add_argument("--material", choices=MATERIALS, default="JankowskiImpact")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="INSTANCE.VAR=VALUE",
                   help="scene override, as for run")
    return parser, subs


def main(argv: Sequence[str] | None = None, prog: str | None = None) -> int:
    """Run one command; returns its exit code.  ``prog``: a shim's name (``python cosim/run.py``),
    whose first argument is then the command."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:2] in (["study", "plot"], ["study", "compare"]):
        prog = f"{prog} {argv[1]}" if prog else None
        argv = [f"study-{argv[1]}", *argv[2:]]
    parser, subs = build_parser()
    if prog and argv and argv[0] in subs:
        subs[argv[0]].prog = prog
        args = subs[argv[0]].parse_args(argv[1:])
    else:
        args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return EXIT_BAD_INPUT
    import warnings

    from .master.fmi import deferred_interrupts

    # numpy's overflow/invalid-value warnings from inside the FMUs and the master are not for the
    # user: every result is checked (FMUs refuse non-finite states, the stability guard stops
    # the run) and the one line that explains it is the error message
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    try:
        with deferred_interrupts():   # Ctrl-C never lands inside an FMU's own code (see there)
            return args.handler(args)
    except BaseException as exc:   # noqa: BLE001 - mapped to an exit code or re-raised
        if isinstance(exc, SystemExit):
            raise
        code = exit_code(exc)
        if code == EXIT_INTERRUPTED:
            print("interrupted", file=sys.stderr)
        else:
            print(f"error: {exc}", file=sys.stderr)
        return code


def console(argv: Sequence[str] | None = None, prog: str | None = None) -> NoReturn:
    """The ``pounding-cosim`` entry point (and the shims'): :func:`main`, then end the process
    through :func:`cosim.master.fmi.exit_process` (pythonfmu libraries loaded: see there)."""
    from .master.fmi import exit_process

    exit_process(main(argv, prog))


if __name__ == "__main__":
    console()
