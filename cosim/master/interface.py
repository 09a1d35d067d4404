"""What the master knows of an FMU's variables, without loading (extracting, instantiating) it.

:class:`FmuInterface` is a light view of one FMU's variables: name, type, causality, start,
unit, value reference, and the parsed element name (``x[3]`` -> ``("x", 3)``, parsed once
here).  Two sources:

* :func:`read_interface`: an FMU file's ``modelDescription.xml``, read from the archive (what
  the loaded FMU really has: the scene loader checks names and types against it);
* :func:`declared_interface`: the slave class's own declaration (``VARIABLES`` in
  ``fmu_src``), available without any built FMU.

Parameter defaults (the value an instance has when a scene does not set it) come from one
resolver, :func:`parameter_defaults`: the slave's declared start values, which are what the
FMU uses when nothing is set.  The modelDescription's start attributes are not used for
numbers: pythonfmu writes them with 16 significant digits (the default storey stiffness
15791367.041742973 N/m becomes ``"15791367.04174297"``).
"""
from __future__ import annotations

import difflib
import functools
import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

from ..fmus import FMU_NAMES, fmu_spec
from .names import base_name, element

_CONVERT = {"Real": float, "Integer": int, "Enumeration": int,
            "Boolean": lambda s: s if isinstance(s, bool) else str(s).lower() in ("true", "1"), "String": str}


@dataclass(frozen=True)
class VariableInfo:
    """What the master needs to know about one FMU variable (``base``/``index``: ``x[3]`` ->
    ``"x"``, 3; a scalar has ``index`` None)."""

    name: str
    type: str                 # Real, Integer, Boolean, String
    causality: str            # parameter, input, output, ...
    variability: str
    value_reference: int | None
    start: Any
    unit: str | None
    description: str | None
    #: the closed bounds of a number (modelDescription ``min``/``max``), None when unbounded
    min: float | None = None
    max: float | None = None
    base: str = field(init=False, compare=False)
    index: int | None = field(init=False, compare=False)

    def __post_init__(self):
        base, index = element(self.name)
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "index", index)


class UnknownVariable(KeyError):
    """A variable the FMU does not have: a ``KeyError`` that reads as
    ``KeyError(FmuInterface.unknown_variable_message(...))`` but composes that message (its
    suggestions come from difflib over every variable: about a millisecond) only when shown.  The
    master probes for optional variables (how many ``t_knot[k]`` an FMU has, at every run's start)
    and catches such errors unseen."""

    def __init__(self, interface: "FmuInterface", name: str, causality: str | None):
        super().__init__(name)
        self._where = (interface, name, causality)
        self._message: str | None = None

    @property
    def message(self) -> str:
        if self._message is None:
            interface, name, causality = self._where
            self._message = interface.unknown_variable_message(name, causality)
        return self._message

    def __str__(self) -> str:
        return repr(self.message)           # as KeyError shows its one argument

    def __reduce__(self):                   # pickled (a study's worker) as the KeyError it reads as
        return KeyError, (self.message,)


class FmuInterface:
    """The variables of one FMU (``name``: ``pounding``, ``building``, ``ground_motion``)."""

    def __init__(self, name: str, variables: Iterable[VariableInfo], source: str, model_description=None):
        self.name = name
        self.source = source
        self.variables: dict[str, VariableInfo] = {v.name: v for v in variables}
        self.model_description = model_description

    def variable(self, name: str, causality: str | None = None) -> VariableInfo:
        """Look a variable up by name (and causality), with a helpful error."""
        try:
            info = self.variables[name]
        except KeyError:
            raise UnknownVariable(self, name, causality) from None
        if causality is not None and info.causality != causality:
            raise KeyError(f"{self.name}.fmu variable {name!r} is an {info.causality}, not a {causality}")
        return info

    def names(self, causality: str | None = None, type: str | None = None) -> list[str]:
        return [n for n, v in self.variables.items()
                if (causality is None or v.causality == causality) and (type is None or v.type == type)]

    def arrays(self, causality: str = "parameter") -> set[str]:
        """Base names of the array variables of a causality (building parameters: m, k, x0, v0)."""
        return {v.base for v in self.variables.values() if v.causality == causality and v.index is not None}

    def unknown_variable_message(self, name: str, causality: str | None = None) -> str:
        pool = self.names(causality)
        base = base_name(name)
        bases = sorted({base_name(p) for p in pool})
        close = difflib.get_close_matches(name, pool, n=3) or [b for b in bases if b == base][:1] or \
            difflib.get_close_matches(base, bases, n=3)
        kind = f" {causality}" if causality else " variable"
        hint = f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else ""
        return f"{self.name}.fmu has no{kind} {name!r}{hint}"

    def __repr__(self) -> str:
        return f"FmuInterface({self.name!r} from {self.source})"


