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

Rules (checked by :func:`cosim.master.loader.load_scene` before anything is instantiated,
each a one-line :class:`SceneError` naming the file, the line, the table and the key):

* Top-level keys: ``name description stop_time step coupling output_interval ground
  buildings pounding``; anything else is an error.  ``output_interval`` (s, >= 0, default
  the step; 0: every communication point) spaces the history's rows
  (:mod:`cosim.master.recording`).
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
plain strings when they do not parse.  The text is parsed once, at the command-line edge
(:func:`parse_override`); programs pass typed :class:`Override` objects.

This module is the data model (:class:`Scene`, :class:`InstanceSpec`,
:class:`ContactLevel`, :class:`Connection`, :class:`Override`); reading and checking a scene
file is :mod:`cosim.master.loader`.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .interface import FmuInterface, declared_interface, parameter_defaults
from .names import base_name, element, element_name

#: the bundled scenes (package data)
SCENES = Path(__file__).resolve().parents[1] / "scenes"


class SceneError(ValueError):
    """A scene (or an override) is invalid; the message is one line."""


@dataclass(frozen=True)
class Override:
    """One ``--set``: ``instance.variable = value`` (``instance`` None: a top-level scene key).

    ``value`` is typed (float, int, bool, str); :func:`parse_override` makes one from the
    command line's text, once.  ``Override.of("pounding.gap", 0.02)`` names the target as text.
    """

    instance: str | None
    variable: str
    value: Any
    #: how error messages name where the value came from, as the user wrote it (``--set
    #: left.m=1e-300``, ``--step 1e-12``); None: ``--set`` and :attr:`text`
    origin: str | None = field(default=None, compare=False)

    @classmethod
    def of(cls, target: str, value: Any) -> "Override":
        """``Override.of("left.m[1]", 2e5)``, ``Override.of("stop_time", 5.0)``."""
        if "." in base_name(target):
            instance, variable = target.split(".", 1)
        else:
            instance, variable = None, target
        return cls(instance, variable, value)

    @property
    def text(self) -> str:
        """How errors quote it: ``left.m[1]=250000.0``."""
        key = f"{self.instance}.{self.variable}" if self.instance else self.variable
        return f"{key}={self.value!r}"

    @property
    def where(self) -> str:
        """Where the value came from, for error messages: ``--set left.m=1e-300`` as typed."""
        return self.origin or f"--set {self.text}"


def parse_override(text: str) -> Override:
    """``"left.m[1]=2e5"`` -> ``Override("left", "m[1]", 200000.0)``; no dot -> top level.

    The value is a TOML literal (``0.02``, ``true``, ``"kobe1995"``), or a bare word taken as a
    string (record and model names).
    """
    if "=" not in text:
        raise SceneError(f"--set {text!r}: expected instance.variable=value")
    key, value_text = text.split("=", 1)
    key, value_text = key.strip(), value_text.strip()
    try:
        value = tomllib.loads(f"v = {value_text}")["v"]
    except tomllib.TOMLDecodeError:
        value = value_text  # a bare word: record names, model names
    override = Override.of(key, value)
    override = Override(override.instance, override.variable, value, origin=f"--set {text.strip()}")
    if not override.variable or (override.instance is not None and not override.instance):
        raise SceneError(f"--set {text!r}: expected instance.variable=value")
    return override


def as_override(item: Override | str | tuple) -> Override:
    """An :class:`Override` from an Override, its text form (kept for the API's callers) or an
    ``(instance, variable, value)`` tuple."""
    if isinstance(item, Override):
        return item
    if isinstance(item, str):
        return parse_override(item)
    return Override(*item)


@dataclass
class InstanceSpec:
    """One FMU instance of a scene: its name, FMU and the parameter values the scene sets
    (FMI names).  :meth:`value` also knows the FMU's defaults for the others."""

    name: str
    fmu: str
    parameters: dict[str, Any] = field(default_factory=dict)

    def value(self, name: str) -> Any:
        """The parameter ``name`` as the instance will have it: set by the scene, else the FMU's
        default (:func:`cosim.master.interface.parameter_defaults`)."""
        if name in self.parameters:
            return self.parameters[name]
        try:
            return parameter_defaults(self.fmu)[name]
        except KeyError:
            raise KeyError(declared_interface(self.fmu).unknown_variable_message(name, "parameter")) from None


