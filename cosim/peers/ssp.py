"""SSP 1.0 export and import: the scene as a System Structure and Parameterization package.

An ``.ssp`` is a zip holding ``SystemStructure.ssd`` (components, their connectors,
the connections between them, parameter bindings and a default experiment) and the
FMUs under ``resources/`` [SSP 1.0, Modelica Association, 2019].  It is how a coupled
system is handed to another FMI tool (libcosim/OSP, FMPy, SSP-aware commercial
tools).  This module has two layers:

* a tool-neutral model of an SSP system (:class:`Component`, :class:`Connection`,
  :class:`System`) with :func:`write_ssp` / :func:`read_ssp`, which know nothing
  about pounding;
* the bridge to scenes: :func:`scene_system` (scene -> :class:`System`, built from
  the same wiring the master uses), :func:`export_scene` and :func:`load_ssp`
  (``.ssp`` -> scene, so that our master can rerun an exported package).

What SSP 1.0 can and cannot say (see :class:`NotExpressibleError`):

* structure, start values of parameters and inputs, connections with a linear
  transformation ``target = factor * source + offset``: yes, but several SSP readers
  ignore the transformation (FMPy 0.3's runner), so the export needs none: each contact
  hands out the signed force on each body, ``F1`` (= -F, body 1) and ``F2`` (= F, body 2);
* parameter sets: every component's start values are one parameter set named
  :data:`PARAMETER_SET`, because Ecos applies a single named set (libcosim applies all);
* the order in which a master steps the components, iterations, rollback and
  step-size control: no.  SSP leaves the algorithm to the importing tool.  The fixed
  communication step goes into the OSP annotation of ``DefaultExperiment`` (read by
  libcosim); the scene's coupling settings go into a ``org.pounding-cosim`` annotation,
  which other tools ignore and our importer uses to reproduce the run exactly;
* a connection delivers one output to one input: an input that would need the sum
  of several outputs (one floor hit by two contact elements) has no SSP 1.0 form.
"""
from __future__ import annotations

import json
import math
import re
import shutil
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

from ..files import file_target, written_file
from ..fmus import BUILDING, GROUND, POUNDING
from ..master.coupling import COUPLINGS
from ..master.loader import load_scene
from ..master.names import element
from ..master.scene import ContactLevel, InstanceSpec, Override, Scene
from ..master.system import Catalog

SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OUR_NS = "urn:pounding-cosim"
# All prefixes are declared on the root: libcosim's parser (boost property_tree) matches the
# literal prefixes ssd:, ssc:, ssv:, osp: and would read a local xmlns declaration as an attribute.
NSMAP = {"ssd": SSD_NS, "ssc": SSC_NS, "ssv": SSV_NS, "osp": OSP_NS, "pc": OUR_NS}
OSP_ANNOTATION = "com.opensimulationplatform"
OUR_ANNOTATION = "org.pounding-cosim"
FMU_MIME = "application/x-fmu-sharedlibrary"
SSD_NAME = "SystemStructure.ssd"
#: the name of the one parameter set every component's start values belong to (Ecos applies
#: the set it is told to, by name; libcosim applies every set)
PARAMETER_SET = "scene"
#: what the export declares as the contacts' host (pounding.fmu parameter ``host``) when the
#: scene leaves it unset: the SSP tools run a fixed-step Jacobi algorithm (libcosim, Ecos)
#: around building.fmu, which is exact for a held force
EXPORTED_HOST = "zoh_late"

Value = bool | int | float | str


class NotExpressibleError(ValueError):
    """The scene has a feature that an SSP 1.0 package cannot carry."""


class SspWarning(UserWarning):
    """Exported, but part of the scene is only kept as a tool-specific annotation."""


@dataclass(frozen=True)
class Component:
    """One FMU instance: its name in the system, its FMU file and the start values it gets.

    ``start_values`` holds parameters and start values of unconnected inputs by FMI
    variable name (``"gap"``, ``"m[2]"``).
    """

    name: str
    fmu: Path
    start_values: Mapping[str, Value] = field(default_factory=dict)


