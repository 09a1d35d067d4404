"""Running a study on Dask: a local cluster or an existing scheduler.

The FMU files travel to the workers inside a worker plugin (:class:`StudyPlugin`), so a
remote worker needs only this package installed; each worker process keeps one
:class:`~cosim.apps.study.runner.CaseRunner`.  Rows are written as cases finish.
"""
from __future__ import annotations

import hashlib
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from distributed.diagnostics.plugin import WorkerPlugin

from ...fmus import default_fmu_dir, fmu_hashes
from ...master.scene import Override
from ...master.system import Catalog
from .cases import Case
from .results_io import _prepare_folder, _RowWriter, columns_for, one_line, write_parquet
from .runner import CaseRunner, validate_study
from .spec import Study, StudyError, load_study

CONNECT_TIMEOUT_S = 5.0           # an unreachable scheduler is reported after this long


class StudyPlugin(WorkerPlugin):
    """Dask worker plugin: carries the FMU files and holds the worker's :class:`CaseRunner`.

    Registered under a name derived from the FMUs' hashes, so studies with
    other FMUs on the same cluster get their own runner.  On a worker the FMUs
    are written once into the worker's local directory.
    """

    def __init__(self, fmu_dir: Path, hashes: Mapping[str, str]):
        self.files = {name: (Path(fmu_dir) / f"{name}.fmu").read_bytes() for name in hashes}
        self.name = "cosim-study-" + hashlib.sha256("".join(sorted(hashes.values())).encode()).hexdigest()[:12]
        self.runner: CaseRunner | None = None

    def setup(self, worker) -> None:
        folder = Path(worker.local_directory) / self.name
        folder.mkdir(parents=True, exist_ok=True)
        for name, data in self.files.items():
            (folder / f"{name}.fmu").write_bytes(data)
        self.files = {}
        self.folder = folder

    def case_runner(self) -> CaseRunner:
        """The worker's runner, created by the first case, in the thread that runs the cases.

        Loading the pythonfmu FMUs in the worker's event-loop thread (``setup``) and stepping
        them in its task thread corrupts the heap: glibc aborts the worker process at exit
        ("free(): corrupted unsorted chunks").
        """
        if self.runner is None:
            self.runner = CaseRunner(self.folder)
        return self.runner

    def teardown(self, worker) -> None:
        if self.runner is not None:
            self.runner.close()
            self.runner = None


def _run_case_on_worker(plugin_name: str, scene_raw: dict, overrides: list[Override], tolerance: float) -> dict:
    from distributed import get_worker

    return get_worker().plugins[plugin_name].case_runner().run(scene_raw, overrides, tolerance)


