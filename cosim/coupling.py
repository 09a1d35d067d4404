"""Coupling strategies: how the master advances a :class:`~cosim.master.System`.

Modelled on scipy's ``OdeSolver``: a strategy is constructed with the
system, ``t0``, ``t_bound`` and the communication step, and each call of
:meth:`CouplingStrategy.step` makes one accepted communication step
(``t`` advances, ``status`` becomes ``"finished"`` at ``t_bound``).  Cost
counters live on the strategy (``communication_steps``, ``rollbacks``) and
on the instances (FMI calls).  A new strategy subclasses
:class:`CouplingStrategy`, implements :meth:`_advance` and registers itself in
:data:`STRATEGIES`; an adaptive one may shorten ``h``, save and restore FMU
states (``Instance.get_state``/``set_state``) and count ``rollbacks``.

Signal graph (the same for every strategy; see ``Scene.connections``):
buildings' ``ag`` := ground ``ag_mean``; contact ``x1, v1`` := left
building ``x[f], v[f]`` and ``x2, v2`` := right building ``x[f'], v[f']``
(floor motion relative to the ground; body 1 is the left, negative-side
building); left ``F[f]`` -= contact ``F``, right ``F[f']`` += contact ``F``
(summed over the contact levels acting on a floor).

Gauss-Seidel (default), per communication step [t, t+h]:

1. the ground-motion FMU steps first (it has no inputs): ``ag_mean`` of
   [t, t+h] is then known;
2. each contact FMU reads the buildings' floor states at t and steps,
   integrating the impact inside the step; its output ``F`` is the mean
   force of [t, t+h], i.e. ``F h`` is the impulse of the step;
3. the buildings step with ``ag_mean`` of [t, t+h] and the contact impulses
   of [t, t+h], so every impulse reaches the buildings in the same step
   (no step of delay, which would pump energy into the impacts).

Jacobi: every FMU reads the outputs at t, then all step (in parallel, in
principle).  Buildings then use the ground's ``ag_mean`` of [t-h, t] and the
contact impulse of [t-h, t]: one step of delay, first-order accurate.
"""
from __future__ import annotations

import math

from .master import System


class CouplingStrategy:
    """Base class: fixed communication step ``h`` from ``t0`` to ``t_bound``.

    The last step is shortened to land on ``t_bound``.  Time is computed as
    ``t0 + k h`` (no accumulated round-off).
    """

    name = "base"
    #: how the buildings receive a contact's force under this strategy: the pounding.fmu
    #: parameter ``host`` (fmu_src.impact.HOSTS) the master declares for every contact whose
    #: scene leaves it unset; "any" lets the contact measure it
    host = "any"

    def __init__(self, system: System, t0: float, t_bound: float, step: float):
        if not (step > 0 and math.isfinite(step)):
            raise ValueError(f"communication step = {step!r} s must be > 0")
        self.system = system
        self.t0 = float(t0)
        self.t = float(t0)
        self.t_bound = float(t_bound)
        self.h = float(step)
        self.status = "running" if t_bound > t0 else "finished"
        self.communication_steps = 0
        self.rollbacks = 0
        # steps shorter than 1e-9 h are round-off of t_bound / h, not a real step
        self._n_steps = max(1, math.ceil((self.t_bound - self.t0) / self.h - 1e-9))

    def step(self) -> None:
        """Advance one communication step."""
        if self.status != "running":
            raise RuntimeError("the strategy has already finished")
        k = self.communication_steps
        t = self.t0 + k * self.h
        t_next = self.t_bound if k + 1 >= self._n_steps else self.t0 + (k + 1) * self.h
        self._advance(t, t_next - t)
        self.communication_steps += 1
        self.t = t_next
        if k + 1 >= self._n_steps:
            self.status = "finished"

    def _advance(self, t: float, h: float) -> None:
        raise NotImplementedError


class GaussSeidel(CouplingStrategy):
    """Sequential: ground, then contacts (from the buildings at t), then buildings."""

    name = "gauss-seidel"
    host = "zoh"        # building.fmu holds F exactly over the step it was computed for

    def __init__(self, system: System, t0: float, t_bound: float, step: float):
        super().__init__(system, t0, t_bound, step)
        self._order = system.ground + system.contacts + system.buildings

    def _advance(self, t: float, h: float) -> None:
        y = self.system.y
        for node in self._order:
            node.step(y, t, h)


class Jacobi(CouplingStrategy):
    """Parallel: every instance reads the outputs at t, then all step."""

    name = "jacobi"
    host = "zoh_late"   # ... over the step after

    def _advance(self, t: float, h: float) -> None:
        y = self.system.y
        nodes = self.system.nodes
        for node in nodes:  # every input from the outputs at t, before anything steps
            node.pull(y)
        for node in nodes:
            node.instance.do_step(t, h)
        for node in nodes:
            node.push()


STRATEGIES: dict[str, type[CouplingStrategy]] = {GaussSeidel.name: GaussSeidel, Jacobi.name: Jacobi}


def get_strategy(strategy: str | type[CouplingStrategy]) -> type[CouplingStrategy]:
    if isinstance(strategy, type) and issubclass(strategy, CouplingStrategy):
        return strategy
    try:
        return STRATEGIES[strategy]
    except KeyError:
        raise ValueError(f"unknown coupling {strategy!r}; known: {', '.join(STRATEGIES)}") from None


# The adaptive strategy with rollback lives in cosim/adaptive.py (it subclasses
# CouplingStrategy) and registers itself in STRATEGIES when imported.
from . import adaptive as _adaptive  # noqa: E402,F401
