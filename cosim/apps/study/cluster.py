"""Running a study on Dask: a local cluster or an existing scheduler.

The FMU files travel to the workers inside a worker plugin (:class:`StudyPlugin`), so a
remote worker needs only this package installed; each worker process keeps one
:class:`~cosim.apps.study.runner.CaseRunner`.  Rows are written as cases finish.

Before any case is sent, every worker's environment is checked
(:mod:`~cosim.apps.study.environment`: this package at the submitter's version and its install
requirements); a worker that joins later is checked by the plugin itself (Dask stops a worker
that cannot unpickle the plugin; one the plugin finds unfit refuses the cases offered to it,
which go to the checked workers).  A worker lost mid-study costs nothing: Dask reruns its cases
elsewhere.  A lost scheduler ends the study with :class:`ClusterLost` (the rows written are
kept; ``--resume`` completes them).
"""
from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

from distributed.diagnostics.plugin import WorkerPlugin

from ... import __version__
from ...fmus import default_fmu_dir, fmu_hashes
from ...master.scene import Override
from ...master.system import Catalog
from .cases import Case
from .environment import WorkerEnvironment, probe, refusal, unfit, worker_environments, worker_requirements
from .results_io import (_RowWriter, claim_folder, columns_for, one_line, recorded_rows, start_results,
                         write_parquet)
from .runner import CaseRunner, validate_study
from .spec import Study, StudyError, load_study

CONNECT_TIMEOUT_S = 5.0    # an unreachable scheduler is reported after this long
WORKER_WAIT_S = 60.0       # a scheduler without workers: how long to wait for the first one


class ClusterLost(RuntimeError):
    """The study had to stop (exit 1): the Dask scheduler went away, or no worker is left that
    can run the cases.  The rows written are kept; ``--resume`` completes the study."""


class WorkerUnfit(RuntimeError):
    """Raised by a case sent to a worker that cannot run it (it joined after the start's check
    and lacks a requirement or has another version of this package): not a row; the case goes
    to the workers that can."""