def _typed(type_: str, value: Any) -> Any:
    return None if value is None else _CONVERT[type_](value)


def _bound(text: Any) -> float | None:
    try:
        return None if text is None else float(text)
    except ValueError:
        return None


def read_interface(path: str | Path) -> FmuInterface:
    """The interface of the FMU file ``path`` (its modelDescription.xml; read once per file version)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"FMU {path} does not exist (build it with: pounding-cosim build-fmus)")
    stat = path.stat()
    return _read_interface(str(path.resolve()), stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _read_interface(path: str, size: int, mtime_ns: int) -> FmuInterface:
    from fmpy import read_model_description

    md = read_model_description(path)
    if md.coSimulation is None:
        raise ValueError(f"{path} is not a co-simulation FMU")
    variables = [VariableInfo(v.name, v.type, v.causality, v.variability, v.valueReference,
                              _typed(v.type, v.start), v.unit, v.description, _bound(v.min), _bound(v.max))
                 for v in md.modelVariables]
    return FmuInterface(Path(path).stem, variables, path, md)


@functools.lru_cache(maxsize=None)
def declared_interface(name: str) -> FmuInterface:
    """The interface FMU ``name`` declares in ``fmu_src`` (its slave class's ``VARIABLES``)."""
    spec = fmu_spec(name)
    slave = getattr(importlib.import_module(f"fmu_src.{spec.module}"), spec.class_name)
    variables = []
    for var in slave.VARIABLES:
        start = None if var.causality == "output" else _typed(var.type, var.start)
        low = var.low if var.low is not None and not var.low_open else None      # as the modelDescription has them
        high = var.high if var.high is not None and not var.high_open else None
        variables.append(VariableInfo(var.name, var.type, var.causality, var.resolved_variability, None, start,
                                      var.unit or None, slave._describe(var), low, high))   # as the FMU writes it
    return FmuInterface(name, variables, f"fmu_src.{spec.module}.{spec.class_name}")


def parameter_defaults(name: str) -> Mapping[str, Any]:
    """Value of every parameter of FMU ``name`` when a scene does not set it (the slave's declared
    start values: see the module docstring)."""
    return _defaults(name)


@functools.lru_cache(maxsize=None)
def _defaults(name: str) -> Mapping[str, Any]:
    from types import MappingProxyType

    interface = declared_interface(name)
    return MappingProxyType({n: v.start for n, v in interface.variables.items() if v.causality == "parameter"})


def interfaces(source: Any = None) -> dict[str, FmuInterface]:
    """The interfaces of every FMU of the package, by name.

    ``source``: None (the slaves' declarations), a folder of built FMUs (their model
    descriptions), or a mapping name -> object with an ``interface`` (a loaded
    :class:`cosim.master.system.Catalog`) or an interface itself.
    """
    if source is None:
        return {name: declared_interface(name) for name in FMU_NAMES}
    if isinstance(source, (str, Path)):
        return {name: read_interface(Path(source) / f"{name}.fmu") for name in FMU_NAMES}
    out = {}
    for name, item in source.items():
        out[name] = getattr(item, "interface", item)
    return out