@dataclass(frozen=True)
class Connection:
    """Output ``start_element.start_connector`` feeds input ``end_element.end_connector``.

    ``factor`` and ``offset`` are SSP's linear transformation
    (``input = factor * output + offset``).
    """

    start_element: str
    start_connector: str
    end_element: str
    end_connector: str
    factor: float = 1.0
    offset: float = 0.0

    def __str__(self) -> str:
        text = f"{self.start_element}.{self.start_connector} -> {self.end_element}.{self.end_connector}"
        if self.factor != 1.0 or self.offset != 0.0:
            text += f" (x {self.factor:g} + {self.offset:g})"
        return text


@dataclass(frozen=True)
class System:
    """A coupled system as SSP sees it, plus the default experiment (s)."""

    name: str
    components: tuple[Component, ...]
    connections: tuple[Connection, ...]
    start_time: float
    stop_time: float
    step_size: float
    annotation: Mapping[str, Any] | None = None   # our tool-specific data (JSON-serialisable)

    def component(self, name: str) -> Component:
        for comp in self.components:
            if comp.name == name:
                return comp
        raise KeyError(f"no component named {name!r}; components: {[c.name for c in self.components]}")


# ---------------------------------------------------------------------------------------------
# units: SSP wants each unit defined by its SI base-unit exponents
# ---------------------------------------------------------------------------------------------
_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
_SYMBOLS = {
    "1": {}, "m": {"m": 1}, "s": {"s": 1}, "kg": {"kg": 1}, "rad": {"rad": 1},
    "N": {"kg": 1, "m": 1, "s": -2}, "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3}, "Pa": {"kg": 1, "m": -1, "s": -2}, "Hz": {"s": -1},
}
_TOKEN = re.compile(r"^([A-Za-z]+|1)(?:\^?(-?\d+(?:\.\d+)?))?$")


def base_unit(unit: str) -> dict[str, float] | None:
    """SI base-unit exponents of a unit string such as ``m/s2``, ``N/m^1.5`` or ``N.s/m``.

    Returns None for a unit this parser does not know or whose exponents are not
    integers (the connector then carries no unit, which SSP allows).
    """
    exponents: dict[str, float] = {}
    parts = unit.replace(" ", "").split("/")
    if not parts[0] or len(parts) > 2:
        return None
    for sign, part in zip((1, -1), parts):
        for token in re.split(r"[.*]", part):
            match = _TOKEN.match(token)
            if not match or match.group(1) not in _SYMBOLS:
                return None
            power = float(match.group(2)) if match.group(2) else 1.0
            for base, exp in _SYMBOLS[match.group(1)].items():
                exponents[base] = exponents.get(base, 0.0) + sign * power * exp
    if any(not float(v).is_integer() for v in exponents.values()):
        return None  # SSP BaseUnit exponents are integers (e.g. N/m^1.5 has none)
    return {k: v for k, v in exponents.items() if v != 0.0}


def _format_exponent(value: float) -> str:
    if float(value).is_integer():
        return str(int(value))
    raise NotExpressibleError(f"unit exponent {value!r} is not an integer (SSP BaseUnit exponents are xs:int)")


# ---------------------------------------------------------------------------------------------
# FMU interface (read once per FMU file)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Var:
    name: str
    type: str
    causality: str
    unit: str | None


def _fmu_variables(fmu: Path) -> dict[str, _Var]:
    from fmpy import read_model_description

    md = read_model_description(str(fmu), validate=False)
    return {v.name: _Var(v.name, v.type, v.causality, v.unit) for v in md.modelVariables}


def _format_value(var: _Var, value: Value, where: str) -> str:
    if var.type == "Real":
        number = float(value)
        if not math.isfinite(number):
            raise ValueError(f"{where}: {var.name} = {value!r} is not finite")
        return repr(number)  # shortest string that reads back to the same double
    if var.type == "Integer":
        if isinstance(value, bool) or int(value) != value:
            raise ValueError(f"{where}: {var.name} = {value!r} is not an integer")
        return str(int(value))
    if var.type == "Boolean":
        if not isinstance(value, (bool, int)) or value not in (0, 1):
            raise ValueError(f"{where}: {var.name} = {value!r} is not a Boolean")
        return "true" if value else "false"
    if var.type == "String":
        return str(value)
    raise NotExpressibleError(f"{where}: variable {var.name} has FMI type {var.type}, not handled")


def _parse_value(type_: str, text: str) -> Value:
    if type_ == "Real":
        return float(text)
    if type_ == "Integer":
        return int(text)
    if type_ == "Boolean":
        if text not in ("true", "false", "1", "0"):
            raise ValueError(f"Boolean value {text!r} is not one of true, false, 1, 0")
        return text in ("true", "1")
    return text


