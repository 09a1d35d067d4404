"""Scenes: small TOML files that say which FMU instances make up a system.

A scene reads like the system it describes::

    name = "default"
    description = "..."
    stop_time = 30.0          # s
    step = 0.01               # s, communication step
    coupling = "adaptive"     # or "gauss-seidel", "jacobi"

    [ground]                  # ground_motion.fmu parameters; no table = free vibration
    record = "elcentro1940"
    target_pga = 3.0          # m/s^2

    [buildings.left]          # building.fmu parameters, one table per building,
    m = [2.0e5]               # ordered left (negative x) to right; a list m = [...]
    k = [3.0e7]               # sets m[1], m[2], ... and n_storeys = len(m)
    zeta = 0.05

    [buildings.right]
    ...

    [pounding]                # pounding.fmu parameters shared by every contact level
    floors = [1]              # master key: floors that can pound (see below)
    gap = 0.03
    CR = 0.65

Rules (checked before anything is instantiated, each a one-line
:class:`SceneError` naming the file, the table and the key):

* Top-level keys: ``name description stop_time step coupling ground
  buildings pounding``; anything else is an error.
* ``[ground]`` keys are ``ground_motion.fmu`` parameters.  Without the table
  no ground-motion FMU is instantiated (free vibration).  ``target_sa`` may be
  written ``{period = 0.5, value = 4.9}`` (s, m/s^2; optional ``damping``,
  default 0.05); at most one of ``target_pga``, ``target_pga_g``, ``target_sa``.
* ``[buildings.<name>]`` keys are ``building.fmu`` parameters.  An array
  parameter (``m``, ``k``, ``x0``, ``v0``) is a list of one value per floor
  (1 = lowest) or a scalar applied to every floor; ``"m[3]" = ...`` sets one
  element.  ``n_storeys`` defaults to the length of the lists.  Masses must be
  > 0 and storey stiffnesses >= 0.
* ``[pounding]`` keys are ``pounding.fmu`` parameters plus two master keys:
  ``floors`` (list of floor numbers that pound floor to floor, or of
  ``[left_floor, right_floor]`` pairs; default: the top floor of the lower
  building) and ``allow_initial_overlap`` (default false).  One contact
  instance per adjacent pair of buildings and pounding level, named
  ``pounding_<floor>`` (``pounding_<fl>_<fr>`` for a pair of different floors;
  ``pounding_<left>_<right>_<floor>`` with three or more buildings).  Its
  ``m1``/``m2`` default to the floor masses of the left/right building at that
  level.  No table, or fewer than two buildings: no contact instance.
* A gap already closed at t = 0 (``x0_left - x0_right - gap > 0``) is an
  error unless ``allow_initial_overlap = true``.  With ``resolve_impacts = true``
  the contact FMU takes such an overlap as the touching point (no preload: the
  resolver models impacts, which start at a crossing); the plain force law
  (``resolve_impacts = false``) pushes the floors apart from the first step.

Overrides (``--set``) use instance names: ``pounding.gap=0.02`` (every
contact instance), ``pounding_3.CR=0.5`` (one), ``left.m[1]=2e5``,
``ground.record=kobe1995``, ``stop_time=5``; values are TOML literals, or
plain strings when they do not parse.
"""
from __future__ import annotations

import copy
import difflib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from fmu_src.ground_records import SCALING_TARGETS, scaling_conflict

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"

TOP_LEVEL = ("name", "description", "stop_time", "step", "coupling", "ground", "buildings", "pounding")
COUPLINGS = ("gauss-seidel", "jacobi", "adaptive")
POUNDING_MASTER_KEYS = ("floors", "allow_initial_overlap")
# Array parameters of building.fmu (contract in docs/architecture.md); used to
# expand scalars when no model description is at hand.
BUILDING_ARRAYS = ("m", "k", "x0", "v0")
GROUND, BUILDING, POUNDING = "ground_motion", "building", "pounding"
# target_sa = {period = ..., value = ..., damping = ...} in [ground] -> ground_motion.fmu parameters
SA_TARGET_KEYS = {"value": "target_sa", "period": "sa_period", "damping": "sa_damping"}


class SceneError(ValueError):
    """A scene (or an override) is invalid; the message is one line."""


