"""Thin FMI 2.0 co-simulation adapter shared by every FMU of the package.

A slave declares its variables once, as data (a tuple of :class:`Variable`),
and implements two hooks: :meth:`SlaveBase.initialize` (after the parameters
are checked) and :meth:`SlaveBase.step` (one communication step).  This base
class does the FMI bookkeeping that pythonfmu leaves to the author:

* parameter checks against the declared ranges, reported as an FMI error
  message that names the variable, its value and the allowed range;
* finite-input checks on every step;
* no Python exception ever escapes ``do_step``: pythonfmu would turn it into
  ``fmi2Fatal`` and free the instance.  pythonfmu 0.7 can only return
  ``fmi2OK``, ``fmi2Discard`` (``do_step`` returning ``False``) or
  ``fmi2Fatal``; a failed step therefore returns ``fmi2Discard`` with a
  message logged under status ``fmi2Error`` (category ``logStatusError``),
  and the instance stays alive so the host can read the message;
* FMU state (``fmi2GetFMUstate``/``fmi2SetFMUstate``) includes the private
  attributes listed in ``PRIVATE_STATE``, deep-copied, so that a restored
  instance continues exactly as the saved one;
* the modelDescription gets units, ``UnitDefinitions``, min/max, and every output is
  ``initial="calculated"`` (computed when initialisation ends) and listed in
  ``ModelStructure/InitialUnknowns``, which pythonfmu alone leaves out; its description
  states what the host's Python must provide (:data:`HOST_REQUIREMENTS`).

Nothing here is mutable at module or class level: every FMU of a process
shares one Python interpreter.
"""
from __future__ import annotations

import copy
import math
import sys
import traceback
from dataclasses import dataclass
from typing import Any, Callable, Iterable
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Initial, Fmi2Status

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}

#: what every FMU of the package imports from the host's Python besides the standard library
#: (pythonfmu travels inside the FMU); written into each FMU as resources/requirements.txt
HOST_REQUIREMENTS = ("numpy>=1.24", "scipy>=1.11")


def host_requirements_text() -> str:
    """One sentence for the modelDescription: the host Python's version and packages."""
    names = " and ".join(r.split(">")[0].split("=")[0] for r in HOST_REQUIREMENTS)
    return (f"Needs a Python {sys.version_info[0]}.{sys.version_info[1]} host with {names} "
            f"(resources/requirements.txt: {', '.join(HOST_REQUIREMENTS)})")


#: communication steps [s] an FMU accepts: below MIN_STEP the in-step arithmetic (rates
#: measured over the step, impulse / h) loses its meaning long before any physics needs such
#: a step (the stiffest contact of the tests lasts 38 us); MAX_STEP bounds a step's work
MIN_STEP = 1e-12
MAX_STEP = 1e6
#: a step must also change the time: h >= TIME_RESOLUTION |t| (t + h distinct from t, with
#: six bits to spare)
TIME_RESOLUTION = 64 * 2.220446049250313e-16


@dataclass(frozen=True)
class Variable:
    """One FMI scalar variable, declared as data.

    ``name`` is the FMI name.  An element of an array is written ``x[3]``
    (1-based, FMI structured naming) and is stored in the numpy array
    attribute ``x`` at index 2.  ``low``/``high`` bound the allowed values of
    a parameter (``low_open``/``high_open`` make the bound strict);
    ``choices`` lists the allowed values of a String parameter.
    """

    name: str
    type: str = "Real"
    causality: str = "parameter"
    start: Any = 0.0
    unit: str = ""
    description: str = ""
    variability: str | None = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] | None = None

    @property
    def attribute(self) -> str:
        return self.name.split("[", 1)[0]

    @property
    def index(self) -> int | None:
        if "[" not in self.name:
            return None
        return int(self.name.split("[", 1)[1].rstrip("]")) - 1

    @property
    def resolved_variability(self) -> str:
        if self.variability is not None:
            return self.variability
        if self.causality == "parameter":
            return "fixed"
        if self.type == "Real":
            return "continuous"
        return "discrete"

    def allowed_range(self) -> str:
        """Human-readable allowed range, e.g. ``0 < CR <= 1``."""
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        parts = []
        if self.low is not None:
            parts.append(f"{self.low:g} {'<' if self.low_open else '<='} ")
        parts.append(self.name)
        if self.high is not None:
            parts.append(f" {'<' if self.high_open else '<='} {self.high:g}")
        return "".join(parts)

    def violation(self, value: Any) -> str | None:
        """Return why ``value`` is not allowed, or None if it is."""
        if isinstance(value, np.generic):  # report 5.0, not np.float64(5.0)
            value = value.item()
        if self.choices is not None:
            if value not in self.choices:
                return f"{self.name} = {value!r} is not allowed: {self.allowed_range()}"
            return None
        if self.type in ("Real", "Integer"):
            v = float(value)
            unit = f" {self.unit}" if self.unit not in ("", "1") else ""
            if not math.isfinite(v):
                return f"{self.name} = {value!r}{unit} is not finite (allowed: {self.allowed_range()})"
            bad_low = self.low is not None and (v <= self.low if self.low_open else v < self.low)
            bad_high = self.high is not None and (v >= self.high if self.high_open else v > self.high)
            if bad_low or bad_high:
                return f"{self.name} = {value!r}{unit} is outside the allowed range {self.allowed_range()}"
        return None


