"""A real Dask cluster on this machine: ``dask scheduler`` and ``dask worker`` as separate processes.

What a cluster of several machines looks like to a study, on 127.0.0.1: the scheduler and each
worker are their own process (each in its own process group, so that it can be stopped, or
killed as a lost machine would be, with everything it started), and each worker runs in its own
working directory with its own temporary folder and Dask local directory, none of them the
submitter's.  Used by the tests of :mod:`cosim.apps.study` on a cluster and by
``benchmarks/bench_study.py --cluster loopback``; docs/studies.md shows the same commands typed
by hand.

    with LoopbackCluster(root) as cluster:
        cluster.add_worker("w1"); cluster.add_worker("w2")
        run_study(study, out, scheduler=cluster.address)

Every wait is bounded (:data:`START_TIMEOUT_S`); :meth:`LoopbackCluster.close` stops every
process it started, by process group (SIGTERM, then SIGKILL after :data:`STOP_TIMEOUT_S`).
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

START_TIMEOUT_S = 60.0   # a scheduler or worker that is not up by then is reported with its log
STOP_TIMEOUT_S = 10.0    # SIGTERM, then SIGKILL


class LoopbackError(RuntimeError):
    """A process of the loopback cluster did not start; the message ends with its log."""


@dataclass
class ClusterProcess:
    """One process of the cluster (scheduler or worker), the leader of its own process group."""

    name: str
    popen: subprocess.Popen
    folder: Path
    log: Path

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None

    def log_tail(self, lines: int = 15) -> str:
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""

    def signal_group(self, sig: int) -> None:
        try:
            os.killpg(self.pid, sig)
        except ProcessLookupError:
            pass

    def freeze(self) -> None:
        """SIGSTOP to the process group: the process hangs as a stalled machine would (it keeps its
        connections open, so the scheduler still counts on it)."""
        self.signal_group(signal.SIGSTOP)

    def thaw(self) -> None:
        """SIGCONT to the process group: a frozen process runs on."""
        self.signal_group(signal.SIGCONT)

    def kill(self) -> None:
        """SIGKILL to the whole process group (the nanny and its worker process): a lost machine."""
        self.signal_group(signal.SIGKILL)
        self.popen.wait(STOP_TIMEOUT_S)

    def stop(self) -> None:
        """SIGTERM to the process group, SIGKILL after :data:`STOP_TIMEOUT_S`."""
        if self.alive():
            self.signal_group(signal.SIGTERM)
            self.signal_group(signal.SIGCONT)   # a stopped process (a test froze it) must run to end
            try:
                self.popen.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                pass
        self.signal_group(signal.SIGKILL)   # whatever of the group is left (a nanny's child)
        self.popen.wait(STOP_TIMEOUT_S)


class LoopbackCluster:
    """A scheduler on 127.0.0.1 (a free port chosen by the system) and workers added one by one.

    ``root``: a folder for the processes' folders and logs (created).  ``python``: the
    interpreter of the processes (default: this one).
    """

    def __init__(self, root: str | Path, python: str | None = None, start_scheduler: bool = True):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.python = python or sys.executable
        self.scheduler: ClusterProcess | None = None
        self.workers: dict[str, ClusterProcess] = {}
        self.address: str | None = None
        self._schedulers = 0
        if start_scheduler:
            self.start_scheduler()

    # -- processes ---------------------------------------------------------------------------------
    def _spawn(self, name: str, argv: Sequence[str], folder: Path, env: Mapping[str, str] | None = None,
               python: str | None = None, python_flags: Sequence[str] = ()) -> ClusterProcess:
        folder.mkdir(parents=True, exist_ok=True)
        log = folder / "process.log"
        environ = dict(os.environ)
        environ.update(env or {})
        with open(log, "ab") as out:
            popen = subprocess.Popen([python or self.python, *python_flags, "-m", "dask", *argv], cwd=folder,
                                     env=environ, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                     start_new_session=True)
        return ClusterProcess(name, popen, folder, log)

    def start_scheduler(self) -> str:
        """Start ``dask scheduler`` (a new one after :meth:`kill_scheduler`); returns its address."""
        if self.scheduler is not None and self.scheduler.alive():
            raise LoopbackError("the scheduler is already running")
        self._schedulers += 1
        folder = self.root / f"scheduler-{self._schedulers}"
        file = folder / "scheduler.json"
        process = self._spawn("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                            "--dashboard-address", "127.0.0.1:0",
                                            "--scheduler-file", str(file)], folder)
        self.scheduler = process
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if not process.alive():
                break
            try:
                self.address = json.loads(file.read_text())["address"]
                return self.address
            except (OSError, ValueError, KeyError):   # not written yet, or half written
                time.sleep(0.05)
        process.stop()
        raise LoopbackError(f"dask scheduler did not start within {START_TIMEOUT_S:g} s:\n{process.log_tail()}")

    def add_worker(self, name: str, *, wait: bool = True, env: Mapping[str, str] | None = None,
                   python: str | None = None, python_flags: Sequence[str] = (), nanny: bool = True) -> ClusterProcess:
        """Start ``dask worker`` named ``name`` (one thread) in its own folder ``root/<name>``:
        working directory, ``TMPDIR`` (``tmp/``) and Dask local directory (``local/``).  ``wait``:
        return once the scheduler lists it.  ``env``, ``python``, ``python_flags``: another
        environment for this worker (tests of workers that lack something)."""
        if self.address is None or name in self.workers:
            raise LoopbackError(f"worker {name!r}: no scheduler, or the name is taken")
        folder = self.root / name
        (folder / "tmp").mkdir(parents=True, exist_ok=True)
        argv = ["worker", self.address, "--name", name, "--nthreads", "1", "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
                "--local-directory", str(folder / "local"), "--nanny" if nanny else "--no-nanny"]
        process = self._spawn(name, argv, folder, {"TMPDIR": str(folder / "tmp"), **(env or {})}, python,
                              python_flags)
        self.workers[name] = process
        if wait:
            self.wait_for_workers([name])
        return process

    def wait_for_workers(self, names: Sequence[str], timeout: float = START_TIMEOUT_S) -> None:
        """Return once the scheduler lists workers of these names; raise with their logs otherwise."""
        from distributed import Client

        deadline = time.monotonic() + timeout
        listed: set[str] = set()
        with Client(self.address, timeout=timeout) as client:
            while time.monotonic() < deadline:
                listed = {str(w.get("name")) for w in client.scheduler_info()["workers"].values()}
                if set(names) <= listed:
                    return
                dead = [n for n in names if not self.workers[n].alive()]
                if dead:
                    break
                time.sleep(0.1)
        missing = [n for n in names if n not in listed]
        raise LoopbackError(f"workers {missing} did not join {self.address} within {timeout:g} s:\n"
                            + "\n".join(f"--- {n}:\n{self.workers[n].log_tail()}" for n in missing))

    def kill_worker(self, name: str) -> None:
        """SIGKILL the worker's process group: the machine is lost, nothing is shut down in order."""
        self.workers[name].kill()

    def kill_scheduler(self) -> None:
        """SIGKILL the scheduler's process group (its workers keep running, without a scheduler)."""
        if self.scheduler is not None:
            self.scheduler.kill()
        self.address = None

    def processes(self) -> list[ClusterProcess]:
        return [p for p in [self.scheduler, *self.workers.values()] if p is not None]

    def close(self) -> None:
        """Stop every process this cluster started (workers first), by process group."""
        for process in [*self.workers.values(), self.scheduler]:
            if process is not None:
                process.stop()

    def __enter__(self) -> "LoopbackCluster":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
