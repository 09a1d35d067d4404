"""fmpy master for the pounding FMUs: scenes, system assembly, coupling, results.

Layers (see docs/architecture.md): :mod:`cosim.fmi` (the only module that
calls FMI functions), :mod:`cosim.scene` (scene files), :mod:`cosim.master`
(system assembly, run loop), :mod:`cosim.coupling` (strategies),
:mod:`cosim.results` (summary, CSV, plots), :mod:`cosim.run` (CLI and
:func:`run_scene`).
"""
from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("pounding-cosim")   # single source: pyproject.toml
except PackageNotFoundError:   # a source tree that was never installed
    __version__ = "0+unknown"

from .coupling import STRATEGIES, CouplingStrategy, GaussSeidel, Jacobi, get_strategy
from .fmi import FMU, FMUError, Instance
from .master import Catalog, SimulationResult, System, simulate
from .results import summarize, write_results
from .scene import Scene, SceneError, load_scene

__all__ = ["STRATEGIES", "CouplingStrategy", "GaussSeidel", "Jacobi", "get_strategy", "FMU", "FMUError",
           "Instance", "Catalog", "SimulationResult", "System", "simulate", "summarize", "write_results",
           "Scene", "SceneError", "load_scene", "run_scene", "RunResult"]


def __getattr__(name):  # run.py is also a script; import it lazily
    if name in ("run_scene", "RunResult"):
        from . import run
        return getattr(run, name)
    raise AttributeError(name)