class StudyPlugin(WorkerPlugin):
    """Dask worker plugin: carries the FMU files and holds the worker's :class:`CaseRunner`.

    Registered under a name derived from the FMUs' hashes, so studies with
    other FMUs on the same cluster get their own runner.  On a worker the FMUs
    are written once into the worker's local directory.

    A worker that joins mid-study was not in the start's check: ``setup`` runs the same check
    (:func:`~cosim.apps.study.environment.probe`; a worker that cannot even unpickle the plugin,
    lacking this package or fmpy, is stopped by Dask itself).  A worker found unfit keeps its
    reasons in ``unfit`` (and its log): every case sent to it raises :class:`WorkerUnfit`
    instead of computing rows with other code.
    """

    def __init__(self, fmu_dir: Path, hashes: Mapping[str, str], package_version: str = __version__):
        self.files = {name: (Path(fmu_dir) / f"{name}.fmu").read_bytes() for name in hashes}
        self.name = "cosim-study-" + hashlib.sha256("".join(sorted(hashes.values())).encode()).hexdigest()[:12]
        self.package_version = package_version
        self.requirements = worker_requirements()
        self.runner: CaseRunner | None = None
        self.unfit: str | None = None

    def setup(self, worker) -> None:
        environment = WorkerEnvironment(worker.address, probe(self.requirements, dask_worker=worker))
        problems = environment.problems(self.package_version)
        self.files, files = {}, self.files
        if problems:
            self.unfit = f"worker {environment.label()}: {'; '.join(problems)}"
            logging.getLogger("distributed.worker").error("this worker cannot run the study's cases: %s",
                                                          self.unfit)
            return
        folder = Path(worker.local_directory) / self.name
        folder.mkdir(parents=True, exist_ok=True)
        for name, data in files.items():
            (folder / f"{name}.fmu").write_bytes(data)
        self.folder = folder

    def case_runner(self) -> CaseRunner:
        """The worker's runner, created by the first case, in the thread that runs the cases.

        Loading the pythonfmu FMUs in the worker's event-loop thread (``setup``) and stepping
        them in its task thread corrupts the heap: glibc aborts the worker process at exit
        ("free(): corrupted unsorted chunks").
        """
        if self.unfit is not None:
            raise WorkerUnfit(self.unfit)
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


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored in this process while the block runs (main thread only; a no-op elsewhere)."""
    if threading.current_thread() is not threading.main_thread():
        yield   # signal dispositions are set from the main thread only
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


class Interrupts:
    """The Ctrl-C noted by :func:`ctrl_c_deferred`; :meth:`check` raises KeyboardInterrupt for it."""

    def __init__(self):
        self.noted = False

    def note(self, signum, frame) -> None:
        self.noted = True

    def check(self) -> None:
        if self.noted:
            raise KeyboardInterrupt


@contextlib.contextmanager
def ctrl_c_deferred() -> Iterator[Interrupts]:
    """A Ctrl-C while the block runs takes effect between its steps (:meth:`Interrupts.check`)
    or when it ends, never in the middle of a call that cannot be interrupted safely.

    Two such places: the FMUs, which run their Python code in this interpreter and thread (a
    KeyboardInterrupt raised inside an FMU call is caught by the FMU and comes back as an FMU
    error, "the FMU refused it", or crashes the process), and Dask's start-up calls into its
    event-loop thread (a local cluster interrupted while its workers register cannot be closed
    any more: ``UnboundLocalError`` from ``distributed.utils.sync`` after 12 s).  The handler
    only notes the Ctrl-C (main thread only; elsewhere a no-op).

    A process started with SIGINT ignored (a job a script put in the background with ``&``: the
    shell makes it ignore SIGINT so that a Ctrl-C meant for the foreground spares it; the
    disposition is inherited across ``exec``) keeps ignoring it here too, as it does for the
    rest of the study: a Ctrl-C is never honoured while the study starts and then dropped
    while its cases run.
    """
    interrupts = Interrupts()
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        yield interrupts
        return
    previous = signal.signal(signal.SIGINT, interrupts.note)
    try:
        yield interrupts
    finally:
        signal.signal(signal.SIGINT, previous)
    interrupts.check()


def _wait_for_workers(client, n: int, timeout: float, poll) -> bool:
    """Wait until the scheduler has ``n`` workers (True) or ``timeout`` s passed (False), calling
    ``poll`` (e.g. :meth:`Interrupts.check`) between short questions to the scheduler."""
    deadline = time.monotonic() + timeout
    while len(client.scheduler_info()["workers"]) < n:
        poll()
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def local_cluster(n: int, timeout: float = WORKER_WAIT_S, poll=lambda: None):
    """``(client, cluster)``: a ``LocalCluster`` of ``n`` worker processes, one thread each, whose
    workers never see a Ctrl-C.

    A Ctrl-C in a terminal sends SIGINT to the whole foreground process group, the local
    cluster's worker processes included: each would print its own KeyboardInterrupt traceback
    and die under the study.  An ignored signal stays ignored across ``exec`` and Python then
    leaves it so; the workers are therefore spawned while this process ignores SIGINT, until
    they exist (not while they import and register, 1-3 s), and only the study's own process
    gets a Ctrl-C: it cancels the cases and stops the workers in order.  The price: a Ctrl-C
    while the worker processes are spawned (milliseconds; up to a second on a loaded machine)
    is lost, and must be pressed again.  (Blocking SIGINT instead does not keep it: the
    interpreter's other threads, numpy's BLAS pool and the thread that starts multiprocessing's
    resource tracker, do not block it, and the kernel hands it to one of them, which ignores
    it.)  ``poll`` is called while the workers register (:func:`ctrl_c_deferred`).
    """
    import multiprocessing

    from distributed import Client, LocalCluster

    # no dashboard; the scheduler's HTTP server (health, metrics) on a free port of the loopback
    # interface: its default, port 8787 on every interface, collides with any other Dask cluster
    cluster = LocalCluster(n_workers=0, threads_per_worker=1, processes=True, dashboard_address=None,
                           scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                           silence_logs=logging.CRITICAL)   # a case's failure is in its row
    try:
        before = len(multiprocessing.active_children())
        deadline = time.monotonic() + timeout
        with _sigint_ignored():
            cluster.scale(n)
            while len(multiprocessing.active_children()) < before + n and time.monotonic() < deadline:
                time.sleep(0.005)
        client = Client(cluster)
        if not _wait_for_workers(client, n, timeout, poll):
            raise StudyError(f"the local cluster's {n} workers did not start within {timeout:g} s")
    except BaseException:
        cluster.close()
        raise
    return client, cluster


def connect(scheduler: str | None = None, workers: int | None = None,
            timeout: float = CONNECT_TIMEOUT_S, poll=lambda: None):
    """``(client, cluster)``: a ``distributed.Client`` to ``scheduler`` (``cluster`` None; a
    :class:`StudyError` after ``timeout`` s if it does not answer), or to a new local cluster
    (:func:`local_cluster`) of ``workers`` processes with one thread each (default: one per core)."""
    from distributed import Client

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
    return local_cluster(n, poll=poll)


def check_workers(client, wait_s: float = WORKER_WAIT_S, poll=lambda: None) -> list[str]:
    """Wait (at most ``wait_s``, calling ``poll`` meanwhile) for a first worker, then check every
    worker's environment (:mod:`.environment`); raise :class:`StudyError` naming each worker
    that cannot run the cases.  Returns the workers' addresses."""
    if not _wait_for_workers(client, 1, wait_s, poll):
        address = client.scheduler.address
        raise StudyError(f"the Dask scheduler at {address} has no worker, and none joined within {wait_s:g} s: "
                         f"start workers (dask worker {address})")
    environments = worker_environments(client)
    bad = unfit(environments, __version__)
    if bad:
        raise StudyError(refusal(bad, len(environments)))
    return [e.address for e in environments]


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
    skipped: int                  # already in the CSV (--resume): kept, not run
    ran: int
    failed: int                   # status failed or unstable, among the cases run now
    workers: int
    startup_s: float
    elapsed_s: float
    validation_s: float
    rows: list[dict[str, Any]] = field(default_factory=list, repr=False)  # the rows of the cases run now
    retried: int = 0              # failed or unstable rows dropped to run their cases again (--retry-failed)
    stale_lock: dict[str, Any] | None = None   # the lock record of a dead study taken over (pid, host, ...)
    unfit_workers: list[str] = field(default_factory=list)   # joiners that could not run cases, and why


