"""building.fmu's knot steps without needless work (issue 17).

* A linear building's step of one knot interval (the ground acceleration linear over it) costs
  one product (``ExactPiecewiseLinear.ramp_step``) and gives what the general path
  (``ExactPiecewiseLinear._interval`` with the segment map of that length) gives: state,
  energies and outputs to round-off (1e-12 relative: both evaluate the same exact solution,
  summed in another order), the same running peaks and the same deferred in-step peak
  searches, the same peaks after them.  The ramp of the ground acceleration is what makes these
  steps differ from a zero-order hold: each comparison also checks that the same step without
  its ramp differs by far more than the tolerance (so the test would fail if the ramp term were
  dropped).
* A knot step's long interval (a multiple of its shortest) is split into intervals of that
  length, and a sliver of round-off is taken as a jump (``_even_intervals``): the same response,
  no segment map made for one step.
"""
from __future__ import annotations

import numpy as np
import pytest

from fmu_src.building_response import StepCost, integrator_for
from fmu_src.building_slave import Building
from fmu_src.fmi_slave import SlaveError
from fmu_src.ground_records import load_record
from fmu_src.hysteresis import StoreyHysteresis
from fmu_src.record_knots import step_knots
from fmu_src.shear_building import ShearBuilding

G = 9.80665
# both paths evaluate the same exact solution with the same matrices summed in another order:
# round-off of a few ulp of the terms' magnitudes (measured below 1e-14 of each quantity's scale)
RTOL = 1e-12


def building(n: int, model: str):
    b = ShearBuilding.from_period(0.3 + 0.1 * n, np.full(n, 3e5), np.linspace(1.0, 0.5, n), 0.05)
    fy = 0.1 * n * 3e5 * G * np.linspace(1.0, 0.4, n) if model == "bilinear" else None
    hysteresis = StoreyHysteresis(model, fy, 0.05) if fy is not None else StoreyHysteresis("linear")
    return integrator_for(b, hysteresis)


def random_state(it, rng, model):
    """A state of ``it`` about its elastic range (bilinear: every storey elastic, yielded before)."""
    n = it.n
    scale = it.dy if model != "linear" else np.full(n, 0.02)
    d = rng.uniform(-0.5, 0.5, n) * scale
    st = it.initial_state(np.cumsum(d), np.cumsum(rng.normal(scale=0.2, size=n) * scale / 0.02))
    if model != "linear":
        st.slip = rng.uniform(-0.3, 0.3, n) * scale
        st.offset = None
    st.E_input, st.E_damping, st.E_external, st.E_hysteretic = rng.uniform(1e3, 1e4, 4)
    # running peaks: some functions below what the step reaches (searched), some above (cleared)
    st.peaks = st.peaks * rng.uniform(0.3, 3.0, st.peaks.size)
    st.pending = []
    return st


def scales(st):
    return np.max(np.abs(st.u)), np.max(np.abs(st.v))


@pytest.mark.parametrize("n", [1, 3, 8])
def test_a_one_interval_step_through_one_matrix_equals_the_interval_path(n):
    rng = np.random.default_rng(17 + n)
    it = building(n, "linear")
    for trial in range(60):
        h = (0.01, 0.02, 0.005, 0.0037)[trial % 4]
        st = random_state(it, rng, "linear")
        ag0 = rng.normal(scale=3.0)
        ag1 = rng.normal(scale=3.0) / h                  # the record moves by ~3 m/s^2 in the interval
        force = rng.normal(scale=1e5, size=n)
        fast, slow = st.snapshot(), st.snapshot()
        fast_cost, slow_cost = StepCost(), StepCost()
        it.ramp_step(fast, h, ag0, ag1, force, fast_cost)
        events = it._interval(slow, h, ag0, ag1, force, slow_cost, h, 0.0)
        assert events == 0 and slow_cost.events == 0
        su, sv = scales(slow)
        np.testing.assert_allclose(fast.u, slow.u, rtol=0.0, atol=RTOL * su)
        np.testing.assert_allclose(fast.v, slow.v, rtol=0.0, atol=RTOL * sv)
        for name in ("E_input", "E_damping", "E_external"):
            # the increments, against the step's own energy scale
            inc_fast = getattr(fast, name) - getattr(st, name)
            inc_slow = getattr(slow, name) - getattr(st, name)
            scale = sum(abs(getattr(slow, e) - getattr(st, e)) for e in ("E_input", "E_damping", "E_external"))
            assert abs(inc_fast - inc_slow) <= RTOL * scale, name
        # peaks: the same end values recorded, the same searches deferred (bounds to round-off)
        np.testing.assert_allclose(fast.peaks, slow.peaks, rtol=RTOL)
        assert [e[0] for e in fast.pending] == [e[0] for e in slow.pending]
        np.testing.assert_allclose([e[1] for e in fast.pending], [e[1] for e in slow.pending], rtol=RTOL)
        assert (fast_cost.cleared, fast_cost.peaks_deferred) == (slow_cost.cleared, slow_cost.peaks_deferred)
        it.resolve_peaks(fast)
        it.resolve_peaks(slow)
        np.testing.assert_allclose(fast.peaks, slow.peaks, rtol=RTOL)
        # the ramp matters: the same step with the ground acceleration held at ag0 ends far away
        held = st.snapshot()
        it.ramp_step(held, h, ag0, 0.0, force, StepCost())
        assert np.max(np.abs(held.v - slow.v)) > 1e3 * RTOL * sv
        assert abs((held.E_input - st.E_input) - (slow.E_input - st.E_input)) > 1e3 * RTOL * abs(
            slow.E_input - st.E_input)


