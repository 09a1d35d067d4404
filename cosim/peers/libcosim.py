"""Run our FMUs in libcosim (Open Simulation Platform), an independent FMI master.

libcosim [OSP, https://open-simulation-platform.github.io/libcosim] is a C++
co-simulation library; libcosimpy wraps its C API (libcosimc) with ctypes and loads
FMUs through FMI Library.  This module drives it for two cases:

* :func:`run_system`: a :class:`cosim.peers.ssp.System` (components, start values,
  connections) built from a scene, added slave by slave through the C API;
* :func:`run_ssp`: an ``.ssp`` package, loaded by libcosim's own SSP parser.

How libcosim couples (``fixed_step_algorithm``, libcosim 0.11):

* time is integer nanoseconds; the base step must be a whole number of ns;
* initialisation: parameter/start values are set before ``fmi2EnterInitializationMode``,
  then N rounds of "set inputs, get outputs, transfer" in initialisation mode
  (N = number of slaves), then ``fmi2ExitInitializationMode``, outputs read and
  transferred once more.  So the first step of every slave already sees the other
  slaves' initial outputs (e.g. a building's ``x0``);
* each step: every slave steps over [t, t+h] (in parallel threads) from the inputs it
  holds, then all outputs are read and transferred to the connected inputs.  That is
  Jacobi coupling: no slave sees another's output of the same step.  The ground
  FMU's ``ag_mean`` over [t-h, t] therefore drives the buildings over [t, t+h]
  (one step late), and the contact force of [t-h, t] acts on the buildings over
  [t, t+h];
* ``from_step_size`` executions start at t = 0.

pythonfmu FMUs call into a Python interpreter.  In a Python process the
interpreter is already there; :func:`ensure_python_symbols` makes sure the
libpython symbols are global (needed when Python itself was linked statically to
an embedding host, harmless otherwise).
"""
from __future__ import annotations

import ctypes
import sysconfig
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..master.fmi import PYTHONFMU_FATAL, slave_message
from .ssp import OSP_NS, SSC_NS, SSD_NAME, SSD_NS, System, build_ssd, check_system

NS_PER_S = 1_000_000_000


class LibcosimError(RuntimeError):
    """libcosim refused a call or a step; the message carries libcosim's own error text."""


@dataclass
class LibcosimResult:
    """Time series observed in a libcosim run.

    ``time`` (s) holds the communication points after each step, t_1 .. t_N;
    ``values["component.variable"]`` the observed values at those points.
    """

    time: np.ndarray
    values: dict[str, np.ndarray]
    steps: int
    step_size: float
    wall_time_s: float
    libcosim_version: str
    algorithm: str = "fixed_step_algorithm (Jacobi: all slaves step from the outputs of the previous step)"
    loaded_from: str = "C API"

    def __getitem__(self, key: str) -> np.ndarray:
        return self.values[key]


_PRELOADED: list[ctypes.CDLL] = []  # keeps the handle alive; filled at most once per process


def ensure_python_symbols() -> str | None:
    """Load the running interpreter's libpython with RTLD_GLOBAL; return its path (None if static).

    pythonfmu's binary resolves ``Py*`` symbols from the process.  A Python built with
    ``--enable-shared`` already exposes them; loading the same library again is a no-op
    besides promoting it to global scope.
    """
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    name = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY")
    libdir = Path(sysconfig.get_config_var("LIBDIR") or "")
    candidate = libdir / name
    target = str(candidate) if candidate.exists() else name
    if not _PRELOADED:
        _PRELOADED.append(ctypes.CDLL(target, mode=ctypes.RTLD_GLOBAL))
    return target


def libcosim_version() -> str:
    from libcosimpy._internal import libcosimc

    class _Version(ctypes.Structure):
        _fields_ = [("major", ctypes.c_int), ("minor", ctypes.c_int), ("patch", ctypes.c_int)]

    fn = libcosimc().cosim_libcosim_version
    fn.restype = _Version
    v = fn()
    return f"{v.major}.{v.minor}.{v.patch}"


def _last_error() -> str:
    from libcosimpy._internal import get_last_error_message

    try:
        return get_last_error_message()
    except Exception:  # pragma: no cover - message itself unavailable
        return "(no message from libcosim)"


def _to_ns(seconds: float, what: str) -> int:
    ns = round(seconds * NS_PER_S)
    if ns <= 0 or abs(ns - seconds * NS_PER_S) > 1e-6 * max(1.0, abs(seconds * NS_PER_S)):
        raise ValueError(f"{what} = {seconds!r} s is not a positive whole number of nanoseconds "
                         f"(libcosim counts time in integer ns)")
    return ns


