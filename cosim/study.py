"""Parameter studies: many runs of one scene, varied through FMU variables, on Dask.

    python cosim/study.py studies/fig8a_gap.toml                 # local cluster, one worker per core
    python cosim/study.py studies/fig8a_gap.toml --workers 1 --out out/gap1
    python cosim/study.py studies/fig8a_gap.toml --scheduler tcp://head:8786   # an existing cluster
    python cosim/study.py studies/fig8a_gap.toml --resume        # finish an interrupted study
    python cosim/study.py studies/fig8a_gap.toml --dry-run       # check it and count the cases
    python cosim/study.py plot out/studies/fig8a_gap/results.csv --x pounding.gap --y peak_force_N --by ground.record

A study file (TOML) names a scene and the variables to vary::

    name = "fig8a_gap"
    scene = "default"              # bundled scene name, or a path relative to this file
    energy_tolerance = 0.05        # optional: energy created > 5 % of the input = "unstable"

    [set]                          # fixed overrides for every case (like run.py --set)
    stop_time = 40.0

    [vary]                         # a grid: the cartesian product of the axes, in file order
    "ground.record" = ["elcentro1940", "kobe1995", "sanfernando1971", "parkfield1966"]
    "pounding.gap" = { start = 0.0, stop = 0.20, num = 21 }   # linspace, both ends included

    [[zip]]                        # one more axis: these variables change together
    "left.v0[1]" = [1.0, 2.0]
    "right.v0[1]" = [-1.0, -2.0]

The axes form a grid in the order of the file (``[vary]`` keys in order, each
``[[zip]]`` one axis), the first varying slowest.

Every case is the scene plus ``--set``-style overrides ``INSTANCE.VAR=VALUE``:
only FMU start values (and top-level scene keys such as ``stop_time``) change,
on the same built FMUs.  Range values are rounded to 12 significant digits, so
``0.03`` is the number a person would type.

Execution: a Dask ``LocalCluster`` of worker processes (``threads_per_worker
= 1``: the pythonfmu slaves run Python code under the worker's GIL) or an
existing scheduler (``--scheduler``).  The FMU files travel to the workers
inside a worker plugin (:class:`StudyPlugin`), so a remote cluster needs only
this package installed, not the files.  Each worker process keeps one
:class:`CaseRunner`: the FMUs are loaded once, the instances of the scene
are created once and reset (``fmi2Reset``) between cases.

Results: ``results.csv`` (one row per case, appended and flushed as each case
finishes), ``results.parquet`` (regenerated from the CSV at the end and on
``--resume``) and ``study.json`` (what the rows depend on: scene, fixed
overrides, FMU hashes), in ``out/studies/<name>/`` or ``--out``.  A case is
identified by :func:`case_id`, a hash of its varied values: ``--resume``
skips every case already in the CSV (ok or failed), and adding values to a
study and resuming computes only the new cases.  A case that fails (FMU or
scene error) or is unstable (non-finite numbers, or the energy balance shows
energy created) is recorded with its reason and the study goes on.

Exit code: 0 when the study completed (failed cases are results, counted in
the output), 2 for bad input (study, variable, value, scheduler), 130 when
interrupted (the rows already written are kept).
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import itertools
import json
import math
import os
import re
import sys
import threading
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

if __package__ in (None, ""):  # run as a script: make the package importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from distributed.diagnostics.plugin import WorkerPlugin  # noqa: E402

from cosim.fmi import FMUError  # noqa: E402
from cosim.scene import ROOT, SceneError, load_scene, resolve_scene  # noqa: E402

STUDY_KEYS = ("name", "description", "scene", "energy_tolerance", "set", "vary", "zip")
RANGE_KEYS = ("start", "stop", "num")
DEFAULT_ENERGY_TOLERANCE = 0.05   # relative: co-simulation residuals of stable runs stay within a few %
SIGNIFICANT_DIGITS = 12           # range values: 0.03, not 0.030000000000000002
CONNECT_TIMEOUT_S = 5.0           # an unreachable scheduler is reported after this long
STATUSES = ("ok", "failed", "unstable")
STRING_COLUMNS = ("case_id", "status", "error", "worker")  # never read back as numbers

# Summary columns of every row, in order (per-building columns are inserted after them).
CASE_COLUMNS = ("case_id", "case")
SUMMARY_COLUMNS = ("status", "error", "peak_force_N", "impacts", "dissipated_energy_J", "max_penetration_m",
                   "peak_impact_velocity_m_s", "first_impact_s")
BUILDING_COLUMNS = ("peak_displacement_m", "peak_drift_m", "peak_base_shear_N")
TAIL_COLUMNS = ("energy_input_J", "energy_residual_relative", "stop_time_s", "communication_steps", "rollbacks",
                "wall_time_s", "case_time_s", "worker")


class StudyError(ValueError):
    """A study is invalid or cannot start; the message is one line and names the place."""


# -- values and identity ---------------------------------------------------------------------------
def _canonical(value: Any) -> Any:
    """The form a value is hashed in: every number as a float (``1`` and ``1.0`` are one case)."""
    if isinstance(value, bool):
        return value
    if isinstance(value, (int, float)):
        return repr(float(value))
    return str(value)


def case_id(values: Mapping[str, Any]) -> str:
    """Stable identity of a case: 12 hex digits of SHA-256 over its sorted varied values."""
    text = json.dumps([[k, _canonical(values[k])] for k in sorted(values)], separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def toml_literal(value: Any) -> str:
    """``value`` as the TOML literal ``--set`` parses back to the same value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    return json.dumps(str(value))  # a TOML basic string


