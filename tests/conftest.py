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
    from build_fmu import build_all

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
    from cosim.master import Catalog

    with Catalog(fmu_dir) as cat:
        yield cat