def _set_log_level(level: str) -> None:
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel[level.upper()])


class _Session:
    """An execution plus the name -> (slave index, value reference, type) lookup."""

    def __init__(self, execution, slaves: dict[str, int], keep: list):
        from libcosimpy.CosimEnums import CosimVariableType

        self.execution = execution
        self.slaves = slaves
        self._keep = keep  # CosimLocalSlave wrappers must outlive the execution's use of them
        self.variables: dict[str, dict[str, tuple[int, CosimVariableType]]] = {}
        for name, index in slaves.items():
            self.variables[name] = {v.name.decode(): (v.reference, CosimVariableType(v.type))
                                    for v in execution.slave_variables(index)}

    def lookup(self, component: str, variable: str):
        if component not in self.variables:
            raise KeyError(f"libcosim has no slave named {component!r}; slaves: {sorted(self.variables)}")
        if variable not in self.variables[component]:
            raise KeyError(f"slave {component!r} has no variable {variable!r}")
        ref, vtype = self.variables[component][variable]
        return self.slaves[component], ref, vtype


def _observe_loop(session: _Session, observe: Sequence[str], steps: int, step_size: float,
                  start_time: float, loaded_from: str) -> LibcosimResult:
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimObserver import CosimObserver

    ex = session.execution
    observer = CosimObserver.create_last_value()
    if not ex.add_observer(observer):
        raise LibcosimError(f"could not add an observer: {_last_error()}")
    groups: dict[tuple[int, str], list[tuple[str, int]]] = {}
    for key in observe:
        component, _, variable = key.partition(".")
        index, ref, vtype = session.lookup(component, variable)
        if vtype not in (CosimVariableType.REAL, CosimVariableType.INTEGER):
            raise ValueError(f"{key}: only Real and Integer variables can be observed, not {vtype.name}")
        groups.setdefault((index, vtype.name), []).append((key, ref))
    data = {key: np.empty(steps) for key in observe}
    t0 = time.perf_counter()
    for k in range(steps):
        if not ex.step(1):
            raise LibcosimError(f"libcosim step {k + 1} (t = {start_time + k * step_size:.9g} s) failed: "
                                f"{_last_error()}")
        for (index, tname), items in groups.items():
            refs = [ref for _, ref in items]
            got = (observer.last_real_values(index, refs) if tname == "REAL"
                   else observer.last_integer_values(index, refs))
            for (key, _), value in zip(items, got):
                data[key][k] = value
    wall = time.perf_counter() - t0
    times = start_time + step_size * np.arange(1, steps + 1)
    return LibcosimResult(time=times, values=data, steps=steps, step_size=step_size, wall_time_s=wall,
                          libcosim_version=libcosim_version(), loaded_from=loaded_from)


def _steps(start: float, stop: float, h: float) -> int:
    n = round((stop - start) / h)
    if n < 1 or abs(n * h - (stop - start)) > 1e-9 * max(1.0, stop - start):
        raise ValueError(f"stop - start = {stop - start!r} s is not a whole number of steps of {h!r} s")
    return n