def run_study(study: Study | str | Path, out: str | Path | None = None, *, workers: int | None = None,
              scheduler: str | None = None, client=None, resume: bool = False, retry_failed: bool = False,
              fmu_dir: str | Path | None = None, progress: bool = True,
              connect_timeout: float = CONNECT_TIMEOUT_S, worker_wait: float = WORKER_WAIT_S) -> StudyResult:
    """Validate, then run every case not yet recorded, appending rows to ``out/results.csv``.

    ``client``: an existing ``distributed.Client`` (then ``workers`` and
    ``scheduler`` are ignored and the client is left open).  ``resume``: complete the rows
    already in ``out``; ``retry_failed`` (implies ``resume``): run the failed and unstable
    cases again too.  Raises :class:`StudyError` for bad input before any case runs (the
    study, the folder, its lock held by another study, the scheduler, a worker's environment)
    and :class:`ClusterLost` when the scheduler goes away.

    Order: the folder is claimed (locked) first, so that a second writer is refused at once;
    then the study is validated on the FMUs, the rows already there are read, and only then is
    a cluster started or reached (not at all when every case has its row).
    """
    if not isinstance(study, Study):
        study = load_study(study)
    resume = resume or retry_failed
    fmu_dir = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()
    folder = Path(out) if out is not None else Path("out") / "studies" / study.name
    with claim_folder(folder) as claim:
        t0 = time.perf_counter()
        with ctrl_c_deferred():   # the FMUs run in this process while the study is validated
            buildings = _validate(study, fmu_dir)
        validation_s = time.perf_counter() - t0
        hashes = fmu_hashes(fmu_dir)
        header = columns_for(study, buildings)
        fingerprint = study.fingerprint(hashes)
        recorded = recorded_rows(folder, fingerprint, header, resume)
        keep = {r["case_id"] for r in recorded if r["status"] == "ok" or not retry_failed}
        cases = study.cases()
        pending = [c for c in cases if c.id not in keep]
        rows, failed, lost, retried, unfit_workers = [], 0, None, 0, []
        n_workers, startup_s, elapsed_s = 0, 0.0, 0.0
        if pending:
            t0 = time.perf_counter()
            own = client is None
            cluster = None
            writer = None
            try:
                with ctrl_c_deferred() as interrupts:   # Dask's start-up: a Ctrl-C between its steps
                    if own:
                        client, cluster = connect(scheduler, workers, connect_timeout, interrupts.check)
                    fit_workers = check_workers(client, worker_wait, interrupts.check)
                    n_workers = len(fit_workers)
                    interrupts.check()
                    retried = start_results(folder, fingerprint, recorded, retry_failed)
                    claim.written = True
                    writer = _RowWriter(folder / "results.csv", header)
                    plugin = StudyPlugin(fmu_dir, hashes)
                    client.register_plugin(plugin, name=plugin.name)
                startup_s = time.perf_counter() - t0
                t1 = time.perf_counter()
                try:
                    rows, failed, lost, unfit_workers = _execute(client, plugin.name, study, pending, writer,
                                                                 progress, len(cases) - len(pending),
                                                                 _Fitness(fit_workers))
                finally:
                    if own and client.status == "running":   # free the workers' FMU instances while they live
                        _unregister(client, plugin.name)
                elapsed_s = time.perf_counter() - t1
            finally:
                if writer is not None:
                    writer.close()
                    write_parquet(folder / "results.csv", folder / "results.parquet")
                if own and client is not None:
                    _close(client, cluster, client.status != "running")
    if lost is not None:
        raise ClusterLost(f"{lost}: {len(rows)} of the {len(pending)} cases of this run finished and are in "
                          f"{folder / 'results.csv'}, {len(pending) - len(rows)} did not run; start a scheduler "
                          f"and workers and complete the study with --resume --scheduler ADDRESS --out {folder}")
    return StudyResult(study, folder, folder / "results.csv", folder / "results.parquet", len(cases),
                       len(cases) - len(pending), len(rows), failed, n_workers, startup_s, elapsed_s,
                       validation_s, rows, retried, claim.lock.stale, unfit_workers)


