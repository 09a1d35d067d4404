"""Run an exported ``.ssp`` in Ecos, a second independent FMI/SSP master.

Ecos [https://github.com/Ecos-platform/ecos, PyPI ``ecospy``] is a C++ co-simulation
engine with a Python wrapper.  It reads SSP 1.0 with its own parser and steps the
components with a fixed step.  What it does differently from libcosim, and what the
export therefore avoids (:mod:`cosim.peers.ssp`):

* it applies one *named* parameter set (``EcosSimulation.init(parameter_set=...)``):
  every component's start values are exported as the one set :data:`cosim.peers.ssp.PARAMETER_SET`;
* variables are addressed as ``component::variable``;
* its time is a sum of float steps (``40.00000000000061`` after 4000 steps of 0.01 s):
  the run takes a whole number of steps.

The native library needs oneTBB's ``libtbb.so.12``, which the PyPI package ``tbb``
installs into the environment's ``lib`` folder; it is loaded first, with global scope.
Ecos runs in a child process, as libcosim does (:func:`cosim.peers.libcosim.run_isolated`).
"""
from __future__ import annotations

import ctypes
import sys
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .libcosim import answer_child, ensure_python_symbols, run_isolated


class EcosError(RuntimeError):
    """Ecos refused to load or step the package; the message carries Ecos's own error text."""


@dataclass
class EcosResult:
    """Time series observed in an Ecos run: ``time`` (s) after each step, ``values["component.variable"]``."""

    time: np.ndarray
    values: dict[str, np.ndarray]
    steps: int
    step_size: float
    wall_time_s: float
    ecos_version: str
    parameter_set: str

    def __getitem__(self, key: str) -> np.ndarray:
        return self.values[key]


def _load_tbb() -> None:
    """Make oneTBB global before ecospy loads ``libecosc.so`` (which links ``libtbb.so.12``)."""
    for folder in (Path(sys.prefix) / "lib", Path(sys.base_prefix) / "lib"):
        candidate = folder / "libtbb.so.12"
        if candidate.exists():
            ctypes.CDLL(str(candidate), mode=ctypes.RTLD_GLOBAL)
            return


def _experiment(path: Path) -> tuple[float, float]:
    """(stop time, fixed step) [s] from the package's DefaultExperiment and its OSP annotation."""
    from lxml import etree

    from .ssp import OSP_NS, SSC_NS, SSD_NAME, SSD_NS

    with zipfile.ZipFile(path) as zf:
        root = etree.fromstring(zf.read(SSD_NAME))
    q = {"ssd": SSD_NS, "ssc": SSC_NS, "osp": OSP_NS}
    exp = root.find("ssd:DefaultExperiment", q)
    algo = root.find("ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", q)
    if exp is None or exp.get("stopTime") is None or algo is None:
        raise ValueError(f"{path}: no DefaultExperiment stopTime with an osp:FixedStepAlgorithm baseStepSize")
    return float(exp.get("stopTime")), float(algo.get("baseStepSize"))


def run_ssp(path: Path | str, observe: Sequence[str], *, stop_time: float | None = None,
            parameter_set: str | None = None, isolate: bool = True) -> EcosResult:
    """Load an ``.ssp`` with Ecos's SSP parser, run it with its fixed step, return ``observe``.

    ``observe``: ``"component.variable"`` names (Real or Integer).  ``parameter_set``:
    the named set Ecos applies (default :data:`cosim.peers.ssp.PARAMETER_SET`).  Stop time and
    step come from the package unless ``stop_time`` is given.
    """
    from .ssp import PARAMETER_SET

    path = Path(path).resolve()
    parameter_set = PARAMETER_SET if parameter_set is None else parameter_set
    if isolate:
        return run_isolated("cosim.peers.ecos", (path, list(observe), stop_time, parameter_set), EcosError, "ecos")
    stop, h = _experiment(path)
    stop = stop if stop_time is None else float(stop_time)
    steps = round(stop / h)
    if steps < 1 or abs(steps * h - stop) > 1e-9 * max(1.0, stop):
        raise ValueError(f"stop time {stop!r} s is not a whole number of steps of {h!r} s")
    ensure_python_symbols()
    _load_tbb()
    from ecospy import EcosLib, EcosSimulation

    EcosLib.set_log_level("warn")
    try:
        sim = EcosSimulation(ssp_path=str(path), step_size=h)
    except Exception as exc:
        raise EcosError(f"Ecos could not load {path}: {exc}") from exc
    sim.init(parameter_set=parameter_set)
    getters = {}
    for key in observe:       # Ecos knows a variable's type once initialised
        component, _, variable = key.partition(".")
        ident = f"{component}::{variable}"
        try:
            sim.get_real(ident)
            getters[key] = (sim.get_real, ident)
        except Exception:
            getters[key] = (sim.get_integer, ident)
    data = {key: np.empty(steps) for key in observe}
    t0 = time.perf_counter()
    for k in range(steps):
        sim.step(1)
        for key, (get, ident) in getters.items():
            data[key][k] = get(ident)
    wall = time.perf_counter() - t0
    sim.terminate()
    return EcosResult(time=h * np.arange(1, steps + 1), values=data, steps=steps, step_size=h, wall_time_s=wall,
                      ecos_version=repr(EcosLib.version()), parameter_set=parameter_set)


def _child_main(request: str, answer: str) -> None:
    def work(path, observe, stop_time, parameter_set):
        return run_ssp(path, observe, stop_time=stop_time, parameter_set=parameter_set, isolate=False)

    answer_child(request, answer, work)


if __name__ == "__main__":   # the child process of run_isolated (a protocol, not a command line)
    if len(sys.argv) != 3 or sys.argv[1].startswith("-"):
        print("usage: python -m cosim.peers.ecos REQUEST.pkl ANSWER.pkl  (the child process of "
              "cosim.peers.ecos.run_ssp; not a command)", file=sys.stderr)
        sys.exit(2)
    # import by package name so that the pickled result refers to cosim.peers.ecos
    from cosim.peers.ecos import _child_main as _main

    _main(sys.argv[1], sys.argv[2])