# ---------------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------------
def check_system(system: System) -> dict[str, dict[str, _Var]]:
    """Check names, types and the one-source-per-input rule; return each component's variables.

    Raises :class:`NotExpressibleError` when an input is fed by more than one
    connection (SSP connections cannot sum), ``ValueError`` for unknown components,
    variables or wrong causalities.  libcosim only warns about an unknown parameter
    name, so the check is done here, before anything is written or run.
    """
    names = [c.name for c in system.components]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"system {system.name!r}: component names {dupes} are not unique")
    if not (system.step_size > 0 and system.stop_time > system.start_time):
        raise ValueError(f"system {system.name!r}: need step_size > 0 and stop_time > start_time, got "
                         f"step_size = {system.step_size!r} s, start = {system.start_time!r} s, "
                         f"stop = {system.stop_time!r} s")
    cache: dict[Path, dict[str, _Var]] = {}
    variables: dict[str, dict[str, _Var]] = {}
    for comp in system.components:
        fmu = Path(comp.fmu)
        if not fmu.is_file():
            raise FileNotFoundError(f"component {comp.name!r}: FMU {fmu} does not exist")
        if fmu not in cache:
            cache[fmu] = _fmu_variables(fmu)
        variables[comp.name] = cache[fmu]
        for name, value in comp.start_values.items():
            var = variables[comp.name].get(name)
            where = f"component {comp.name!r} ({fmu.name})"
            if var is None:
                raise ValueError(f"{where}: no variable named {name!r}")
            if var.causality not in ("parameter", "input"):
                raise ValueError(f"{where}: {name} has causality {var.causality!r}; only parameters and "
                                 f"inputs take start values")
            _format_value(var, value, where)
    fed: dict[tuple[str, str], list[Connection]] = {}
    for con in system.connections:
        for elem, conn, role in ((con.start_element, con.start_connector, "output"),
                                 (con.end_element, con.end_connector, "input")):
            if elem not in variables:
                raise ValueError(f"connection {con}: no component named {elem!r}")
            var = variables[elem].get(conn)
            if var is None:
                raise ValueError(f"connection {con}: component {elem!r} has no variable {conn!r}")
            if var.causality != role:
                raise ValueError(f"connection {con}: {elem}.{conn} has causality {var.causality!r}, "
                                 f"expected {role!r}")
        fed.setdefault((con.end_element, con.end_connector), []).append(con)
    for (elem, conn), cons in fed.items():
        if len(cons) > 1:
            raise NotExpressibleError(
                f"input {elem}.{conn} receives the sum of {len(cons)} outputs "
                f"({'; '.join(str(c) for c in cons)}): an SSP 1.0 connection carries one output "
                f"to one input and cannot add signals, so this scene cannot be exported")
    return variables


