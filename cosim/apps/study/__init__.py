"""Parameter studies: many runs of one scene, varied through FMU variables, on Dask.

    pounding-cosim study fig8a_gap                     # a bundled study; local cluster, one worker per core
    pounding-cosim study fig8a_gap --workers 1 --out out/gap1
    pounding-cosim study my_study.toml --scheduler tcp://head:8786   # an existing cluster
    pounding-cosim study fig8a_gap --resume            # finish an interrupted study
    pounding-cosim study fig8a_gap --dry-run           # check it and count the cases
    pounding-cosim study plot out/studies/fig8a_gap/results.csv --x pounding.gap --y peak_force_N --by ground.record

(``python cosim/study.py ...`` is the same command.)  The package's modules, one job each:
:mod:`.spec` (study files), :mod:`.cases` (the cases and their identity), :mod:`.runner`
(one case in one process, the checks before a study), :mod:`.results_io` (the result
files), :mod:`.cluster` (execution on Dask), :mod:`.plot` (plots).

A study file (TOML) names a scene and the variables to vary::

    name = "fig8a_gap"
    scene = "default"              # bundled scene name, or a path relative to this file
    energy_tolerance = 0.05        # optional: energy created > 5 % of the input = "unstable"

    [set]                          # fixed overrides for every case (like run --set)
    stop_time = 40.0

    [vary]                         # a grid: the cartesian product of the axes, in file order
    "ground.record" = ["elcentro1940", "kobe1995", "sanfernando1971", "parkfield1966"]
    "pounding.gap" = { start = 0.0, stop = 0.20, num = 21 }   # linspace, both ends included

    [[zip]]                        # one more axis: these variables change together
    "left.v0[1]" = [1.0, 2.0]
    "right.v0[1]" = [-1.0, -2.0]

The axes form a grid in the order of the file (``[vary]`` keys in order, each
``[[zip]]`` one axis), the first varying slowest.

Every case is the scene plus ``--set``-style overrides ``INSTANCE.VAR=VALUE``:
only FMU start values (and top-level scene keys such as ``stop_time``) change,
on the same built FMUs.  Range values are rounded to 12 significant digits, so
``0.03`` is the number a person would type.

Execution: a Dask ``LocalCluster`` of worker processes (``threads_per_worker
= 1``: the pythonfmu slaves run Python code under the worker's GIL) or an
existing scheduler (``--scheduler``).  The FMU files travel to the workers
inside a worker plugin (:class:`StudyPlugin`), so a remote cluster needs only
this package installed, not the files.  Each worker process keeps one
:class:`CaseRunner`: the FMUs are loaded once, the instances of the scene
are created once and reset (``fmi2Reset``) between cases.

Results: ``results.csv`` (one row per case, appended and flushed as each case
finishes), ``results.parquet`` (regenerated from the CSV at the end and on
``--resume``) and ``study.json`` (what the rows depend on: scene, fixed
overrides, FMU hashes), in ``out/studies/<name>/`` or ``--out``.  A case is
identified by :func:`case_id`, a hash of its varied values: ``--resume``
skips every case already in the CSV (ok or failed), and adding values to a
study and resuming computes only the new cases.  A case that fails (FMU or
scene error) or is unstable (non-finite numbers, or the energy balance shows
energy created) is recorded with its reason and the study goes on.

Exit code: 0 when the study completed (failed cases are results, counted in
the output), 2 for bad input (study, variable, value, scheduler), 130 when
interrupted (the rows already written are kept).
"""
from __future__ import annotations

from .cases import Axis, Case, case_id
from .cluster import (CONNECT_TIMEOUT_S, WORKER_WAIT_S, ClusterLost, StudyPlugin, StudyResult, check_workers,
                      connect, fmu_hashes, run_study)
from .lock import StudyLock
from .plot import plot_results
from .results_io import STATUSES, columns_for, read_results, write_parquet
from .runner import CaseRunner, case_row, validate_study
from .spec import DEFAULT_ENERGY_TOLERANCE, MAX_CASES, Study, StudyError, bundled_studies, load_study, resolve_study

__all__ = ["Axis", "Case", "case_id", "CONNECT_TIMEOUT_S", "WORKER_WAIT_S", "ClusterLost", "StudyPlugin",
           "StudyResult", "check_workers", "connect", "fmu_hashes", "run_study", "StudyLock", "MAX_CASES", "plot_results", "STATUSES", "columns_for", "read_results", "write_parquet", "CaseRunner",
           "case_row", "validate_study", "DEFAULT_ENERGY_TOLERANCE", "Study", "StudyError", "bundled_studies",
           "load_study", "resolve_study"]