def override(variable: str, value: Any) -> str:
    return f"{variable}={toml_literal(value)}"


@dataclass(frozen=True)
class Case:
    """One run of a study: its position, identity and varied values."""

    index: int
    id: str
    values: dict[str, Any]

    @property
    def overrides(self) -> list[str]:
        return [override(k, v) for k, v in self.values.items()]


@dataclass
class Axis:
    """One axis of the grid: one variable, or several zipped together (same length)."""

    variables: list[str]
    values: list[tuple]          # one tuple (one value per variable) per point of the axis

    def __len__(self) -> int:
        return len(self.values)


# -- study files -----------------------------------------------------------------------------------
@dataclass
class Study:
    """A parsed and checked study file (see the module doc for the format)."""

    name: str
    description: str
    scene: Path
    scene_raw: dict[str, Any]
    fixed: list[str]
    axes: list[Axis]
    energy_tolerance: float = DEFAULT_ENERGY_TOLERANCE
    path: Path | None = None

    @property
    def variables(self) -> list[str]:
        return [v for axis in self.axes for v in axis.variables]

    @property
    def n_cases(self) -> int:
        return math.prod(len(a) for a in self.axes)

    def cases(self) -> list[Case]:
        """Every case, the last axis varying fastest."""
        out = []
        for index, points in enumerate(itertools.product(*(a.values for a in self.axes))):
            values = {}
            for axis, point in zip(self.axes, points):
                values.update(zip(axis.variables, point))
            out.append(Case(index, case_id(values), values))
        return out

    def fingerprint(self, fmu_hashes: Mapping[str, str]) -> dict[str, Any]:
        """What every row depends on besides its varied values (compared on ``--resume``)."""
        return dict(study=self.name, scene=self.scene_raw, fixed=list(self.fixed), variables=self.variables,
                    energy_tolerance=self.energy_tolerance, fmus=dict(fmu_hashes))


class _StudyReader:
    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = text.splitlines()

    def error(self, message: str, key: str | None = None) -> StudyError:
        line = None
        if key is not None:
            pattern = re.compile(rf'^\s*["\']?{re.escape(key)}["\']?\s*=')
            line = next((i for i, t in enumerate(self.lines, 1) if pattern.match(t)), None)
        return StudyError(f"{self.path}" + (f", line {line}" if line else "") + f": {message}")

    def values(self, key: str, spec: Any, table: str) -> list[Any]:
        if isinstance(spec, list):
            if not spec:
                raise self.error(f"[{table}] {key} = [] has no values", key)
            for v in spec:
                if isinstance(v, (list, dict)) or (isinstance(v, float) and not math.isfinite(v)):
                    raise self.error(f"[{table}] {key}: {v!r} is not a single finite value", key)
            if len({_canonical(v) for v in spec}) != len(spec):
                raise self.error(f"[{table}] {key} lists a value twice: {spec!r}", key)
            return list(spec)
        if isinstance(spec, dict):
            unknown = set(spec) - set(RANGE_KEYS)
            missing = set(RANGE_KEYS) - set(spec)
            if unknown or missing:
                raise self.error(f"[{table}] {key}: a range is {{start, stop, num}}"
                                 + (f"; unknown {sorted(unknown)}" if unknown else "")
                                 + (f"; missing {sorted(missing)}" if missing else ""), key)
            start, stop, num = spec["start"], spec["stop"], spec["num"]
            for name, v in (("start", start), ("stop", stop)):
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise self.error(f"[{table}] {key}: {name} = {v!r} is not a finite number", key)
            if isinstance(num, bool) or not isinstance(num, int) or num < 1:
                raise self.error(f"[{table}] {key}: num = {num!r}: a range needs an integer num >= 1 "
                                 f"(a range with no values has nothing to run)", key)
            if num > 1 and start == stop:
                raise self.error(f"[{table}] {key}: start = stop = {start!r} with num = {num}: the values repeat", key)
            if num == 1:
                return [float(start)]
            return [float(f"{start + (stop - start) * i / (num - 1):.{SIGNIFICANT_DIGITS}g}") for i in range(num)]
        raise self.error(f"[{table}] {key} = {spec!r}: give a list of values or a range {{start, stop, num}} "
                         f"(a fixed value goes in [set])", key)


