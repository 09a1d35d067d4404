"""The record's knots over a step (fmu_src.record_knots.step_knots) against the sample-by-sample
loop it replaced (main 0a0e525, kept here as the oracle; tests/test_building_ramp_step.py and the
bundled scenes check that loop's knots against the record itself): the same times and values,
bit for bit, and the same refusals (None) beyond the capacity, on random steps anywhere (before,
across the start, inside, across the end, after the record; ends snapped to samples; steps
shorter than a sampling interval), then on every step a bundled scene's ground takes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmu_src.ground_records import BUNDLED, Record, load_record
from fmu_src.record_knots import KNOT_CAPACITY, SNAP, _inside_value, step_knots


def loop_knots(record, t0, t1, capacity=KNOT_CAPACITY):
    """The knots as the earlier version built them, one sample at a time."""
    start, dt, last, end = record.start_time, record.dt, record.npts - 1, record.end_time
    snap = SNAP * dt
    times, values = [], []
    if t0 < start - snap or t0 >= end - snap:
        times.append(t0), values.append(0.0)
    else:
        times.append(t0), values.append(_inside_value(record, min(max(t0, start), end)))
    a = record.acceleration
    for i in range(max(0, int(math.floor((t0 + snap - start) / dt)) + 1),
                   min(last, int(math.ceil((t1 - snap - start) / dt)) - 1) + 1):
        ti = start + i * dt
        if not (t0 + snap < ti < t1 - snap):
            continue
        if len(times) + 2 > capacity:
            return None
        if i == 0:
            times.append(ti), values.append(0.0)
        times.append(ti), values.append(float(a[i]))
        if i == last:
            times.append(ti), values.append(0.0)
    if t1 <= start + snap or t1 > end + snap:
        times.append(t1), values.append(0.0)
    else:
        times.append(t1), values.append(_inside_value(record, min(max(t1, start), end)))
    if len(times) > capacity:
        return None
    return np.array(times), np.array(values)


def same(new, old):
    if new is None or old is None:
        return new is None and old is None
    return (new[0].dtype == old[0].dtype == new[1].dtype == np.float64
            and np.array_equal(new[0], old[0]) and np.array_equal(new[1], old[1])
            and [math.copysign(1, x) for x in new[0]] == [math.copysign(1, x) for x in old[0]])


@pytest.mark.parametrize("seed", range(4))
def test_the_same_knots_as_the_loop(seed):
    rng = np.random.default_rng(seed)
    dt = float(rng.choice([0.01, 0.02, 0.005, 0.0123]))
    npts = int(rng.integers(3, 60))
    record = Record("random", dt, rng.normal(0.0, 2.0, npts), start_time=float(rng.choice([0.0, 0.3, -0.1])))
    start, end = record.start_time, record.end_time
    checked = 0
    for _ in range(3000):
        kind = rng.integers(4)
        if kind == 0:        # anywhere around the record, any length up to 40 intervals
            t0 = rng.uniform(start - 5 * dt, end + 5 * dt)
            t1 = t0 + rng.uniform(1e-4, 40.0) * dt
        elif kind == 1:      # ends on samples, as a master's sums of a step give them (round-off)
            i, n = int(rng.integers(-3, npts + 3)), int(rng.integers(1, 40))
            t0, t1 = start + i * dt, start + i * dt + n * dt
        elif kind == 2:      # ends within the snapping distance of a sample
            i = int(rng.integers(-2, npts + 2))
            t0 = start + i * dt + rng.uniform(-2, 2) * SNAP * dt
            t1 = t0 + int(rng.integers(1, 35)) * dt + rng.uniform(-2, 2) * SNAP * dt
        else:                # short steps inside one interval
            t0 = rng.uniform(start - dt, end + dt)
            t1 = t0 + rng.uniform(1e-6, 1.0) * dt
        t0, t1 = float(t0), float(t1)
        capacity = int(rng.choice([KNOT_CAPACITY, 5, 3]))
        assert same(step_knots(record, t0, t1, capacity), loop_knots(record, t0, t1, capacity)), (t0, t1, capacity)
        checked += 1
    assert checked == 3000


def test_jumps_where_the_record_starts_and_ends():
    record = Record("ramp", 0.1, np.array([1.0, 2.0, 3.0]), start_time=1.0)
    times, values = step_knots(record, 0.5, 1.5)
    assert times.tolist() == [0.5, 1.0, 1.0, 1.0 + 0.1, 1.0 + 2 * 0.1, 1.0 + 2 * 0.1, 1.5]
    assert values[:3].tolist() == [0.0, 0.0, 1.0] and values[-3:].tolist() == [3.0, 0.0, 0.0]
    assert same((times, values), loop_knots(record, 0.5, 1.5))
    assert step_knots(record, 0.5, 1.5, capacity=6) is None        # 7 knots needed


@pytest.mark.parametrize("name", sorted(BUNDLED))
def test_the_same_knots_on_a_bundled_record_in_chunks(name):
    """Chunks as the master's look-ahead takes them (cosim/master/knots.py: from 10 ms, doubling
    up to 32 intervals, ends summed step by step), over the whole record and past its end."""
    record = load_record(name, target_pga_g=0.3)
    t, width, checked = 0.0, 0.01, 0
    while t < record.end_time + 1.0:
        h = min(width, 0.32)
        assert same(step_knots(record, t, t + h), loop_knots(record, t, t + h)), (t, h)
        t, width, checked = t + h, 2.0 * width, checked + 1
    assert checked > 100
