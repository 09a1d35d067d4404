"""The FMI layer: every call into an FMU goes through here.

One choke point (:meth:`Instance.call` and the fast paths built on the same
raw function table: :class:`RealPort`, :class:`IntegerPort`,
:meth:`Instance.do_step`) calls the FMI 2.0 C functions of an fmpy
``FMU2Slave``, checks the returned status in :meth:`Instance.check` and turns
a failure into a typed :class:`FMUError` that carries the messages the
instance logged through its own ``fmi2CallbackFunctions.logger``.

Two pythonfmu facts shape this module:

* pythonfmu forwards the slave's log messages only when the instance is
  created with ``loggingOn = fmi2True``; we always do, and keep the last
  messages of each instance in a bounded queue.
* pythonfmu 0.7 cannot return ``fmi2Error`` from
  ``fmi2ExitInitializationMode``: the package's slaves log the parameter
  problem with status ``fmi2Error`` and return ``fmi2OK``.  :meth:`Instance.call`
  therefore also fails a call during which the instance logged an error.

* pythonfmu 0.7 turns a Python exception in a slave's ``exit_initialization_mode`` or a setter
  into ``fmi2Fatal`` with the exception's repr logged ("Fatal py exception encountered:
  [exitInitializationMode] ...\\nSlaveError('left: invalid parameters: ...')"); the package's
  slaves refuse bad parameters that way, and :class:`FMUError` reports the slave's own line
  (:func:`slave_message`), not pythonfmu's wrapper.

Ctrl-C (:func:`deferred_interrupts`): pythonfmu slaves run Python code in this interpreter, so a
KeyboardInterrupt raised while a slave's code runs would escape it and become ``fmi2Fatal``
("Fatal py exception encountered: [getReal]").  While :func:`deferred_interrupts` is active,
SIGINT is held while an FMU's code runs and raised by the master right after the FMI call
returns (:func:`raise_pending_interrupt`), as a plain KeyboardInterrupt.

A corrupt or unreadable FMU file is :class:`FMULoadError`, naming the file.

Performance: fmpy's convenience methods (``getReal([...])``) allocate ctypes
arrays on every call.  The hot loop instead uses ports with value references
and a numpy buffer prepared once (``RealPort``), so one ``fmi2GetReal`` costs
one ctypes call.  Measured on pythonfmu slaves: about 2-4 us per get or set,
the slave's Python ``do_step`` dominating the rest.
"""
from __future__ import annotations

import ast
import atexit
import contextlib
import itertools
import os
import re
import shutil
import signal
import sys
import threading
import weakref
import zipfile
from collections import deque
from ctypes import CFUNCTYPE, POINTER, byref, c_char_p, c_double, c_int, c_size_t, c_uint, c_void_p, cast
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, NoReturn, Protocol, Sequence

import numpy as np
from fmpy import extract
from fmpy.fmi1 import calloc, free
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

from .interface import VariableInfo, read_interface

STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
#: the calls of every step (doStep and the ports' get/set), made through an unprototyped copy of
#: the function pointer with arguments already of their C types (:func:`_unchecked`)
HOT_CALLS = ("fmi2DoStep", "fmi2GetReal", "fmi2SetReal", "fmi2GetInteger", "fmi2SetInteger",
             "fmi2GetBoolean", "fmi2SetBoolean")
_STATUS_ONLY = CFUNCTYPE(c_int)
FMI2_OK, FMI2_WARNING, FMI2_DISCARD, FMI2_ERROR = 0, 1, 2, 3


def _dispatch_log(environment, instance_name, status, category, message) -> None:
    """The one logger of the process: routes a message to its :class:`Instance`.

    fmpy's native logger proxy (which formats the variadic C message) keeps a
    single Python logger for the whole process, so per-instance loggers would
    overwrite each other; each instance is told apart by the
    ``componentEnvironment`` pointer of its own callbacks struct instead.
    """
    instance = _LIVE.get(environment or 0)
    if instance is not None:
        instance._log(status, category, message)