def load_study(path: str | Path, extra_fixed: Sequence[str] = ()) -> Study:
    """Read and check a study file (syntax, axes, scene file); ``extra_fixed`` adds ``--set`` overrides.

    Variables are checked against the FMUs by :func:`validate_study`.
    """
    path = Path(path)
    if not path.is_file():
        raise StudyError(f"study file {path} not found")
    text = path.read_text(encoding="utf-8")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{path}: invalid TOML: {exc}") from None
    reader = _StudyReader(path, text)
    for key in raw:
        if key not in STUDY_KEYS:
            raise reader.error(f"unknown key {key!r}; allowed: {', '.join(STUDY_KEYS)}", key)
    name = raw.get("name", path.stem)
    if not isinstance(name, str) or not re.fullmatch(r"[\w.-]+", name):
        raise reader.error(f"name = {name!r} must be a word (letters, digits, _ . -): it names the output folder",
                           "name")
    if "scene" not in raw or not isinstance(raw["scene"], str):
        raise reader.error("needs scene = \"<bundled scene name or path>\"", "scene")
    scene_ref = raw["scene"]
    relative = path.parent / scene_ref
    try:
        scene_path = relative if relative.is_file() else resolve_scene(scene_ref)
    except SceneError as exc:
        raise reader.error(str(exc), "scene") from None
    try:
        scene_raw = tomllib.loads(scene_path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{scene_path}: invalid TOML: {exc}") from None
    scene_raw.setdefault("name", scene_path.stem)
    tolerance = raw.get("energy_tolerance", DEFAULT_ENERGY_TOLERANCE)
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not tolerance > 0:
        raise reader.error(f"energy_tolerance = {tolerance!r} must be a number > 0 (fraction of the energy input)",
                           "energy_tolerance")

    fixed_table = raw.get("set", {})
    if not isinstance(fixed_table, dict):
        raise reader.error("set must be a table [set]", "set")
    fixed = [override(k, v) for k, v in fixed_table.items()] + list(extra_fixed)

    axes: list[Axis] = []
    seen: set[str] = set()

    def claim(variable: str) -> None:
        if variable in seen or variable in fixed_table:
            raise reader.error(f"{variable} is given twice (in [set], [vary] or [[zip]])", variable)
        seen.add(variable)

    vary = raw.get("vary", {})
    if not isinstance(vary, dict):
        raise reader.error("vary must be a table [vary]", "vary")
    zips = raw.get("zip", [])
    if not isinstance(zips, list) or not all(isinstance(z, dict) for z in zips):
        raise reader.error("zip must be an array of tables [[zip]]", "zip")
    # axes in the order of the file: the first one varies slowest
    grid_first = list(raw).index("vary") < list(raw).index("zip") if "vary" in raw and "zip" in raw else True
    if grid_first:
        for variable, spec in vary.items():
            claim(variable)
            axes.append(Axis([variable], [(v,) for v in reader.values(variable, spec, "vary")]))
    for number, table in enumerate(zips, 1):
        if not table:
            raise reader.error(f"[[zip]] number {number} is empty", "zip")
        columns = {}
        for variable, spec in table.items():
            claim(variable)
            columns[variable] = reader.values(variable, spec, "zip")
        lengths = {v: len(c) for v, c in columns.items()}
        if len(set(lengths.values())) != 1:
            raise reader.error(f"[[zip]] number {number}: the lists must have one length, got "
                               + ", ".join(f"{v}: {n}" for v, n in lengths.items()), next(iter(columns)))
        axes.append(Axis(list(columns), list(zip(*columns.values()))))
    if not grid_first:
        for variable, spec in vary.items():
            claim(variable)
            axes.append(Axis([variable], [(v,) for v in reader.values(variable, spec, "vary")]))
    if not axes:
        raise reader.error("varies nothing: add a [vary] table or a [[zip]] table")
    for text in extra_fixed:
        variable = text.split("=", 1)[0].strip()
        if variable in seen:
            raise StudyError(f"--set {text}: {path} varies {variable}; a variable is either fixed or varied")
    return Study(name, str(raw.get("description", "")), scene_path, scene_raw, fixed, axes, float(tolerance), path)


# -- one case --------------------------------------------------------------------------------------
def columns_for(study: Study, buildings: Sequence[str]) -> list[str]:
    """The CSV header: identity, varied variables, summary, per-building peaks, costs."""
    return (list(CASE_COLUMNS) + study.variables + list(SUMMARY_COLUMNS)
            + [f"{b}.{c}" for b in buildings for c in BUILDING_COLUMNS] + list(TAIL_COLUMNS))


def case_row(summary: Mapping[str, Any], result, energy_tolerance: float) -> dict[str, Any]:
    """Flatten a run's summary (:func:`cosim.results.summarize`) into study columns, with a status."""
    contacts = summary["contacts"].values()
    v_impact = [float(np.max(np.abs(result[f"{c}.v_impact"]))) for c in summary["contacts"]
                if result.has(f"{c}.v_impact")]
    firsts = [c["first_impact_s"] for c in contacts if c["first_impact_s"] is not None]
    row: dict[str, Any] = dict(
        peak_force_N=summary["peak_force_N"], impacts=summary["impacts"],
        dissipated_energy_J=summary["dissipated_energy_J"],
        max_penetration_m=max([c["max_penetration_m"] for c in contacts], default=0.0),
        peak_impact_velocity_m_s=max(v_impact, default=0.0),
        first_impact_s=min(firsts) if firsts else None,
        energy_input_J=summary["energy_input_J"], energy_residual_relative=summary["energy_residual_relative"],
        stop_time_s=summary["stop_time_s"], communication_steps=summary["communication_steps"],
        rollbacks=summary["rollbacks"], wall_time_s=summary["wall_time_s"])
    for name, b in summary["buildings"].items():
        for c in BUILDING_COLUMNS:
            row[f"{name}.{c}"] = b[c]
    numbers = [v for v in row.values() if isinstance(v, float)]
    if not all(math.isfinite(v) for v in numbers):
        row.update(status="unstable", error="non-finite result: " + ", ".join(
            k for k, v in row.items() if isinstance(v, float) and not math.isfinite(v)))
    elif summary["energy_residual_relative"] < -energy_tolerance:
        # a negative residual is energy the system has and was never given: the coupling created it
        row.update(status="unstable", error=f"energy created: {-summary['energy_residual_relative']:.3g} "
                                            f"of the energy input (tolerance {energy_tolerance:g})")
    else:
        row.update(status="ok", error="")
    return row


try:  # the master's stability monitor, when present
    from cosim.adaptive import InstabilityError as _InstabilityError
except ImportError:  # pragma: no cover - older master without the monitor
    class _InstabilityError(RuntimeError):
        pass


def _one_line(text: str) -> str:
    return " | ".join(part.strip() for part in str(text).splitlines() if part.strip())


class CaseRunner:
    """Runs cases in one process: FMUs loaded once, one :class:`~cosim.master.System` reused.

    The system of the previous case is ``reset`` (fmi2Reset + the new start
    values) when the new case has the same instances and connections, rebuilt
    otherwise, and dropped after a failure (an FMU that refused a step is not
    trusted again).  A lock serialises cases if a worker has several threads.
    """

    def __init__(self, fmu_dir: str | Path):
        from cosim.master import Catalog

        self.catalog = Catalog(fmu_dir)
        self.system = None
        self.lock = threading.Lock()
        self.cases_run = 0
        self.systems_built = 0

    def _system_for(self, scene):
        from cosim.master import System

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

    def run(self, scene_raw: Mapping[str, Any], overrides: Sequence[str],
            energy_tolerance: float = DEFAULT_ENERGY_TOLERANCE) -> dict[str, Any]:
        """Run one case; always returns a row (failures become ``status = "failed"``)."""
        from cosim.master import simulate
        from cosim.results import summarize

        with self.lock:
            start = time.perf_counter()
            try:
                scene = load_scene(scene_raw, overrides, self.catalog)
                system = self._system_for(scene)
                result = simulate(system, progress=False)
                row = case_row(summarize(result), result, energy_tolerance)
            except (SceneError, FMUError) as exc:
                self._drop_system()
                row = dict(status="failed", error=_one_line(exc))
            except _InstabilityError as exc:  # the master's run-time monitor stopped the run
                self._drop_system()
                row = dict(status="unstable", error=_one_line(f"{type(exc).__name__}: {exc}"))
            except Exception as exc:  # noqa: BLE001 - any failure of one case is recorded, the study goes on
                self._drop_system()
                row = dict(status="failed", error=_one_line(f"{type(exc).__name__}: {exc}"))
            self.cases_run += 1
            row["case_time_s"] = time.perf_counter() - start
            row["worker"] = f"{os.uname().nodename}:{os.getpid()}"
            return row

    def close(self) -> None:
        self._drop_system()
        self.catalog.close()


# -- Dask ------------------------------------------------------------------------------------------
def fmu_hashes(fmu_dir: Path) -> dict[str, str]:
    from cosim.scene import BUILDING, GROUND, POUNDING

    return {n: hashlib.sha256((fmu_dir / f"{n}.fmu").read_bytes()).hexdigest() for n in (POUNDING, BUILDING, GROUND)}


class StudyPlugin(WorkerPlugin):
    """Dask worker plugin: carries the FMU files and holds the worker's :class:`CaseRunner`.

    Registered under a name derived from the FMUs' hashes, so studies with
    other FMUs on the same cluster get their own runner.  On a worker the FMUs
    are written once into the worker's local directory.
    """

    def __init__(self, fmu_dir: Path, hashes: Mapping[str, str]):
        self.files = {name: (Path(fmu_dir) / f"{name}.fmu").read_bytes() for name in hashes}
        self.name = "cosim-study-" + hashlib.sha256("".join(sorted(hashes.values())).encode()).hexdigest()[:12]
        self.runner: CaseRunner | None = None

    def setup(self, worker) -> None:
        folder = Path(worker.local_directory) / self.name
        folder.mkdir(parents=True, exist_ok=True)
        for name, data in self.files.items():
            (folder / f"{name}.fmu").write_bytes(data)
        self.files = {}
        self.folder = folder

    def case_runner(self) -> CaseRunner:
        """The worker's runner, created by the first case, in the thread that runs the cases.

        Loading the pythonfmu FMUs in the worker's event-loop thread (``setup``) and stepping
        them in its task thread corrupts the heap: glibc aborts the worker process at exit
        ("free(): corrupted unsorted chunks").
        """
        if self.runner is None:
            self.runner = CaseRunner(self.folder)
        return self.runner

    def teardown(self, worker) -> None:
        if self.runner is not None:
            self.runner.close()
            self.runner = None


def _run_case_on_worker(plugin_name: str, scene_raw: dict, overrides: list[str], tolerance: float) -> dict:
    from distributed import get_worker

    return get_worker().plugins[plugin_name].case_runner().run(scene_raw, overrides, tolerance)


def connect(scheduler: str | None = None, workers: int | None = None,
            timeout: float = CONNECT_TIMEOUT_S):
    """``(client, cluster)``: a ``distributed.Client`` to ``scheduler`` (``cluster`` None; a
    :class:`StudyError` after ``timeout`` s if it does not answer), or to a new ``LocalCluster``
    of ``workers`` processes with one thread each (default: one per core)."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=timeout), None
        except (OSError, TimeoutError) as exc:
            raise StudyError(f"cannot reach the Dask scheduler at {scheduler!r} within {timeout:g} s "
                             f"({type(exc).__name__}: {_one_line(exc)})") from None
        except ValueError as exc:
            raise StudyError(f"--scheduler {scheduler!r}: {_one_line(exc)}") from None
    n = workers or os.cpu_count() or 1
    if n < 1:
        raise StudyError(f"--workers {workers}: needs at least 1 worker")
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    return Client(cluster), cluster


# -- validation ------------------------------------------------------------------------------------
def validate_study(study: Study, catalog) -> list[str]:
    """Check every variable and every value against the scene and the FMUs, before anything runs.

    Each value of each axis is tried with the other axes at their first
    value: the scene loader checks the names (a variable no FMU of the scene
    has) and types, then the FMUs are initialised with those start values, so
    the FMU's own range checks run and their message reaches the user.
    Returns the names of the scene's buildings (their columns in the table).
    """
    from cosim.master import System

    first = [axis.values[0] for axis in study.axes]
    trials: list[list[str]] = []
    for a, axis in enumerate(study.axes):
        for point in axis.values if a == 0 else axis.values[1:]:
            values: dict[str, Any] = {}
            for b, other in enumerate(study.axes):
                values.update(zip(other.variables, point if b == a else first[b]))
            trials.append([override(k, v) for k, v in values.items()])
    where = f"{study.path or study.name}"
    scenes = []
    for overrides in trials:
        try:
            scenes.append(load_scene(study.scene, study.fixed + overrides, catalog))
        except SceneError as exc:
            raise StudyError(f"{where}: {', '.join(overrides)}: {exc}") from None
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
                raise StudyError(f"{where}: {', '.join(overrides)}: the FMU refused it: {exc}") from None
    finally:
        system.close()
    return [b.name for b in scenes[0].buildings]


# -- result files ----------------------------------------------------------------------------------
def _infer(values: list[str], text: bool = False):
    """Typed column from CSV text: int, float, bool or str (empty = missing)."""
    present = [v for v in values if v != ""]
    for convert in () if text else (int, float):
        try:
            out = [convert(v) for v in present]
        except ValueError:
            continue
        return [None if v == "" else convert(v) for v in values]
    if present and all(v in ("True", "False") for v in present):
        return [None if v == "" else v == "True" for v in values]
    return [None if v == "" else v for v in values]


def read_results(csv_path: str | Path) -> tuple[list[str], list[dict[str, Any]]]:
    """``(header, rows)`` of a study's CSV, typed (int, float, bool, str, None), in file order.

    A last line without its newline (the study was killed while writing it)
    is ignored.
    """
    text = Path(csv_path).read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
    lines = list(csv.reader(text.splitlines()))
    if not lines:
        return [], []
    header, body = lines[0], lines[1:]
    for number, line in enumerate(body, 2):
        if len(line) != len(header):
            raise StudyError(f"{csv_path}, line {number}: {len(line)} fields, the header has {len(header)}")
    columns = {name: _infer([line[j] for line in body], name in STRING_COLUMNS) for j, name in enumerate(header)}
    rows = [{name: columns[name][i] for name in header} for i in range(len(body))]
    return header, rows


def write_parquet(csv_path: Path, parquet_path: Path) -> Path:
    """Regenerate the Parquet table from the CSV (sorted by case number), written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    header, rows = read_results(csv_path)
    rows.sort(key=lambda r: r.get("case") if r.get("case") is not None else -1)
    table = pa.table({name: pa.array([r[name] for r in rows]) for name in header}) if header else pa.table({})
    tmp = parquet_path.with_name(parquet_path.name + ".partial")
    pq.write_table(table, tmp)
    os.replace(tmp, parquet_path)
    return parquet_path


def _cell(value: Any) -> str:
    """CSV text of one value: floats exactly (repr round-trips), one line per row."""
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return _one_line(value)


class _RowWriter:
    """Appends one CSV row per finished case, flushed and synced, so a kill loses nothing written."""

    def __init__(self, path: Path, header: list[str]):
        self.header = header
        new = not path.exists() or path.stat().st_size == 0
        self.file = open(path, "a", newline="", encoding="utf-8")
        self.writer = csv.DictWriter(self.file, fieldnames=header, extrasaction="ignore", lineterminator="\n")
        if new:
            self.writer.writeheader()
            self._sync()

    def write(self, row: Mapping[str, Any]) -> None:
        self.writer.writerow({k: _cell(v) for k, v in row.items()})
        self._sync()

    def _sync(self) -> None:
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self) -> None:
        self.file.close()


