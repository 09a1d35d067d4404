"""The knots of a record's piecewise-linear signal over one communication step.

A :class:`~fmu_src.ground_records.Record` is linear between its samples and zero before the
first and after the last sample (with real jumps there).  Over a step ``[t0, t1]`` that signal
is exactly the polyline through the knots

    (t0, a(t0+)),  every sample strictly inside (t0, t1),  (t1, a(t1-)),

with one-sided values at the ends (the step's own side of a jump) and a jump inside the step
encoded as two knots at the same time (``(t_first, 0), (t_first, a_0)`` where the record
starts, ``(t_last, a_last), (t_last, 0)`` where it ends).  A building that integrates its exact
solution for a piecewise-linear input across these knots (first-order hold) is exact for the
record over any step length, which lets a master take long steps where nothing happens.

A sample closer to ``t0`` or ``t1`` than ``SNAP`` times the sampling interval counts as the
end itself: step ends and sample times that differ only by round-off (``0.3`` against
``30 * 0.01``) would otherwise create an interval of 1e-17 s.  The signal's value there
differs from the sample by at most the slope times that distance.
"""
from __future__ import annotations

import math

import numpy as np

KNOT_CAPACITY = 33   # knots per step the FMUs carry (FMI 2.0 arrays have a build-time size)
SNAP = 1e-9          # relative to the record's dt, see module docstring


def _value(record, k: int, s: float) -> float:
    a = record.acceleration
    return float(a[k] + (a[k + 1] - a[k]) * (s / record.dt))


def _inside_value(record, t: float) -> float:
    """Value at t with start <= t <= end (the linear interpolation)."""
    x = (t - record.start_time) / record.dt
    k = min(max(int(math.floor(x)), 0), record.npts - 2)
    return _value(record, k, t - (record.start_time + k * record.dt))


def step_knots(record, t0: float, t1: float, capacity: int = KNOT_CAPACITY):
    """``(times, values)`` (s, m/s^2) of the record over ``[t0, t1]``, or None if more than
    ``capacity`` knots are needed.  ``t1 > t0``.

    The samples inside are one slice of the record (their times ``start + i dt`` rise with
    ``i``, so only the candidates at either end of the index range can fall within the snapping
    distance): no Python loop over them, which made this a third of ground_motion.fmu's cost
    per step (tests/test_record_knots.py: the same knots as that loop, bit for bit)."""
    start, dt, npts = record.start_time, record.dt, record.npts
    last = npts - 1
    end = record.end_time
    snap = SNAP * dt
    # the ends: the value just after t0 and just before t1 (zero outside the record)
    left = 0.0 if (t0 < start - snap or t0 >= end - snap) else _inside_value(record, min(max(t0, start), end))
    right = 0.0 if (t1 <= start + snap or t1 > end + snap) else _inside_value(record, min(max(t1, start), end))
    # samples strictly inside (t0, t1), beyond the snapping distance of either end
    lo = max(0, int(math.floor((t0 + snap - start) / dt)) + 1)
    hi = min(last, int(math.ceil((t1 - snap - start) / dt)) - 1)
    while lo <= hi and not t0 + snap < start + lo * dt:
        lo += 1
    while hi >= lo and not start + hi * dt < t1 - snap:
        hi -= 1
    inside = hi - lo + 1 if hi >= lo else 0
    starts = inside and lo == 0          # the record starts inside: a jump from 0
    ends = inside and hi == last         # the record ends inside: a jump to 0
    count = 2 + inside + starts + ends
    if count > capacity:
        return None
    times = np.empty(count)
    values = np.empty(count)
    times[0], values[0] = t0, left
    times[-1], values[-1] = t1, right
    if inside:
        first = 1 + starts
        times[first:first + inside] = start + np.arange(lo, hi + 1) * dt
        values[first:first + inside] = record.acceleration[lo:hi + 1]
        if starts:
            times[1], values[1] = times[2], 0.0
        if ends:
            times[-2], values[-2] = times[-3], 0.0
    return times, values


def polyline_mean(times, values) -> float:
    """Mean of the polyline over its span (trapezoids; jumps have zero width)."""
    t = np.asarray(times, float)
    a = np.asarray(values, float)
    return float(np.sum(0.5 * (a[1:] + a[:-1]) * np.diff(t)) / (t[-1] - t[0]))