#: contact parameters the coupling strategy sets when the scene does not (System.initialize)
COUPLING_DECLARED = ("host",)


def _effective(spec: InstanceSpec, n_storeys: int | None = None) -> dict[str, Any]:
    """Every parameter of ``spec`` as its FMU gets it; array elements only up to ``n_storeys``."""
    values = dict(parameter_defaults(spec.fmu))
    values.update(spec.parameters)
    if n_storeys is not None:
        values = {k: v for k, v in values.items() if (element(k)[1] or 0) <= n_storeys}
    return values


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
    """A validated scene: the instances (in Gauss-Seidel order), where the contacts act and the
    run settings (``stop_time``, ``step`` in s; ``coupling`` a registered strategy name).
    ``interfaces`` are the FMU interfaces it was checked against."""

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
    interfaces: dict[str, FmuInterface] | None = field(default=None, repr=False, compare=False)
    #: s, at most one history row per interval (None: the step; 0: every communication point)
    output_interval: float | None = None
    #: the overrides applied after the file was read (their text, in order)
    overrides: tuple[str, ...] = ()
    #: where each top-level setting came from (``stop_time`` -> ``"--set stop_time=1e9"`` or
    #: ``"scenes/default.toml, line 3"``), for messages about the run's size
    origins: dict[str, str] = field(default_factory=dict, repr=False, compare=False)

    def origin(self, key: str) -> str:
        """Where the top-level setting ``key`` came from (see :attr:`origins`)."""
        return self.origins.get(key, self.source)

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

    def as_run(self) -> dict[str, Any]:
        """The scene as it runs, in the scene-file format (a dict TOML or JSON can hold): every
        parameter of every instance with the value the FMU gets (the scene's, else the FMU's
        default; a building's floors up to ``n_storeys``), after every override.  Loading it
        (:func:`cosim.master.loader.load_scene`) gives this scene again: ``summary.json`` keeps
        it as ``scene_as_run`` so that a run can be repeated from its results."""
        out: dict[str, Any] = dict(name=self.name, description=self.description, stop_time=self.stop_time,
                                   step=self.step, coupling=self.coupling)
        if self.output_interval is not None:
            out["output_interval"] = self.output_interval
        if self.ground is not None:
            out["ground"] = _effective(self.ground)
        out["buildings"] = {b.name: _effective(b, int(b.parameters["n_storeys"])) for b in self.buildings}
        if self.contacts:
            # a contact parameter the scene left unset that the coupling declares at initialization
            # (System.initialize: host) stays unset, so that the coupling declares it again
            values = [{k: v for k, v in _effective(c).items() if k not in COUPLING_DECLARED or k in c.parameters}
                      for c in self.contacts]
            shared = {k: v for k, v in values[0].items() if all(k in x and x[k] == v for x in values[1:])}
            pounding: dict[str, Any] = {}
            pairs: dict[tuple[str, str], list[list[int]]] = {}
            for level in self.levels:
                pairs.setdefault((level.left, level.right), []).append([level.floor_left, level.floor_right])
            lists = list(pairs.values())
            if all(x == lists[0] for x in lists[1:]):   # given once for every pair of buildings
                pounding["floors"] = lists[0]
            pounding["allow_initial_overlap"] = self.allow_initial_overlap
            pounding.update(shared)
            for spec, own in zip(self.contacts, values):
                differs = {k: v for k, v in own.items() if k not in shared}
                if differs:
                    pounding[spec.name] = differs
            out["pounding"] = pounding
        return out

    def connections(self) -> list[Connection]:
        """The signal graph (the same for every coupling strategy)."""
        out = []
        if self.ground:
            for b in self.buildings:
                out.append(Connection(self.ground.name, "ag_mean", b.name, "ag"))
        for level in self.levels:
            c, fl, fr = level.instance, level.floor_left, level.floor_right
            out += [Connection(level.left, element_name("x", fl), c, "x1"),
                    Connection(level.left, element_name("v", fl), c, "v1"),
                    Connection(level.right, element_name("x", fr), c, "x2"),
                    Connection(level.right, element_name("v", fr), c, "v2"),
                    # the signed forces on each body (F1 = -F pushes the left body to -x, F2 = F
                    # the right one to +x): no linear transformation, which some SSP tools ignore
                    Connection(c, "F1", level.left, element_name("F", fl)),
                    Connection(c, "F2", level.right, element_name("F", fr))]
        return out
