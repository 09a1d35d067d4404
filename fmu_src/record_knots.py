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


def step_knots(record, t0: float, t1: float, capacity: int = KNOT_CAPACITY):
    """``(times, values)`` (s, m/s^2) of the record over ``[t0, t1]``, or None if more than
    ``capacity`` knots are needed.  ``t1 > t0``."""
    start, dt, npts = record.start_time, record.dt, record.npts
    last = npts - 1
    end = record.end_time
    snap = SNAP * dt
    times: list[float] = []
    values: list[float] = []

    def add(t, a):
        times.append(t)
        values.append(a)

    def inside_value(t):
        """Value at t with start <= t <= end (the linear interpolation)."""
        x = (t - start) / dt
        k = min(max(int(math.floor(x)), 0), last - 1)
        return _value(record, k, t - (start + k * dt))

    # left end: the value just after t0
    if t0 < start - snap or t0 >= end - snap:
        add(t0, 0.0)
    else:
        add(t0, inside_value(min(max(t0, start), end)))
    # samples strictly inside (t0, t1), beyond the snapping distance of either end
    i_first = max(0, int(math.floor((t0 + snap - start) / dt)) + 1)
    i_last = min(last, int(math.ceil((t1 - snap - start) / dt)) - 1)
    a = record.acceleration
    for i in range(i_first, i_last + 1):
        ti = start + i * dt
        if not (t0 + snap < ti < t1 - snap):
            continue
        if len(times) + 2 > capacity:     # this sample and the right end must still fit
            return None
        if i == 0:
            add(ti, 0.0)          # the record starts: jump from 0
        add(ti, float(a[i]))
        if i == last:
            add(ti, 0.0)          # the record ends: jump to 0
    # right end: the value just before t1
    if t1 <= start + snap or t1 > end + snap:
        add(t1, 0.0)
    else:
        add(t1, inside_value(min(max(t1, start), end)))
    if len(times) > capacity:
        return None
    return np.array(times), np.array(values)


def polyline_mean(times, values) -> float:
    """Mean of the polyline over its span (trapezoids; jumps have zero width)."""
    t = np.asarray(times, float)
    a = np.asarray(values, float)
    return float(np.sum(0.5 * (a[1:] + a[:-1]) * np.diff(t)) / (t[-1] - t[0]))