def _prepare_folder(folder: Path, fingerprint: dict, header: list[str], resume: bool) -> set[str]:
    """Create or reopen the output folder; return the ids of the cases already recorded."""
    csv_path, meta_path = folder / "results.csv", folder / "study.json"
    fingerprint = json.loads(json.dumps(fingerprint))  # compare as stored (tuples -> lists)
    if csv_path.exists() and csv_path.stat().st_size > 0:
        if not resume:
            raise StudyError(f"{csv_path} already holds results: use --resume to complete it, "
                             f"or --out for a new folder")
        if meta_path.exists():
            saved = json.loads(meta_path.read_text())
            changed = [k for k in fingerprint if saved.get(k) != fingerprint[k]]
            if changed:
                raise StudyError(f"--resume {folder}: the study changed since its rows were computed "
                                 f"({', '.join(changed)} differ; new values of the varied variables are fine); "
                                 f"use --out for a new folder")
        text = csv_path.read_text(encoding="utf-8")
        if not text.endswith("\n"):  # killed while writing a row: drop the torn line
            with open(csv_path, "r+", encoding="utf-8") as f:
                f.truncate(len(text[:text.rfind("\n") + 1].encode("utf-8")))
        saved_header, rows = read_results(csv_path)
        if saved_header != header:
            raise StudyError(f"--resume {csv_path}: its columns differ from this study's; use --out for a new folder")
        return {r["case_id"] for r in rows}
    folder.mkdir(parents=True, exist_ok=True)
    tmp = meta_path.with_name("study.json.partial")
    tmp.write_text(json.dumps(fingerprint, indent=2) + "\n")
    os.replace(tmp, meta_path)
    return set()


