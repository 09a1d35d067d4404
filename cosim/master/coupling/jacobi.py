"""Jacobi coupling: every instance reads the outputs at t, then all step.

Buildings get the ground motion and the contact impulse one step late (first order); this
is libcosim's fixed-step algorithm.
"""
from __future__ import annotations

from .base import CouplingStrategy


class Jacobi(CouplingStrategy):
    """Parallel: every instance reads the outputs at t, then all step."""

    name = "jacobi"
    host = "zoh_late"   # building.fmu holds F exactly, over the step after the one it was computed for

    def _advance(self, t: float, h: float) -> None:
        y = self.system.y
        nodes = self.system.nodes
        for node in nodes:  # every input from the outputs at t, before anything steps
            node.pull(y)
        for node in nodes:
            node.instance.do_step(t, h)
        for node in nodes:
            node.push()
