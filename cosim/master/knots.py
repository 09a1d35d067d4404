"""The ground motion handed to the buildings as knots, read ahead of them.

``ground_motion.fmu`` outputs the record over its last step exactly, as the polyline through
its knots (``n_knots``, ``t_knot[k]``, ``ag_knot[k]``: the step's ends and every sample
inside; a jump is two knots at one time).  ``building.fmu`` takes the same knots as inputs and
integrates its exact first-order-hold response across them (``n_knots = 0``: the old held
``ag``).  The ground motion is a source: nothing it computes depends on the other FMUs, so in
Gauss-Seidel order it may run ahead.  :class:`GroundLookahead` steps it in chunks ahead of the
communication points and keeps the polyline of what lies ahead; each building step
``[t0, t1]`` gets the polyline cut at its ends (:meth:`GroundLookahead.cut`: one-sided values
at the cuts, the samples in between), and the planner gets the largest ``|ag|`` ahead
(:meth:`GroundLookahead.bound`) before it chooses the step.  Fewer ground steps, exact
buildings over any step that holds at most ``capacity`` knots, and a known input for the proof
that a gap stays open (:mod:`cosim.master.gap_bound`).

Chunks start at the base step and double while a chunk holds at most
:data:`GROW_BELOW` knots (a uniformly sampled record then never needs more than the FMUs'
capacity in one chunk, a jump where the record starts or ends included), up to ``max_chunk``.
The ground FMU's own outputs (``ag``, ``vg``, ...) then belong to the end of its latest chunk,
not to the master's communication points.
"""
from __future__ import annotations

import numpy as np

#: a chunk that held at most this many knots may double: 2 (17 - 1) intervals of a uniformly
#: sampled record hold 33 knots (a jump where the record starts or ends lies in a chunk that
#: is partly outside the record, so it never adds to a full one)
GROW_BELOW = 17


class KnotsUnavailable(RuntimeError):
    """The record is sampled too finely for the FMUs' knot capacity at the base step."""