# -- running a study -------------------------------------------------------------------------------
@dataclass
class StudyResult:
    """What :func:`run_study` did.  Times in s; ``elapsed_s`` runs from the first
    submitted case to the last result (cluster start-up excluded)."""

    study: Study
    folder: Path
    csv: Path
    parquet: Path
    n_cases: int
    skipped: int                  # already in the CSV (--resume)
    ran: int
    failed: int                   # status failed or unstable, among the cases run now
    workers: int
    startup_s: float
    elapsed_s: float
    validation_s: float
    rows: list[dict[str, Any]] = field(default_factory=list, repr=False)  # the rows of the cases run now


def run_study(study: Study | str | Path, out: str | Path | None = None, *, workers: int | None = None,
              scheduler: str | None = None, client=None, resume: bool = False, fmu_dir: str | Path | None = None,
              progress: bool = True, connect_timeout: float = CONNECT_TIMEOUT_S) -> StudyResult:
    """Validate, then run every case not yet recorded, appending rows to ``out/results.csv``.

    ``client``: an existing ``distributed.Client`` (then ``workers`` and
    ``scheduler`` are ignored and the client is left open).  Raises
    :class:`StudyError` for bad input before any case runs.
    """
    from cosim.master import Catalog
    from cosim.run import default_fmu_dir

    if not isinstance(study, Study):
        study = load_study(study)
    fmu_dir = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()
    t0 = time.perf_counter()
    try:
        catalog = Catalog(fmu_dir)
    except FileNotFoundError as exc:
        raise StudyError(str(exc)) from None
    try:
        buildings = validate_study(study, catalog)
    finally:
        catalog.close()
    validation_s = time.perf_counter() - t0
    hashes = fmu_hashes(fmu_dir)
    header = columns_for(study, buildings)
    cases = study.cases()
    folder = Path(out) if out is not None else ROOT / "out" / "studies" / study.name

    t0 = time.perf_counter()
    own = client is None
    cluster = None
    if own:
        client, cluster = connect(scheduler, workers, connect_timeout)
    writer = None
    try:
        startup_s = time.perf_counter() - t0
        done = _prepare_folder(folder, study.fingerprint(hashes), header, resume)
        pending = [c for c in cases if c.id not in done]
        plugin = StudyPlugin(fmu_dir, hashes)
        n_workers = len(client.nthreads())
        writer = _RowWriter(folder / "results.csv", header)
        rows, failed = [], 0
        t1 = time.perf_counter()
        if pending:
            client.register_plugin(plugin, name=plugin.name)
            try:
                rows, failed = _execute(client, plugin.name, study, pending, writer, progress,
                                        len(cases) - len(pending))
            finally:
                if own:   # free the workers' FMU instances while their interpreters are alive
                    _unregister(client, plugin.name)
        elapsed_s = time.perf_counter() - t1
    finally:
        if writer is not None:
            writer.close()
            write_parquet(folder / "results.csv", folder / "results.parquet")
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    return StudyResult(study, folder, folder / "results.csv", folder / "results.parquet", len(cases),
                       len(cases) - len(pending), len(rows), failed, n_workers, startup_s, elapsed_s,
                       validation_s, rows)


