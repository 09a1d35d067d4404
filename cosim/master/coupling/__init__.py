"""Coupling strategies, one small class per algorithm, registered in ONE table.

:data:`STRATEGIES` (name -> class) is the list every part of the package uses: the scene
loader checks a scene's ``coupling`` against it, the command line offers its names and the
accuracy study runs them.  A new strategy is a module with a subclass of
:class:`~cosim.master.coupling.base.CouplingStrategy` plus one line here.
"""
from __future__ import annotations

from types import MappingProxyType

from .adaptive import Adaptive
from .base import CouplingStrategy
from .gauss_seidel import GaussSeidel
from .jacobi import Jacobi

STRATEGIES: "MappingProxyType[str, type[CouplingStrategy]]" = MappingProxyType({
    cls.name: cls for cls in (GaussSeidel, Jacobi, Adaptive)})
#: the registered names, in the order of the table (scene files, --coupling)
COUPLINGS = tuple(STRATEGIES)


def get_strategy(strategy: str | type[CouplingStrategy]) -> type[CouplingStrategy]:
    """The strategy class registered as ``strategy`` (or ``strategy`` itself if it is a class)."""
    if isinstance(strategy, type) and issubclass(strategy, CouplingStrategy):
        return strategy
    try:
        return STRATEGIES[strategy]
    except KeyError:
        raise ValueError(f"unknown coupling {strategy!r}; known: {', '.join(STRATEGIES)}") from None


__all__ = ["STRATEGIES", "COUPLINGS", "CouplingStrategy", "GaussSeidel", "Jacobi", "Adaptive", "get_strategy"]