def build_ssd(system: System, sources: Mapping[str, str] | None = None) -> bytes:
    """SystemStructure.ssd of ``system`` as UTF-8 XML (sources: component -> path in the zip)."""
    from lxml import etree

    variables = check_system(system)
    sources = sources or {c.name: f"resources/{Path(c.fmu).name}" for c in system.components}
    ssd, ssc, ssv = (lambda t: f"{{{SSD_NS}}}{t}"), (lambda t: f"{{{SSC_NS}}}{t}"), (lambda t: f"{{{SSV_NS}}}{t}")

    units: dict[str, dict[str, float]] = {}

    def unit_of(var: _Var) -> str | None:
        if var.type != "Real" or not var.unit:
            return None
        if var.unit not in units:
            exps = base_unit(var.unit)
            if exps is None:
                return None
            units[var.unit] = exps
        return var.unit

    root = etree.Element(ssd("SystemStructureDescription"), nsmap=NSMAP,
                         attrib={"version": "1.0", "name": system.name,
                                 "generationTool": "pounding-cosim (cosim/ssp.py)"})
    sys_el = etree.SubElement(root, ssd("System"), name=system.name)
    elements = etree.SubElement(sys_el, ssd("Elements"))
    for comp in system.components:
        vars_ = variables[comp.name]
        el = etree.SubElement(elements, ssd("Component"), name=comp.name, type=FMU_MIME,
                              source=sources[comp.name])
        connectors = etree.SubElement(el, ssd("Connectors"))
        for var in vars_.values():
            if var.causality not in ("input", "output", "parameter", "calculatedParameter"):
                continue
            c = etree.SubElement(connectors, ssd("Connector"), name=var.name, kind=var.causality)
            typed = etree.SubElement(c, ssc(var.type))
            unit = unit_of(var)
            if unit:
                typed.set("unit", unit)
        if comp.start_values:
            bindings = etree.SubElement(el, ssd("ParameterBindings"))
            binding = etree.SubElement(bindings, ssd("ParameterBinding"))
            values = etree.SubElement(binding, ssd("ParameterValues"))
            pset = etree.SubElement(values, ssv("ParameterSet"), version="1.0", name=PARAMETER_SET)
            params = etree.SubElement(pset, ssv("Parameters"))
            set_units = set()
            for name, value in comp.start_values.items():
                var = vars_[name]
                p = etree.SubElement(params, ssv("Parameter"), name=name)
                typed = etree.SubElement(p, ssv(var.type),
                                         value=_format_value(var, value, f"component {comp.name!r}"))
                unit = unit_of(var)
                if unit:
                    typed.set("unit", unit)
                    set_units.add(unit)
            if set_units:
                _write_units(etree.SubElement(pset, ssv("Units")), set_units, units, ssc)
    if system.connections:
        cons = etree.SubElement(sys_el, ssd("Connections"))
        for con in system.connections:
            c = etree.SubElement(cons, ssd("Connection"), startElement=con.start_element,
                                 startConnector=con.start_connector, endElement=con.end_element,
                                 endConnector=con.end_connector)
            if con.factor != 1.0 or con.offset != 0.0:
                etree.SubElement(c, ssc("LinearTransformation"), factor=repr(float(con.factor)),
                                 offset=repr(float(con.offset)))
    if units:
        _write_units(etree.SubElement(root, ssd("Units")), set(units), units, ssc)
    exp = etree.SubElement(root, ssd("DefaultExperiment"), startTime=repr(float(system.start_time)),
                           stopTime=repr(float(system.stop_time)))
    anns = etree.SubElement(exp, ssd("Annotations"))
    osp = etree.SubElement(anns, ssc("Annotation"), type=OSP_ANNOTATION)
    algorithm = etree.SubElement(osp, f"{{{OSP_NS}}}Algorithm")
    etree.SubElement(algorithm, f"{{{OSP_NS}}}FixedStepAlgorithm", baseStepSize=repr(float(system.step_size)))
    if system.annotation is not None:
        top = etree.SubElement(root, ssd("Annotations"))
        ours = etree.SubElement(top, ssc("Annotation"), type=OUR_ANNOTATION)
        payload = etree.SubElement(ours, f"{{{OUR_NS}}}Scene", format="json")
        payload.text = json.dumps(system.annotation, sort_keys=True)
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def _write_units(parent, names: Iterable[str], table: Mapping[str, Mapping[str, float]], ssc) -> None:
    from lxml import etree

    for name in sorted(names):
        u = etree.SubElement(parent, ssc("Unit"), name=name)
        exps = {k: _format_exponent(v) for k, v in table[name].items()}
        etree.SubElement(u, ssc("BaseUnit"), attrib={k: exps[k] for k in _BASE if k in exps})


def write_ssp(system: System, path: Path | str) -> Path:
    """Write ``system`` as an SSP package (zip); FMUs go to ``resources/<file>.fmu``.

    The file appears under its name only when complete (written next to it, then renamed).
    """
    path = Path(path)
    sources: dict[str, str] = {}
    files: dict[str, Path] = {}
    for comp in system.components:
        arcname = f"resources/{Path(comp.fmu).name}"
        if arcname in files and files[arcname].resolve() != Path(comp.fmu).resolve():
            raise ValueError(f"two different FMUs share the file name {Path(comp.fmu).name!r}")
        files[arcname] = Path(comp.fmu)
        sources[comp.name] = arcname
    ssd = build_ssd(system, sources)
    with written_file(path) as partial:
        with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr(SSD_NAME, ssd)
            for arcname, fmu in files.items():
                zf.write(fmu, arcname)
    return path