def slave(n, ramps=True):
    b = Building(instance_name=f"b{n}", resources=None, visible=False, logger=None)
    b.n_storeys = n
    b.T1 = 0.5
    b.m[:n] = 3e5
    b.k[:n] = np.linspace(1.0, 0.6, n)
    b.exit_initialization_mode()
    assert b._error is None
    b._ramps = ramps and b._ramps       # False: every step through ExactPiecewiseLinear.advance
    return b


def test_every_output_of_a_record_run_equals_the_general_path():
    """Two linear instances through 20 s of El Centro at 0.3 g in 10 ms knot steps with a floor
    force, one with the one-matrix step, one without: every output at every step within 1e-12 of
    its scale, the same work counters, the same peaks after every search."""
    rec = load_record("elcentro1940")
    rec = rec.scaled(0.3 * G / rec.pga)
    n = 3
    fast, slow = slave(n), slave(n, ramps=False)
    outputs = [vr for vr, var in fast.vars.items() if var.causality.name == "output"
               and type(var).__name__ == "Real" and ("[" not in var.name or int(var.name[:-1].split("[")[1]) <= n)
               and var.name.split("[")[0] not in ("x_peak", "drift_peak", "a_peak", "drift_ratio_peak", "mu")]
    runs = {id(fast): [], id(slow): []}
    h = 0.01
    for i in range(2000):
        t = i * h
        kt, ka = step_knots(rec, t, t + h)
        for b in (fast, slow):
            b.n_knots = len(kt)
            b.t_knot[:len(kt)] = kt
            b.ag_knot[:len(kt)] = ka
            b.F[:n] = 2e5 * np.sin(0.7 * t) * np.arange(1, n + 1) / n
            assert b.do_step(t, h), b._error
            runs[id(b)].append(b.get_real(outputs))
    a, b_ = np.array(runs[id(fast)]), np.array(runs[id(slow)])
    scale = np.max(np.abs(b_), axis=0)
    assert np.all(np.abs(a - b_) <= RTOL * scale)
    assert fast.cost == slow.cost and fast.cost.segments == 2000
    peaks = [vr for vr, var in fast.vars.items() if var.name.split("[")[0] in ("x_peak", "drift_peak", "a_peak")]
    np.testing.assert_allclose(fast.get_real(peaks), slow.get_real(peaks), rtol=RTOL)


def test_a_non_finite_ramp_step_is_refused_with_nothing_changed():
    b = slave(3)
    b.n_knots = 2
    b.t_knot[:2] = [0.0, 0.01]
    b.ag_knot[:2] = [1.0, 2.0]
    assert b.do_step(0.0, 0.01)
    saved = (b._state.u.copy(), b._state.v.copy(), b._state.E_input, b.x[:3].copy())
    b.t_knot[:2] = [0.01, 0.02]
    b.ag_knot[:2] = [1.0, 1e308]          # finite knots, a slope that overflows the state
    with pytest.raises(SlaveError, match="not finite.*nothing was changed"), np.errstate(all="ignore"):
        b.step(0.01, 0.01)
    np.testing.assert_array_equal(b._state.u, saved[0])
    np.testing.assert_array_equal(b._state.v, saved[1])
    assert b._state.E_input == saved[2]
    np.testing.assert_array_equal(b.x[:3], saved[3])


