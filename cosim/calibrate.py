"""``python cosim/calibrate.py ...`` = ``pounding-cosim calibrate ...`` (a shim over :mod:`cosim.cli`)."""
import sys
from pathlib import Path

if __package__ in (None, ""):   # run as a script: the checkout, not this folder, is the import root
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from cosim.cli import console  # noqa: E402

if __name__ == "__main__":
    console(["calibrate", *sys.argv[1:]], prog="python cosim/calibrate.py")