def _unregister(client, name: str) -> None:
    try:
        client.unregister_worker_plugin(name)
    except Exception:  # noqa: BLE001 - a worker already gone has nothing left to free
        pass


def _execute(client, plugin_name: str, study: Study, pending: list[Case], writer: _RowWriter,
             progress: bool, already: int) -> tuple[list[dict], int]:
    from distributed import as_completed

    scene_raw = study.scene_raw  # a few hundred bytes: sent with each task
    futures = {}
    for case in pending:
        future = client.submit(_run_case_on_worker, plugin_name, scene_raw, study.fixed + case.overrides,
                               study.energy_tolerance, key=f"cosim-case-{study.name}-{case.id}", pure=False)
        futures[future.key] = (future, case)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=already + len(pending), initial=already, unit="case", desc=study.name, smoothing=0.1)
    rows, failed = [], 0
    try:
        for future in as_completed([f for f, _ in futures.values()]):
            case = futures[future.key][1]
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - e.g. the worker died (KilledWorker): record and go on
                row = dict(status="failed", error=_one_line(f"{type(exc).__name__}: {exc}"))
            row = {**row, "case_id": case.id, "case": case.index, **case.values}
            writer.write(row)
            rows.append(row)
            if row["status"] != "ok":
                failed += 1
            if bar is not None:
                bar.set_postfix_str(f"failed {failed}", refresh=False)
                bar.update(1)
    except BaseException:
        client.cancel([f for f, _ in futures.values()])
        raise
    finally:
        if bar is not None:
            bar.close()
    return rows, failed


