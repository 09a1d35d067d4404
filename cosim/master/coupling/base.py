"""The base of every coupling strategy: how the master advances a :class:`~cosim.master.system.System`.

Modelled on scipy's ``OdeSolver``: a strategy is constructed with the
system, ``t0``, ``t_bound`` and the communication step, and each call of
:meth:`CouplingStrategy.step` makes one accepted communication step
(``t`` advances, ``status`` becomes ``"finished"`` at ``t_bound``).  Cost
counters live on the strategy (``communication_steps``, ``rollbacks``) and
on the instances (FMI calls).  A new strategy subclasses
:class:`CouplingStrategy` in a module of its own, implements :meth:`_advance` and is
added to the registry :data:`cosim.master.coupling.STRATEGIES` (one line); an adaptive
one may shorten ``h``, save and restore FMU states (``Instance.get_state``/``set_state``)
and count ``rollbacks``.  A strategy sees the system only through its protocol
(``y``, ``nodes``, ``ground``/``contacts``/``buildings``, each node's ``pull``/``step``/
``push``): a system of fake instances tests it without any FMU.

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
from typing import TYPE_CHECKING, Container

if TYPE_CHECKING:
    from ..system import System


class CouplingStrategy:
    """Base class: fixed communication step ``h`` from ``t0`` to ``t_bound``.

    The last step is shortened to land on ``t_bound``.  Time is computed as
    ``t0 + k h`` (no accumulated round-off).
    """

    name = "base"
    #: how the buildings receive a contact's force under this strategy: the pounding.fmu
    #: parameter ``host`` (fmu_src.host_observer.HOSTS) the master declares for every contact whose
    #: scene leaves it unset; "any" lets the contact measure it
    host = "any"
    #: takes steps longer than ``step``: a run that asks for history rows at an output interval
    #: passes it as the keyword ``row_interval`` (s), and the steps land on every row time
    #: (cosim.master.simulate)
    takes_long_steps = False

    def __init__(self, system: "System", t0: float, t_bound: float, step: float):
        if not (step > 0 and math.isfinite(step)):
            raise ValueError(f"communication step = {step!r} s must be > 0")
        self.system = system
        if getattr(system, "knots", 0):     # a strategy that hands knots over says so itself
            system.use_knots(0)
        self.t0 = float(t0)
        self.t = float(t0)
        self.t_bound = float(t_bound)
        self.h = float(step)
        self.status = "running" if t_bound > t0 else "finished"
        self.communication_steps = 0
        self.rollbacks = 0
        # steps shorter than 1e-9 h are round-off of t_bound / h, not a real step
        self._n_steps = max(1, math.ceil((self.t_bound - self.t0) / self.h - 1e-9))

    #: called with the end time (s) of a step before the step is taken (the run loop uses it to
    #: read the recorded outputs with that step's read: :class:`cosim.master.system.ReadPlan`)
    on_step = None

    def watched_columns(self) -> list[str]:
        """The Real outputs this strategy reads after every step: the coupling's sources."""
        return self.system.coupling_sources()

    def finish(self) -> None:
        """Bring every instance to the end time (a strategy that skips calls catches up here)."""

    def sleeping(self) -> Container[str]:
        """The contact instances (names) not called since before the last accepted step (asleep,
        :mod:`cosim.master.dormancy`): their outputs are those they had at its start.  None here."""
        return ()

    def _before(self, t_next: float) -> None:
        if self.on_step is not None:
            self.on_step(t_next)

    def step(self) -> None:
        """Advance one communication step."""
        if self.status != "running":
            raise RuntimeError("the strategy has already finished")
        k = self.communication_steps
        t = self.t0 + k * self.h
        t_next = self.t_bound if k + 1 >= self._n_steps else self.t0 + (k + 1) * self.h
        self._before(t_next)
        self._advance(t, t_next - t)
        self.communication_steps += 1
        self.t = t_next
        if k + 1 >= self._n_steps:
            self.status = "finished"

    def _advance(self, t: float, h: float) -> None:
        raise NotImplementedError