def validate_ssp(path: Path | str) -> list[str]:
    """Problems of an .ssp: SSP 1.0 XML schema of the SSD (FMPy ships the XSDs), FMUs present."""
    from fmpy.ssp.ssd import validate_tree
    from lxml import etree

    problems = []
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
        if SSD_NAME not in names:
            return [f"{path}: no {SSD_NAME} in the package"]
        root = etree.fromstring(zf.read(SSD_NAME))
    try:
        validate_tree(root, "SystemStructureDescription.xsd")
    except Exception as exc:  # fmpy raises a bare Exception listing the schema errors
        problems.append(str(exc))
    for comp in root.iter(f"{{{SSD_NS}}}Component"):
        if comp.get("source") not in names:
            problems.append(f"component {comp.get('name')!r}: source {comp.get('source')!r} is not in the package")
    return problems


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------
def read_ssp(path: Path | str, extract_to: Path | str) -> System:
    """Read an SSP written by :func:`write_ssp` (or any flat SSP 1.0 system of FMUs).

    FMUs are extracted to ``extract_to``.  Nested systems, parameter mappings and
    parameter files (``.ssv`` sources) are refused with a message naming them.
    """
    from lxml import etree

    path = Path(path)
    out = Path(extract_to)
    with zipfile.ZipFile(path) as zf:
        if SSD_NAME not in zf.namelist():
            raise ValueError(f"{path}: not an SSP package (no {SSD_NAME})")
        root = etree.fromstring(zf.read(SSD_NAME))
        q = {"ssd": SSD_NS, "ssc": SSC_NS, "ssv": SSV_NS, "osp": OSP_NS}
        system_el = root.find("ssd:System", q)
        if system_el.find("ssd:Elements/ssd:System", q) is not None:
            raise NotExpressibleError(f"{path}: nested systems are not supported by the importer")
        components = []
        for el in system_el.findall("ssd:Elements/ssd:Component", q):
            name, source = el.get("name"), el.get("source")
            where = f"{path}: component {name!r}"
            if source not in zf.namelist():
                raise ValueError(f"{where}: source {source!r} is not in the package")
            types = {c.get("name"): c[0].tag.split("}")[1] for c in el.findall("ssd:Connectors/ssd:Connector", q)
                     if len(c)}
            start_values: dict[str, Value] = {}
            for binding in el.findall("ssd:ParameterBindings/ssd:ParameterBinding", q):
                if binding.get("source") is not None or binding.find("ssd:ParameterMapping", q) is not None:
                    raise NotExpressibleError(f"{where}: parameter files and parameter mappings are not "
                                              f"supported by the importer (write inline ParameterValues)")
                for p in binding.findall("ssd:ParameterValues/ssv:ParameterSet/ssv:Parameters/ssv:Parameter", q):
                    typed = p[0]
                    type_ = typed.tag.split("}")[1]
                    if types.get(p.get("name"), type_) != type_:
                        raise ValueError(f"{where}: parameter {p.get('name')} is {type_} in the parameter "
                                         f"set but {types[p.get('name')]} in the connectors")
                    start_values[p.get("name")] = _parse_value(type_, typed.get("value"))
            target = out / Path(source).name
            out.mkdir(parents=True, exist_ok=True)
            with zf.open(source) as src, open(target, "wb") as dst:
                shutil.copyfileobj(src, dst)
            components.append(Component(name, target, start_values))
        connections = []
        for c in system_el.findall("ssd:Connections/ssd:Connection", q):
            lt = c.find("ssc:LinearTransformation", q)
            connections.append(Connection(
                c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"),
                factor=float(lt.get("factor", 1.0)) if lt is not None else 1.0,
                offset=float(lt.get("offset", 0.0)) if lt is not None else 0.0))
        exp = root.find("ssd:DefaultExperiment", q)
        if exp is None or exp.get("stopTime") is None:
            raise ValueError(f"{path}: DefaultExperiment with stopTime is missing")
        step = exp.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", q)
        if step is None:
            raise ValueError(f"{path}: no fixed communication step (osp:FixedStepAlgorithm baseStepSize)")
        annotation = None
        ours = root.find(f"ssd:Annotations/ssc:Annotation[@type='{OUR_ANNOTATION}']", q)
        if ours is not None and len(ours):
            annotation = json.loads(ours[0].text)
    system = System(name=root.get("name"), components=tuple(components), connections=tuple(connections),
                    start_time=float(exp.get("startTime", 0.0)), stop_time=float(exp.get("stopTime")),
                    step_size=float(step.get("baseStepSize")), annotation=annotation)
    check_system(system)
    return system


