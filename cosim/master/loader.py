"""Reading and checking scene files (the format: :mod:`cosim.master.scene`).

:func:`load_scene` reads a TOML scene (a file, a bundled scene's name or an already parsed
dict), applies typed overrides and checks everything before any FMU is instantiated.  Each
problem is one :class:`~cosim.master.scene.SceneError` line that names the file and line, the
table and the key (or the ``--set`` that gave the value).  Keys are checked against the FMUs'
interfaces (:mod:`cosim.master.interface`): the model descriptions of the FMUs about to run
when given, else the slaves' own declarations; no FMU has to be loaded.
"""
from __future__ import annotations

import copy
import difflib
import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
from typing import Any, Mapping, Sequence

from fmu_src.ground_records import BUNDLED, SCALING_TARGETS, scaling_conflict
from fmu_src.hysteresis import StoreyHysteresis
from fmu_src.shear_building import ShearBuilding

from ..files import plain_name_problem
from ..fmus import BUILDING, GROUND, POUNDING
from .coupling import COUPLINGS
from .interface import FmuInterface, interfaces, parameter_defaults
from .names import base_name, element, element_name
from .scene import SCENES, ContactLevel, InstanceSpec, Override, Scene, SceneError, as_override

TOP_LEVEL = ("name", "description", "stop_time", "step", "coupling", "output_interval", "ground", "buildings",
             "pounding")
#: top-level keys a --set may change
SETTABLE = ("name", "description", "stop_time", "step", "coupling", "output_interval")
POUNDING_MASTER_KEYS = ("floors", "allow_initial_overlap")
# target_sa = {period = ..., value = ..., damping = ...} in [ground] -> ground_motion.fmu parameters
SA_TARGET_KEYS = {"value": "target_sa", "period": "sa_period", "damping": "sa_damping"}


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


def load_scene(name_or_path: str | Path | Mapping[str, Any], overrides: Sequence[Override | str] = (),
               catalog: Any = None) -> Scene:
    """Read, override and validate a scene.

    ``name_or_path``: a file, a bundled scene name, or an already parsed dict.
    ``overrides``: :class:`~cosim.master.scene.Override` objects (their text form
    ``"instance.variable=value"`` is accepted too, see the scene module).
    ``catalog``: what the keys are checked against (:func:`cosim.master.interface.interfaces`):
    a loaded :class:`~cosim.master.system.Catalog`, a folder of built FMUs, or None (the
    slaves' own declarations: no FMU needed).
    """
    text = None
    if isinstance(name_or_path, Mapping):
        raw, path = copy.deepcopy(dict(name_or_path)), None
    else:
        path = resolve_scene(name_or_path)
        text = path.read_text(encoding="utf-8")
        if path.suffix.lower() == ".json":
            raw, text = _scene_of_summary(path, text), None
        else:
            try:
                raw = tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise SceneError(f"{path}: invalid TOML: {exc}") from None
    return _Builder(raw, path, text, interfaces(catalog)).build([as_override(o) for o in overrides])


def _scene_of_summary(path: Path, text: str) -> dict:
    """The scene a run's ``summary.json`` records (``scene_as_run``: :meth:`Scene.as_run`)."""
    try:
        summary = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError(f"{path}: invalid JSON: {exc}") from None
    scene = summary.get("scene_as_run") if isinstance(summary, dict) else None
    if not isinstance(scene, dict):
        raise SceneError(f"{path}: a JSON scene must be a run's summary.json with the key 'scene_as_run' "
                         f"(written by pounding-cosim run); scene files are TOML")
    return scene


