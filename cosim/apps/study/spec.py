"""Study files: reading and checking a study (TOML) before anything runs.

The format is the package's (:mod:`cosim.apps.study`); every problem is one
:class:`StudyError` line naming the file and the line.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from ...master.loader import resolve_scene
from ...master.scene import Override, SceneError, as_override
from .cases import Axis, Case, _canonical, fixed_text, grid

STUDY_KEYS = ("name", "description", "scene", "energy_tolerance", "set", "vary", "zip")
RANGE_KEYS = ("start", "stop", "num")
DEFAULT_ENERGY_TOLERANCE = 0.05   # relative: co-simulation residuals of stable runs stay within a few %
SIGNIFICANT_DIGITS = 12           # range values: 0.03, not 0.030000000000000002
#: the most cases a study may have unless raised on purpose (--max-cases): 10,000 full-record
#: runs are about 70 min of one core at 0.43 s per run, the scale of an incremental dynamic
#: analysis (20 records x 20 intensities x 10 gaps = 4,000); a typo such as num = 100000000
#: is refused at once instead of filling the memory with cases
MAX_CASES = 10_000
#: the bundled studies (package data)
STUDIES = Path(__file__).resolve().parents[2] / "studies"


class StudyError(ValueError):
    """A study is invalid or cannot start; the message is one line and names the place."""


def bundled_studies() -> list[str]:
    return sorted(p.stem for p in STUDIES.glob("*.toml"))


def resolve_study(name_or_path: str | Path) -> Path:
    """A study file path, or the name of a bundled study (``fig8a_gap``...)."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    candidate = STUDIES / f"{name_or_path}.toml"
    if candidate.is_file():
        return candidate
    raise StudyError(f"study file {path} not found (bundled studies: {', '.join(bundled_studies())})")


# -- study files -----------------------------------------------------------------------------------
@dataclass
class Study:
    """A parsed and checked study file (see the module doc for the format)."""

    name: str
    description: str
    scene: Path
    scene_raw: dict[str, Any]
    fixed: list[Override]
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
        return grid(self.axes)

    def fingerprint(self, fmu_hashes: Mapping[str, str]) -> dict[str, Any]:
        """What every row depends on besides its varied values (compared on ``--resume``)."""
        return dict(study=self.name, scene=self.scene_raw, fixed=[fixed_text(o) for o in self.fixed],
                    variables=self.variables,
                    energy_tolerance=self.energy_tolerance, fmus=dict(fmu_hashes))


class _StudyReader:
    def __init__(self, path: Path, text: str, max_cases: int = MAX_CASES):
        self.path = path
        self.lines = text.splitlines()
        self.max_cases = max_cases

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
            if num > self.max_cases:
                raise self.error(f"[{table}] {key}: num = {num} values, more than the {self.max_cases} cases a study "
                                 f"may have (--max-cases raises the limit)", key)
            if num > 1 and start == stop:
                raise self.error(f"[{table}] {key}: start = stop = {start!r} with num = {num}: the values repeat", key)
            if num == 1:
                return [float(start)]
            return [float(f"{start + (stop - start) * i / (num - 1):.{SIGNIFICANT_DIGITS}g}") for i in range(num)]
        raise self.error(f"[{table}] {key} = {spec!r}: give a list of values or a range {{start, stop, num}} "
                         f"(a fixed value goes in [set])", key)


def load_study(path: str | Path, extra_fixed: Sequence[Override | str] = (), max_cases: int = MAX_CASES) -> Study:
    """Read and check a study file (syntax, axes, scene file); ``extra_fixed`` adds ``--set`` overrides.

    ``path``: a study file, or the name of a bundled study (``cosim/studies/<name>.toml``).
    ``max_cases``: a study with more cases is refused (:data:`MAX_CASES`), before any case is made.

    Variables are checked against the FMUs by :func:`validate_study`.
    """
    path = resolve_study(path)
    text = path.read_text(encoding="utf-8")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{path}: invalid TOML: {exc}") from None
    reader = _StudyReader(path, text, max_cases)
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
    extra_fixed = [as_override(o) for o in extra_fixed]
    fixed = [Override.of(k, v) for k, v in fixed_table.items()] + extra_fixed

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
    n_cases = math.prod(len(a) for a in axes)
    if n_cases > max_cases:
        raise StudyError(f"{path}: {' x '.join(str(len(a)) for a in axes)} = {n_cases} cases, more than the "
                         f"{max_cases} a study may have (--max-cases raises the limit)")
    for o in extra_fixed:
        variable = f"{o.instance}.{o.variable}" if o.instance else o.variable
        if variable in seen:
            raise StudyError(f"--set {fixed_text(o)}: {path} varies {variable}; a variable is either fixed or varied")
    return Study(name, str(raw.get("description", "")), scene_path, scene_raw, fixed, axes, float(tolerance), path)
