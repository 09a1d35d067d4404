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

What a sleep costs per step: one row of a journal shared by every sleeping contact, the
step's ``(t, h)`` and the floors' states its inputs come from (one gather of ``System.y``,
:meth:`Dormancy.skip`); a contact's own inputs for a skipped step are computed from that row
only when it wakes (:class:`_Skipped`), with the same arithmetic as at the step.  On
kasai_maison 7 of the 8 contacts sleep at most steps: one row instead of 7 sets of inputs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .system import Node, System

#: ordinary steps that end a catch-up: the resolver extrapolates the structures' acceleration
#: from the means of its last two steps (fmu_src/host_observer.py, ``HostObserver._predict``), so
#: after two ordinary steps its prediction of the next step is the one it makes without sleeping
#: (a host with exact positions, ``host = "zoh"``: after one)
ORDINARY_STEPS = 2
#: journal rows no sleeping contact needs any more that :meth:`Dormancy.commit` lets pile up before
#: it drops them (a list's head is dropped by moving its tail: not at every step)
JOURNAL_TRIM = 256


@dataclass(frozen=True, eq=False)
class _Sleep:
    """One contact's sleep: its FMU state when it fell asleep, where its skipped steps begin in the
    journal (:class:`Dormancy`: an absolute row number) and what the catch-up must find unchanged."""

    state: Any                                       # fmi2FMUstate at the start of the first skipped step
    start: int                                       # journal row of its first skipped step
    outputs: np.ndarray | None = None                # the contact's watched outputs then
    impacts: int = 0


class _Snapshot(dict):
    """The sleeps at a save (contact name -> :class:`_Sleep`) and the journal's length then."""

    journal = 0


class _Skipped:
    """The steps one contact skipped, ``(t, h, inputs)`` each, read from the journal (rows
    ``start`` to ``end``) when asked: its inputs from the row's gathered sources with the same
    arithmetic as :meth:`cosim.master.system.Node._inputs` at that step."""

    def __init__(self, dormancy: "Dormancy", node: "Node", start: int, end: int):
        self._d, self._node, self._start, self._n = dormancy, node, start, end - start

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, k: int) -> tuple[float, float, np.ndarray]:
        if k < 0:
            k += self._n
        if not 0 <= k < self._n:
            raise IndexError(k)
        d, node = self._d, self._node
        row = self._start + k - d._base
        t, h = d._steps[row]
        sources = d._sources[row]
        inputs = np.empty(node.A.shape[0])
        if inputs.size:
            local = d._local.get(node.name)
            if local is None:                       # a row of the whole System.y
                node._inputs(sources, inputs)
            else:
                np.multiply(sources[local], node._factor, out=inputs)
        return t, h, inputs


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
        #: the journal's oldest needed row was looked for (commit) and no contact woke since
        self._oldest_known = False
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
        # the journal of skipped steps, shared by every sleeping contact: row r (absolute number
        # r, list index r - _base) holds a step's (t, h) and the values of System.y the contacts'
        # inputs are taken from at its start (``_columns``; every value when a contact's inputs
        # are not single outputs with a factor: ``_columns`` None)
        self._steps: list[tuple[float, float]] = []
        self._sources: list[np.ndarray] = []
        self._base = 0
        single = all(n._source is not None for n in system.contacts if n.A.shape[0])
        self._columns: np.ndarray | None = None
        self._local: dict[str, np.ndarray] = {}     # contact -> its sources' places in a row
        if single:
            used = [n._source for n in system.contacts if n.A.shape[0]]
            self._columns = np.unique(np.concatenate(used)) if used else np.zeros(0, dtype=np.intp)
            for n in system.contacts:
                if n.A.shape[0]:
                    self._local[n.name] = np.searchsorted(self._columns, n._source)

    def asleep(self, node: "Node") -> bool:
        return node.name in self.sleeping

    def skip(self, nodes: "list[Node]", t: float, h: float) -> None:
        """``nodes`` do not step over ``[t, t + h]`` (each falls asleep now if awake): one journal
        row for all of them."""
        if not nodes:
            return
        y = self.system.y
        row = self._base + len(self._steps)
        sleeping = self.sleeping
        for node in nodes:
            if node.name not in sleeping:
                sleeping[node.name] = _Sleep(node.instance.get_state(), row,
                                             outputs=y[self._quiet[node.name]].copy(), impacts=self._impacts(node))
        self._steps.append((t, h))
        self._sources.append(y[self._columns] if self._columns is not None else y.copy())
        self.stats["dormant_steps"] += len(nodes)

    def _impacts(self, node: "Node") -> int:
        i = self._i_impacts[node.name]
        return int(node.integers.values[i]) if i >= 0 else 0

    def wake(self, node: "Node") -> None:
        """Catch ``node`` up to the end of its last skipped step (module docstring)."""
        sleep = self.sleeping.pop(node.name, None)
        if sleep is None:
            return
        self._oldest_known = False
        self.stats["catch_ups"] += 1
        skipped = _Skipped(self, node, sleep.start, self._base + len(self._steps))
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
    def snapshot(self) -> _Snapshot:
        """The bookkeeping now (taken with the FMU states before a step that may be redone)."""
        snap = _Snapshot(self.sleeping)
        snap.journal = self._base + len(self._steps)
        return snap

    def restore(self, snapshot: _Snapshot) -> None:
        """Back to ``snapshot``: states saved since then are freed, those it holds stay."""
        kept = {id(s.state) for s in snapshot.values()}
        for name, sleep in self.sleeping.items():
            if id(sleep.state) not in kept:
                self._free(self.system.node(name).instance, sleep.state)
        self._retired = [(inst, st) for inst, st in self._retired if id(st) not in kept]
        for inst, st in self._retired:
            self._free(inst, st)
        self._retired = []
        self.sleeping = dict(snapshot)
        self._oldest_known = False
        del self._steps[snapshot.journal - self._base:]
        del self._sources[snapshot.journal - self._base:]

    def commit(self) -> None:
        """The step is accepted: free the states of the contacts that woke in it, and forget the
        journal's rows no sleeping contact needs."""
        if self._retired:
            for inst, state in self._retired:
                self._free(inst, state)
            self._retired = []
        if not self.sleeping:
            if self._steps:
                self._base += len(self._steps)
                self._steps.clear()
                self._sources.clear()
            return
        if len(self._steps) < JOURNAL_TRIM or self._oldest_known:     # now and then, not at every step
            return
        # the oldest sleep's first row only moves when a contact wakes (a new sleep starts later)
        self._oldest_known = True
        first = min(s.start for s in self.sleeping.values()) - self._base
        if first >= JOURNAL_TRIM:
            del self._steps[:first]
            del self._sources[:first]
            self._base += first

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
