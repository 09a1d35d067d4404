"""Shared fixtures: FMUs are built once per test session into a temporary folder."""
from __future__ import annotations

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