# Process-wide by necessity (see _dispatch_log); entries vanish with their instance.
_LIVE: "weakref.WeakValueDictionary[int, Instance]" = weakref.WeakValueDictionary()
_IDS = itertools.count(1)
_LOGGER = fmi2CallbackLoggerTYPE(_dispatch_log)
_ALLOCATE = fmi2CallbackAllocateMemoryTYPE(calloc)
_FREE = fmi2CallbackFreeMemoryTYPE(free)


# Extracted FMUs, one folder per FMU file version, shared by every FMU object of
# the process and removed at exit.  pythonfmu imports each slave module once per
# interpreter (sys.modules), and the module keeps pointing at the folder it was
# first imported from: deleting that folder while the process lives would break
# every later instance of the same FMU.
_EXTRACTED: dict[tuple[str, int, int], Path] = {}
# Paths of the FMUs whose library has been loaded (never unloaded: see Instance.free).
_LOADED: set[str] = set()


def _extract_once(path: Path) -> Path:
    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    folder = _EXTRACTED.get(key)
    if folder is None or not folder.exists():
        folder = _EXTRACTED[key] = Path(extract(str(path)))
    return folder


@atexit.register
def _remove_extracted() -> None:
    for folder in _EXTRACTED.values():
        shutil.rmtree(folder, ignore_errors=True)


# -- Ctrl-C ----------------------------------------------------------------------------------------
#: SIGINTs held while an FMU's code ran (process-wide by nature: signals are); see deferred_interrupts
_PENDING_INTERRUPT = [0]
#: code that runs inside an FMU call: the FMUs' own packages (cosim.fmus.PACKAGE_PREFIX), pythonfmu's
#: slave base, the package's physics (when a slave runs in-process), and the log callback below
_FMU_CODE = ("pounding_cosim_", "pythonfmu", "fmu_src")


def _inside_fmu(frame) -> bool:
    """True if the Python stack ending in ``frame`` runs an FMU's code (called from its C side).

    Instantiation counts whole (:func:`_instantiate` on the stack): pythonfmu's fmi2Instantiate
    imports the slave's module from C, and the import machinery's frames (``importlib``) run
    before any of the module's own, so no FMU name is on the stack yet; a KeyboardInterrupt raised
    there became "Failed to instantiate model" instead of "interrupted")."""
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if name.startswith(_FMU_CODE) or frame.f_code in _FMU_CALL_CODES:
            return True
        frame = frame.f_back
    return False


def _instantiate(slave, callbacks) -> None:
    """fmpy's ``instantiate`` of ``slave``; a Ctrl-C during it is held (see :func:`_inside_fmu`)."""
    slave.instantiate(callbacks=callbacks, loggingOn=True)


#: frames of these functions mean an FMU's code runs beneath them (see _inside_fmu)
_FMU_CALL_CODES = frozenset({_dispatch_log.__code__, _instantiate.__code__})


def _on_sigint(signum, frame) -> None:
    if _inside_fmu(frame):
        _PENDING_INTERRUPT[0] += 1      # raised by the master when the FMI call returns
        return
    _PENDING_INTERRUPT[0] = 0
    raise KeyboardInterrupt


def raise_pending_interrupt() -> None:
    """Raise KeyboardInterrupt if a Ctrl-C arrived while an FMU's code ran (see
    :func:`deferred_interrupts`); called after FMI calls and before results are written."""
    if _PENDING_INTERRUPT[0]:
        _PENDING_INTERRUPT[0] = 0
        raise KeyboardInterrupt


@contextlib.contextmanager
def deferred_interrupts():
    """Within the block, Ctrl-C never interrupts an FMU's own code: it is held until the FMI call
    returns and then raised in the master as KeyboardInterrupt.  Only in the main thread (where
    Python delivers signals); elsewhere a no-op.  The command line wraps every command in it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
        raise_pending_interrupt()
    finally:
        signal.signal(signal.SIGINT, previous)
        _PENDING_INTERRUPT[0] = 0


def libraries_loaded() -> bool:
    """True once an FMU's shared library has been loaded into this process."""
    return bool(_LOADED)


