"""Fresh virtual environments for the tests that run the package or its FMUs outside this one
(tests marked ``venv``: test_fmu_hosts, test_wheel)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def pip_install(python: Path, *args: str) -> subprocess.CompletedProcess:
    """``pip install -q --no-compile ARGS`` into the environment of ``python`` by this
    environment's pip (``pip --python``, pip >= 22.3): the new environment needs no pip of its own
    (seeding it costs ~3 s), and skipping the byte-compilation of numpy, scipy and matplotlib
    (~5 s) changes nothing the tests import (imports compile what they load)."""
    return subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-compile",
                           *args], capture_output=True, text=True)


def make_venv(folder: Path, packages: list[str]) -> Path:
    """A fresh virtual environment with ``packages`` and nothing else (not even pip); returns its
    python."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(folder)], check=True)
    python = folder / "bin" / "python"
    proc = pip_install(python, *packages)
    assert proc.returncode == 0, f"pip install {packages} failed:\n{proc.stderr[-2000:]}"
    return python