class _Builder:
    """Turns the raw TOML dict into a validated :class:`Scene` (one-line errors)."""

    def __init__(self, raw: dict, path: Path | None, text: str | None, fmus: Mapping[str, FmuInterface]):
        self.raw = raw
        self.path = path
        self.text = text
        self.fmus = fmus
        self.where = str(path) if path else "scene"
        #: (table, key) -> the --set text that gave its value: errors name the override, not a file line
        self.overridden: dict[tuple[str | None, str], str] = {}

    # -- errors --------------------------------------------------------------------------------
    def error(self, message: str, key: str | None = None, table: str | None = None) -> SceneError:
        # an element's own override, else one that set the whole array
        override = (self.overridden.get((table, key)) or self.overridden.get((table, base_name(key)))
                    if key else None)
        if override:
            return SceneError(f"{override}: {message}")
        line = self._line_of(key, table) if key else None
        loc = f"{self.where}, line {line}" if line else self.where
        return SceneError(f"{loc}: {message}")

    def _line_of(self, key: str, table: str | None) -> int | None:
        if not self.text:
            return None
        base = re.escape(base_name(key))
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

    # -- build: the steps, in order ------------------------------------------------------------
    def build(self, overrides: Sequence[Override]) -> Scene:
        self._check_tables()
        buildings_raw = self.raw["buildings"]
        contact_overrides = self._apply_overrides(overrides, buildings_raw)
        name, description, stop_time, step, coupling = self._settings()
        ground = None
        if "ground" in self.raw:
            ground = InstanceSpec("ground", GROUND, self._ground_parameters(self.raw["ground"]))
        buildings = [InstanceSpec(n, BUILDING, self._building_parameters(n, t)) for n, t in buildings_raw.items()]
        contacts, levels, allow_overlap = self._contacts(buildings)
        self._apply_contact_overrides(contact_overrides, ground, buildings, contacts)
        self._contact_defaults(levels, contacts, buildings)
        scene = Scene(name, description, stop_time, step, coupling, ground, buildings, contacts, levels,
                      allow_overlap, self.path, dict(self.fmus), overrides=tuple(o.text for o in overrides),
                      output_interval=self._output_interval(), origins=self._origins())
        self._check_initial_gaps(scene)
        return scene

    def _origins(self) -> dict[str, str]:
        """Where each top-level setting came from: its ``--set`` (or ``--step``...), else the file line."""
        out = {}
        for key in SETTABLE:
            override = self.overridden.get((None, key))
            line = self._line_of(key, None) if override is None else None
            out[key] = override or (f"{self.where}, line {line}" if line else self.where)
        return out

    def _check_tables(self) -> None:
        """Top-level keys, at least one building, every table a table and every name usable."""
        raw = self.raw
        for key in raw:
            if key not in TOP_LEVEL:
                hint = difflib.get_close_matches(key, TOP_LEVEL, n=1)
                raise self.error(f"unknown key {key!r}" + (f" (did you mean {hint[0]!r}?)" if hint else "")
                                 + f"; allowed: {', '.join(TOP_LEVEL)}", key)
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

    def _apply_overrides(self, overrides: Sequence[Override], buildings_raw: dict) -> list[tuple[Override, str]]:
        """Overrides of the top level, ground, buildings and the shared pounding table go into
        the raw tables; those of one contact instance are returned for later (with their text)."""
        raw = self.raw
        later = []
        for o in overrides:
            instance, variable, value, text = o.instance, o.variable, o.value, o.where
            # keyed by the table the errors name: top level, ground, buildings.<b>, pounding or a contact
            self.overridden[(f"buildings.{instance}" if instance in buildings_raw else instance, variable)] = text
            if instance is None:
                if variable not in SETTABLE:
                    raise SceneError(f"{text}: unknown top-level key {variable!r} "
                                     f"(allowed: {', '.join(SETTABLE)})")
                raw[variable] = value
            elif instance == "ground":
                if "ground" not in raw:
                    raise SceneError(f"{text}: {self.where} has no ground motion (no [ground] table)")
                raw["ground"][variable] = value
            elif instance in buildings_raw:
                if not isinstance(buildings_raw[instance], dict):
                    raise SceneError(f"{text}: buildings.{instance} is not a table in {self.where}")
                buildings_raw[instance][variable] = value
            elif instance == "pounding":
                if "pounding" not in raw or len(buildings_raw) < 2:
                    raise SceneError(f"{text}: {self.where} has no contact instance "
                                     f"(needs a [pounding] table and two buildings)")
                raw["pounding"][variable] = value
            else:
                later.append((o, text))
        return later

    def _settings(self) -> tuple[str, str, float, float, str]:
        """``name``, ``description``, ``stop_time``, ``step``, ``coupling``."""
        raw = self.raw
        name = raw.get("name", self.path.stem if self.path else "scene")
        description = raw.get("description", "")
        problem = plain_name_problem(name)
        if problem:
            raise self.error(f"name = {problem}", "name")
        stop_time = self._positive(raw, "stop_time")
        step = self._positive(raw, "step")
        if step > stop_time:
            raise self.error(f"step = {step} s is longer than stop_time = {stop_time} s", "step")
        coupling = raw.get("coupling", "adaptive")
        if coupling not in COUPLINGS:
            raise self.error(f"coupling = {coupling!r} is not one of {', '.join(COUPLINGS)}", "coupling")
        return name, description, stop_time, step, coupling

    def _output_interval(self) -> float | None:
        """``output_interval`` (s, >= 0; 0: every communication point), None when not given."""
        if "output_interval" not in self.raw:
            return None
        value = self.raw["output_interval"]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise self.error(f"output_interval = {value!r} must be a number >= 0 (s; 0: every communication "
                             f"point)", "output_interval")
        return float(value)

    def _contacts(self, buildings: list[InstanceSpec]) -> tuple[list[InstanceSpec], list[ContactLevel], bool]:
        """One contact instance per adjacent pair of buildings and pounding level."""
        raw = self.raw
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
            # [pounding.<contact instance>]: that level's own parameters (summary.json writes them)
            own = {k: table.pop(k) for k in list(table) if isinstance(table[k], dict)}
            shared = self._flat_parameters(table, POUNDING, "pounding")
            for left, right in zip(buildings, buildings[1:]):
                for fl, fr in self._floors(floors, left, right):
                    if len(buildings) > 2:
                        cname = f"pounding_{left.name}_{right.name}_{fl}" + (f"_{fr}" if fr != fl else "")
                    else:
                        cname = f"pounding_{fl}" + (f"_{fr}" if fr != fl else "")
                    levels.append(ContactLevel(cname, left.name, right.name, fl, fr))
                    contacts.append(InstanceSpec(cname, POUNDING, dict(shared)))
            names = [c.name for c in contacts]
            for cname, values in own.items():
                if cname not in names:
                    raise self.error(f"pounding.{cname} is a table, but {cname!r} is not a contact instance of "
                                     f"this scene ({', '.join(names)})", cname, "pounding")
                contacts[names.index(cname)].parameters.update(
                    self._flat_parameters(values, POUNDING, f"pounding.{cname}"))
        elif "pounding" in raw:
            unknown = set(raw["pounding"]) - set(POUNDING_MASTER_KEYS)
            self._flat_parameters({k: raw["pounding"][k] for k in unknown}, POUNDING, "pounding")
        return contacts, levels, allow_overlap

    def _apply_contact_overrides(self, overrides: list[tuple[Override, str]], ground, buildings, contacts) -> None:
        by_name = {c.name: c for c in contacts}
        for o, text in overrides:   # text: where the override came from (o.where)
            if o.instance not in by_name:
                names = [s.name for s in ([ground] if ground else []) + buildings + contacts]
                if contacts:
                    names.insert(len(names) - len(contacts), "pounding")
                raise SceneError(f"{text}: no instance {o.instance!r} in {self.where} "
                                 f"(instances: {', '.join(names)})")
            if o.variable in POUNDING_MASTER_KEYS:
                raise SceneError(f"{text}: {o.variable} applies to every level; use pounding.{o.variable}")
            by_name[o.instance].parameters.update(self._flat_parameters({o.variable: o.value}, POUNDING, o.instance))

    def _contact_defaults(self, levels: list[ContactLevel], contacts: list[InstanceSpec],
                          buildings: list[InstanceSpec]) -> None:
        """Contact masses default to the floor masses at that level; masses, stiffness > 0, gap >= 0."""
        for level, spec in zip(levels, contacts):
            left = next(b for b in buildings if b.name == level.left)
            right = next(b for b in buildings if b.name == level.right)
            spec.parameters.setdefault("m1", float(left.parameters[element_name("m", level.floor_left)]))
            spec.parameters.setdefault("m2", float(right.parameters[element_name("m", level.floor_right)]))
            for key in ("m1", "m2", "k", "gap"):
                value = spec.parameters.get(key)
                if value is None:
                    continue
                table = spec.name if (spec.name, key) in self.overridden else "pounding"
                if key == "gap" and self._number(value, key, table) < 0:
                    raise self.error(f"{spec.name}.gap = {value!r} m must be >= 0", key, table)
                if key != "gap" and self._number(value, key, table) <= 0:
                    raise self.error(f"{spec.name}.{key} = {value!r} must be > 0", key, table)

    # -- values --------------------------------------------------------------------------------
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

    def _check_value(self, fmu: str, table: str, key: str, value: Any) -> Any:
        """Check one FMI-named parameter against the FMU (name, causality, type)."""
        interface = self.fmus[fmu]
        info = interface.variables.get(key)
        if info is None or info.causality != "parameter":
            base, _ = element(key)
            if info is None:
                why = interface.unknown_variable_message(key, "parameter")
            else:
                why = f"{fmu}.fmu {key!r} is an {info.causality}, not a parameter"
            raise self.error(f"unknown key {key!r} in [{table}]: {why}", base, table)
        ok = {"Real": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
              "Integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
              "Boolean": lambda v: isinstance(v, bool),
              "String": lambda v: isinstance(v, str)}[info.type](value)
        if not ok:
            raise self.error(f"{table}.{key} = {value!r} must be a {info.type}", key, table)
        if info.type in ("Real", "Integer"):
            self._check_range(info, fmu, table, key, value)
        return float(value) if info.type == "Real" else value

    def _check_range(self, info, fmu: str, table: str, key: str, value: float) -> None:
        """The FMU's declared closed bounds (its modelDescription's min/max): refused here, with
        the file line or the --set, rather than by the FMU at initialisation."""
        if not math.isfinite(value):
            raise self.error(f"{table}.{key} = {value!r} is not a finite number", key, table)
        low, high = info.min, info.max
        if (low is not None and value < low) or (high is not None and value > high):
            unit = f" {info.unit}" if info.unit and info.unit != "1" else ""
            bounds = (f"{low:g} <= " if low is not None else "") + key + (f" <= {high:g}" if high is not None else "")
            stated = (info.description or "").rpartition("; allowed: ")[2]   # the FMU's own words, open bounds too
            if stated and "; allowed: " in (info.description or ""):
                bounds = stated
            raise self.error(f"{table}.{key} = {value!r}{unit} is outside the allowed range {bounds} ({fmu}.fmu)",
                             key, table)

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
        if isinstance(flat.get("record"), str):
            flat["record"] = self._record_path(flat["record"])
        conflict = scaling_conflict(**{k: flat.get(k) for k in SCALING_TARGETS})
        if conflict:
            given = [k for k in SCALING_TARGETS if flat.get(k)]
            raise self.error(f"[ground]: {conflict}", given[-1], "ground")
        return flat

    def _record_path(self, record: str) -> str:
        """A record file named relative to the scene file (or, given with ``--set``, to the working
        folder), made absolute: the scene runs the same from any folder.  Bundled names and
        absolute paths are kept."""
        if record in BUNDLED or not record or Path(record).is_absolute():
            return record
        if self.path is not None and ("ground", "record") not in self.overridden:
            return str(Path(self.path).parent.absolute() / record)
        return str(Path(record).absolute())

    def _building_parameters(self, name: str, table: Mapping[str, Any]) -> dict[str, Any]:
        where = f"buildings.{name}"
        arrays = self.fmus[BUILDING].arrays()
        n = self._storeys(where, table)
        flat: dict[str, Any] = {"n_storeys": n}
        elements = {}
        for key, value in table.items():
            base, index = element(key)
            if key == "n_storeys":
                continue
            if isinstance(value, list):
                if base not in arrays or index is not None:
                    raise self.error(f"{where}.{key} is not an array parameter (arrays: {', '.join(sorted(arrays))})",
                                     key, where)
                if len(value) != n:
                    if (where, "n_storeys") in self.overridden:   # the count came from a --set
                        raise self.error(f"{where}.n_storeys = {n}, but {where}.{key} has {len(value)} values",
                                         "n_storeys", where)
                    raise self.error(f"{where}.{key} has {len(value)} values for n_storeys = {n}", key, where)
                for i, v in enumerate(value, 1):
                    flat[element_name(base, i)] = v
            elif index is not None:
                if index > n:
                    raise self.error(f"{where}.{key}: floor {index} > n_storeys = {n}", key, where)
                elements[key] = value  # applied last: overrides a list element
            elif base in arrays:
                for i in range(1, n + 1):
                    flat[element_name(base, i)] = value
            else:
                flat[key] = value
        flat.update(elements)
        for i in range(1, n + 1):
            if element_name("m", i) not in flat:
                raise self.error(f"{where}: missing mass m[{i}] (kg); give m = [...] with {n} values", "m", where)
        # the physical rules first (their messages say why: a yielding storey needs Fy > 0 where
        # the FMU declares only Fy >= 0), then the FMU's declared ranges
        for key in list(flat):
            self._check_storey(where, key, flat[key], n)
        self._check_storey_law(where, flat, n)
        for key in list(flat):
            flat[key] = self._check_value(BUILDING, where, key, flat[key])
        return flat

    def _storeys(self, where: str, table: Mapping[str, Any]) -> int:
        """``n_storeys``: given, or the length of the lists / the highest element named; at most
        the building FMU's capacity (named, with where the value came from, when exceeded)."""
        capacity = self._storey_capacity()
        room = (f"{BUILDING}.fmu has room for 1 to {capacity} storeys (N_MAX = {capacity} in "
                f"fmu_src/building_slave.py: raise it and rebuild the FMUs for a taller building)")
        for key, value in table.items():
            base, index = element(key)
            if isinstance(value, list) and len(value) > capacity:
                raise self.error(f"{where}.{key} has {len(value)} values: {room}", key, where)
            if index is not None and index > capacity:
                raise self.error(f"{where}.{key}: floor {index} is beyond the top floor: {room}", key, where)
        n = table.get("n_storeys")
        if n is None:
            lengths = [len(v) for v in table.values() if isinstance(v, list)]
            indices = [element(k)[1] for k in table if element(k)[1]]
            n = max(lengths + indices + [1])
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise self.error(f"{where}.n_storeys = {n!r} must be an integer >= 1", "n_storeys", where)
        if n > capacity:
            raise self.error(f"{where}.n_storeys = {n!r}: {room}", "n_storeys", where)
        return n

    def _storey_capacity(self) -> int:
        """How many storeys the building FMU has variables for (its ``m[i]`` parameters)."""
        interface = self.fmus[BUILDING]
        return max((v.index for v in interface.variables.values()
                    if v.base == "m" and v.index is not None and v.causality == "parameter"), default=1)

    def _check_storey(self, where: str, key: str, value: Any, n: int) -> None:
        base, index = element(key)
        if base in ("m", "k") and index is not None and index <= n:
            value = self._number(value, key, where)
            if base == "m" and value <= 0:
                raise self.error(f"{where}.{key} = {value!r} kg: a mass must be > 0", key, where)
            if base == "k" and value < 0:
                raise self.error(f"{where}.{key} = {value!r} N/m: a storey stiffness must be >= 0", key, where)

    def _check_storey_law(self, where: str, flat: Mapping[str, Any], n: int) -> None:
        """The storey law's own rules (``StoreyHysteresis.parameter_problems``, what building.fmu
        refuses at initialisation: yield shears of yielding storeys, alpha, Bouc-Wen parameters,
        an initial drift beyond yield), named at the line of the parameter they are about."""
        defaults = parameter_defaults(BUILDING)

        def value(key):
            return flat.get(key, defaults[key])

        floors = range(1, n + 1)
        law = StoreyHysteresis(str(value("hysteresis")), [float(value(element_name("Fy", i))) for i in floors],
                               float(value("alpha")), float(value("bw_n")), float(value("bw_beta")),
                               float(value("bw_gamma")))
        try:   # the stiffnesses the FMU will use (scaled to T1); other problems are reported elsewhere
            masses = [float(value(element_name("m", i))) for i in floors]
            k = [float(value(element_name("k", i))) for i in floors]
            T1, zeta, damping = float(value("T1")), float(value("zeta")), str(value("damping"))
            building = (ShearBuilding.from_period(T1, masses, k, zeta, damping) if T1 > 0.0
                        else ShearBuilding(masses, k, zeta, damping))
        except ValueError:
            return
        x0 = np.array([float(value(element_name("x0", i))) for i in floors])
        drifts = np.diff(x0, prepend=0.0)
        for keys, message in law.parameter_problems(building.stiffnesses, building.damping_ratio, drifts):
            # a rule on several parameters: name the one the scene (or a --set) gave
            names = keys.split()
            key = next((k for k in names if (where, k) in self.overridden or self._line_of(k, where)), names[0])
            text = (f"{where}.{message}" if any(message.startswith(base_name(k)) for k in names)
                    else f"{where}: {message}")
            raise self.error(text, key, where)

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
        gap_start = parameter_defaults(POUNDING)["gap"]
        x0_start = parameter_defaults(BUILDING)[element_name("x0", 1)]
        for level, spec in zip(scene.levels, scene.contacts):
            left, right = scene.instance(level.left), scene.instance(level.right)
            x1 = float(left.parameters.get(element_name("x0", level.floor_left), x0_start))
            x2 = float(right.parameters.get(element_name("x0", level.floor_right), x0_start))
            gap = float(spec.parameters.get("gap", gap_start))
            delta = x1 - x2 - gap
            if delta > 0 and not scene.allow_initial_overlap:
                raise self.error(
                    f"the gap of {spec.name} is already closed at t = 0: x0 {level.left} "
                    f"({x1:g} m) - x0 {level.right} ({x2:g} m) - gap ({gap:g} m) = {delta:g} m > 0; "
                    f"set allow_initial_overlap = true in [pounding] to start in contact", "gap", "pounding")