def exit_process(code: int | None) -> NoReturn:
    """End a program that ran FMUs in this process, with exit status ``code``.

    When the interpreter has been finalised and the C runtime runs the shared libraries'
    destructors, with pythonfmu libraries still loaded, about one run in 25 aborts on a
    corrupted heap ("corrupted double-linked list", caught in libgfortran's exit-time
    close; PythonFMU issue #228 reports the same): a finished run then exits with 134.
    Callers have closed everything they wrote.  So once a library is loaded, the process
    flushes its output, removes the extracted FMUs and ends with ``os._exit``, skipping the
    finalisation; otherwise it exits normally.
    """
    if not _LOADED:
        raise SystemExit(code)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):   # closed or broken pipe: nothing left to save
            pass
    _remove_extracted()
    os._exit(0 if code is None else code if isinstance(code, int) else 1)   # as SystemExit reads it


#: how pythonfmu 0.7 begins the log line of a Python exception it turned into fmi2Fatal
PYTHONFMU_FATAL = "Fatal py exception encountered"


def slave_message(text: str) -> str:
    """The slave's own message in a log line: pythonfmu's fatal wrapper
    ("Fatal py exception encountered: [call] ...\\nSlaveError('msg')") unwrapped to ``msg``; any
    other text as it is."""
    if not text.startswith(PYTHONFMU_FATAL):
        return text
    for line in text.splitlines()[1:]:
        match = re.fullmatch(r"\s*\w+\((.*)\)\s*", line)
        if match:
            try:
                value = ast.literal_eval(match.group(1))
            except (ValueError, SyntaxError):
                continue
            if isinstance(value, str) and value:
                return value
    return text


class FMULoadError(RuntimeError):
    """An FMU file cannot be read (corrupt, not an FMU, not co-simulation); names the file."""


class FMUError(RuntimeError):
    """An FMI call failed.

    ``str(error)`` is one line: the instance name and the first message the
    instance logged (or the function and status if it logged nothing).
    ``messages`` holds every warning/error message the instance logged, in
    order; ``details`` joins them with the function and status.
    """

    def __init__(self, instance: str, function: str, status: int, messages: Sequence[str] = ()):
        self.instance = instance
        self.function = function
        self.status = status
        self.messages = list(messages)
        label = STATUS[status] if 0 <= status < len(STATUS) else f"illegal status {status}"
        # a slave's refusal reaches us inside pythonfmu's wrapper of its exception: unwrapped
        own = [slave_message(m) for m in self.messages if m.strip()]
        plain = [m for m in own if not m.startswith(PYTHONFMU_FATAL)]
        if plain:
            first = plain[-1].strip().splitlines()[0]
            # the slaves already prefix their messages with the instance name
            text = first if first.startswith(f"{instance}:") else f"{instance}: {first}"
        elif own:   # pythonfmu's wrapper of an exception it could not read: its last line
            text = f"{instance}: {function} returned fmi2{label}: {own[-1].strip().splitlines()[-1]}"
        else:
            text = f"{instance}: {function} returned fmi2{label}"
        super().__init__(text)

    @property
    def details(self) -> str:
        head = f"{self.instance}: {self.function} failed with status {self.status}"
        return "\n".join([head, *self.messages])


@dataclass(frozen=True)
class LogMessage:
    status: int
    category: str
    text: str


class PortProtocol(Protocol):
    """A fixed list of variables of one type, read or written as one vector (``values``)."""

    names: list[str]
    values: np.ndarray

    def get(self) -> np.ndarray: ...

    def set(self, values: Any = None) -> None: ...

    def get_first(self, count: int) -> np.ndarray: ...

    def set_first(self, count: int) -> None: ...