@dataclass
class InstanceSpec:
    """One FMU instance of a scene: its name, FMU and parameter values (FMI names)."""

    name: str
    fmu: str
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ContactLevel:
    """Where a contact instance acts: ``left`` floor ``floor_left`` against
    ``right`` floor ``floor_right`` (body 1 = left, on the negative side)."""

    instance: str
    left: str
    right: str
    floor_left: int
    floor_right: int


@dataclass(frozen=True)
class Connection:
    """``target.input += factor * source.output`` at every communication step.

    Several connections into one input add up (a floor pounded on both sides).
    """

    source: str
    output: str
    target: str
    input: str
    factor: float = 1.0


@dataclass
class Scene:
    name: str
    description: str
    stop_time: float
    step: float
    coupling: str
    ground: InstanceSpec | None
    buildings: list[InstanceSpec]
    contacts: list[InstanceSpec]
    levels: list[ContactLevel]
    allow_initial_overlap: bool = False
    path: Path | None = None

    @property
    def source(self) -> str:
        return str(self.path) if self.path else f"scene {self.name!r}"

    def instances(self) -> list[InstanceSpec]:
        """Every instance, in Gauss-Seidel order: ground, contacts, buildings."""
        return ([self.ground] if self.ground else []) + self.contacts + self.buildings

    def instance(self, name: str) -> InstanceSpec:
        for spec in self.instances():
            if spec.name == name:
                return spec
        raise KeyError(name)

    def n_storeys(self, building: str) -> int:
        return int(self.instance(building).parameters["n_storeys"])

    def connections(self) -> list[Connection]:
        """The signal graph (the same for every coupling strategy)."""
        out = []
        if self.ground:
            for b in self.buildings:
                out.append(Connection(self.ground.name, "ag_mean", b.name, "ag"))
        for level in self.levels:
            c, fl, fr = level.instance, level.floor_left, level.floor_right
            out += [Connection(level.left, f"x[{fl}]", c, "x1"), Connection(level.left, f"v[{fl}]", c, "v1"),
                    Connection(level.right, f"x[{fr}]", c, "x2"), Connection(level.right, f"v[{fr}]", c, "v2"),
                    # F >= 0 is compressive: it pushes the left body to -x and the right one to +x
                    Connection(c, "F", level.left, f"F[{fl}]", -1.0),
                    Connection(c, "F", level.right, f"F[{fr}]", +1.0)]
        return out


# -- loading ---------------------------------------------------------------------------------------
def bundled_scenes() -> list[str]:
    return sorted(p.stem for p in SCENES.glob("*.toml"))


