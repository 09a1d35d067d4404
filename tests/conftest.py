"""Shared fixtures: FMUs are built once per test session into a temporary folder.

The suite runs on every core (pytest-xdist, ``-n auto`` in pyproject's addopts): each worker is
its own session, so session fixtures run once per worker, each into its own temporary folder.
Tests whose assertions bound a wall time (an unbounded request refused "in under 5 s", the
child's start and imports included) are marked ``exclusive``: no other test of the suite runs
while they do (:func:`pytest_runtest_protocol`), so that they see the machine as in a
one-process run.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory) -> Path:
    """Folder holding every FMU, built from the current sources for this session."""
    from cosim.fmus import build_all

    out = tmp_path_factory.mktemp("fmus")
    build_all(out)
    return out


@pytest.fixture(scope="session")
def fmu_path(fmu_dir):
    """``fmu_path("pounding")`` -> path of the built pounding.fmu."""
    def get(name: str) -> Path:
        path = fmu_dir / f"{name}.fmu"
        assert path.exists(), f"{name}.fmu was not built"
        return path
    return get


@pytest.fixture(scope="module")
def catalog(fmu_dir):
    """The session's FMUs loaded once per test module (``cosim.master.Catalog``)."""
    from cosim.master.system import Catalog

    with Catalog(fmu_dir) as cat:
        yield cat


# -- several workers (pytest-xdist) ---------------------------------------------------------------
def _share_locks(item) -> tuple[int, int] | None:
    """The two lock files the workers of this run share (opened once per worker), or None when
    the suite runs in one process.  In the run's base temporary folder: the controller's, whose
    subfolders (``popen-gw0``, ...) are the workers' own."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return None
    stash = item.config.stash
    if _LOCKS not in stash:
        # what the tmp_path_factory fixture returns; a worker's base folder is <run's>/popen-gwN
        shared = item.config._tmp_path_factory.getbasetemp().parent
        stash[_LOCKS] = tuple(os.open(shared / name, os.O_RDWR | os.O_CREAT, 0o600)
                              for name in ("machine.gate.lock", "machine.lock"))
    return stash[_LOCKS]


#: the worker's open lock files (per pytest config, not module state)
_LOCKS = pytest.StashKey[tuple[int, int]]()


@contextlib.contextmanager
def _machine_share(item):
    """A readers-writer lock over the workers: an ``exclusive`` test holds ``machine.lock``
    exclusively, every other test holds it shared.  ``machine.gate.lock`` gives the writer
    priority: a waiting exclusive test holds the gate, so no new test starts on another worker
    meanwhile (without it two workers taking turns could keep the lock shared for ever).  Both
    locks are always taken in the same order (gate, then machine): no deadlock."""
    locks = _share_locks(item)
    if locks is None:
        yield
        return
    gate, machine = locks
    exclusive = item.get_closest_marker("exclusive") is not None
    fcntl.flock(gate, fcntl.LOCK_EX)
    try:
        fcntl.flock(machine, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
    except BaseException:   # interrupted while waiting: never leave the gate shut
        fcntl.flock(gate, fcntl.LOCK_UN)
        raise
    if not exclusive:
        fcntl.flock(gate, fcntl.LOCK_UN)
    try:
        yield
    finally:
        fcntl.flock(machine, fcntl.LOCK_UN)
        if exclusive:
            fcntl.flock(gate, fcntl.LOCK_UN)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Setup, call and teardown of ``item`` under :func:`_machine_share`."""
    with _machine_share(item):
        yield


_EXIT_STATUS = []


def pytest_sessionfinish(session, exitstatus):
    _EXIT_STATUS.append(int(exitstatus))


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """End the test process like the command-line tools do (cosim.fmi.exit_process): once
    pythonfmu libraries are loaded, a normal interpreter exit can abort on a corrupted heap
    after every test has passed, and CI would read exit code 134."""
    from cosim.master.fmi import exit_process, libraries_loaded

    if libraries_loaded() and _EXIT_STATUS:
        exit_process(_EXIT_STATUS[-1])
