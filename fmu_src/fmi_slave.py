"""Thin FMI 2.0 co-simulation adapter shared by every FMU of the package.

A slave declares its variables once, as data (a tuple of :class:`Variable`),
and implements two hooks: :meth:`SlaveBase.initialize` (after the parameters
are checked) and :meth:`SlaveBase.step` (one communication step).  This base
class does the FMI bookkeeping that pythonfmu leaves to the author:

* parameter checks, declared as data: the ranges of each :class:`Variable` (``low``/``high``,
  ``choices``) and the cross-parameter rules of :meth:`SlaveBase.validate`, run at
  ``fmi2ExitInitializationMode`` (the earliest point FMI allows);
* refusals the host sees (pythonfmu 0.7 can only return ``fmi2OK``, ``fmi2Discard`` (``do_step``
  returning ``False``) or ``fmi2Fatal`` (a Python exception escaping); ``fmi2Error`` is not
  reachable from Python):

  - bad parameters at ``fmi2ExitInitializationMode``, a parameter set after initialisation, a
    state freed twice or used after it was freed: the call raises, which pythonfmu returns as
    ``fmi2Fatal`` and logs, with status ``fmi2Fatal``, as "Fatal py exception encountered:
    [<call>] ..." followed by ``SlaveError('<one line naming the variable, value and allowed
    range>')``.  The instance may still be freed or reset (:meth:`SlaveBase._refuse` keeps
    pythonfmu's reference counts straight);
  - a step the model cannot take (a non-finite input, a bad step size, a state that would not
    be finite): ``fmi2Discard`` with the message logged as ``fmi2Error``, nothing changed;
    the instance stays alive so the host can read the message;
  - an instance refused at initialisation refuses every step with the same message;

* FMU state (``fmi2GetFMUstate``/``fmi2SetFMUstate``) includes the private
  attributes listed in ``PRIVATE_STATE``, copied (:func:`snapshot`), so that a restored
  instance continues exactly as the saved one.  A state freed twice by the host, or used
  after it was freed, is refused at the next state call instead of corrupting the process
  (:class:`_SavedStates`);
* the modelDescription gets units, ``UnitDefinitions``, min/max, and every output is
  ``initial="calculated"`` (computed when initialisation ends) and listed in
  ``ModelStructure/InitialUnknowns``, which pythonfmu alone leaves out; its description
  states what the host's Python must provide (:data:`HOST_REQUIREMENTS`).

Nothing here is mutable at module or class level: every FMU of a process
shares one Python interpreter.
"""
from __future__ import annotations

import copy
import ctypes
import functools
import math
import operator
import sys
import traceback
from dataclasses import dataclass, field
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
#: value-reference lists whose fmi2GetReal/fmi2SetReal plan an instance remembers (a master
#: uses a handful, the same every step); beyond that the plans are dropped and rebuilt
MAX_ACCESS_PLANS = 64


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

    # the attribute and 0-based index of the name, parsed once (every instantiation of an FMU
    # reads them a few times per variable: 4000 parses for building.fmu's 464 variables)
    attribute: str = field(init=False, repr=False, compare=False)
    index: int | None = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        attribute, bracket, rest = self.name.partition("[")
        object.__setattr__(self, "attribute", attribute)
        object.__setattr__(self, "index", int(rest.rstrip("]")) - 1 if bracket else None)

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


#: values an FMU state keeps as they are: nothing can change them in place
_IMMUTABLE = (float, int, str, bytes, frozenset, type(None), np.generic)


def snapshot(value: Any) -> Any:
    """A copy of one attribute for an FMU state, as independent of the live one as a deep copy.

    Immutable values are kept, a numeric numpy array is copied, an object with a ``snapshot()``
    method gives its own copy (a slave's state object that knows which of its parts can change,
    e.g. :class:`fmu_src.building_response.BuildingState`), anything else is deep-copied.  A
    deep copy of every attribute cost 0.4-0.7 ms per fmi2GetFMUstate of building.fmu (most of
    it ``copy.deepcopy`` walking the list of deferred peak searches), which a master that saves
    states for rollback paid hundreds of times per run.
    """
    if isinstance(value, _IMMUTABLE):
        return value
    if type(value) is np.ndarray and value.dtype != object:
        return value.copy()
    own = getattr(value, "snapshot", None)
    if own is not None:
        return own()
    return copy.deepcopy(value)