def run_system(system: System, observe: Sequence[str], *, stop_time: float | None = None,
               log_level: str = "error", isolate: bool = True) -> LibcosimResult:
    """Run ``system`` in libcosim with its fixed step and return the observed variables.

    ``isolate`` (default) runs libcosim in a child process (see :func:`_in_child`).

    ``observe`` lists ``"component.variable"`` names.  Slaves, start values and plain
    connections go through libcosim's C API.  libcosimc has no call for a connection
    with a linear transformation, so a system that has one is handed to libcosim as an
    SSD in a temporary folder that points at the FMU files (no copy), which libcosim's
    SSP loader turns into the same slaves plus a ``linear_transformation`` function
    (evaluated in the same transfer, so it adds no delay).
    """
    check_system(system)
    if isolate:
        return _in_child("system", system, list(observe), stop_time=stop_time, log_level=log_level)
    stop = system.stop_time if stop_time is None else stop_time
    if any(c.factor != 1.0 or c.offset != 0.0 for c in system.connections):
        with tempfile.TemporaryDirectory(prefix="libcosim_ssd_") as tmp:
            sources = {c.name: Path(c.fmu).resolve().as_uri() for c in system.components}
            (Path(tmp) / "SystemStructure.ssd").write_bytes(build_ssd(system, sources))
            return run_ssp(tmp, observe, stop_time=stop, log_level=log_level, isolate=False,
                           _loaded_from="SSD (the C API has no linear transformation)")
    if system.start_time != 0.0:
        raise ValueError(f"start_time = {system.start_time!r} s: libcosimpy's from_step_size starts at 0 s")
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimSlave import CosimLocalSlave

    ensure_python_symbols()
    _set_log_level(log_level)
    ex = CosimExecution.from_step_size(_to_ns(system.step_size, "step_size"))
    slaves, keep = {}, []
    for comp in system.components:
        local = CosimLocalSlave(str(Path(comp.fmu).resolve()), comp.name)
        keep.append(local)
        index = ex.add_local_slave(local)
        if index < 0:
            raise LibcosimError(f"could not load {comp.fmu} as {comp.name!r}: {_last_error()}")
        slaves[comp.name] = index
    session = _Session(ex, slaves, keep)
    setters = {CosimVariableType.REAL: ex.real_initial_value, CosimVariableType.INTEGER: ex.integer_initial_value,
               CosimVariableType.BOOLEAN: ex.boolean_initial_value, CosimVariableType.STRING: ex.string_initial_value}
    convert = {CosimVariableType.REAL: float, CosimVariableType.INTEGER: int,
               CosimVariableType.BOOLEAN: bool, CosimVariableType.STRING: str}
    for comp in system.components:
        for name, value in comp.start_values.items():
            index, ref, vtype = session.lookup(comp.name, name)
            if not setters[vtype](index, ref, convert[vtype](value)):
                raise LibcosimError(f"{comp.name}.{name} = {value!r}: libcosim refused the start value: "
                                    f"{_last_error()}")
    connect = {CosimVariableType.REAL: ex.connect_real_variables,
               CosimVariableType.INTEGER: ex.connect_integer_variables,
               CosimVariableType.BOOLEAN: ex.connect_boolean_variables,
               CosimVariableType.STRING: ex.connect_string_variables}
    for con in system.connections:
        src = session.lookup(con.start_element, con.start_connector)
        dst = session.lookup(con.end_element, con.end_connector)
        if connect[src[2]](src[0], src[1], dst[0], dst[1]) != 0:
            raise LibcosimError(f"could not connect {con}: {_last_error()}")
    steps = _steps(system.start_time, stop, system.step_size)
    return _observe_loop(session, observe, steps, system.step_size, system.start_time, "C API")


def run_ssp(path: Path | str, observe: Sequence[str], *, stop_time: float | None = None,
            step_size: float | None = None, log_level: str = "error", isolate: bool = True,
            _loaded_from: str = "SSP package") -> LibcosimResult:
    """Load an ``.ssp`` (or a folder with ``SystemStructure.ssd``) with libcosim's SSP parser and run it.

    ``isolate`` (default) runs libcosim in a child process (see :func:`_in_child`).

    Start/stop time and the fixed step come from the SSD's ``DefaultExperiment``
    (the step from its OSP ``FixedStepAlgorithm`` annotation) unless given here.
    """
    from lxml import etree
    import zipfile

    from libcosimpy.CosimExecution import CosimExecution

    path = Path(path)
    if isolate:
        return _in_child("ssp", path.resolve(), list(observe), stop_time=stop_time, step_size=step_size,
                         log_level=log_level)
    if path.is_dir():
        xml = (path / SSD_NAME).read_bytes()
    else:
        with zipfile.ZipFile(path) as zf:
            xml = zf.read(SSD_NAME)
    root = etree.fromstring(xml)
    q = {"ssd": SSD_NS, "ssc": SSC_NS, "osp": OSP_NS}
    exp = root.find("ssd:DefaultExperiment", q)
    start = float(exp.get("startTime", 0.0)) if exp is not None else 0.0
    stop = stop_time if stop_time is not None else (float(exp.get("stopTime")) if exp is not None
                                                    and exp.get("stopTime") else None)
    if stop is None:
        raise ValueError(f"{path}: no stop time (give stop_time or DefaultExperiment stopTime)")
    algo = root.find("ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", q)
    h = step_size if step_size is not None else (float(algo.get("baseStepSize")) if algo is not None else None)
    if h is None:
        raise ValueError(f"{path}: no fixed step (give step_size or an osp:FixedStepAlgorithm annotation)")
    names = [c.get("name") for c in root.iter(f"{{{SSD_NS}}}Component")]

    ensure_python_symbols()
    _set_log_level(log_level)
    try:
        ex = CosimExecution.from_ssp_file(str(path.resolve()), step_size=_to_ns(h, "step_size"))
    except AssertionError as exc:
        raise LibcosimError(f"libcosim could not load {path}: {_last_error()}") from exc
    slaves = {}
    for name in names:
        index = ex.slave_index_from_instance_name(name)
        if index is None:
            raise LibcosimError(f"{path}: libcosim did not create slave {name!r}")
        slaves[name] = index
    session = _Session(ex, slaves, [])
    return _observe_loop(session, observe, _steps(start, stop, h), h, start, _loaded_from)


