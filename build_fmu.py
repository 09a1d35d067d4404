"""``python build_fmu.py [--out DIR] [--force] [NAME ...]`` = ``pounding-cosim build-fmus ...``.

Builds every FMU into ``build/fmus`` (or ``--out``), skipping FMUs built from the same
sources; what is built and how lives in :mod:`cosim.fmus`.  A shim over :mod:`cosim.cli`.
"""
import sys
from pathlib import Path

sys.path[0] = str(Path(__file__).resolve().parent)   # this checkout's cosim, even if another is installed

from cosim.cli import console  # noqa: E402

if __name__ == "__main__":
    console(["build-fmus", *sys.argv[1:]], prog="python build_fmu.py")
