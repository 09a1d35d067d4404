"""Dormant contacts: no call to a contact FMU over a step in which its gap cannot close.

A contact FMU out of contact has nothing to do while its gap provably stays open
(:mod:`cosim.master.gap_bound`).  The master then does not call it: the contact *sleeps*.  Its
outputs stay those of its last step (``F = 0``: it was out of contact), and the master keeps
what it would have been given, the floors' states at the start of each skipped step.

When the gap may close again (or the run ends) the contact *wakes* and catches up, so that it
is at the same time as the others and in the state it would have had, in at most
``1 + ORDINARY_STEPS`` doSteps whatever the length slept, every one declared open (``pounding.fmu``
input ``gap_open``, :meth:`LoggedContact.declare_open`: the master proved the gap open over
them, so the contact does no onset search and predicts no flight over them, fmu_src/resolver.py
rule 8):

1. one step over the skipped interval up to the start of its last ``ORDINARY_STEPS`` steps,
   from the floors' states at its start;
2. the last ``ORDINARY_STEPS`` skipped steps as they would have been taken, each from the
   floors' states at its start: the contact learns the structures' motion from the host's
   increments over its last steps (rule 1: the extrapolation of the means of its last two
   steps), so the step that follows is the one it would have taken without sleeping.

A skipped step longer than ``span`` (a long step of the adaptive master, which only an asleep
contact ever sees) that holds one of those last steps is cut into equal pieces of at most
``span``, the floors' states inside it interpolated between its ends (cubic Hermite: positions
from the positions and velocities at both ends, velocities its derivative): the contact's
prediction of the step after the catch-up is learnt from them.

The master proved the gap open over the whole interval, so the catch-up must leave the
contact as it was (no impact, no dissipation, no force).  A contact FMU that nevertheless
finds an impact there (one that took a declared step in full: an impact in progress, an
impulse still on its way) is restored to its state when it fell asleep (saved then with
``fmi2GetFMUstate``) and given every skipped step as it would have had them, undeclared, a step
longer than ``span`` in pieces as above (``stats["catch_up_replays"]``): results are then those
of a run without sleeping.

Counters in ``stats``: ``dormant_steps`` (contact steps not called), ``catch_ups``,
``catch_up_steps`` (the doSteps they made), ``catch_up_replays``.  Every step attempt calls a
contact once or counts it dormant, so its doSteps are the attempts minus ``dormant_steps``
plus ``catch_up_steps``.  The bookkeeping follows the adaptive coupling's rollback
(:meth:`Dormancy.snapshot` / :meth:`Dormancy.restore`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .system import Node, System

#: ordinary steps that end a catch-up: the resolver extrapolates the structures' acceleration
#: from the means of its last two steps (fmu_src/host_observer.py, ``HostObserver._predict``), so
#: after two ordinary steps its prediction of the next step is the one it makes without sleeping
#: (a host with exact positions, ``host = "zoh"``: after one)
ORDINARY_STEPS = 2


@dataclass
class _Sleep:
    """One contact's sleep: its FMU state when it fell asleep and the steps it skipped."""

    state: Any                                       # fmi2FMUstate at the start of the first skipped step
    skipped: list = field(default_factory=list)      # (t, h, inputs) of every skipped step
    outputs: np.ndarray | None = None                # the contact's watched outputs then
    impacts: int = 0