# ---------------------------------------------------------------------------------------------
# isolation in a child process
# ---------------------------------------------------------------------------------------------
def _in_child(kind: str, target, observe: list[str], **kwargs) -> LibcosimResult:
    """Run libcosim in a fresh Python process and return its result (:func:`run_isolated`)."""
    return run_isolated("cosim.peers.libcosim", (kind, target, observe, kwargs), LibcosimError, "libcosim")


def run_isolated(module: str, request, error: type[Exception], tool: str, env_extra: dict | None = None):
    """Run ``python -m module REQUEST ANSWER`` in a fresh process and return what it pickled.

    ``request`` is pickled for the child; the child writes ``("ok", result)`` or
    ``("error", text)``, and an error becomes ``error(text)``.  ``env_extra`` is added to
    the child's environment.

    Why: libcosim steps the slaves from its own worker threads.  pythonfmu takes the
    GIL there, but the numpy/scipy code inside our FMUs then calls OpenBLAS from those
    foreign threads while OpenBLAS runs its own thread pool; in a process that has also
    run the FMUs through fmpy we measured intermittent heap corruption, reported by
    glibc in OpenBLAS's exit handler ("corrupted double-linked list" in
    ``blas_thread_shutdown_``).  With ``OPENBLAS_NUM_THREADS=1`` (which must be set
    before numpy loads, hence a new process) it did not happen in repeated runs.  A
    child process is also what a third-party host is: its own interpreter, with its own
    copy of the FMUs' Python modules.
    """
    import os
    import pickle
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]   # the folder holding the cosim package
    with tempfile.TemporaryDirectory(prefix=f"{tool}_run_") as tmp:
        request_file, answer = Path(tmp) / "request.pkl", Path(tmp) / "result.pkl"
        request_file.write_bytes(pickle.dumps(request))
        env = dict(os.environ)
        env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", **(env_extra or {}))
        env["PYTHONPATH"] = os.pathsep.join([str(root)] + [p for p in [env.get("PYTHONPATH")] if p])
        proc = subprocess.run([sys.executable, "-m", module, str(request_file), str(answer)],
                              env=env, cwd=tmp, capture_output=True, text=True)
        if not answer.exists():
            text = (proc.stderr or proc.stdout).strip()
            tail = "\n".join(text.splitlines()[-15:])
            # libcosim aborts its process when an FMU refuses initialisation (fmi2Fatal, the only
            # refusal pythonfmu can give there); the refusal itself is in pythonfmu's wrapper
            start = text.find(PYTHONFMU_FATAL)
            refusal = slave_message(text[start:]) if start >= 0 else ""
            if refusal and not refusal.startswith(PYTHONFMU_FATAL):
                raise error(f"{tool} stopped (exit code {proc.returncode}) when an FMU refused to "
                            f"initialise: {refusal}")
            raise error(f"{tool} child process failed (exit code {proc.returncode}):\n{tail}")
        status, payload = pickle.loads(answer.read_bytes())
    if status == "error":
        raise error(payload)
    return payload


def answer_child(request: str, answer: str, work) -> None:
    """The child side of :func:`run_isolated`: ``work(*request)`` pickled to ``answer``."""
    import os
    import pickle
    import traceback

    try:
        result = ("ok", work(*pickle.loads(Path(request).read_bytes())))
    except Exception as exc:  # carried back to the parent as text
        result = ("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}")
    partial = Path(answer).with_suffix(".partial")
    partial.write_bytes(pickle.dumps(result))
    partial.replace(answer)
    # Skip interpreter and library teardown: the result is safely on disk, and the exit
    # handlers of the FMUs' native libraries are where the problem above surfaces.
    os._exit(0)


def _child_main(request: str, answer: str) -> None:
    def work(kind, target, observe, kwargs):
        if kind == "system":
            return run_system(target, observe, isolate=False, **kwargs)
        return run_ssp(target, observe, isolate=False, **kwargs)

    answer_child(request, answer, work)


if __name__ == "__main__":   # the child process of run_isolated (a protocol, not a command line)
    import sys

    if len(sys.argv) != 3 or sys.argv[1].startswith("-"):
        print("usage: python -m cosim.peers.libcosim REQUEST.pkl ANSWER.pkl  (the child process of "
              "cosim.peers.libcosim.run_system / run_ssp; not a command)", file=sys.stderr)
        sys.exit(2)
    # import by package name so that the pickled result refers to cosim.peers.libcosim
    from cosim.peers.libcosim import _child_main as _main

    _main(sys.argv[1], sys.argv[2])