# ---------------------------------------------------------------------------------------------
# scenes <-> SSP
# ---------------------------------------------------------------------------------------------
def scene_system(scene, fmu_dir: Path | str) -> System:
    """The SSP view of a :class:`cosim.master.scene.Scene` whose FMUs are in ``fmu_dir``.

    Components, start values and connections are exactly the instances, parameters and
    signal graph the master uses (``scene.instances()``, ``scene.connections()``).
    Raises :class:`NotExpressibleError` if an input would need the sum of several
    outputs (a floor pounded by two contact instances).
    """
    fmu_dir = Path(fmu_dir)
    components = tuple(Component(spec.name, fmu_dir / f"{spec.fmu}.fmu",
                                 {**({"host": EXPORTED_HOST} if spec.fmu == POUNDING and "host" not in spec.parameters
                                     else {}), **spec.parameters})
                       for spec in scene.instances())
    connections = tuple(Connection(c.source, c.output, c.target, c.input, factor=float(c.factor))
                        for c in scene.connections())
    fed: dict[tuple[str, str], list[Connection]] = {}
    for con in connections:
        fed.setdefault((con.end_element, con.end_connector), []).append(con)
    for (elem, conn), cons in fed.items():
        if len(cons) > 1:
            sources = ", ".join(f"{c.start_element}.{c.start_connector}" for c in cons)
            raise NotExpressibleError(
                f"{scene.source}: input {elem}.{conn} is the sum of {sources}; the master adds them, "
                f"but an SSP 1.0 connection carries one output to one input and cannot add signals. "
                f"Not exportable: pound that floor from one side only, or use separate floors")
    annotation = {"format": 1, "description": scene.description, "coupling": scene.coupling,
                  "allow_initial_overlap": bool(scene.allow_initial_overlap),
                  "declared_host": {spec.name: EXPORTED_HOST for spec in scene.contacts if "host" not in spec.parameters}}
    return System(name=scene.name, components=components, connections=connections, start_time=0.0,
                  stop_time=float(scene.stop_time), step_size=float(scene.step), annotation=annotation)


def export_notes(scene) -> list[str]:
    """What of ``scene`` only travels as our annotation, or is machine-specific (one line each)."""
    notes = []
    if scene.coupling != "jacobi":
        notes.append(
            f"coupling = {scene.coupling!r} is not expressible in SSP 1.0, which describes structure and "
            f"parameters, not the order in which a master steps the components; it is kept in the "
            f"{OUR_ANNOTATION!r} annotation (used by cosim.peers.ssp.load_ssp, ignored by other tools). "
            f"libcosim and Ecos run the package with their fixed-step Jacobi algorithm at h = {scene.step:g} s "
            f"(the contacts are declared host = {EXPORTED_HOST!r} for it)")
    if scene.ground is not None:
        record = str(scene.ground.parameters.get("record", ""))
        if any(sep in record for sep in ("/", "\\")) or Path(record).suffix:
            notes.append(f"ground.record = {record!r} is a file on this machine: the package refers to it "
                         f"by that path and runs only where the file exists")
    return notes


def export_scene(scene, path: Path | str, fmu_dir: Path | str) -> tuple[Path, list[str]]:
    """Write ``scene`` as an SSP package; return its path and the notes of :func:`export_notes`.

    Each note is also issued as an :class:`SspWarning`.
    """
    system = scene_system(scene, fmu_dir)
    notes = export_notes(scene)
    out = write_ssp(system, path)
    for note in notes:
        warnings.warn(note, SspWarning, stacklevel=2)
    return out, notes