class Dormancy:
    """Which contact FMUs sleep and how they catch up (module docstring)."""

    def __init__(self, system: "System", stats: dict, span: float):
        """``span`` [s]: the longest ordinary catch-up step (module docstring)."""
        if not (span > 0.0 and math.isfinite(span)):
            raise ValueError(f"catch-up span = {span!r} s must be > 0")
        self.span = float(span)
        self.system = system
        self.stats = stats
        stats.setdefault("dormant_steps", 0)
        stats.setdefault("catch_ups", 0)
        stats.setdefault("catch_up_steps", 0)
        stats.setdefault("catch_up_replays", 0)
        self.sleeping: dict[str, _Sleep] = {}
        self._retired: list[Any] = []               # states freed at the next commit
        self._i_impacts: dict[str, int] = {}
        #: per contact: the (position, velocity) input pairs ``x<i>``, ``v<i>`` for the Hermite
        #: interpolation inside a long skipped step (None: inputs of another kind, not split)
        self._pairs: dict[str, tuple[np.ndarray, np.ndarray] | None] = {}
        #: outputs that stay as they are over a step out of contact: the force (0) and the energy
        #: dissipated so far (the catch-up checks them, with the impacts counter)
        self._quiet: dict[str, np.ndarray] = {}
        index = {c: i for i, c in enumerate(system.columns[:system.y.size])}
        for node in system.contacts:
            names = node.integers.names
            self._i_impacts[node.name] = names.index("impacts") if "impacts" in names else -1
            self._pairs[node.name] = _position_velocity_pairs(list(node.inputs.names)[:node.A.shape[0]])
            self._quiet[node.name] = np.array([index[f"{node.name}.{v}"] for v in ("F", "E_dissipated")
                                               if f"{node.name}.{v}" in index], dtype=np.intp)

    def asleep(self, node: "Node") -> bool:
        return node.name in self.sleeping

    def skip(self, node: "Node", t: float, h: float) -> None:
        """``node`` does not step over ``[t, t + h]`` (it falls asleep now if awake)."""
        sleep = self.sleeping.get(node.name)
        if sleep is None:
            sleep = self.sleeping[node.name] = _Sleep(
                node.instance.get_state(), outputs=self.system.y[self._quiet[node.name]].copy(),
                impacts=self._impacts(node))
        inputs = np.empty(node.A.shape[0])
        if inputs.size:
            node._inputs(self.system.y, inputs)
        sleep.skipped.append((t, h, inputs))
        self.stats["dormant_steps"] += 1

    def _impacts(self, node: "Node") -> int:
        i = self._i_impacts[node.name]
        return int(node.integers.values[i]) if i >= 0 else 0

    def wake(self, node: "Node") -> None:
        """Catch ``node`` up to the end of its last skipped step (module docstring)."""
        sleep = self.sleeping.pop(node.name, None)
        if sleep is None:
            return
        self.stats["catch_ups"] += 1
        skipped = sleep.skipped
        tail = self._tail(node, skipped)
        t0, _, u0 = skipped[0]
        steps = ([(t0, tail[0][0] - t0, u0)] if tail[0][0] > t0 else []) + tail
        inst, inputs = node.instance, node.inputs
        inst.declare_open(True)             # the proof holds over every one of them
        try:
            for t, h, u in steps:
                inputs.set(u)
                inst.do_step(t, h)
        finally:                            # no later step, saved state or replay inherits it
            inst.declare_open(False)
        self.stats["catch_up_steps"] += len(steps)
        node.push()
        node.integers.get()
        now = self.system.y[self._quiet[node.name]]
        if self._impacts(node) != sleep.impacts or not np.array_equal(now, sleep.outputs):
            # the contact found what the proof excludes: redo the interval as it would have been
            self.stats["catch_up_replays"] += 1
            inst.set_state(sleep.state)
            for t, h, u in (piece for k in range(len(skipped)) for piece in self._pieces(node, skipped, k)):
                inputs.set(u)
                inst.do_step(t, h)
                self.stats["catch_up_steps"] += 1
            node.push()
            node.integers.get()
        self._retired.append((inst, sleep.state))

    def _tail(self, node: "Node", skipped: list) -> list:
        """The last ``ORDINARY_STEPS`` steps of ``skipped`` as the contact takes them, ``(t, h,
        inputs)``: a skipped step longer than ``span`` cut into pieces (module docstring)."""
        tail: list = []
        k = len(skipped)
        while len(tail) < ORDINARY_STEPS and k > 0:
            k -= 1
            tail[:0] = self._pieces(node, skipped, k)
        return tail[-ORDINARY_STEPS:]

    def _pieces(self, node: "Node", skipped: list, k: int) -> list:
        """Skipped step ``k`` as ``(t, h, inputs)`` pieces: itself, or when longer than ``span``
        equal pieces of at most ``span``, the inputs inside interpolated (module docstring)."""
        t, h, u0 = skipped[k]
        pairs = self._pairs[node.name]
        if pairs is None or h <= self.span * (1.0 + 1e-9):
            return [skipped[k]]
        ix, iv = pairs
        if k + 1 < len(skipped):
            u1 = skipped[k + 1][2]
        else:                                       # the last skipped step ends now
            u1 = np.empty(node.A.shape[0])
            node._inputs(self.system.y, u1)
        m = math.ceil(h / self.span - 1e-9)
        return [(t + j * h / m, h / m, hermite(u0, u1, ix, iv, h, j / m)) for j in range(m)]

    def wake_all(self) -> None:
        for node in self.system.contacts:
            if node.name in self.sleeping:
                self.wake(node)

    # -- rollback ----------------------------------------------------------------------------------
    def snapshot(self) -> dict[str, _Sleep]:
        """The bookkeeping now (taken with the FMU states before a step that may be redone)."""
        return {name: _Sleep(s.state, list(s.skipped), s.outputs, s.impacts) for name, s in self.sleeping.items()}

    def restore(self, snapshot: dict[str, _Sleep]) -> None:
        """Back to ``snapshot``: states saved since then are freed, those it holds stay."""
        kept = {id(s.state) for s in snapshot.values()}
        for name, sleep in self.sleeping.items():
            if id(sleep.state) not in kept:
                self._free(self.system.node(name).instance, sleep.state)
        self._retired = [(inst, st) for inst, st in self._retired if id(st) not in kept] 
        for inst, st in self._retired:
            self._free(inst, st)
        self._retired = []
        self.sleeping = {name: _Sleep(s.state, list(s.skipped), s.outputs, s.impacts) for name, s in snapshot.items()}

    def commit(self) -> None:
        """The step is accepted: free the states of the contacts that woke in it."""
        for inst, state in self._retired:
            self._free(inst, state)
        self._retired = []

    @staticmethod
    def _free(instance, state) -> None:
        instance.free_state(state)