class GroundLookahead:
    """The ground FMU stepped ahead in chunks; its polyline over ``[t, t_end]`` (module docstring).

    ``node``: the ground's :class:`~cosim.master.system.Node`; ``capacity``: knots the FMUs
    carry; ``base``: the first chunk (s); ``max_chunk``: the longest chunk (s).
    """

    def __init__(self, node, capacity: int, base: float, max_chunk: float, stop_time: float):
        self.node = node
        self.capacity = int(capacity)
        inst = node.instance
        # every slot, times then values (two slices of the FMU's arrays: one copy each, where the
        # interleaved order of the buildings' inputs costs a Python loop over the knots)
        names = [f"t_knot[{k}]" for k in range(1, self.capacity + 1)] + \
                [f"ag_knot[{k}]" for k in range(1, self.capacity + 1)]
        self.port = inst.real_port(names)
        self.count = inst.integer_port(["n_knots"])
        self.width = float(base)
        self.max_chunk = float(max(max_chunk, base))
        self.stop_time = float(stop_time)
        self.t_end = 0.0
        self.times = np.zeros(1)
        self.values = np.zeros(1)
        self.chunks = 0             # chunks of the current polyline (restored with it on a rollback)
        self.ground_steps = 0       # every ground doStep made (never restored: a cost counter)

    def start(self, t0: float) -> None:
        self.t_end = float(t0)
        self.times = np.array([t0])
        self.values = np.array([0.0])

    def cover(self, t1: float) -> None:
        """Step the ground ahead until its polyline covers ``[.., t1]``."""
        while self.t_end < t1:
            h = min(self.width, self.stop_time - self.t_end)
            if not h > 0.0:            # at the stop time: nothing after it is asked for
                return
            t0 = self.t_end
            self.node.instance.do_step(t0, h)
            self.ground_steps += 1
            n = self._knots(t0, t0 + h)
            if n < 2:
                raise KnotsUnavailable(f"the ground motion's record needs more than {self.capacity} knots over "
                                       f"{h:g} s (a sampling interval below {h / (self.capacity - 1):.3g} s)")
            raw = self.port.values
            times, values = raw[:n].copy(), raw[self.capacity:self.capacity + n].copy()
            times[0], times[-1] = t0, t0 + h          # the chunk's ends as the master computes them
            self.t_end = t0 + h
            self.chunks += 1
            # keep the polyline from the last retained knot on (the master never goes back
            # beyond the start of its current step: see drop_before)
            # the previous chunk's last knot and this one's first are the same point unless the
            # record jumps there (both then stay: a jump is two knots at one time)
            scale = 1e-12 * max(abs(self.values[-1]), abs(values[0]), 1e-300)
            keep = self.times.size - (0 if abs(self.values[-1] - values[0]) > scale and self.chunks > 1 else 1)
            self.times = np.concatenate((self.times[:keep], times))
            self.values = np.concatenate((self.values[:keep], values))
            if n <= GROW_BELOW and self.width < self.max_chunk:
                self.width = min(2.0 * self.width, self.max_chunk)

    def _knots(self, t0: float, t1: float) -> int:
        """Read every knot slot of the step ``[t0, t1]`` just taken (one fmi2GetReal) and return
        ``n_knots``.

        The step's first knot is at its start and its last at its end, ``t_knot[n_knots] =
        current_time + step_size`` (ground_motion.fmu computes that sum as the master does,
        ``t1``, bit for bit); every knot before the last lies earlier (inside knots end ``SNAP``
        before it: fmu_src/record_knots.py), so ``n_knots`` is one more than the first slot after
        the first that holds ``t1`` (tests/test_knots.py): no fmi2GetInteger.  Otherwise (no
        knots, ``n_knots = 0``: every slot 0; an FMU whose ends differ by round-off) ``n_knots``
        is read."""
        times = self.port.get()[:self.capacity]
        at_end = times[1:] == t1
        last = int(at_end.argmax())     # the first True (0 if none)
        if at_end[last] and times[0] == t0:
            return last + 2
        return int(self.count.get()[0])

    def drop_before(self, t: float) -> None:
        """Forget the knots before the last one at or before ``t`` (the current step's start)."""
        i = int(self.times.searchsorted(t, side="right")) - 1
        if i > 0:
            self.times = self.times[i:]
            self.values = self.values[i:]

    def slice(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """The polyline over ``[t0, t1]``: ``(times, values)`` with ``times[0] = t0``,
        ``times[-1] = t1``, the value just after ``t0`` and just before ``t1`` (one-sided at a
        jump) and every knot strictly between (views of :meth:`cut`)."""
        knots = self.cut(t0, t1)
        return knots[0::2], knots[1::2]

    def cut(self, t0: float, t1: float) -> np.ndarray:
        """:meth:`slice` interleaved, ``[t0, a0, t_1, a_1, ..., t1, a1]``: the order of the
        buildings' knot inputs (``t_knot[k], ag_knot[k]``), so that each building copies it in
        one piece.  A knot within 1e-12 of the step of an end is that end (its value differs by
        at most the slope times that distance)."""
        times, values = self.times, self.values
        snap = 1e-12 * (t1 - t0)
        i0 = int(times.searchsorted(t0 + snap, side="right"))   # first knot after t0
        i1 = int(times.searchsorted(t1 - snap, side="left"))    # first knot at or after t1
        # just after t0: the last knot at t0 (the later of a jump), else the line to the next one
        j = i0 - 1
        if j < 0:
            v0 = float(values[0])
        elif times[j] >= t0 - snap or i0 >= times.size:
            v0 = float(values[j])
        else:
            v0 = float(values[j] + (t0 - times[j]) / (times[i0] - times[j]) * (values[i0] - values[j]))
        # just before t1: the first knot at t1 (the earlier of a jump), else the line from the one before
        if i1 >= times.size:
            v1 = float(values[-1])
        elif times[i1] <= t1 + snap or i1 == 0:
            v1 = float(values[i1])
        else:
            v1 = float(values[i1 - 1] + (t1 - times[i1 - 1]) / (times[i1] - times[i1 - 1])
                       * (values[i1] - values[i1 - 1]))
        n = i1 - i0 + 2
        knots = np.empty(2 * n)
        knots[0], knots[1] = t0, v0
        if n > 2:
            knots[2:-2:2], knots[3:-2:2] = times[i0:i1], values[i0:i1]
        knots[-2], knots[-1] = t1, v1
        return knots

    def knots_in(self, t0: float, t1: float) -> int:
        """How many knots :meth:`slice` would give over ``[t0, t1]``."""
        snap = 1e-12 * (t1 - t0)
        times = self.times
        return int(times.searchsorted(t1 - snap, side="left") - times.searchsorted(t0 + snap, side="right")) + 2