@pytest.mark.parametrize("model", ["linear", "bilinear"])
def test_a_long_interval_is_split_into_the_record_intervals_with_the_same_response(model):
    """A record's last samples leave a long interval to the end of the run (El Centro: 0.31 s
    after a 10 ms one): ``_even_intervals`` splits it into 10 ms intervals on the same polyline,
    so the step takes the cached map of 10 ms instead of building one of 0.31 s for one step.
    The response equals the one interval by interval with the long interval's own map: state and
    energies to round-off, peaks to the searches' precision; no map of the long length is made."""
    from fmu_src.building_response import _even_intervals
    from fmu_src.linear_response import PEAK_RTOL

    rng = np.random.default_rng(5)
    # the knots: ten 10 ms intervals, a jump, a 0.19 s interval, a 10 ms one (as at a record's end)
    times = np.concatenate([0.01 * np.arange(11), [0.1, 0.29, 0.30]])
    ag = rng.normal(scale=2.0, size=times.size)
    new_times, new_ag = _even_intervals(times, ag)
    lengths = np.diff(new_times)
    assert new_times.size == 32 and np.count_nonzero(lengths == 0.0) == 1
    np.testing.assert_allclose(lengths[lengths > 0.0], 0.01, rtol=1e-12)
    for t, a in zip(new_times, new_ag):       # on the polyline (at the jump: on one of its sides)
        sides = [ag[j] + (t - times[j]) / (times[j + 1] - times[j]) * (ag[j + 1] - ag[j])
                 for j in range(times.size - 1) if times[j] <= t <= times[j + 1] and times[j + 1] > times[j]]
        assert min(abs(a - v) for v in sides) <= 1e-12 * (1.0 + abs(a))
    # nothing to split: the knots as given
    for uniform in (0.01 * np.arange(5), np.array([0.0, 0.01, 0.025])):
        out, _ = _even_intervals(uniform, np.zeros(uniform.size))
        assert out is uniform
    it = building(5, model)
    st = random_state(it, rng, model)
    st.peaks[:] = 0.0
    split, whole = st.snapshot(), st.snapshot()
    force = rng.normal(scale=1e5, size=5)
    it.advance(split, times, ag, force)
    assert not it.configuration(np.zeros(5, dtype=np.int64)).has_map(0.19)
    cost = StepCost()
    for j in range(times.size - 1):
        L = times[j + 1] - times[j]
        if L > 0.0:
            it._interval(whole, L, ag[j], (ag[j + 1] - ag[j]) / L, force, cost, times[-1], times[j])
    su, sv = scales(whole)
    np.testing.assert_allclose(split.u, whole.u, rtol=0.0, atol=RTOL * su)
    np.testing.assert_allclose(split.v, whole.v, rtol=0.0, atol=RTOL * sv)
    np.testing.assert_array_equal(split.mode, whole.mode)
    scale = sum(abs(getattr(whole, e)) for e in ("E_input", "E_damping", "E_external", "E_hysteretic"))
    for e in ("E_input", "E_damping", "E_external", "E_hysteretic"):
        assert abs(getattr(split, e) - getattr(whole, e)) <= RTOL * scale, e
    it.resolve_peaks(split)
    it.resolve_peaks(whole)
    np.testing.assert_allclose(split.peaks, whole.peaks, rtol=2 * PEAK_RTOL)


@pytest.mark.parametrize("model", ["linear", "bilinear"])
def test_a_sliver_interval_becomes_a_jump_with_the_same_response(model):
    """A record sample 2e-14 s after a step's start (measured: a step from 28.79 s, a sample at
    28.79000000000002 s) leaves a knot interval of 2e-14 s, whose own segment map cost 1.9 ms
    for 15 storeys: ``_even_intervals`` takes it as a jump; the response equals the one through
    the sliver to round-off, and no map of the sliver's length is made."""
    from fmu_src.building_response import _even_intervals

    h = 0.010000000000001563
    sliver = 2.1316282072803006e-14
    for times, moved in (([0.0, sliver, h], [0.0, 0.0, h]), ([0.0, h - sliver, h], [0.0, h, h]),
                         ([0.0, sliver, 0.5 * h, h], [0.0, 0.0, 0.5 * h, h])):
        out, values = _even_intervals(np.array(times), np.arange(len(times), dtype=float))
        assert out.tolist() == moved and values.tolist() == list(range(len(times)))
    rng = np.random.default_rng(7)
    it = building(5, model)
    st = random_state(it, rng, model)
    force = rng.normal(scale=1e5, size=5)
    times = np.array([0.0, sliver, h])
    ag = np.array([-0.11486344456838857, -0.11486344456856909, -0.20253077751605242])
    merged, through = st.snapshot(), st.snapshot()
    it.advance(merged, times, ag, force)
    cfg = it.configuration(np.zeros(5, dtype=np.int64))
    assert not cfg.has_map(sliver)
    cost = StepCost()
    for j in range(2):
        L = times[j + 1] - times[j]
        it._interval(through, L, ag[j], (ag[j + 1] - ag[j]) / L, force, cost, h, times[j])
    # the knot moves by the sliver, 2e-12 of the step: the ground acceleration over the step
    # shifts by its slope (877 m/s^3) times 2e-14 s, the velocities by that times the step, ~2e-13
    # m/s (the order of canonical_length's merging of lengths equal to 12 digits)
    tol = 1e-11
    su, sv = scales(through)
    np.testing.assert_allclose(merged.u, through.u, rtol=0.0, atol=tol * su)
    np.testing.assert_allclose(merged.v, through.v, rtol=0.0, atol=tol * sv)
    scale = sum(abs(getattr(through, e) - getattr(st, e)) for e in ("E_input", "E_damping", "E_external"))
    for e in ("E_input", "E_damping", "E_external", "E_hysteretic"):
        assert abs(getattr(merged, e) - getattr(through, e)) <= tol * scale, e