def _position_velocity_pairs(names: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """Indices of the inputs ``x<i>`` and their ``v<i>`` when every input is one of such a pair."""
    ix, iv = [], []
    for i, name in enumerate(names):
        if name.startswith("x") and ("v" + name[1:]) in names:
            ix.append(i)
            iv.append(names.index("v" + name[1:]))
    if not ix or 2 * len(ix) != len(names):
        return None
    return np.array(ix, dtype=np.intp), np.array(iv, dtype=np.intp)


def hermite(u0: np.ndarray, u1: np.ndarray, ix: np.ndarray, iv: np.ndarray, h: float, s: float) -> np.ndarray:
    """Inputs at the fraction ``s`` of a step of ``h`` s: positions ``u[ix]`` by the cubic Hermite
    through the positions and velocities ``u[iv]`` at both ends, velocities its derivative."""
    x0, x1, v0, v1 = u0[ix], u1[ix], u0[iv], u1[iv]
    s2, s3 = s * s, s * s * s
    u = np.empty_like(u0)
    u[ix] = (2 * s3 - 3 * s2 + 1) * x0 + (s3 - 2 * s2 + s) * h * v0 + (3 * s2 - 2 * s3) * x1 + (s3 - s2) * h * v1
    u[iv] = ((6 * s2 - 6 * s) * (x0 - x1)) / h + (3 * s2 - 4 * s + 1) * v0 + (3 * s2 - 2 * s) * v1
    return u