class InstanceProtocol(Protocol):
    """What the master asks of an FMU instance (:class:`Instance` is the real one; a fake with
    the same methods runs a system without FMUs).  Times in s; ``calls`` counts FMI calls,
    ``do_steps`` the doSteps."""

    name: str
    calls: int
    do_steps: int

    def setup(self, start_time: float = 0.0, stop_time: float | None = None) -> None: ...

    def set(self, values: Mapping[str, Any]) -> None: ...

    def exit_initialization(self) -> None: ...

    def do_step(self, t: float, h: float) -> None: ...

    def reset(self) -> None: ...

    def terminate(self) -> None: ...

    def free(self) -> None: ...

    def get_state(self) -> Any: ...

    def set_state(self, state: Any) -> None: ...

    def free_state(self, state: Any) -> None: ...

    def variable(self, name: str, causality: str | None = None) -> VariableInfo: ...

    def real_port(self, names: Sequence[str], buffer: np.ndarray | None = None) -> PortProtocol: ...

    def integer_port(self, names: Sequence[str], buffer: np.ndarray | None = None) -> PortProtocol: ...

    def boolean_port(self, names: Sequence[str], buffer: np.ndarray | None = None) -> PortProtocol: ...


class FMU:
    """One FMU file: interface read and archive extracted once.

    Create as many instances as needed with :meth:`instantiate`.  The
    extracted folder is shared by every ``FMU`` object of the same file in the
    process and removed at interpreter exit (see ``_EXTRACTED``); :meth:`close`
    only detaches this object.  ``interface`` (:class:`~cosim.master.interface.FmuInterface`)
    holds the variables, read from the modelDescription.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            self.interface = read_interface(self.path)
            self.unzip_dir: Path | None = _extract_once(self.path)
        except FileNotFoundError:
            raise
        except Exception as exc:   # BadZipFile, a missing modelDescription, bad XML, not co-simulation
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise FMULoadError(f"{self.path} is not a usable FMU ({type(exc).__name__}: {why}); rebuild it with "
                               f"`pounding-cosim build-fmus --force --out {self.path.parent}`") from None
        self.model_description = self.interface.model_description
        self.name = self.path.stem
        self.variables: dict[str, VariableInfo] = self.interface.variables

    def variable(self, name: str, causality: str | None = None) -> VariableInfo:
        """Look a variable up by name (and causality), with a helpful error."""
        return self.interface.variable(name, causality)

    def names(self, causality: str | None = None, type: str | None = None) -> list[str]:
        return self.interface.names(causality, type)

    def unknown_variable_message(self, name: str, causality: str | None = None) -> str:
        return self.interface.unknown_variable_message(name, causality)

    def instantiate(self, instance_name: str) -> "Instance":
        if self.unzip_dir is None:
            raise RuntimeError(f"{self.path} was closed")
        return Instance(self, instance_name)

    def close(self) -> None:
        self.unzip_dir = None

    def __enter__(self) -> "FMU":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Instance:
    """One co-simulation instance of an :class:`FMU`, behind one choke point.

    Life cycle: ``setup(t0, t_stop)`` (setupExperiment + enterInitializationMode),
    ``set(...)`` parameters, ``exit_initialization()``, then ``do_step`` and
    ports, ``reset()`` to go back to the instantiated state with start values,
    ``free()``.  Counters: ``do_steps`` (fmi2DoStep calls) and ``calls`` (every
    FMI call made through this object or its ports).
    """

    MAX_MESSAGES = 200

    def __init__(self, fmu: FMU, name: str):
        self.fmu = fmu
        self.name = name
        self.messages: deque[LogMessage] = deque(maxlen=self.MAX_MESSAGES)
        self.errors_logged = 0
        self.calls = 0
        self.do_steps = 0
        md = fmu.model_description
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = _LOGGER
        self._callbacks.allocateMemory = _ALLOCATE
        self._callbacks.freeMemory = _FREE
        self._id = next(_IDS)
        self._callbacks.componentEnvironment = self._id
        _LIVE[self._id] = self
        from fmpy.logging import addLoggerProxy  # formats the variadic C message for Python
        addLoggerProxy(byref(self._callbacks))
        self._slave = FMU2Slave(guid=md.guid, unzipDirectory=str(fmu.unzip_dir),
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        _LOADED.add(str(fmu.path))
        self.functions = self._slave._functions  # raw ctypes functions, status returned as int
        _instantiate(self._slave, self._callbacks)
        self.component = self._slave.component
        self.calls += 1
        #: the component as a C pointer, and the hot calls without argument conversion (_unchecked)
        self.c_component = c_void_p(self.component)
        self.unchecked = {name: _unchecked(self.functions[name]) for name in HOT_CALLS}
        self._do_step = self.unchecked["fmi2DoStep"]
        self._do_step_flag = c_int(1)
        self._freed = False
        if _PENDING_INTERRUPT[0]:   # a Ctrl-C held during instantiation: this instance is not handed out
            self.free()
            raise_pending_interrupt()

    # -- logging and status ------------------------------------------------------------------
    def _log(self, status, category, message) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        cat = category.decode("utf-8", "replace") if category else ""
        self.messages.append(LogMessage(int(status), cat, text))
        if status >= FMI2_ERROR:
            self.errors_logged += 1

    def problems(self, since: int = 0) -> list[str]:
        """Texts of the warning/error messages logged (the last ``since`` errors if > 0)."""
        texts = [m.text for m in self.messages if m.status >= FMI2_WARNING]
        return texts[-since:] if since > 0 else texts

    def check(self, function: str, status: int, errors_before: int | None = None) -> int:
        """Raise :class:`FMUError` if ``status`` is worse than Warning, or if the
        instance logged an error since ``errors_before``."""
        new_errors = 0 if errors_before is None else self.errors_logged - errors_before
        if status > FMI2_WARNING or new_errors > 0:
            messages = [m.text for m in self.messages if m.status >= FMI2_ERROR]
            if new_errors > 0:
                messages = messages[-new_errors:]
            elif not messages:
                messages = self.problems()
            raise FMUError(self.name, function, max(status, FMI2_ERROR if new_errors else status),
                           messages[-5:])
        return status

    def call(self, function: str, *args) -> int:
        """Call the FMI function ``function`` with ``args`` and check the outcome (a Ctrl-C held
        during the call is raised after it: :func:`deferred_interrupts`)."""
        before = self.errors_logged
        status = self.functions[function](*args)
        self.calls += 1
        if _PENDING_INTERRUPT[0]:
            raise_pending_interrupt()
        return self.check(function, status, before)

    # -- life cycle --------------------------------------------------------------------------
    def setup(self, start_time: float = 0.0, stop_time: float | None = None) -> None:
        self.call("fmi2SetupExperiment", self.component, 0, 0.0, float(start_time),
                  1 if stop_time is not None else 0, float(stop_time or 0.0))
        self.call("fmi2EnterInitializationMode", self.component)

    def exit_initialization(self) -> None:
        self.call("fmi2ExitInitializationMode", self.component)

    def do_step(self, t: float, h: float) -> None:
        status = self._do_step(self.c_component, c_double(t), c_double(h), self._do_step_flag)
        self.calls += 1
        self.do_steps += 1
        if _PENDING_INTERRUPT[0]:   # one list read per step; the ports' calls are checked here too
            raise_pending_interrupt()
        if status:
            self.check("fmi2DoStep", status)

    def reset(self) -> None:
        """fmi2Reset: back to the instantiated state, every variable at its start value."""
        self.call("fmi2Reset", self.component)

    def terminate(self) -> None:
        self.call("fmi2Terminate", self.component)

    def free(self) -> None:
        """fmi2FreeInstance.  The shared library stays loaded on purpose: a pythonfmu
        library runs inside this interpreter, and unloading it while Python objects
        it created may still be alive can corrupt the heap (cf. FMPy issue #147,
        PythonFMU issue #228); every later instance of the FMU reuses it anyway."""
        if not self._freed:
            self._freed = True
            self._slave.fmi2FreeInstance(self.component)
            _LIVE.pop(self._id, None)

    # -- FMU state (for rollback) ---------------------------------------------------------------
    def get_state(self):
        from fmpy.fmi2 import fmi2FMUstate

        state = fmi2FMUstate()
        self.call("fmi2GetFMUstate", self.component, byref(state))
        return state

    def set_state(self, state) -> None:
        if not state:
            raise FMUError(self.name, "fmi2SetFMUstate", FMI2_ERROR, [f"{self.name}: the FMU state was freed"])
        self.call("fmi2SetFMUstate", self.component, state)

    def free_state(self, state) -> None:
        """fmi2FreeFMUstate, once: the handle is cleared afterwards (pythonfmu 0.7 does not clear it,
        and a second free of the same state would release the state's Python object twice)."""
        if not state:
            return
        self.call("fmi2FreeFMUstate", self.component, byref(state))
        state.value = None

    # -- variables -----------------------------------------------------------------------------
    def variable(self, name: str, causality: str | None = None) -> VariableInfo:
        return self.fmu.variable(name, causality)

    def set(self, values: Mapping[str, Any]) -> None:
        """Set variables by name, each with the setter of its declared type."""
        for name, value in values.items():
            info = self.variable(name)
            vr = (c_uint * 1)(info.value_reference)
            if info.type == "Real":
                self.call("fmi2SetReal", self.component, vr, 1, (c_double * 1)(float(value)))
            elif info.type in ("Integer", "Enumeration"):
                if isinstance(value, bool) or float(value) != int(value):
                    raise TypeError(f"{self.name}.{name} is an Integer, got {value!r}")
                self.call("fmi2SetInteger", self.component, vr, 1, (c_int * 1)(int(value)))
            elif info.type == "Boolean":
                if not isinstance(value, (bool, np.bool_)):
                    raise TypeError(f"{self.name}.{name} is a Boolean, got {value!r}")
                self.call("fmi2SetBoolean", self.component, vr, 1, (c_int * 1)(int(bool(value))))
            elif info.type == "String":
                if not isinstance(value, str):
                    raise TypeError(f"{self.name}.{name} is a String, got {value!r}")
                self.call("fmi2SetString", self.component, vr, 1, (c_char_p * 1)(value.encode("utf-8")))
            else:  # pragma: no cover - the package's FMUs have no other types
                raise TypeError(f"{self.name}.{name}: unsupported type {info.type}")

    def get(self, names: Iterable[str]) -> dict[str, Any]:
        """Get variables by name, each with the getter of its declared type."""
        out = {}
        for name in names:
            info = self.variable(name)
            vr = (c_uint * 1)(info.value_reference)
            if info.type == "Real":
                value = (c_double * 1)()
                self.call("fmi2GetReal", self.component, vr, 1, value)
                out[name] = value[0]
            elif info.type in ("Integer", "Enumeration", "Boolean"):
                value = (c_int * 1)()
                self.call("fmi2Get" + ("Boolean" if info.type == "Boolean" else "Integer"),
                          self.component, vr, 1, value)
                out[name] = bool(value[0]) if info.type == "Boolean" else int(value[0])
            elif info.type == "String":
                value = (c_char_p * 1)()
                self.call("fmi2GetString", self.component, vr, 1, value)
                out[name] = (value[0] or b"").decode("utf-8")
        return out

    def real_port(self, names: Sequence[str], buffer: np.ndarray | None = None) -> "RealPort":
        return RealPort(self, names, buffer)

    def integer_port(self, names: Sequence[str], buffer: np.ndarray | None = None) -> "IntegerPort":
        return IntegerPort(self, names, buffer)

    def boolean_port(self, names: Sequence[str], buffer: np.ndarray | None = None) -> "BooleanPort":
        return BooleanPort(self, names, buffer)

    def __repr__(self) -> str:
        return f"Instance({self.name!r} of {self.fmu.path.name})"


class _Port:
    """A fixed list of variables of one type read or written as one vector.

    ``values`` is a numpy array (possibly a view into a larger array owned by
    the caller) that ``get`` fills and ``set`` sends, without allocation.
    """

    _ctype: Any = c_double
    _dtype: Any = np.float64
    _type = "Real"

    def __init__(self, instance: Instance, names: Sequence[str], buffer: np.ndarray | None = None):
        self.instance = instance
        self.names = list(names)
        infos = [instance.variable(n) for n in self.names]
        wrong = [i.name for i in infos if i.type != self._type]
        if wrong:
            raise TypeError(f"{instance.name}: {wrong} are not {self._type} variables")
        n = len(self.names)
        if buffer is None:
            buffer = np.zeros(n, dtype=self._dtype)
        if buffer.shape != (n,) or buffer.dtype != self._dtype or not buffer.flags.c_contiguous:
            raise ValueError(f"port buffer must be a contiguous {self._dtype.__name__} vector of {n}")
        self.values = buffer
        self._n = n
        self._vr = (c_uint * n)(*[i.value_reference for i in infos])
        self._ptr = buffer.ctypes.data_as(POINTER(self._ctype))
        # every argument of its C type once (the calls take no conversion: _unchecked)
        self._get = instance.unchecked[f"fmi2Get{self._type}"]
        self._set = instance.unchecked[f"fmi2Set{self._type}"]
        self._component = instance.c_component
        self._counts = [c_size_t(k) for k in range(n + 1)]
        self._count = self._counts[n]

    def get(self) -> np.ndarray:
        if self._n:
            status = self._get(self._component, self._vr, self._count, self._ptr)
            self.instance.calls += 1
            if status:
                self.instance.check(f"fmi2Get{self._type}", status)
        return self.values

    def set(self, values: Any = None) -> None:
        if values is not None:
            self.values[:] = values
        if self._n:
            status = self._set(self._component, self._vr, self._count, self._ptr)
            self.instance.calls += 1
            if status:
                self.instance.check(f"fmi2Set{self._type}", status)

    def get_first(self, count: int) -> np.ndarray:
        """fmi2Get of the first ``count`` variables only (one call), into ``values[:count]``."""
        if count:
            status = self._get(self._component, self._vr, self._counts[count], self._ptr)
            self.instance.calls += 1
            if status:
                self.instance.check(f"fmi2Get{self._type}", status)
        return self.values[:count]

    def set_first(self, count: int) -> None:
        """fmi2Set of the first ``count`` variables only (one call), from ``values[:count]``."""
        if count:
            status = self._set(self._component, self._vr, self._counts[count], self._ptr)
            self.instance.calls += 1
            if status:
                self.instance.check(f"fmi2Set{self._type}", status)


def _unchecked(function: Any) -> Any:
    """``function`` (a ctypes function with ``argtypes``) called without them: the same address
    as a prototype that converts nothing, to be given arguments already of the C types its
    ``argtypes`` name (a ``c_void_p`` component, ``c_size_t`` counts, ``c_double`` times, arrays and
    pointers as they are).  ctypes' per-argument conversion cost ~0.4 us of a ~2 us
    fmi2GetReal through pythonfmu (measured, 14 values); the ports and doStep make
    thousands of calls per run.  Returns the status as an int."""
    return _STATUS_ONLY(cast(function, c_void_p).value)


class RealPort(_Port):
    pass


class IntegerPort(_Port):
    _ctype = c_int
    _dtype = np.int32
    _type = "Integer"


class BooleanPort(IntegerPort):
    """fmi2Boolean is a C int: 0 or 1 in an int32 buffer."""

    _type = "Boolean"
