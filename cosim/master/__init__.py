"""The master: FMI layer, scenes, system assembly, coupling strategies, guard, results.

Modules, bottom up (each imports only those above it):

* :mod:`.names` (``x[i]`` element names), :mod:`.interface` (FMU variables without loading
  an FMU; parameter defaults), :mod:`.fmi` (the only module that calls FMI functions);
* :mod:`.scene` (the data model) and :mod:`.loader` (scene files, checked);
* :mod:`.system` (catalog of FMUs, instances wired as the scene says);
* :mod:`.guard` (stability guard, :class:`~.guard.InstabilityError`), :mod:`.coupling`
  (strategies, one registry);
* :mod:`.results` (history, typed summary, cost), :mod:`.simulate` (the run loop),
  :mod:`.output` (files and plots), :mod:`.runner` (:func:`run_scene`).
"""
from __future__ import annotations

from .coupling import COUPLINGS, STRATEGIES, CouplingStrategy, get_strategy
from .fmi import FMU, FMUError, Instance
from .guard import InstabilityError, StabilityGuard
from .loader import bundled_scenes, load_scene
from .output import format_summary, write_results
from .results import Cost, RunResult, SimulationResult, Summary, summarize
from .runner import run_scene
from .scene import Override, Scene, SceneError, parse_override
from .simulate import simulate
from .system import Catalog, System

__all__ = ["COUPLINGS", "STRATEGIES", "CouplingStrategy", "get_strategy", "FMU", "FMUError", "Instance",
           "InstabilityError", "StabilityGuard", "bundled_scenes", "load_scene", "format_summary", "write_results",
           "Cost", "RunResult", "SimulationResult", "Summary", "summarize", "run_scene", "Override", "Scene",
           "SceneError", "parse_override", "simulate", "Catalog", "System"]