@dataclass(frozen=True)
class _AccessPlan:
    """How one fmi2GetReal/fmi2SetReal value-reference list is served (:meth:`SlaveBase.get_real`).

    ``arrays``: per array, ``(reader or attribute name, element selector, position selector)``
    (a selector is a slice where the numbers form an arithmetic progression, else a list);
    ``scalars``: runs of plain scalar attributes, ``(attrgetter, slice of positions)``;
    ``single``: ``(getter or setter, position)`` of every other variable.
    """

    arrays: tuple
    scalars: tuple
    single: tuple


def _selector(numbers: list[int]) -> slice | list[int]:
    """A slice selecting ``numbers`` (ascending, evenly spaced), or the list itself."""
    if len(numbers) == 1:
        return slice(numbers[0], numbers[0] + 1)
    step = numbers[1] - numbers[0]
    if step > 0 and all(b - a == step for a, b in zip(numbers, numbers[1:])):
        return slice(numbers[0], numbers[-1] + 1, step)
    return list(numbers)


def _attrgetter(names: list[str]) -> Callable[[Any], tuple]:
    """``operator.attrgetter`` of the names, returning a tuple even for one."""
    if len(names) > 1:
        return operator.attrgetter(*names)
    get = operator.attrgetter(names[0])
    return lambda obj: (get(obj),)


class SlaveError(Exception):
    """An error that a slave reports through FMI status and the log."""


class _SavedState(dict):
    """One saved FMU state (the attributes, copied by :func:`snapshot`): a dict, as pythonfmu expects."""

    __slots__ = ("__weakref__",)


