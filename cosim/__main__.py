"""``python -m cosim ...`` = ``pounding-cosim ...`` (:mod:`cosim.cli`)."""
from cosim.cli import console

console()