def _validate(study: Study, fmu_dir: Path) -> list[str]:
    """:func:`validate_study` on the FMUs of ``fmu_dir``; the names of the scene's buildings."""
    try:
        catalog = Catalog(fmu_dir)
    except FileNotFoundError as exc:
        raise StudyError(str(exc)) from None
    try:
        return validate_study(study, catalog)
    finally:
        catalog.close()


def _unregister(client, name: str) -> None:
    try:
        client.unregister_worker_plugin(name)
    except Exception:  # noqa: BLE001 - a worker already gone has nothing left to free
        pass


def _close(client, cluster, scheduler_lost: bool) -> None:
    """Close the client (and the local cluster).  After a lost scheduler the client's reconnection
    attempt, cancelled by ``close``, would log a traceback: that logger is silenced meanwhile."""
    logger = logging.getLogger("distributed.client")
    level = logger.level
    if scheduler_lost:
        logger.setLevel(logging.CRITICAL)
    try:
        client.close(timeout=CONNECT_TIMEOUT_S)
        if cluster is not None:
            cluster.close()
    finally:
        logger.setLevel(level)


class _Fitness:
    """Which workers can run the cases: those of the start's check, and joiners checked when one
    of them refuses a case.  A worker is probed once (a hung worker the start's check passed is
    not asked again, which would hang the study)."""

    def __init__(self, fit: Sequence[str]):
        self.fit = set(fit)
        self.unfit: dict[str, str] = {}    # address -> "label: problems"

    def refresh(self, client) -> list[str]:
        """Probe the workers not seen yet; return the addresses of the fit ones present now."""
        present = set(client.scheduler_info()["workers"])
        new = sorted(present - self.fit - set(self.unfit))
        if new:
            for env in worker_environments(client, new):
                problems = env.problems(__version__)
                if problems:
                    self.unfit[env.address] = f"{env.label()}: {'; '.join(problems)}"
                else:
                    self.fit.add(env.address)
        return sorted(self.fit & present)


MAX_REROUTES = 3   # a case refused by unfit workers this often ends the study (exit 1, --resume later)


def _execute(client, plugin_name: str, study: Study, pending: list[Case], writer: _RowWriter,
             progress: bool, already: int, fitness: _Fitness) -> tuple[list[dict], int, str | None, list[str]]:
    """Submit the pending cases and write each row as it arrives.  Returns the rows, the number of
    failed ones, why the study had to stop (None if it did not: the scheduler lost, no worker
    able to run the cases) and the workers found unfit on the way (joiners)."""
    from distributed import as_completed
    from distributed.client import FutureCancelledError

    def submit(case: Case, attempt: int = 0, workers: list[str] | None = None):
        future = client.submit(_run_case_on_worker, plugin_name, study.scene_raw, list(study.fixed) + case.overrides,
                               study.energy_tolerance, key=f"cosim-case-{study.name}-{case.id}"
                               + (f"-rerouted-{attempt}" if attempt else ""), pure=False, workers=workers)
        futures[future.key] = (future, case, attempt)
        return future

    futures: dict[str, tuple[Any, Case, int]] = {}
    completed = as_completed([submit(case) for case in pending])
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=already + len(pending), initial=already, unit="case", desc=study.name, smoothing=0.1)
    rows, failed = [], 0
    try:
        for future in completed:
            _, case, attempt = futures.pop(future.key)
            try:
                row = future.result()
            except FutureCancelledError as exc:   # not by us: the scheduler is gone (or someone cancelled it)
                address = getattr(client.scheduler, "address", "?")
                return rows, failed, f"lost the Dask scheduler at {address} ({getattr(exc, 'reason', None)})", \
                    list(fitness.unfit.values())
            except WorkerUnfit as exc:   # a joiner the start's check did not see: the case goes elsewhere
                fit = fitness.refresh(client)
                if not fit or attempt >= MAX_REROUTES:
                    return rows, failed, f"no worker left that can run the cases ({one_line(exc)})", \
                        list(fitness.unfit.values())
                completed.add(submit(case, attempt + 1, fit))
                continue
            except Exception as exc:  # noqa: BLE001 - e.g. the case killed its workers (KilledWorker): a result
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
        client.cancel([f for f, _, _ in futures.values()])
        raise
    finally:
        if bar is not None:
            bar.close()
    return rows, failed, None, list(fitness.unfit.values())