class _SavedStates:
    """The FMU states an instance handed out, kept so that a host's mistakes are refused.

    pythonfmu 0.7's ``fmi2FreeFMUstate`` releases the state's Python object (``Py_XDECREF``)
    without calling Python and without clearing the host's handle: a state freed twice would
    release an object already gone (heap corruption), and a state used after it was freed would
    read freed memory.  So each state handed out carries one extra reference held here
    (``Py_IncRef``), besides the list entry: the object outlives the host's frees, and its
    reference count says how many the host made.  At every state call (:meth:`check`) a state
    the host freed once is let go; one freed twice is let go too (its count repaired) and the
    call is refused, naming the mistake.  ``fmi2SetFMUstate`` with a freed state is refused
    the same way.
    """

    def __init__(self):
        self.states: list[_SavedState] = []

    def add(self, state: _SavedState) -> _SavedState:
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(state))
        self.states.append(state)
        return state

    def holds(self, state: Any) -> bool:
        """True if ``state`` is a state of this instance that the host has not freed (after :meth:`check`)."""
        return any(s is state for s in self.states)

    def check(self, passed: Any = None) -> str | None:
        """Let go of the states the host freed; a message if one was freed more than once.
        ``passed``: the state the current FMI call passes in (fmi2SetFMUstate), which the call
        itself references three times more (pythonfmu's argument tuple, the call's arguments and
        the method's parameter; measured on CPython 3.11, and tested: a live state is accepted,
        a freed one refused)."""
        problem = None
        keep = []
        for state in self.states:
            # references besides the host's: the list entry, the extra one, the loop variable and
            # getrefcount's argument (CPython, which pythonfmu embeds)
            host = sys.getrefcount(state) - 4 - (3 if state is passed else 0)
            if host >= 1:
                keep.append(state)
                continue
            if host < 0:   # freed twice: give back what the second free took, then let go
                for _ in range(-host):
                    ctypes.pythonapi.Py_IncRef(ctypes.py_object(state))
                problem = "the host freed an FMU state twice (fmi2FreeFMUstate); a state may be freed only once"
            ctypes.pythonapi.Py_DecRef(ctypes.py_object(state))   # the extra reference
        self.states = keep
        return problem


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
        self._initialized = False            # True after fmi2ExitInitializationMode succeeded
        self._saved = _SavedStates()
        # what an FMU state holds (one tuple: fmi2GetFMUstate must not rebuild it each call)
        names = [v.attribute for v in self.VARIABLES] + list(self.PRIVATE_STATE) + ["_error", "_t_next"]
        self._state_attributes = tuple(dict.fromkeys(names))
        # pythonfmu looks _set_fmu_state up on the instance: the checks run first (see there)
        self._set_fmu_state = self._checked_set_state
        # (variable, attribute, index) triples, resolved once: do_step runs thousands of times
        self._real_inputs: list[tuple[Variable, str, int | None]] = []
        self._real_outputs: list[tuple[Variable, str, int | None]] = []
        self._checked: list[tuple[Variable, str, int | None]] = []
        arrays: dict[str, int] = {}
        strings: set[str] = set()           # arrays with String elements (one pass, not one per array)
        for var in self.VARIABLES:
            if var.index is not None:
                arrays[var.attribute] = max(arrays.get(var.attribute, 0), var.index + 1)
                if var.type == "String":
                    strings.add(var.attribute)
        for attr, size in arrays.items():
            setattr(self, attr, np.zeros(size, dtype=object if attr in strings else float))
        for var in self.VARIABLES:
            self._register(var)
            slot = (var, var.attribute, var.index)
            if var.causality == "input" and var.type == "Real":
                self._real_inputs.append(slot)
            if var.causality == "output" and var.type == "Real":
                self._real_outputs.append(slot)
            if var.causality == "parameter" and (var.low is not None or var.high is not None
                                                  or var.choices is not None or var.type == "Real"):
                self._checked.append(slot)
        # the scalar Real outputs in one C call, the arrays whole (a Python loop over the outputs
        # cost 3.5 us per step on pounding.fmu, a third of its doStep)
        scalars = [a for _, a, i in self._real_outputs if i is None]
        self._scalar_outputs = operator.attrgetter(*scalars) if len(scalars) > 1 else None
        self._array_outputs = sorted({a for _, a, i in self._real_outputs if i is not None})
        self._declared = {v.name: v for v in self.VARIABLES}
        self._read_plans: dict[tuple[int, ...], list] = {}
        self._write_plans: dict[tuple[int, ...], list] = {}

    # -- fmi2GetReal / fmi2SetReal: one plan per value-reference list -----------------------------
    # pythonfmu calls one getter or setter per value (about 0.5 us each: a dict look-up, a type
    # test, a lambda, getattr, a numpy scalar); a master reads and writes the same lists at every
    # step (building.fmu: 12-62 outputs; 33 knot times and values, interleaved).  So each list is
    # turned once into a plan (:class:`_AccessPlan`): the elements of one array are read or
    # written together, through a slice where they form one (the interleaved knots: two strided
    # slices); consecutive plain scalars are read by one attrgetter; any variable whose access a
    # subclass customises keeps its own getter or setter.  The values are the doubles pythonfmu's
    # path gives (tests/test_access_plans.py).
    def get_real(self, vrs):
        key = tuple(vrs)
        plan = self._read_plans.get(key)
        if plan is None:
            plan = self._access_plan(key, write=False)
            if plan is None:
                return super().get_real(vrs)     # not every one a Real: pythonfmu's TypeError
        out = [0.0] * len(key)
        for read, index, where in plan.arrays:
            values = read()[index].tolist()
            if type(where) is slice:
                out[where] = values
            else:
                for position, value in zip(where, values):
                    out[position] = value
        for getter, where in plan.scalars:
            out[where] = map(float, getter(self))
        for getter, position in plan.single:
            out[position] = float(getter())
        return out

    def set_real(self, vrs, values):
        key = tuple(vrs)
        plan = self._write_plans.get(key)
        if plan is None:
            plan = self._access_plan(key, write=True)
            if plan is None:
                return super().set_real(vrs, values)
        for setter, position in plan.single:
            setter(values[position])
        for attr, index, where in plan.arrays:
            getattr(self, attr)[index] = values[where] if type(where) is slice else [values[p] for p in where]
        return None

    def _access_plan(self, key: tuple[int, ...], write: bool) -> "_AccessPlan | None":
        """The plan of ``key`` (see above), remembered; None to leave the call to pythonfmu (a value
        reference that is not a Real, one without a setter, or one given twice in a write)."""
        if write and len(set(key)) < len(key):
            return None                    # pythonfmu's order decides which value stays
        arrays: dict[str, tuple[Any, list[int], list[int]]] = {}
        scalars: list[list] = []           # runs of consecutive plain scalars: [names, first, stop]
        single: list[tuple[Callable, int]] = []
        for position, vr in enumerate(key):
            var = self.vars.get(vr)
            if not isinstance(var, Real):
                return None
            decl = self._declared.get(var.name)
            attr, idx = (decl.attribute, decl.index) if decl is not None else (None, None)
            access = None
            if idx is not None:
                if write:
                    access = attr if decl.causality == "input" and self._plain_element_setter(attr) else None
                else:
                    access = self._array_reader(attr)
            if access is not None:
                group = arrays.setdefault(attr, (access, [], []))
                group[1].append(idx)
                group[2].append(position)
            elif write:
                if var.setter is None:
                    return None            # pythonfmu's own error for a variable without a setter
                single.append((var.setter, position))
            elif attr is not None and idx is None and self._scalar_getter(attr) is None:
                if scalars and scalars[-1][2] == position:
                    scalars[-1][0].append(attr)
                    scalars[-1][2] = position + 1
                else:
                    scalars.append([[attr], position, position + 1])
            else:
                single.append((var.getter, position))
        plan = _AccessPlan(
            arrays=tuple((access, _selector(index), _selector(where)) for access, index, where in arrays.values()),
            scalars=tuple((_attrgetter(names), slice(first, stop)) for names, first, stop in scalars),
            single=tuple(single))
        plans = self._write_plans if write else self._read_plans
        if len(plans) >= MAX_ACCESS_PLANS:
            plans.clear()
        plans[key] = plan
        return plan

    def _array_reader(self, attr: str) -> Callable[[], np.ndarray] | None:
        """A function giving the array ``attr`` whole, each element as its getter gives it (for
        :meth:`get_real`), or None to call the element getters one by one.  A subclass that
        overrides :meth:`_element_getter` overrides this too (until then: element by element)."""
        if type(self)._element_getter is not SlaveBase._element_getter:
            return None
        return functools.partial(getattr, self, attr)

    def _plain_element_setter(self, attr: str) -> bool:
        """True if setting an element of the input array ``attr`` only stores the value."""
        return type(self)._element_setter is SlaveBase._element_setter

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
        if var.causality == "parameter":
            setter = self._parameter_setter(var, setter)
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

    def _parameter_setter(self, var: Variable, setter: Callable[[Any], None] | None) -> Callable[[Any], None]:
        """The setter of a parameter: refused once the instance is initialised (every parameter is
        ``fixed``: FMI 2.0 allows setting it only before fmi2ExitInitializationMode)."""
        attr = var.attribute
        set_value = setter or (lambda value: setattr(self, attr, value))

        def set_parameter(value: Any) -> None:
            if self._initialized:
                self._refuse(f"{self.instance_name}: {var.name} is a fixed parameter: it cannot change after "
                             f"initialisation (fmi2ExitInitializationMode); the value {value!r} was not applied "
                             f"(set it before, or fmi2Reset the instance)", disable=False)
            set_value(value)
        return set_parameter

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

    def _outputs_problem(self) -> str | None:
        """Why the outputs cannot be trusted (one is not finite), or None.  Run after every step
        and at the end of initialisation; a subclass that checks its new state before committing
        it (and so can refuse a step with nothing changed) may replace it with a cheaper check."""
        # the fast path: a sum is finite if every term is (a finite sum that overflows only sends
        # it to the exact check below)
        total = sum(self._scalar_outputs(self)) if self._scalar_outputs is not None else 0.0
        for attr in self._array_outputs:
            total += float(np.sum(getattr(self, attr)))
        if math.isfinite(total):
            return None
        for var, attr, idx in self._real_outputs:
            value = getattr(self, attr) if idx is None else getattr(self, attr)[idx]
            if not math.isfinite(value):
                return f"output {var.name} = {float(value)!r} is not finite"
        return None

    def _step_outputs_problem(self) -> str | None:
        """:meth:`_outputs_problem` after a step (a subclass that refuses a non-finite state
        before committing it returns None here)."""
        return self._outputs_problem()

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
            self._refuse(f"{self.instance_name}: invalid parameters: " + "; ".join(problems))
        try:
            self.initialize()
        except SlaveError as exc:
            self._refuse(f"{self.instance_name}: {exc}")
        except Exception as exc:
            self._refuse(f"{self.instance_name}: initialisation failed: {exc!r}\n{traceback.format_exc(limit=3)}")
        problem = self._outputs_problem()
        if problem:
            self._refuse(f"{self.instance_name}: after initialisation {problem}: the parameters are beyond what "
                         f"the model's arithmetic supports")
        self._initialized = True

    def _refuse(self, message: str, disable: bool = True) -> None:
        """Refuse the current FMI call with ``message``: raise, which pythonfmu 0.7 returns as
        fmi2Fatal (the only failure status a Python exception can give there) and logs, with
        status fmi2Fatal, as "Fatal py exception encountered: [<call>] ...\\nSlaveError('<message>')".
        ``disable``: the instance also refuses every later step with the message.

        The message travels in the exception, not as a log message of its own: pythonfmu reads
        the exception only after it has forwarded the queued log messages, and forwarding them
        loses the exception (it then logs "unknown error"), which is all libcosim shows.  So any
        message still queued is folded into this one and the queue emptied.

        pythonfmu 0.7 (PySlaveInstance.cpp, ``handle_py_exception``) releases its references to
        this instance, its class and its log queue when an exception escapes, and releases them
        again when the host frees or resets the instance (``cleanPyObject``, ``initialize``):
        without one more reference to each, freeing the refused instance would free objects
        twice and corrupt the heap.  Each refusal therefore hands one of each back.
        """
        queued = [getattr(m, "msg", "") for m in self.log_queue]
        self.log_queue.clear()
        if queued:
            message = f"{message} (logged before: {'; '.join(str(q) for q in queued)})"
        if disable:
            self._error = message
        for obj in (self, type(self), self.log_queue):
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
        raise SlaveError(message)

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
        problem = self._step_outputs_problem()
        if problem:   # the state has changed and is not usable: every later step is refused too
            self._error = (f"{self.instance_name}: t = {current_time:.9g} s: the step of h = {step_size!r} s left "
                           f"{problem}: the model cannot take this step (restore a saved state, or reset)")
            self.log(self._error, Fmi2Status.error)
            return False
        self._t_next = current_time + step_size
        return True

    def _step_problem(self, t: float, h: float) -> str | None:
        """Why a doStep(t, h) is refused, or None: the allowed step sizes and times."""
        # the usual step first: where the last one ended (so t is finite) and h within every
        # bound below (comparisons with NaN fail); the same verdict as the full checks, cheaper
        if t == self._t_next and MIN_STEP <= h <= MAX_STEP and h >= TIME_RESOLUTION * (t if t >= 0.0 else -t):
            return None
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

    # -- FMU state -------------------------------------------------------------------------------
    def _get_fmu_state(self) -> dict[str, Any]:
        problem = self._saved.check()
        if problem:
            self._refuse(f"{self.instance_name}: {problem}", disable=False)
        state = _SavedState()
        for attr in self._state_attributes:
            state[attr] = snapshot(getattr(self, attr))
        return self._saved.add(state)

    def _checked_set_state(self, state: dict[str, Any]) -> None:
        """What pythonfmu calls for fmi2SetFMUstate (an instance attribute named ``_set_fmu_state``,
        set in ``__init__``, so that the call always reaches this frame first, at the depth
        :meth:`_SavedStates.check` counts with, whatever a subclass overrides): refuse a state
        freed or foreign, then restore it (:meth:`_set_fmu_state`)."""
        problem = self._saved.check(passed=state)
        if problem:
            self._refuse(f"{self.instance_name}: {problem}", disable=False)
        if not self._saved.holds(state):
            self._refuse(f"{self.instance_name}: fmi2SetFMUstate with a state that was freed (fmi2FreeFMUstate) "
                         f"or was not saved by this instance", disable=False)
        type(self)._set_fmu_state(self, state)

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        """Restore a saved state (a subclass may extend it; the checks are in :meth:`_checked_set_state`)."""
        for attr, value in state.items():
            setattr(self, attr, snapshot(value))