def array(name: str, count: int, **kwargs) -> tuple[Variable, ...]:
    """Declare ``name[1] .. name[count]`` with the same properties."""
    description = kwargs.pop("description", "")
    return tuple(
        Variable(f"{name}[{i}]", description=f"{description} (element {i})".strip(), **kwargs)
        for i in range(1, count + 1)
    )


class SlaveError(Exception):
    """An error that a slave reports through FMI status and the log."""


class SlaveBase(Fmi2Slave):
    """Base of every FMU slave of the package (see module docstring)."""

    VARIABLES: tuple[Variable, ...] = ()
    PRIVATE_STATE: tuple[str, ...] = ()
    DESCRIPTION = ""
    DEFAULT_EXPERIMENT = (0.0, 10.0, 0.01)

    author = "pounding co-simulation developers"
    license = "MIT"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = f"{self.DESCRIPTION}. {host_requirements_text()}"
        start, stop, step = self.DEFAULT_EXPERIMENT
        self.default_experiment = DefaultExperiment(start_time=start, stop_time=stop, step_size=step)
        self._error: str | None = None
        self._t_next: float | None = None   # s, where the next step must start (None: anywhere)
        # (variable, attribute, index) triples, resolved once: do_step runs thousands of times
        self._real_inputs: list[tuple[Variable, str, int | None]] = []
        self._checked: list[tuple[Variable, str, int | None]] = []
        arrays: dict[str, int] = {}
        for var in self.VARIABLES:
            if var.index is not None:
                arrays[var.attribute] = max(arrays.get(var.attribute, 0), var.index + 1)
        for attr, size in arrays.items():
            dtype = object if any(v.attribute == attr and v.type == "String" for v in self.VARIABLES) else float
            setattr(self, attr, np.zeros(size, dtype=dtype))
        for var in self.VARIABLES:
            self._register(var)
            slot = (var, var.attribute, var.index)
            if var.causality == "input" and var.type == "Real":
                self._real_inputs.append(slot)
            if var.causality == "parameter" and (var.low is not None or var.high is not None
                                                  or var.choices is not None or var.type == "Real"):
                self._checked.append(slot)

    # -- declaration ---------------------------------------------------------------------------
    def _register(self, var: Variable) -> None:
        cls = _TYPES[var.type]
        # Outputs are computed at fmi2ExitInitializationMode (from parameters and x0...), so
        # they are initial="calculated" and listed in InitialUnknowns (written in to_xml).
        output = var.causality == "output"
        initial = Fmi2Initial.calculated if output else None
        causality = getattr(Fmi2Causality, var.causality)
        variability = getattr(Fmi2Variability, var.resolved_variability)
        idx = var.index
        attr = var.attribute
        if idx is None:
            setattr(self, attr, var.start)
            getter = self._scalar_getter(attr)
            setter = None
        else:
            getattr(self, attr)[idx] = var.start
            getter = self._element_getter(attr, idx)
            setter = self._element_setter(attr, idx)
        self.register_variable(
            cls(var.name, causality=causality, variability=variability, initial=initial,
                description=self._describe(var), getter=getter, setter=setter,
                start=None if output else var.start),
            nested=False,
        )

    def _scalar_getter(self, attr: str) -> Callable[[], Any] | None:
        """Getter of a scalar variable; None = pythonfmu reads the attribute.  A subclass may
        return a function that computes an output when it is read."""
        return None

    def _element_getter(self, attr: str, idx: int) -> Callable[[], Any]:
        return lambda: getattr(self, attr)[idx]

    def _element_setter(self, attr: str, idx: int) -> Callable[[Any], None]:
        def set_element(value: Any) -> None:
            getattr(self, attr)[idx] = value
        return set_element

    @staticmethod
    def _describe(var: Variable) -> str:
        text = var.description
        if var.unit:
            text = f"{text} [{var.unit}]"
        if var.causality == "parameter" and (var.low is not None or var.high is not None or var.choices):
            text = f"{text}; allowed: {var.allowed_range()}"
        return text

    def to_xml(self, model_options: dict[str, str] = dict()) -> Element:
        """Model description with units, ranges, and calculated outputs listed as InitialUnknowns."""
        root = super().to_xml(model_options)
        by_name = {v.name: v for v in self.VARIABLES}
        units = sorted({v.unit for v in self.VARIABLES if v.unit and v.type == "Real"})
        if units:
            unit_defs = Element("UnitDefinitions")
            for unit in units:
                SubElement(unit_defs, "Unit", attrib={"name": unit})
            # FMI 2.0 orders UnitDefinitions before LogCategories/DefaultExperiment.
            position = [i for i, child in enumerate(root) if child.tag == "CoSimulation"][0] + 1
            root.insert(position, unit_defs)
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        if outputs is not None:
            initial_unknowns = SubElement(structure, "InitialUnknowns")
            for unknown in outputs:
                SubElement(initial_unknowns, "Unknown", attrib={"index": unknown.attrib["index"]})
        for scalar in root.iter("ScalarVariable"):
            var = by_name[scalar.attrib["name"]]
            typed = scalar[0]
            if var.type == "Real" and var.unit:
                typed.set("unit", var.unit)
            if var.type in ("Real", "Integer"):
                if var.low is not None and not var.low_open:
                    typed.set("min", f"{var.low:.16g}" if var.type == "Real" else str(int(var.low)))
                if var.high is not None and not var.high_open:
                    typed.set("max", f"{var.high:.16g}" if var.type == "Real" else str(int(var.high)))
        return root

    # -- hooks for subclasses ------------------------------------------------------------------
    def validate(self) -> Iterable[str]:
        """Cross-parameter checks; yield one message per problem."""
        return ()

    def initialize(self) -> None:
        """Prepare the internal state once parameters are valid."""

    def step(self, current_time: float, step_size: float) -> None:
        """Advance one communication step; raise SlaveError to refuse it."""
        raise NotImplementedError

    # -- FMI entry points ------------------------------------------------------------------------
    def exit_initialization_mode(self):
        problems = []
        for var, attr, idx in self._checked:
            value = getattr(self, attr) if idx is None else getattr(self, attr)[idx]
            msg = var.violation(value)
            if msg:
                problems.append(msg)
        if not problems:
            try:
                problems.extend(self.validate())
            except Exception as exc:  # a broken check must not kill the host
                problems.append(f"parameter check failed: {exc!r}")
        self._t_next = None
        if problems:
            self._fail(f"{self.instance_name}: invalid parameters: " + "; ".join(problems))
            return
        try:
            self.initialize()
        except SlaveError as exc:
            self._fail(f"{self.instance_name}: {exc}")
        except Exception as exc:
            self._fail(f"{self.instance_name}: initialisation failed: {exc!r}\n{traceback.format_exc(limit=3)}")

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self._error is not None:
            self.log(self._error, Fmi2Status.error)
            return False
        problem = self._step_problem(current_time, step_size)
        if problem is not None:   # refused before anything changes: a valid step may follow
            self.log(f"{self.instance_name}: {problem}", Fmi2Status.error)
            return False
        for var, attr, idx in self._real_inputs:
            value = getattr(self, attr) if idx is None else getattr(self, attr)[idx]
            if not math.isfinite(value):
                self.log(f"{self.instance_name}: input {var.name} = {value!r} is not finite "
                         f"at t = {current_time:.9g} s", Fmi2Status.error)
                return False
        try:
            self.step(current_time, step_size)
        except SlaveError as exc:
            self.log(f"{self.instance_name}: t = {current_time:.9g} s: {exc}", Fmi2Status.error)
            return False
        except Exception as exc:
            self.log(f"{self.instance_name}: t = {current_time:.9g} s: internal error {exc!r}\n"
                     f"{traceback.format_exc(limit=4)}", Fmi2Status.error)
            return False
        self._t_next = current_time + step_size
        return True

    def _step_problem(self, t: float, h: float) -> str | None:
        """Why a doStep(t, h) is refused, or None: the allowed step sizes and times."""
        if not math.isfinite(t):
            return f"communication point t = {t!r} s is not finite"
        floor = max(MIN_STEP, TIME_RESOLUTION * abs(t))
        if not (math.isfinite(h) and floor <= h <= MAX_STEP):
            return (f"communication step size h = {h!r} s at t = {t:.17g} s is outside the allowed range "
                    f"{floor:.3g} s <= h <= {MAX_STEP:g} s")
        if self._t_next is not None:
            # FMI 2.0: each step starts where the last ended, unless a saved state was restored
            # (fmi2SetFMUstate restores this too); round-off of the host's own time sums allowed
            slack = 1e-9 * h + 4.0 * TIME_RESOLUTION * max(abs(t), abs(self._t_next))
            if abs(t - self._t_next) > slack:
                went = "back in time" if t < self._t_next else "forward, skipping time"
                return (f"communication point t = {t:.17g} s: the last step ended at {self._t_next:.17g} s, so "
                        f"the host went {went} without restoring a saved FMU state (fmi2SetFMUstate); "
                        f"allowed: t = {self._t_next:.17g} s")
        return None

    def _fail(self, message: str) -> None:
        self._error = message
        self.log(message, Fmi2Status.error)

    # -- FMU state -------------------------------------------------------------------------------
    def _get_fmu_state(self) -> dict[str, Any]:
        state = {}
        for attr in {v.attribute for v in self.VARIABLES} | set(self.PRIVATE_STATE) | {"_error", "_t_next"}:
            state[attr] = copy.deepcopy(getattr(self, attr))
        return state

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        for attr, value in state.items():
            setattr(self, attr, copy.deepcopy(value))