def resolve_scene(name_or_path: str | Path) -> Path:
    """A scene file path, or the name of a bundled scene (``default``, ``kobe``...)."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    candidate = SCENES / f"{name_or_path}.toml"
    if candidate.is_file():
        return candidate
    raise SceneError(f"scene {str(name_or_path)!r} not found: not a file, and not a bundled scene "
                     f"(bundled: {', '.join(bundled_scenes())})")


def load_scene(name_or_path: str | Path | Mapping[str, Any], overrides: Sequence[str] = (),
               catalog: Mapping[str, Any] | None = None) -> Scene:
    """Read, override and validate a scene.

    ``name_or_path``: a file, a bundled scene name, or an already parsed dict.
    ``overrides``: ``"instance.variable=value"`` strings (see module doc).
    ``catalog``: ``{"building": FMU, "pounding": FMU, "ground_motion": FMU}``
    (objects with ``variables`` and ``unknown_variable_message``, e.g.
    :class:`cosim.fmi.FMU`); with it, every key is checked against the FMU's
    parameters and their types, and FMU start values are known for the
    initial-gap check.
    """
    text = None
    if isinstance(name_or_path, Mapping):
        raw, path = copy.deepcopy(dict(name_or_path)), None
    else:
        path = resolve_scene(name_or_path)
        text = path.read_text(encoding="utf-8")
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SceneError(f"{path}: invalid TOML: {exc}") from None
    return _Builder(raw, path, text, catalog).build(overrides)


def parse_override(text: str) -> tuple[str | None, str, Any]:
    """``"left.m[1]=2e5"`` -> ``("left", "m[1]", 200000.0)``; no dot -> top level."""
    if "=" not in text:
        raise SceneError(f"--set {text!r}: expected instance.variable=value")
    key, value_text = text.split("=", 1)
    key, value_text = key.strip(), value_text.strip()
    try:
        value = tomllib.loads(f"v = {value_text}")["v"]
    except tomllib.TOMLDecodeError:
        value = value_text  # a bare word: record names, model names
    if "." in key.split("[", 1)[0]:
        instance, variable = key.split(".", 1)
    else:
        instance, variable = None, key
    if not variable or (instance is not None and not instance):
        raise SceneError(f"--set {text!r}: expected instance.variable=value")
    return instance, variable, value


def _element(name: str) -> tuple[str, int | None]:
    m = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)\[(\d+)\]", name)
    if m:
        return m.group(1), int(m.group(2))
    return name, None


class _Builder:
    """Turns the raw TOML dict into a validated :class:`Scene` (one-line errors)."""

    def __init__(self, raw: dict, path: Path | None, text: str | None, catalog):
        self.raw = raw
        self.path = path
        self.text = text
        self.catalog = catalog
        self.where = str(path) if path else "scene"
        #: (table, key) -> the --set text that gave its value: errors name the override, not a file line
        self.overridden: dict[tuple[str | None, str], str] = {}

    # -- errors --------------------------------------------------------------------------------
    def error(self, message: str, key: str | None = None, table: str | None = None) -> SceneError:
        # an element's own override, else one that set the whole array
        override = (self.overridden.get((table, key)) or self.overridden.get((table, key.split("[", 1)[0]))
                    if key else None)
        if override:
            return SceneError(f"--set {override}: {message}")
        line = self._line_of(key, table) if key else None
        loc = f"{self.where}, line {line}" if line else self.where
        return SceneError(f"{loc}: {message}")

    def _line_of(self, key: str, table: str | None) -> int | None:
        if not self.text:
            return None
        base = re.escape(key.split("[", 1)[0])
        in_table = table is None
        header = f"[{table}]" if table else None
        for number, line in enumerate(self.text.splitlines(), 1):
            stripped = line.strip()
            if stripped.startswith("["):
                in_table = header is not None and stripped.split("#", 1)[0].strip() == header
                continue
            if in_table and re.match(rf'["\']?{base}(\[\d+\])?["\']?\s*=', stripped):
                return number
        return None

    # -- build ---------------------------------------------------------------------------------
    def build(self, overrides: Sequence[str]) -> Scene:
        raw = self.raw
        for key in raw:
            if key not in TOP_LEVEL:
                hint = difflib.get_close_matches(key, TOP_LEVEL, n=1)
                raise self.error(f"unknown key {key!r}" + (f" (did you mean {hint[0]!r}?)" if hint else "")
                                 + f"; allowed: {', '.join(TOP_LEVEL)}", key)
        parsed = [parse_override(o) if isinstance(o, str) else tuple(o) for o in overrides]
        buildings_raw = raw.get("buildings", {})
        if not isinstance(buildings_raw, dict) or not buildings_raw:
            raise self.error("needs at least one [buildings.<name>] table")
        for name, table in buildings_raw.items():
            if not isinstance(table, dict):
                raise self.error(f"buildings.{name} must be a table [buildings.{name}]", name)
            if name in ("ground", "pounding") or name.startswith("pounding_") or not re.fullmatch(r"[A-Za-z_]\w*", name):
                raise self.error(f"building name {name!r} is reserved or not an identifier", name)
        for table in ("ground", "pounding"):
            if table in raw and not isinstance(raw[table], dict):
                raise self.error(f"{table} must be a table [{table}]", table)

        # overrides on the raw tables (top level, ground, buildings, shared pounding values)
        contact_overrides: list[tuple[str, str, Any, str]] = []
        for instance, variable, value in parsed:
            text = f"{instance}.{variable}={value!r}" if instance else f"{variable}={value!r}"
            # keyed by the table the errors name: top level, ground, buildings.<b>, pounding or a contact
            self.overridden[(f"buildings.{instance}" if instance in buildings_raw else instance, variable)] = text
            if instance is None:
                if variable not in ("name", "description", "stop_time", "step", "coupling"):
                    raise SceneError(f"--set {text}: unknown top-level key {variable!r} "
                                     f"(allowed: name, description, stop_time, step, coupling)")
                raw[variable] = value
            elif instance == "ground":
                if "ground" not in raw:
                    raise SceneError(f"--set {text}: {self.where} has no ground motion (no [ground] table)")
                raw["ground"][variable] = value
            elif instance in buildings_raw:
                buildings_raw[instance][variable] = value
            elif instance == "pounding":
                if "pounding" not in raw or len(buildings_raw) < 2:
                    raise SceneError(f"--set {text}: {self.where} has no contact instance "
                                     f"(needs a [pounding] table and two buildings)")
                raw["pounding"][variable] = value
            else:
                contact_overrides.append((instance, variable, value, text))

        name = raw.get("name", self.path.stem if self.path else "scene")
        description = raw.get("description", "")
        if not isinstance(name, str) or not re.fullmatch(r"[\w.-]+", name):
            raise self.error(f"name = {name!r} must be a word (letters, digits, _ . -): it names the output folder", "name")
        stop_time = self._positive(raw, "stop_time")
        step = self._positive(raw, "step")
        if step > stop_time:
            raise self.error(f"step = {step} s is longer than stop_time = {stop_time} s", "step")
        coupling = raw.get("coupling", "adaptive")
        if coupling not in COUPLINGS:
            raise self.error(f"coupling = {coupling!r} is not one of {', '.join(COUPLINGS)}", "coupling")

        ground = None
        if "ground" in raw:
            ground = InstanceSpec("ground", GROUND, self._ground_parameters(raw["ground"]))
        buildings = [InstanceSpec(n, BUILDING, self._building_parameters(n, t)) for n, t in buildings_raw.items()]

        contacts: list[InstanceSpec] = []
        levels: list[ContactLevel] = []
        allow_overlap = False
        if "pounding" in raw and len(buildings) >= 2:
            table = dict(raw["pounding"])
            allow_overlap = table.pop("allow_initial_overlap", False)
            if not isinstance(allow_overlap, bool):
                raise self.error(f"allow_initial_overlap = {allow_overlap!r} must be true or false",
                                 "allow_initial_overlap", "pounding")
            floors = table.pop("floors", None)
            shared = self._flat_parameters(table, POUNDING, "pounding")
            for left, right in zip(buildings, buildings[1:]):
                for fl, fr in self._floors(floors, left, right):
                    if len(buildings) > 2:
                        cname = f"pounding_{left.name}_{right.name}_{fl}" + (f"_{fr}" if fr != fl else "")
                    else:
                        cname = f"pounding_{fl}" + (f"_{fr}" if fr != fl else "")
                    params = dict(shared)
                    levels.append(ContactLevel(cname, left.name, right.name, fl, fr))
                    contacts.append(InstanceSpec(cname, POUNDING, params))
        elif "pounding" in raw:
            unknown = set(raw["pounding"]) - set(POUNDING_MASTER_KEYS)
            self._flat_parameters({k: raw["pounding"][k] for k in unknown}, POUNDING, "pounding")

        by_name = {c.name: c for c in contacts}
        for instance, variable, value, text in contact_overrides:
            if instance not in by_name:
                names = [s.name for s in ([ground] if ground else []) + buildings + contacts]
                if contacts:
                    names.insert(len(names) - len(contacts), "pounding")
                raise SceneError(f"--set {text}: no instance {instance!r} in {self.where} "
                                 f"(instances: {', '.join(names)})")
            if variable in POUNDING_MASTER_KEYS:
                raise SceneError(f"--set {text}: {variable} applies to every level; use pounding.{variable}")
            by_name[instance].parameters.update(self._flat_parameters({variable: value}, POUNDING, instance))

        # contact masses default to the floor masses at that level
        for level, spec in zip(levels, contacts):
            left = next(b for b in buildings if b.name == level.left)
            right = next(b for b in buildings if b.name == level.right)
            spec.parameters.setdefault("m1", float(left.parameters[f"m[{level.floor_left}]"]))
            spec.parameters.setdefault("m2", float(right.parameters[f"m[{level.floor_right}]"]))
            for key in ("m1", "m2", "k", "gap"):
                value = spec.parameters.get(key)
                if value is None:
                    continue
                table = spec.name if (spec.name, key) in self.overridden else "pounding"
                if key == "gap" and self._number(value, key, table) < 0:
                    raise self.error(f"{spec.name}.gap = {value!r} m must be >= 0", key, table)
                if key != "gap" and self._number(value, key, table) <= 0:
                    raise self.error(f"{spec.name}.{key} = {value!r} must be > 0", key, table)

        scene = Scene(name, description, stop_time, step, coupling, ground, buildings, contacts, levels,
                      allow_overlap, self.path)
        self._check_initial_gaps(scene)
        return scene

    def _positive(self, raw: dict, key: str) -> float:
        if key not in raw:
            raise self.error(f"missing {key} (s)")
        value = raw[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise self.error(f"{key} = {value!r} must be a number > 0 (s)", key)
        return float(value)

    def _number(self, value: Any, key: str, table: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(f"{table}.{key} = {value!r} is not a finite number", key, table)
        return float(value)

    def _fmu_variables(self, fmu: str) -> dict | None:
        if self.catalog is None:
            return None
        return self.catalog[fmu].variables

    def _check_value(self, fmu: str, table: str, key: str, value: Any) -> Any:
        """Check one FMI-named parameter against the FMU (name, causality, type)."""
        variables = self._fmu_variables(fmu)
        if variables is None:
            if isinstance(value, (list, dict)):
                raise self.error(f"{table}.{key} = {value!r} must be a single value", key, table)
            return value
        info = variables.get(key)
        if info is None or info.causality != "parameter":
            base, _ = _element(key)
            if info is None:
                why = self.catalog[fmu].unknown_variable_message(key, "parameter")
            else:
                why = f"{fmu}.fmu {key!r} is an {info.causality}, not a parameter"
            raise self.error(f"unknown key {key!r} in [{table}]: {why}", base, table)
        ok = {"Real": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
              "Integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
              "Boolean": lambda v: isinstance(v, bool),
              "String": lambda v: isinstance(v, str)}[info.type](value)
        if not ok:
            raise self.error(f"{table}.{key} = {value!r} must be a {info.type}", key, table)
        return float(value) if info.type == "Real" else value

    def _flat_parameters(self, table: Mapping[str, Any], fmu: str, where: str) -> dict[str, Any]:
        out = {}
        for key, value in table.items():
            if isinstance(value, (list, dict)):
                raise self.error(f"{where}.{key} = {value!r} must be a single value", key, where)
            out[key] = self._check_value(fmu, where, key, value)
        return out

    def _ground_parameters(self, table: Mapping[str, Any]) -> dict[str, Any]:
        """``[ground]`` as FMU parameters: ``target_sa = {period = T, value = PSa, damping = z}``
        becomes ``sa_period``, ``target_sa`` and ``sa_damping``; at most one scaling target."""
        flat = dict(table)
        target = flat.get("target_sa")
        if isinstance(target, dict):
            del flat["target_sa"]
            unknown = sorted(set(target) - set(SA_TARGET_KEYS))
            missing = [k for k in ("period", "value") if k not in target]
            if unknown or missing:
                raise self.error(f"ground.target_sa = {target!r}: " + (
                    f"unknown key {unknown[0]!r}" if unknown else f"missing {missing[0]!r}")
                    + f"; write target_sa = {{period = <s>, value = <m/s^2>}} (optional damping = <ratio>, "
                    f"default 0.05)", "target_sa", "ground")
            for key, parameter in SA_TARGET_KEYS.items():
                if key in target:
                    if parameter in flat:
                        raise self.error(f"ground.{parameter} is given twice: as {parameter} and as "
                                         f"target_sa.{key}", "target_sa", "ground")
                    flat[parameter] = target[key]
        flat = self._flat_parameters(flat, GROUND, "ground")
        conflict = scaling_conflict(**{k: flat.get(k) for k in SCALING_TARGETS})
        if conflict:
            given = [k for k in SCALING_TARGETS if flat.get(k)]
            raise self.error(f"[ground]: {conflict}", given[-1], "ground")
        return flat

    def _array_names(self) -> set[str]:
        variables = self._fmu_variables(BUILDING)
        if variables is None:
            return set(BUILDING_ARRAYS)
        return {_element(n)[0] for n, v in variables.items() if v.causality == "parameter" and _element(n)[1]}

    def _building_parameters(self, name: str, table: Mapping[str, Any]) -> dict[str, Any]:
        where = f"buildings.{name}"
        arrays = self._array_names()
        lengths = {k: len(v) for k, v in table.items() if isinstance(v, list)}
        n = table.get("n_storeys")
        if n is None:
            indices = [_element(k)[1] for k in table if _element(k)[1]]
            n = max(list(lengths.values()) + indices + [1])
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise self.error(f"{where}.n_storeys = {n!r} must be an integer >= 1", "n_storeys", where)
        flat: dict[str, Any] = {"n_storeys": n}
        elements = {}
        for key, value in table.items():
            base, index = _element(key)
            if key == "n_storeys":
                continue
            if isinstance(value, list):
                if base not in arrays or index is not None:
                    raise self.error(f"{where}.{key} is not an array parameter (arrays: {', '.join(sorted(arrays))})",
                                     key, where)
                if len(value) != n:
                    raise self.error(f"{where}.{key} has {len(value)} values for n_storeys = {n}", key, where)
                for i, v in enumerate(value, 1):
                    flat[f"{base}[{i}]"] = v
            elif index is not None:
                if index > n:
                    raise self.error(f"{where}.{key}: floor {index} > n_storeys = {n}", key, where)
                elements[key] = value  # applied last: overrides a list element
            elif base in arrays:
                for i in range(1, n + 1):
                    flat[f"{base}[{i}]"] = value
            else:
                flat[key] = value
        flat.update(elements)
        for i in range(1, n + 1):
            if f"m[{i}]" not in flat:
                raise self.error(f"{where}: missing mass m[{i}] (kg); give m = [...] with {n} values", "m", where)
        for key in list(flat):
            flat[key] = self._check_value(BUILDING, where, key, flat[key])
            base, index = _element(key)
            if base in ("m", "k") and index is not None and index <= n:
                value = self._number(flat[key], key, where)
                if base == "m" and value <= 0:
                    raise self.error(f"{where}.{key} = {value!r} kg: a mass must be > 0", key, where)
                if base == "k" and value < 0:
                    raise self.error(f"{where}.{key} = {value!r} N/m: a storey stiffness must be >= 0", key, where)
        return flat

    def _floors(self, floors: Any, left: InstanceSpec, right: InstanceSpec) -> list[tuple[int, int]]:
        nl, nr = int(left.parameters["n_storeys"]), int(right.parameters["n_storeys"])
        if floors is None:
            top = min(nl, nr)
            return [(top, top)]
        if not isinstance(floors, list) or not floors:
            raise self.error(f"pounding.floors = {floors!r} must be a list of floors or [left, right] pairs",
                             "floors", "pounding")
        pairs = []
        for item in floors:
            if isinstance(item, int) and not isinstance(item, bool):
                pair = (item, item)
            elif (isinstance(item, list) and len(item) == 2
                  and all(isinstance(i, int) and not isinstance(i, bool) for i in item)):
                pair = (item[0], item[1])
            else:
                raise self.error(f"pounding.floors entry {item!r} must be a floor number or a [left, right] pair",
                                 "floors", "pounding")
            if not (1 <= pair[0] <= nl and 1 <= pair[1] <= nr):
                raise self.error(f"pounding.floors entry {item!r}: {left.name} has floors 1..{nl}, "
                                 f"{right.name} has floors 1..{nr}", "floors", "pounding")
            if pair in pairs:
                raise self.error(f"pounding.floors lists {item!r} twice", "floors", "pounding")
            pairs.append(pair)
        return pairs

    def _check_initial_gaps(self, scene: Scene) -> None:
        gap_start = 0.0
        x0_start = 0.0
        if self.catalog is not None:
            gap_start = self.catalog[POUNDING].variables["gap"].start or 0.0
            x0_start = self.catalog[BUILDING].variables.get("x0[1]").start or 0.0
        for level, spec in zip(scene.levels, scene.contacts):
            left, right = scene.instance(level.left), scene.instance(level.right)
            x1 = float(left.parameters.get(f"x0[{level.floor_left}]", x0_start))
            x2 = float(right.parameters.get(f"x0[{level.floor_right}]", x0_start))
            gap = float(spec.parameters.get("gap", gap_start))
            delta = x1 - x2 - gap
            if delta > 0 and not scene.allow_initial_overlap:
                raise self.error(
                    f"the gap of {spec.name} is already closed at t = 0: x0 {level.left} "
                    f"({x1:g} m) - x0 {level.right} ({x2:g} m) - gap ({gap:g} m) = {delta:g} m > 0; "
                    f"set allow_initial_overlap = true in [pounding] to start in contact", "gap", "pounding")