def connect(scheduler: str | None = None, workers: int | None = None,
            timeout: float = CONNECT_TIMEOUT_S):
    """``(client, cluster)``: a ``distributed.Client`` to ``scheduler`` (``cluster`` None; a
    :class:`StudyError` after ``timeout`` s if it does not answer), or to a new ``LocalCluster``
    of ``workers`` processes with one thread each (default: one per core)."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=timeout), None
        except (OSError, TimeoutError) as exc:
            raise StudyError(f"cannot reach the Dask scheduler at {scheduler!r} within {timeout:g} s "
                             f"({type(exc).__name__}: {one_line(exc)})") from None
        except ValueError as exc:
            raise StudyError(f"--scheduler {scheduler!r}: {one_line(exc)}") from None
    n = workers or os.cpu_count() or 1
    if n < 1:
        raise StudyError(f"--workers {workers}: needs at least 1 worker")
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    return Client(cluster), cluster


# -- running a study -------------------------------------------------------------------------------
@dataclass
class StudyResult:
    """What :func:`run_study` did.  Times in s; ``elapsed_s`` runs from the first
    submitted case to the last result (cluster start-up excluded)."""

    study: Study
    folder: Path
    csv: Path
    parquet: Path
    n_cases: int
    skipped: int                  # already in the CSV (--resume)
    ran: int
    failed: int                   # status failed or unstable, among the cases run now
    workers: int
    startup_s: float
    elapsed_s: float
    validation_s: float
    rows: list[dict[str, Any]] = field(default_factory=list, repr=False)  # the rows of the cases run now


def run_study(study: Study | str | Path, out: str | Path | None = None, *, workers: int | None = None,
              scheduler: str | None = None, client=None, resume: bool = False, fmu_dir: str | Path | None = None,
              progress: bool = True, connect_timeout: float = CONNECT_TIMEOUT_S) -> StudyResult:
    """Validate, then run every case not yet recorded, appending rows to ``out/results.csv``.

    ``client``: an existing ``distributed.Client`` (then ``workers`` and
    ``scheduler`` are ignored and the client is left open).  Raises
    :class:`StudyError` for bad input before any case runs.
    """
    if not isinstance(study, Study):
        study = load_study(study)
    fmu_dir = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()
    t0 = time.perf_counter()
    try:
        catalog = Catalog(fmu_dir)
    except FileNotFoundError as exc:
        raise StudyError(str(exc)) from None
    try:
        buildings = validate_study(study, catalog)
    finally:
        catalog.close()
    validation_s = time.perf_counter() - t0
    hashes = fmu_hashes(fmu_dir)
    header = columns_for(study, buildings)
    cases = study.cases()
    folder = Path(out) if out is not None else Path("out") / "studies" / study.name

    t0 = time.perf_counter()
    own = client is None
    cluster = None
    if own:
        client, cluster = connect(scheduler, workers, connect_timeout)
    writer = None
    try:
        startup_s = time.perf_counter() - t0
        done = _prepare_folder(folder, study.fingerprint(hashes), header, resume)
        pending = [c for c in cases if c.id not in done]
        plugin = StudyPlugin(fmu_dir, hashes)
        n_workers = len(client.nthreads())
        writer = _RowWriter(folder / "results.csv", header)
        rows, failed = [], 0
        t1 = time.perf_counter()
        if pending:
            client.register_plugin(plugin, name=plugin.name)
            try:
                rows, failed = _execute(client, plugin.name, study, pending, writer, progress,
                                        len(cases) - len(pending))
            finally:
                if own:   # free the workers' FMU instances while their interpreters are alive
                    _unregister(client, plugin.name)
        elapsed_s = time.perf_counter() - t1
    finally:
        if writer is not None:
            writer.close()
            write_parquet(folder / "results.csv", folder / "results.parquet")
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    return StudyResult(study, folder, folder / "results.csv", folder / "results.parquet", len(cases),
                       len(cases) - len(pending), len(rows), failed, n_workers, startup_s, elapsed_s,
                       validation_s, rows)


def _unregister(client, name: str) -> None:
    try:
        client.unregister_worker_plugin(name)
    except Exception:  # noqa: BLE001 - a worker already gone has nothing left to free
        pass


def _execute(client, plugin_name: str, study: Study, pending: list[Case], writer: _RowWriter,
             progress: bool, already: int) -> tuple[list[dict], int]:
    from distributed import as_completed

    scene_raw = study.scene_raw  # a few hundred bytes: sent with each task
    futures = {}
    for case in pending:
        future = client.submit(_run_case_on_worker, plugin_name, scene_raw, list(study.fixed) + case.overrides,
                               study.energy_tolerance, key=f"cosim-case-{study.name}-{case.id}", pure=False)
        futures[future.key] = (future, case)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=already + len(pending), initial=already, unit="case", desc=study.name, smoothing=0.1)
    rows, failed = [], 0
    try:
        for future in as_completed([f for f, _ in futures.values()]):
            case = futures[future.key][1]
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - e.g. the worker died (KilledWorker): record and go on
                row = dict(status="failed", error=one_line(f"{type(exc).__name__}: {exc}"))
            row = {**row, "case_id": case.id, "case": case.index, **case.values}
            writer.write(row)
            rows.append(row)
            if row["status"] != "ok":
                failed += 1
            if bar is not None:
                bar.set_postfix_str(f"failed {failed}", refresh=False)
                bar.update(1)
    except BaseException:
        client.cancel([f for f, _ in futures.values()])
        raise
    finally:
        if bar is not None:
            bar.close()
    return rows, failed
