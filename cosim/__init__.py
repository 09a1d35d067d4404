"""pounding-cosim: structural pounding of adjacent buildings as FMI 2.0 co-simulation.

Layers (docs/architecture.md), each importing only those before it:

* ``fmu_src`` (a separate package): the physics and the pythonfmu slaves;
* :mod:`cosim.fmus` (the FMUs as data, building them), :mod:`cosim.files`;
* :mod:`cosim.master`: FMI layer, scenes, system, coupling strategies, guard, results;
* :mod:`cosim.peers`: the reference solver, OpenSees, libcosim, SSP;
* :mod:`cosim.apps`: studies, calibration, accuracy study, reproduction report;
* :mod:`cosim.cli`: the one command line (``pounding-cosim``).

The common names are importable from here (lazily: ``import cosim`` loads nothing else).
"""
from __future__ import annotations

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("pounding-cosim")   # single source: pyproject.toml
except PackageNotFoundError:   # a source tree that was never installed
    __version__ = "0+unknown"

_EXPORTS = {name: "cosim.master" for name in (
    "run_scene", "RunResult", "load_scene", "Override", "Scene", "SceneError", "FMUError", "InstabilityError",
    "Catalog", "System", "simulate", "summarize", "Summary", "Cost", "SimulationResult", "STRATEGIES",
    "get_strategy", "bundled_scenes")}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'cosim' has no attribute {name!r}")