def load_ssp(path: Path | str, extract_to: Path | str):
    """Read an SSP package back into a :class:`cosim.master.scene.Scene` for our master.

    The FMUs are extracted to ``extract_to`` (run the scene with that folder as the
    FMU folder).  The scene is rebuilt from the standard content: components by FMU
    file (``ground_motion``, ``building``, ``pounding``), start values, contact levels
    from the connections into ``x1``/``x2``.  The coupling comes from our annotation,
    or is ``"jacobi"`` (what libcosim runs) in a package written by another tool.  A
    package whose wiring is not the one our master makes is refused, naming the
    connection.
    """
    path = Path(path)
    system = read_ssp(path, extract_to)
    if system.start_time != 0.0:
        raise NotExpressibleError(f"{path}: startTime = {system.start_time!r} s; scenes start at 0 s")
    kinds = {c.name: Path(c.fmu).stem for c in system.components}
    for name, kind in kinds.items():
        if kind not in (GROUND, BUILDING, POUNDING):
            raise NotExpressibleError(f"{path}: component {name!r} uses {kind}.fmu, which is not one of "
                                      f"{GROUND}.fmu, {BUILDING}.fmu, {POUNDING}.fmu")
    ann = dict(system.annotation or {})
    declared = ann.get("declared_host", {})
    # the host the export declared for the SSP tools goes: our master declares its own
    specs = {c.name: InstanceSpec(c.name, kinds[c.name], {k: v for k, v in c.start_values.items()
                                                          if not (k == "host" and declared.get(c.name) == v)})
             for c in system.components}
    grounds = [specs[n] for n, k in kinds.items() if k == GROUND]
    if len(grounds) > 1:
        raise NotExpressibleError(f"{path}: {len(grounds)} ground-motion components; a scene has at most one")
    buildings = [specs[n] for n, k in kinds.items() if k == BUILDING]
    contacts = [specs[n] for n, k in kinds.items() if k == POUNDING]
    feeds = {(c.end_element, c.end_connector): c for c in system.connections}
    levels = []
    for contact in contacts:
        ends = []
        for port in ("x1", "x2"):
            con = feeds.get((contact.name, port))
            base, floor = element(con.start_connector) if con else (None, None)
            if con is None or base != "x" or floor is None or kinds.get(con.start_element) != BUILDING:
                raise NotExpressibleError(f"{path}: input {contact.name}.{port} is not fed by a building floor "
                                          f"displacement x[i]")
            ends.append((con.start_element, floor))
        levels.append(ContactLevel(contact.name, ends[0][0], ends[1][0], ends[0][1], ends[1][1]))
    coupling = ann.get("coupling", "jacobi")
    if coupling not in COUPLINGS:
        raise ValueError(f"{path}: annotation coupling = {coupling!r} is not one of {', '.join(COUPLINGS)}")
    scene = Scene(name=system.name, description=ann.get("description", ""), stop_time=system.stop_time,
                  step=system.step_size, coupling=coupling, ground=grounds[0] if grounds else None,
                  buildings=buildings, contacts=contacts, levels=levels,
                  allow_initial_overlap=bool(ann.get("allow_initial_overlap", False)), path=None)
    expected = {(c.source, c.output, c.target, c.input, float(c.factor)) for c in scene.connections()}
    found = {(c.start_element, c.start_connector, c.end_element, c.end_connector, c.factor)
             for c in system.connections}
    offsets = [c for c in system.connections if c.offset != 0.0]
    if offsets or expected != found:
        odd = sorted(found - expected) or sorted(expected - found)
        what = (f"connection {offsets[0]} has an offset" if offsets else
                f"connections differ from the pounding master's wiring, e.g. {odd[0][0]}.{odd[0][1]} -> "
                f"{odd[0][2]}.{odd[0][3]} (x {odd[0][4]:g}) is {'extra' if found - expected else 'missing'}")
        raise NotExpressibleError(f"{path}: {what}")
    return scene


def export(scene: str | Path, path: Path | str, overrides: Iterable[Override | str] = (), *,
           fmu_dir: Path | str, overwrite: bool = False) -> tuple[Path, list[str], Scene]:
    """Load ``scene`` as a run would (overrides checked against the FMUs in ``fmu_dir``) and write
    it as an SSP package at ``path``; returns the package, the notes of :func:`export_notes`
    (not issued as warnings: the caller prints them) and the scene.  ``path`` follows the
    package's file rule (:func:`cosim.files.file_target`: a new path, or an existing file with
    ``overwrite``; never a folder).  Raises :class:`NotExpressibleError` for a scene SSP 1.0
    cannot express, :class:`cosim.files.OutputError` for a refused path."""
    fmu_dir = Path(fmu_dir)
    with Catalog(fmu_dir) as catalog:
        loaded = load_scene(scene, overrides, catalog)
    path = file_target(path, overwrite=overwrite)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SspWarning)
        out, notes = export_scene(loaded, path, fmu_dir)
    return out, notes, loaded
