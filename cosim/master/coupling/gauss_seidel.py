"""Gauss-Seidel coupling: ground, then contacts (from the buildings at t), then buildings.

Every impulse reaches the buildings in the step it happens in (see :mod:`.base` for the
signal graph and the order).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from .base import CouplingStrategy

if TYPE_CHECKING:
    from ..system import System


class GaussSeidel(CouplingStrategy):
    """Sequential: ground, then contacts (from the buildings at t), then buildings."""

    name = "gauss-seidel"
    host = "zoh"        # building.fmu holds F exactly over the step it was computed for

    def __init__(self, system: "System", t0: float, t_bound: float, step: float):
        super().__init__(system, t0, t_bound, step)
        self._order = system.ground + system.contacts + system.buildings

    def _advance(self, t: float, h: float) -> None:
        y = self.system.y
        for node in self._order:
            node.step(y, t, h)
