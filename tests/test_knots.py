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


def test_yielding_buildings_follow_the_record_exactly_at_every_step(catalog):
    """A yielding building gets the record's knots over every step (system.Node.pull_with_knots),
    also over a step inside one record interval, where a linear building holds the interval's
    mean: out of contact the master's floors are then the reference's (solve_ivp of the same
    bilinear storeys, rtol 1e-10) at every communication point, base steps and long steps
    alike.  Measured: 5e-12 m over 4.5 s (294 steps, 28 of them long).  With the held mean: 9e-5 m
    (the relative floor velocity at level 8 0.22 % off before the first impact at 4.64 s), enough
    for kasai_maison_inelastic to miss the criteria."""
    from cosim.master.loader import load_scene
    from cosim.peers.reference import reference_for_scene
    from scenario_checks import simulate_scene

    overrides = ["stop_time=4.5"]
    scene = load_scene("kasai_maison_inelastic", overrides, catalog)
    # rows every 0.32 s: long steps up to 0.32 s stay possible (adaptive.row_step)
    result = simulate_scene(catalog, scene.name, overrides, record="all", output_interval=0.32)
    assert result.stats["long_steps"] > 0 and result.cost.communication_steps > result.stats["long_steps"]
    ref = reference_for_scene(scene, {"rtol": 1e-10, "output_dt": 0.01})
    assert sum(len(v) for v in result.onsets.values()) == 0 and ref.impacts == 0      # no contact yet
    floors = [f"{b.name}.x[{i}]" for b in scene.buildings for i in range(1, scene.n_storeys(b.name) + 1)]
    got = np.column_stack([result[c] for c in floors])
    rows = np.searchsorted(ref.t, result.time - 1e-9)
    # 1e-8 m: the reference's tolerance (rtol 1e-10 on displacements of ~0.1 m) with margin
    np.testing.assert_allclose(got, ref.u[rows], rtol=0, atol=1e-8)
    # the storeys did yield (hysteretic energy) before the first impact
    assert all(result.value_at_end(f"{b.name}.E_hysteretic") > 0.0 for b in scene.buildings)


def test_the_knot_count_is_found_without_reading_it(catalog, monkeypatch):
    """GroundLookahead reads a chunk's knots in one fmi2GetReal and finds ``n_knots`` from the
    last knot's time (the chunk's end): on every chunk of runs over a record's start, its middle
    and its end, with the ground's chunks doubling, the count it finds is ground_motion.fmu's
    ``n_knots``, and no run asks for the Integer."""
    from cosim.master.loader import load_scene
    from cosim.master.simulate import simulate
    from cosim.master.system import System

    found = []
    own = GroundLookahead._knots

    def checked(self, t0, t1):
        n = own(self, t0, t1)
        found.append((n, int(self.count.get()[0])))
        return n

    monkeypatch.setattr(GroundLookahead, "_knots", checked)
    for name, overrides in (("default", ["stop_time=3"]), ("kasai_maison", []), ("free_vibration", [])):
        scene = load_scene(name, overrides, catalog)
        with System(scene, catalog) as system:
            simulate(system, "adaptive", progress=False)
    assert len(found) > 100 and {n for n, _ in found} >= {2}
    assert all(n == count for n, count in found), [f for f in found if f[0] != f[1]][:3]


class _Port:
    def __init__(self, values):
        self.values = np.asarray(values, float)
        self.gets = 0

    def get(self):
        self.gets += 1
        return self.values


def test_a_last_knot_off_the_end_falls_back_to_the_count():
    """An FMU whose last knot time is not the step's end bit for bit (or whose first is not its
    start, or that has no knots, ``n_knots = 0``: every slot 0, even for a step ending at 0 s)
    gets its ``n_knots`` read."""
    look = GroundLookahead.__new__(GroundLookahead)
    look.capacity = 4
    t0, t1 = 0.0, 0.3
    look.port = _Port([t0, 0.2, np.nextafter(t1, 1.0), 0.0, 1.0, 2.0, 3.0, 0.0])
    look.count = _Port([3])
    assert look._knots(t0, t1) == 3 and look.count.gets == 1
    look.port = _Port([t0, 0.2, t1, 0.0, 1.0, 2.0, 3.0, 0.0])
    assert look._knots(t0, t1) == 3 and look.count.gets == 1        # found: not read
    look.port = _Port([t0, t1, t1, t1, 1.0, 2.0, 3.0, 4.0])         # the first slot after the first holding t1
    assert look._knots(t0, t1) == 2
    look.port = _Port([0.0] * 8)
    look.count = _Port([0])
    assert look._knots(t0, t1) == 0 and look.count.gets == 1
    assert look._knots(-0.3, 0.0) == 0 and look.count.gets == 2     # the zeros are not knots
    look.port = _Port([np.nextafter(t0, 1.0), 0.2, t1, 0.0, 1.0, 2.0, 3.0, 0.0])
    look.count = _Port([3])
    assert look._knots(t0, t1) == 3 and look.count.gets == 1