# -- plots -----------------------------------------------------------------------------------------
def plot_results(csv_path: str | Path, x: str, y: str, by: str | None = None, where: Sequence[str] = (),
                 out: str | Path | None = None, logy: bool = False) -> Path:
    """Plot column ``y`` against varied column ``x`` of the ok rows, one curve per value of ``by``.

    ``where``: ``"COLUMN=VALUE"`` filters, needed when another varied column
    would put several points on one abscissa of one curve.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    csv_path = Path(csv_path)
    if not csv_path.is_file():
        raise StudyError(f"results file {csv_path} not found")
    header, rows = read_results(csv_path)
    for name in [x, y] + ([by] if by else []):
        if name not in header:
            raise StudyError(f"{csv_path} has no column {name!r}; columns: {', '.join(header)}")
    for condition in where:
        if "=" not in condition:
            raise StudyError(f"--where {condition!r}: expected COLUMN=VALUE")
        column, text = (s.strip() for s in condition.split("=", 1))
        if column not in header:
            raise StudyError(f"--where {condition!r}: no column {column!r}")
        rows = [r for r in rows if str(r[column]) == text or _canonical(r[column]) == _canonical(_parse(text))]
    ok = [r for r in rows if r["status"] == "ok" and r[x] is not None and r[y] is not None]
    if not ok:
        raise StudyError(f"{csv_path}: no ok row to plot" + (f" with {', '.join(where)}" if where else ""))
    groups: dict[Any, list[dict]] = {}
    for r in ok:
        groups.setdefault(r[by] if by else None, []).append(r)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for key, group in groups.items():
        group.sort(key=lambda r: r[x])
        xs = [r[x] for r in group]
        if len(set(map(_canonical, xs))) != len(xs):
            raise StudyError(f"{csv_path}: several rows share {x} = {xs[0]!r}"
                             + (f" for {by} = {key!r}" if by else "")
                             + ": another column varies too; pick one value with --where COLUMN=VALUE")
        ax.plot(xs, [r[y] for r in group], "o-", ms=3, lw=1.2, label=f"{key}" if by else None)
    skipped = len(rows) - len(ok)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    if logy:
        ax.set_yscale("log")
    ax.set_title(f"{csv_path.parent.name}: {y} against {x}" + (f" ({skipped} failed/unstable rows left out)"
                                                                 if skipped else ""), fontsize=10)
    ax.grid(alpha=0.3)
    if by:
        ax.legend(title=by, fontsize=8)
    fig.tight_layout()
    out = Path(out) if out else csv_path.parent / f"{_slug(y)}_vs_{_slug(x)}" \
        f"{'_by_' + _slug(by) if by else ''}.png"
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _parse(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _slug(name: str) -> str:
    return re.sub(r"[^\w.-]+", "_", name)


# -- command line ----------------------------------------------------------------------------------
def _plot_main(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(prog="python cosim/study.py plot",
                                     description="plot a summary column against a varied variable")
    parser.add_argument("results", type=Path, help="results.csv of a study")
    parser.add_argument("--x", required=True, help="varied column on the abscissa, e.g. pounding.gap")
    parser.add_argument("--y", required=True, help="summary column, e.g. peak_force_N")
    parser.add_argument("--by", help="one curve per value of this column, e.g. ground.record")
    parser.add_argument("--where", action="append", default=[], metavar="COLUMN=VALUE",
                        help="keep only these rows (repeatable)")
    parser.add_argument("--logy", action="store_true", help="logarithmic y axis")
    parser.add_argument("--out", type=Path, help="PNG file (default: next to the CSV)")
    args = parser.parse_args(argv)
    try:
        path = plot_results(args.results, args.x, args.y, args.by, args.where, args.out, args.logy)
    except StudyError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"plot: {path}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "plot":
        return _plot_main(argv[1:])
    parser = argparse.ArgumentParser(prog="python cosim/study.py", description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="plots: python cosim/study.py plot RESULTS.csv --x VAR --y COLUMN [--by VAR]")
    parser.add_argument("study", type=Path, help="study file (TOML), e.g. studies/fig8a_gap.toml")
    parser.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="use the Dask cluster at this address instead")
    parser.add_argument("--out", type=Path, help="result folder (default: out/studies/<study name>)")
    parser.add_argument("--resume", action="store_true", help="complete the results already in --out")
    parser.add_argument("--set", dest="fixed", action="append", default=[], metavar="INSTANCE.VAR=VALUE",
                        help="one more fixed override for every case (repeatable), e.g. stop_time=5")
    parser.add_argument("--fmu-dir", type=Path, help="folder with the FMUs (default: build them into build/fmus)")
    parser.add_argument("--dry-run", action="store_true", help="check the study and list the cases, run nothing")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        study = load_study(args.study, args.fixed)
        if args.dry_run:
            from cosim.master import Catalog
            from cosim.run import default_fmu_dir

            with Catalog(args.fmu_dir or default_fmu_dir()) as catalog:
                validate_study(study, catalog)
            print(f"{study.name}: {study.n_cases} cases of scene {study.scene}, varying "
                  + " x ".join("(" + ", ".join(a.variables) + f": {len(a)})" for a in study.axes))
            return 0
        if args.workers is not None and args.workers < 1:
            raise StudyError(f"--workers {args.workers}: needs at least 1 worker")
        result = run_study(study, args.out, workers=args.workers, scheduler=args.scheduler, resume=args.resume,
                           fmu_dir=args.fmu_dir, progress=not args.no_progress)
    except StudyError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: the finished cases are in the results; complete them with --resume", file=sys.stderr)
        return 130
    print(f"{study.name}: {result.n_cases} cases, {result.skipped} already done, {result.ran} run now "
          f"({result.failed} failed or unstable) in {result.elapsed_s:.1f} s on {result.workers} workers")
    print(f"results: {result.csv}\n         {result.parquet}")
    return 0


if __name__ == "__main__":
    # Run through the package module, not ``__main__``: the tasks and the worker plugin are
    # pickled by reference, and a worker process can import ``cosim.study`` but not our __main__.
    from cosim.fmi import exit_process
    from cosim.study import main as _main

    exit_process(_main())
