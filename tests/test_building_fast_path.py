"""building.fmu's linear step at a fraction of its cost (issue 17): the shortcuts give what the
long way gives.

* step and interval lengths that differ by round-off share their matrices
  (``linear_response.canonical_length``), and nothing else does;
* the first zero-order-hold step of a length, taken from the modal solution without matrices
  (``ExactPiecewiseLinear.advance_unmapped``), equals the matrix step to round-off, state,
  energies and in-step peaks; a building of up to ``_EAGER_MATRIX_STOREYS`` storeys builds the
  matrices at the first step instead (they cost little more than a step without them there);
* the in-step peak tests of a knot step's intervals run together
  (``ExactPiecewiseLinear._interval_peaks``) with the decisions of one ``_peaks`` per interval:
  the same running peaks and the same deferred searches, bit for bit.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmu_src import building_response
from fmu_src.building_response import integrator_for
from fmu_src.building_slave import _EAGER_MATRIX_STOREYS, Building
from fmu_src.ground_records import load_record
from fmu_src.hysteresis import StoreyHysteresis
from fmu_src.linear_response import LENGTH_DIGITS, Scan, canonical_length
from fmu_src.record_knots import step_knots
from fmu_src.shear_building import ShearBuilding

G = 9.80665


def el_centro(scale_g=0.3):
    rec = load_record("elcentro1940")
    return rec.scaled(scale_g * G / rec.pga)


def test_lengths_equal_to_round_off_share_one_canonical_length():
    # measured in 40 s runs: the master's t_next - t and the differences of knot times
    for nominal, seen in ((0.01, (0.00999999999999801, 0.009999999999999787, 0.010000000000001563,
                                  0.01 - 3e-14, 0.01 + 3e-14)),
                          (0.02, (0.019999999999999574, 0.020000000000003126)),
                          (0.16, (0.1599999999999966, 0.1600000000000037)),
                          (0.005, (0.005 - 1e-17, 0.005 + 1e-17))):
        assert canonical_length(nominal) == nominal          # a decimal length is its own
        assert all(canonical_length(h) == nominal for h in seen)
    # lengths a host means apart stay apart: 12 significant digits
    assert canonical_length(0.0099999999999) == 0.0099999999999
    assert canonical_length(0.0123456789012345) == 0.0123456789012
    assert canonical_length(1.0 + 1e-10) != 1.0
    # monotonic (the batch's test of one length by its shortest and longest interval relies on it)
    rng = np.random.default_rng(3)
    for centre in (1e-6, 0.001, 0.01, 0.1, 1.0, 37.0):
        lengths = np.sort(centre * (1.0 + rng.uniform(-1e-9, 1e-9, 4000)))
        canon = [canonical_length(float(h)) for h in lengths]
        assert all(a <= b for a, b in zip(canon, canon[1:]))
        # the change is round-off only: at most half a unit of the 12th digit
        assert np.max(np.abs(np.array(canon) - lengths) / lengths) <= 0.5 * 10.0 ** (1 - LENGTH_DIGITS)


def slave(n=5, T1=1.0):
    b = Building(instance_name=f"b{n}", resources=None, visible=False, logger=None)
    b.n_storeys = n
    b.T1 = T1
    b.m[:n] = 3e5
    b.k[:n] = np.linspace(1.0, 0.5, n)
    b.exit_initialization_mode()
    assert b._error is None
    return b


@pytest.mark.parametrize("h", [0.01, 0.05, 0.16])
def test_a_first_zero_order_hold_step_without_matrices_equals_the_matrix_step(h):
    """Two instances take the same zero-order-hold steps of El Centro with floor forces; one is
    told it has stepped every length before (so every step takes the cached matrices), the
    other takes the first step of each length from the modal solution.  Every step alternates
    between two lengths, so each instance's first step of a length comes at a different time of
    the record: the comparison covers many states."""
    rec = el_centro()
    n = _EAGER_MATRIX_STOREYS + 1      # smaller buildings build the matrices at a length's first step
    fresh, mapped = slave(n), slave(n)
    names = ("x", "v", "a", "drift")
    rng = np.random.default_rng(1)
    t = 0.0
    worst = dict.fromkeys(names + ("E",), 0.0)
    diff = dict.fromkeys(names + ("E",), 0.0)
    scale = dict.fromkeys(names + ("E",), 0.0)
    for i in range(60):
        step = h if i % 2 else 0.5 * h
        ag = rec.mean_over(t, t + step)
        force = rng.normal(scale=2e4, size=n)
        for b in (fresh, mapped):
            if b is mapped:
                b._stepped_lengths = b._stepped_lengths | {canonical_length(step)}
            else:
                b._stepped_lengths = frozenset()          # every step the first of its length
            b.ag = ag
            b.F[:n] = force
            assert b.do_step(t, step), b._error
        t += step
        for name in names:
            a, m = getattr(fresh, name)[:n], getattr(mapped, name)[:n]
            diff[name] = max(diff[name], float(np.max(np.abs(a - m))))
            scale[name] = max(scale[name], float(np.max(np.abs(m))))
        for e in ("E_input", "E_damping", "E_external", "E_kinetic", "E_strain"):
            diff["E"] = max(diff["E"], abs(getattr(fresh, e) - getattr(mapped, e)))
            scale["E"] = max(scale["E"], abs(getattr(mapped, e)))
    worst = {name: diff[name] / scale[name] for name in diff}
    assert fresh.cost.segments > 25            # the modal path did the steps
    # two exact methods, relative to each output's largest magnitude in the run: the matrices'
    # Van Loan expm of the doubled system is accurate to ~1e-11 of the response at 10 ms
    # (tests/test_building_inelastic_fmu.py compares the two at 1e-10) and ~1e-9 at 0.16 s (7e-10
    # measured against the modal maps, which the modal step matches to 1e-15: the next test)
    assert max(worst.values()) < (1e-10 if h <= 0.01 else 2e-9), worst
    for b in (fresh, mapped):
        b._integrator.resolve_peaks(b._state)
    np.testing.assert_allclose(fresh._state.peaks, mapped._state.peaks, rtol=1e-9)   # PEAK_RTOL


@pytest.mark.parametrize("h", [0.01, 0.16, 1.0])
def test_the_modal_step_without_matrices_equals_the_modal_maps(h):
    """ExactPiecewiseLinear.advance_unmapped (the modal solution at h, energies by quadrature of
    it) against advance over the same zero-order-hold step (the cached modal maps): the same
    exact solution by two evaluations, to round-off."""
    rec = el_centro()
    n = 5
    b = ShearBuilding.from_period(1.0, [3e5] * n, np.linspace(1.0, 0.5, n), 0.05)
    it = integrator_for(b, StoreyHysteresis("linear"))
    a, m = it.initial_state(np.zeros(n), np.zeros(n)), it.initial_state(np.zeros(n), np.zeros(n))
    force = np.linspace(-3e4, 5e4, n)
    scale_u = scale_v = 0.0
    for i in range(int(round(8.0 / h))):
        ag = rec.mean_over(i * h, (i + 1) * h)
        it.advance_unmapped(a, h, ag, force)
        it.advance(m, (0.0, h), (ag, ag), force)
        scale_u = max(scale_u, float(np.max(np.abs(m.u))))
        scale_v = max(scale_v, float(np.max(np.abs(m.v))))
        # 1e-12 of the largest motion so far: up to 800 steps of round-off, each ~cond(V) eps
        # (1e-14) of the response through the modal transformations
        np.testing.assert_allclose(a.u, m.u, rtol=0.0, atol=1e-12 * scale_u)
        np.testing.assert_allclose(a.v, m.v, rtol=0.0, atol=1e-12 * scale_v)
    for e in ("E_input", "E_damping", "E_external"):
        assert getattr(a, e) == pytest.approx(getattr(m, e), rel=1e-12)
    it.resolve_peaks(a)
    it.resolve_peaks(m)
    np.testing.assert_allclose(a.peaks, m.peaks, rtol=1e-9)     # PEAK_RTOL of the searches


def test_a_small_building_builds_a_lengths_matrices_at_its_first_step():
    """Up to _EAGER_MATRIX_STOREYS storeys the first step of a length is a matrix step (building
    the matrices at once costs less than the step without them saves when the length is stepped
    again, free_vibration's case, and little when it is not: a record's tail); taller buildings
    take it without matrices (the last test: a length stepped once costs no matrices)."""
    rec = el_centro()
    for n, eager in ((1, True), (_EAGER_MATRIX_STOREYS, True), (_EAGER_MATRIX_STOREYS + 1, False)):
        b = slave(n, 0.5)
        t = 0.0
        for h in (0.01, 0.02, 0.013):
            b.ag = rec.mean_over(t, t + h)
            assert b.do_step(t, h), b._error
            t += h
            # a matrix step builds (or finds) the length's matrices; a step without them builds none
            assert (canonical_length(h) in b._steps) == eager, (n, h)
        assert b.cost.segments == (0 if eager else 3)       # steps without matrices count segments


def test_a_restored_state_takes_the_same_paths():
    """The stepped lengths are FMU state: a run restored to before the first step of a length
    takes it without matrices again, and replays bit for bit (a building above
    _EAGER_MATRIX_STOREYS: smaller ones build the matrices at the first step)."""
    b = slave(_EAGER_MATRIX_STOREYS + 1, 0.5)
    rec = el_centro()
    for i in range(20):
        b.ag = rec.mean_over(0.01 * i, 0.01 * (i + 1))
        assert b.do_step(0.01 * i, 0.01)
    saved = b._get_fmu_state()
    runs = []
    for _ in range(2):
        Building._set_fmu_state(b, saved)
        out = []
        t = 0.2
        for i in range(10):
            step = 0.005 if i % 2 else 0.02
            b.ag = rec.mean_over(t, t + step)
            assert b.do_step(t, step)
            out.append(np.concatenate([b.x[:5], b.a[:5], [b.E_damping, b.E_input]]))
            t += step
        runs.append(np.array(out))
        assert canonical_length(0.005) in b._stepped_lengths
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("max_pending", [building_response.MAX_PENDING, 8])
def test_the_knot_step_peak_tests_together_decide_as_one_per_interval(monkeypatch, max_pending):
    """A 15-storey building through 40 s of El Centro in 0.16 s knot steps: the running peaks,
    the deferred searches and the peaks after them, with the intervals tested together and one
    by one (Scan and _peaks per interval, as before), bit for bit.  With at most 8 deferred
    searches kept, the list is pruned and searched inside a step's intervals (the intervals
    after that one go through _peaks against the raised peaks): the same, and it happens."""
    pruned = max_pending < building_response.MAX_PENDING
    monkeypatch.setattr(building_response, "MAX_PENDING", max_pending)
    fallbacks = []
    original = building_response.ExactPiecewiseLinear._peaks_one_by_one

    def counted(self, *args):
        fallbacks.append(1)
        return original(self, *args)
    monkeypatch.setattr(building_response.ExactPiecewiseLinear, "_peaks_one_by_one", counted)
    rec = el_centro(0.3)

    def one_by_one(self, cfg, state, Y, scans, flags, p, length, xtol, cost):
        two_n = 2 * self.n
        for y, vector, row in zip(Y, scans, flags):
            self._peaks(cfg, Scan(cfg, vector, float(y[two_n + 1]), length), None, state, y.copy(), p, length,
                        xtol, cost, row.tolist())

    runs = []
    for together in (True, False):
        if not together:
            monkeypatch.setattr(building_response.ExactPiecewiseLinear, "_interval_peaks", one_by_one)
        b = ShearBuilding.from_period(1.5, [9e5] * 15, np.linspace(15.0, 4.0, 15), 0.05)
        it = integrator_for(b, StoreyHysteresis("linear"))
        st = it.initial_state(np.zeros(15), np.zeros(15))
        force = np.zeros(15)
        deferred = 0
        for i in range(250):
            times, values = step_knots(rec, 0.16 * i, 0.16 * (i + 1))
            cost = it.advance(st, times - 0.16 * i, values, force)
            deferred += cost.peaks_deferred
        pending = [(j, U) for j, U, *_ in st.pending]
        before = st.peaks.copy()
        it.resolve_peaks(st)
        runs.append((before, pending, deferred, st.peaks.copy(), st.u.copy()))
    assert runs[0][2] == runs[1][2] > 0 and runs[0][1] == runs[1][1]
    for a, b_ in zip(runs[0][3:], runs[1][3:]):
        np.testing.assert_array_equal(a, b_)
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert math.isfinite(float(runs[0][3].sum()))
    assert bool(fallbacks) == pruned


def test_reading_the_storey_shears_leaves_the_deferred_peak_searches_deferred():
    """The master reads V at every step and the peaks once at the end: reading V must not run
    the deferred in-step peak searches (each one run early cannot be superseded by a later,
    higher peak), and must give what the full derived block gives.  Two bilinear instances take
    the same steps of El Centro at 0.6 g (the storeys yield); one reads V after every step, the
    other reads the peaks after every step (every search run at once).  At the end both read the
    peaks: the same V at every step bit for bit, the same peaks to the search's precision, and
    the instance that read only V ran fewer searches."""
    rec = el_centro(0.6)
    n = 3

    def bilinear():
        b = Building(instance_name="bil", resources=None, visible=False, logger=None)
        b.n_storeys = n
        b.T1 = 0.5
        b.m[:n] = 3e5
        b.k[:n] = [1.0, 0.8, 0.6]
        b.hysteresis = "bilinear"
        b.Fy[:n] = [0.2 * 3 * 3e5 * G, 0.17 * 3 * 3e5 * G, 0.12 * 3 * 3e5 * G]
        b.exit_initialization_mode()
        assert b._error is None
        return b

    lazy, eager = bilinear(), bilinear()
    h = 0.02
    yielded = False
    for i in range(300):
        t = 1.5 + i * h
        for b in (lazy, eager):
            b.ag = rec.mean_over(t, t + h)
            assert b.do_step(t, h), b._error
        shears = lazy._derived_array("V").copy()
        assert lazy._derived_cache is None, "reading V ran the deferred peak searches"
        eager_peaks = eager._derived_array("x_peak").copy()
        np.testing.assert_array_equal(shears, eager._derived_array("V"))
        np.testing.assert_array_equal(eager_peaks[:n], eager._state.peaks[:n])
        yielded = yielded or bool(lazy._state.mode.any())
    assert yielded, "the storeys never yielded: the test would not cover a yielding building"
    assert lazy.cost.peak_searches < eager.cost.peak_searches
    for name in ("x_peak", "drift_peak", "a_peak", "mu"):
        # max_abs locates a peak's time to PEAK_XTOL = 1e-7 of the segment (building_response),
        # so its value to ~(w L 1e-7)^2 ~ 1e-14 relative; the searches of the two instances start
        # from different running peaks (their thresholds), so their paths may differ by that
        np.testing.assert_allclose(lazy._derived_array(name), eager._derived_array(name), rtol=1e-12, atol=0.0)
    assert np.all(lazy._derived_array("mu")[:n] > 1.0)


@pytest.mark.parametrize("count", [1, 2, 7, 32])
def test_the_knot_chain_gives_the_chain_of_values_and_slopes(count):
    """ExactPiecewiseLinear._knot_chain (a linear building's knot steps: the knot values in, the
    states and slopes out) gives every interval's y = [z_j; ag_j; slope_j; p] and the end state of
    _chain (values and slopes in, each interval's map applied in turn) to round-off: a knot's
    weight through the interval before it (S^(j-k) a1 / L) left out or misplaced fails by O(1).
    Tolerance: the two sum the same terms in different orders (and a0 - a1/L once), a few eps of
    the largest term, here < 1e-13 relative to each column's magnitude."""
    building = ShearBuilding(np.array([2e5, 1.8e5, 1.5e5]), np.array([3e8, 2.5e8, 2e8]), 0.05)
    integ = integrator_for(building, StoreyHysteresis("linear", np.zeros(3)))
    n = 3
    smap = integ.configuration(np.zeros(n, dtype=np.int64)).segment_map(0.01)
    rng = np.random.default_rng(count)
    u, v, p = rng.normal(size=n) * 1e-2, rng.normal(size=n) * 1e-1, rng.normal(size=n) * 1e4
    ag = rng.normal(size=count + 1) * 3.0
    chain, gather = integ._chain(smap, count)
    x = np.concatenate((u, v, p, ag[:-1], (ag[1:] - ag[:-1]) / smap.length))
    known = np.concatenate((x, chain @ x))
    knot_chain, knot_gather = integ._knot_chain(smap, count)
    x2 = np.concatenate((u, v, p, ag))
    known2 = np.concatenate((x2, knot_chain @ x2))
    Y, Y2 = known[gather], known2[knot_gather]
    scale = np.abs(Y).max(axis=0)
    assert np.all(np.abs(Y2 - Y) <= 1e-13 * scale)
    end, end2 = known[-2 * n:], known2[-(2 * n + count):-count]
    assert np.all(np.abs(end2 - end) <= 1e-13 * np.abs(np.concatenate((Y[:, :2 * n], end[None, :]))).max(axis=0))
