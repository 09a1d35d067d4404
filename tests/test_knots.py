"""The ground motion's knots read ahead and cut per step (cosim/master/knots.py)."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.master.knots import GroundLookahead


def polyline(times, values):
    look = GroundLookahead.__new__(GroundLookahead)
    look.times, look.values = np.asarray(times, float), np.asarray(values, float)
    return look


def integral(t, a):
    """Exact integral of a polyline (jumps: zero-length pieces)."""
    return float(np.sum(0.5 * (a[1:] + a[:-1]) * np.diff(t)))


@pytest.mark.parametrize("seed", range(6))
def test_a_cut_is_the_polyline_over_the_step(seed):
    """Cut anywhere, the knots are the polyline's own: the ends are its values there (the right
    side at the start, the left side at the end of a jump), every knot in between is kept, and
    the cut's integral equals the polyline's over the step (what a building integrates)."""
    rng = np.random.default_rng(seed)
    times = np.round(np.cumsum(rng.uniform(0.005, 0.02, 60)), 6)
    values = rng.normal(0, 2, times.size)
    # a jump: two knots at one time
    j = 30
    times = np.insert(times, j, times[j])
    values = np.insert(values, j, values[j] + 5.0)
    look = polyline(times, values)
    for _ in range(40):
        t0, t1 = np.sort(rng.uniform(times[0], times[-1], 2))
        t, a = look.slice(t0, t1)
        assert t[0] == t0 and t[-1] == t1 and np.all(np.diff(t) >= 0)
        inside = times[(times > t0) & (times < t1)]
        np.testing.assert_array_equal(t[1:-1], inside)
        dense = np.linspace(t0, t1, 2001)
        # np.interp on the cut equals np.interp on the whole polyline away from the jump
        away = np.abs(dense - times[j]) > 1e-9
        np.testing.assert_allclose(np.interp(dense[away], t, a), np.interp(dense[away], times, values), atol=1e-12)
        keep = (times > t0) & (times < t1)
        whole_t = np.concatenate(([t0], times[keep], [t1]))
        whole_a = np.concatenate(([a[0]], values[keep], [a[-1]]))
        assert integral(t, a) == pytest.approx(integral(whole_t, whole_a), abs=1e-12)
        assert look.knots_in(t0, t1) == t.size


def test_ends_at_a_jump_take_their_own_side():
    look = polyline([0.0, 1.0, 1.0, 2.0], [0.0, 1.0, 5.0, 5.0])
    t, a = look.slice(0.5, 1.0)
    assert a[-1] == 1.0                       # left of the jump
    t, a = look.slice(1.0, 1.5)
    assert a[0] == 5.0 and t.size == 2       # right of the jump, nothing inside
    t, a = look.slice(0.5, 1.5)
    np.testing.assert_array_equal(t, [0.5, 1.0, 1.0, 1.5])
    np.testing.assert_array_equal(a, [0.5, 1.0, 5.0, 5.0])


def test_a_system_reused_after_knots_runs_as_a_fresh_one(catalog):
    """The adaptive coupling hands the buildings knots; a fixed-step run on the same system after
    it (fmi2Reset, knots off) equals a run on a fresh system, bit for bit."""
    from cosim.master.loader import load_scene
    from cosim.master.simulate import simulate
    from cosim.master.system import System

    scene = load_scene("default", ["stop_time=2.5"], catalog)
    with System(scene, catalog) as system:
        simulate(system, "adaptive", progress=False)
        reused = simulate(system, "gauss-seidel", progress=False, record="all")
    with System(scene, catalog) as system:
        fresh = simulate(system, "gauss-seidel", progress=False, record="all")
    np.testing.assert_array_equal(reused.values, fresh.values)
