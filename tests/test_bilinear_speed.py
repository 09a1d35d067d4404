"""The cheap paths of the yielding (bilinear) building's step (issue 18, speed): each must give
what the general path gives, to round-off, and its bounds must hold."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from fmu_src.linear_response import Configuration, ModalSegment, TaylorSegment
from fmu_src.shear_building import ShearBuilding


def yielding_configuration(n=5, T1=0.4, alpha=0.05, yielded=(1, 3)):
    """A configuration of a stiff building with some storeys on their post-yield branch."""
    b = ShearBuilding.from_period(T1, [3e5] * n, np.linspace(1.0, 0.5, n), 0.05)
    kt = b.stiffnesses.copy()
    kt[list(yielded)] *= alpha
    return b, Configuration(b.masses, b.C, kt, elastic=False)


@pytest.mark.parametrize("rho", [0.05, 0.5, 1.0, 2.0])
def test_taylor_segment_values_equal_the_modal_solution(rho):
    """Values and first two derivatives of drifts and accelerations on a segment with
    max|lam| L = rho: the Taylor polynomial against the modal evaluation (itself checked against
    the matrix exponential in test_hysteresis), within 1e-13 of the modal magnitudes of each
    derivative (round-off: both are exact; a truncated series would miss by rho^(K+1)/(K+1)!)."""
    b, cfg = yielding_configuration()
    n = cfg.n
    length = rho / cfg.rate
    rng = np.random.default_rng(1)
    for trial in range(5):
        z0 = rng.normal(size=2 * n) * np.concatenate([np.full(n, 0.02), np.full(n, 0.2)])
        w = np.concatenate([[rng.normal() * 3.0, rng.normal() * 300.0], rng.normal(size=n) * 1e5])
        modal = ModalSegment(cfg, z0, w)
        taylor = TaylorSegment(cfg, z0, w, length)
        assert taylor.taylor() is not None
        for row in range(n, 3 * n):          # drifts and accelerations
            c = cfg.peak_modal[row]
            f = taylor.evaluator(c, 3)
            for s in np.linspace(0.0, length, 13):
                want = modal.derivatives(c, float(s), 3)
                scale = modal.magnitudes(np.abs(c), float(s), 3)
                got = f(float(s))
                for k in range(3):
                    assert abs(got[k] - want[k]) <= 1e-13 * scale[k] + 1e-300, (trial, row, s, k)
    # the state at the end from the matrix exponential: the modal solution is the oracle above
    A = cfg.A
    z1 = expm(A * length) @ z0
    assert np.allclose(ModalSegment(cfg, z0, np.zeros(n + 2)).cfg.state_at(
        *cfg.modal(z0, np.zeros(n + 2)), length), z1, rtol=1e-10, atol=1e-14)


def test_taylor_segment_bounds_hold_over_the_segment():
    """bound(order) and bounds45 over [s, s + w] dominate |g^(order)| sampled densely there (the
    bounds come from the segment's start, not from s)."""
    b, cfg = yielding_configuration()
    n = cfg.n
    length = 1.5 / cfg.rate
    rng = np.random.default_rng(2)
    z0 = rng.normal(size=2 * n) * 0.05
    w = np.array([1.0, 200.0] + [0.0] * n)
    seg = TaylorSegment(cfg, z0, w, length)
    modal = ModalSegment(cfg, z0, w)
    for row in range(3 * n):
        c = cfg.peak_modal[row]
        for s, width in ((0.0, length), (0.3 * length, 0.2 * length), (0.7 * length, 0.3 * length)):
            samples = [modal.derivatives(c, float(t), 6) for t in np.linspace(s, s + width, 41)]
            for order in (3, 4, 5):
                bound = seg.bound(np.abs(c), order, s, width)
                assert max(abs(v[order]) for v in samples) <= bound * (1 + 1e-12)
            b4, b5 = seg.bounds45(np.abs(c), s, width)
            assert max(abs(v[4]) for v in samples) <= b4 * (1 + 1e-12)
            assert max(abs(v[5]) for v in samples) <= b5 * (1 + 1e-12)


def test_a_long_segment_falls_back_to_the_modal_form():
    b, cfg = yielding_configuration()
    n = cfg.n
    z0 = np.full(2 * n, 0.01)
    w = np.zeros(n + 2)
    seg = TaylorSegment(cfg, z0, w, 2.5 / cfg.rate)
    assert seg.taylor() is None
    c = cfg.peak_modal[n]
    assert seg.evaluator(c, 3)(0.5 / cfg.rate) == ModalSegment(cfg, z0, w).derivatives(c, 0.5 / cfg.rate, 3)


@pytest.mark.parametrize("rho", [0.1, 1.0, 2.0])
def test_taylor_segment_state_and_energies_equal_the_modal_ones(rho):
    """The state inside a segment and its energy integrals (what an event's partial segments
    use) from the Taylor columns against the modal solution, to round-off of their magnitudes."""
    b, cfg = yielding_configuration()
    n = cfg.n
    length = rho / cfg.rate
    rng = np.random.default_rng(3)
    z0 = rng.normal(size=2 * n) * np.concatenate([np.full(n, 0.02), np.full(n, 0.2)])
    w = np.concatenate([[2.0, -150.0], rng.normal(size=n) * 1e5])
    seg = TaylorSegment(cfg, z0, w, length)
    q0, b0, b1 = cfg.modal(z0, w)
    for s in (0.0, 0.3 * length, length):
        want = cfg.state_at(q0, b0, b1, s)
        scale = np.abs(cfg.V) @ np.abs(cfg.modal_at(q0, b0, b1, s))
        assert np.all(np.abs(seg.state(s) - want) <= 1e-13 * scale)
    for stop in (0.4 * length, length):
        got = seg.energies(w, stop)
        want = cfg.energies(q0, b0, b1, w, stop)
        for g, wv in zip(got, want):
            assert g == pytest.approx(wv, rel=1e-12)


def _ductile_three_storeys():
    """El Centro at 0.3 g and a 3-storey bilinear building (T1 = 0.5 s, yield shears 10 % down
    to 4 % of the weight, 5 % hardening) that reaches a ductility of about 3 under it."""
    from fmu_src.building_response import ExactPiecewiseLinear
    from fmu_src.ground_records import load_record
    from fmu_src.hysteresis import StoreyHysteresis
    rec = load_record("elcentro1940")
    rec = rec.scaled(0.3 * 9.80665 / rec.pga)
    n = 3
    b = ShearBuilding.from_period(0.5, [3e5] * n, [1.0] * n, 0.05)
    fy = 0.1 * n * 3e5 * 9.80665 * np.linspace(1.0, 0.4, n)
    return rec, b, ExactPiecewiseLinear(b, StoreyHysteresis("bilinear", fy, 0.05))


def test_second_order_event_test_never_clears_a_segment_with_an_event(monkeypatch):
    """ExactPiecewiseLinear._second_order_quiet in a yielding run (3 storeys, ductility about 3
    under El Centro at 0.3 g, 10 ms steps) against the modal solution sampled densely: a segment
    it clears has every elastic storey inside its elastic range and every yielding storey
    moving in its yield direction throughout; and it clears a good part of the segments that
    the first-order bound leaves (it is tighter)."""
    from fmu_src.building_response import ExactPiecewiseLinear
    rec, b, it = _ductile_three_storeys()
    n = len(b.masses)
    calls = []
    plain = ExactPiecewiseLinear._second_order_quiet

    def watched(self, cfg, state, elastic, e0, rate0, scan_vector, ag1, length, up, down, unload):
        flags = (up.copy(), down.copy(), unload.copy())
        quiet = plain(self, cfg, state, elastic, e0, rate0, scan_vector, ag1, length, up, down, unload)
        calls.append((cfg, state.u, state.v, state.mode, state.slip, self._net_force(state, np.zeros(n)),
                      ag1, length, quiet, flags, (up.copy(), down.copy(), unload.copy())))
        return quiet
    monkeypatch.setattr(ExactPiecewiseLinear, "_second_order_quiet", watched)
    state = it.initial_state(np.zeros(n), np.zeros(n))
    h = 0.01
    ags = []
    for k in range(800):
        ag = rec.mean_over(k * h, (k + 1) * h)
        before = len(calls)
        it.advance(state, (0.0, h), (ag, ag), np.zeros(n))
        ags.extend([ag] * (len(calls) - before))
    assert float(np.max(state.peak_drift / it.dy)) > 2.0          # it yields
    cleared = events = 0
    for (cfg, u, v, mode, slip, p, ag1, length, quiet, first, second), ag in zip(calls, ags):
        y = np.concatenate([u, v, [ag, ag1], p])
        seg = ModalSegment(cfg, y[:2 * n], y[2 * n:])
        ts = np.linspace(0.0, length, 201)
        z = cfg.state_at(seg.q0, seg.beta0, seg.beta1, ts)            # (2n, 201)
        d = np.diff(np.vstack([np.zeros((1, ts.size)), z[:n]]), axis=0)
        dv = np.diff(np.vstack([np.zeros((1, ts.size)), z[n:]]), axis=0)
        for i in range(n):
            if mode[i] == 0:
                ok = np.all(np.abs(d[i] - slip[i]) < it.dy[i])
                kept = second[0][i] or second[1][i]
            else:
                ok = np.all(mode[i] * dv[i, 1:] > 0.0)
                kept = second[2][i]
            if not ok:
                events += 1
                assert kept and not quiet, (i, mode)
        cleared += quiet
    assert len(calls) > 100 and events > 10      # the test meets real events
    assert cleared > 0.2 * len(calls)


def test_segment_maps_of_yield_patterns_equal_the_einsum_ones():
    """A yield pattern's segment map sums by matrix products; the elastic configuration keeps the
    einsum of earlier versions: the same matrices to round-off (1e-14 of their largest entry)."""
    b, cfg = yielding_configuration(n=8, T1=1.0, yielded=(0, 4))
    legacy = Configuration(b.masses, b.C, cfg.tangent, elastic=False)
    legacy.legacy_arithmetic = True
    assert not cfg.legacy_arithmetic
    for length in (0.01, 0.0137, 0.16):
        a, c = cfg.segment_map(length), legacy.segment_map(length)
        for name in ("state", "damping", "input", "stacked"):
            x, y = getattr(a, name), getattr(c, name)
            assert np.max(np.abs(x - y)) <= 1e-14 * np.max(np.abs(y)), (length, name)


@pytest.mark.parametrize("n", [3, 8])
def test_ad_hoc_and_mapped_segments_give_the_same_run(monkeypatch, n):
    """Brief yield patterns go through ad hoc segments until MAP_AFTER_SEGMENTS; with every
    pattern mapped at once, or never, a yielding run (ductility > 2) ends in the same state,
    energies and peaks to round-off, with the same events."""
    import fmu_src.building_response as response
    from fmu_src.ground_records import load_record
    from fmu_src.hysteresis import StoreyHysteresis
    from fmu_src.record_knots import step_knots
    rec = load_record("elcentro1940")
    rec = rec.scaled(0.3 * 9.80665 / rec.pga)
    b = ShearBuilding.from_period(0.3 * n ** 0.5, [3e5] * n, np.linspace(1.0, 0.6, n), 0.05)
    fy = 0.1 * n * 3e5 * 9.80665 * np.linspace(1.0, 0.4, n)
    runs = []
    for after in (0, 10 ** 9):
        monkeypatch.setattr(response, "MAP_AFTER_SEGMENTS", after)
        it = response.integrator_for(b, StoreyHysteresis("bilinear", fy, 0.05))
        st = it.initial_state(np.zeros(n), np.zeros(n))
        events = 0
        for i in range(200):
            kt, ka = step_knots(rec, 0.02 * i, 0.02 * (i + 1))
            events += it.advance(st, kt - 0.02 * i, ka, np.zeros(n)).events
        it.resolve_peaks(st)
        runs.append((st, events))
    (a, ea), (c, ec) = runs
    assert ea == ec > 10
    assert float(np.max(a.peak_drift / (fy / b.stiffnesses))) > 2.0
    np.testing.assert_allclose(a.u, c.u, rtol=0, atol=1e-12 * np.abs(c.u).max())
    np.testing.assert_allclose(a.peaks, c.peaks, rtol=1e-9)
    for key in ("E_input", "E_damping", "E_hysteretic"):
        assert getattr(a, key) == pytest.approx(getattr(c, key), rel=1e-11)


def test_newton_reads_the_value_and_slope_bit_for_bit():
    """first_root's Newton takes g and g' from ``value_and_slope``, which skips three's g'': the
    same Horner operations, so the same bits (an event time must not move by a search's shortcut)."""
    b, cfg = yielding_configuration()
    n = cfg.n
    rng = np.random.default_rng(7)
    for rho in (0.1, 1.0, 2.0):
        length = rho / cfg.rate
        z0 = rng.normal(size=2 * n) * 0.02
        w = np.concatenate([[1.5, -90.0], rng.normal(size=n) * 1e5])
        seg = TaylorSegment(cfg, z0, w, length)
        for row in range(n, 2 * n):
            three = seg.evaluator(cfg.peak_modal[row], 3)
            for s in np.linspace(0.0, length, 7).tolist():
                assert three.value_and_slope(s) == tuple(three(s)[:2])


def test_one_chunk_nodes_and_cached_taylor_powers_are_the_general_ones():
    """The one-chunk quadrature nodes and the per-degree Taylor powers kept by the configuration
    give the values of the general formulas, bit for bit; and the Taylor columns are
    ``q^(k)(0) / k!`` (``lam^(k-1) q'(0) + lam^(k-2) beta1``), to round-off."""
    import math
    from fmu_src.linear_response import GAUSS_NODES, GAUSS_WEIGHTS, _taylor_powers
    b, cfg = yielding_configuration()
    n = cfg.n
    length = 1.0 / cfg.rate                       # one chunk (CHUNK_RATE = 2)
    nodes, weights = cfg.chunk_nodes(length)
    width = length
    assert np.array_equal(nodes, (width * np.arange(1)[:, None] + width * GAUSS_NODES[None, :]).ravel())
    assert np.array_equal(weights, np.tile(width * GAUSS_WEIGHTS, 1))
    assert cfg.chunk_nodes(3.0 / cfg.rate)[0].size == 2 * GAUSS_NODES.size     # two chunks: general form
    assert cfg.taylor_powers(12) is cfg.taylor_powers(12)
    # every degree (prefixes of the highest one a TaylorSegment asks, or made apart above it)
    from fmu_src.linear_response import TAYLOR_MAX_SPAN, _taylor_degree
    for degree in range(3, _taylor_degree(TAYLOR_MAX_SPAN) + 3):
        fresh = _taylor_powers(cfg.lam, degree)
        kept = cfg.taylor_powers(degree)
        assert kept[3] == degree and all(np.array_equal(a, c) for a, c in zip(kept[:3], fresh[:3]))
    rng = np.random.default_rng(8)
    z0 = rng.normal(size=2 * n) * 0.02
    w = np.concatenate([[1.5, -90.0], rng.normal(size=n) * 1e5])
    seg = TaylorSegment(cfg, z0, w, length)
    columns = seg.taylor()
    q0, beta0, beta1 = cfg.modal(z0, w)
    dq0 = cfg.lam * q0 + beta0
    for k in range(2, columns.shape[1]):
        want = (cfg.lam ** (k - 1) * dq0 + cfg.lam ** (k - 2) * beta1) / math.factorial(k)
        scale = (np.abs(cfg.lam) ** (k - 1) * np.abs(dq0) + np.abs(cfg.lam) ** (k - 2) * np.abs(beta1)) / math.factorial(k)
        assert np.all(np.abs(columns[:, k] - want) <= 1e-13 * scale + 1e-300), k


def test_scalar_hermite_range_is_the_vectorised_one_and_brackets_the_cubic():
    """hermite_range_scalar (written out for speed) gives what the vectorised hermite_range gives
    on the same floats, and its range holds every sample of the cubic Hermite and is reached (to
    1e-12 of the magnitudes) by the densest of them: an extremum left out or misplaced fails."""
    from fmu_src.linear_response import hermite_range, hermite_range_scalar
    rng = np.random.default_rng(11)
    t = np.linspace(0.0, 1.0, 20001)
    h00, h01 = 2 * t ** 3 - 3 * t ** 2 + 1, -2 * t ** 3 + 3 * t ** 2
    h10, h11 = t ** 3 - 2 * t ** 2 + t, t ** 3 - t ** 2
    special = [0.0, 1.0, -1.0, 2.0, 0.5]
    for trial in range(3000):
        if trial % 3 == 0:
            g = rng.choice(special, size=4)              # ties, zero slopes, a vanishing cubic term
        else:
            g = rng.normal(size=4) * 10.0 ** rng.integers(-3, 4, size=4)
        g0, g1, d0, d1 = (float(x) for x in g)
        lo, hi = hermite_range_scalar(g0, g1, d0, d1)
        vlo, vhi = hermite_range(*(np.array([x]) for x in (g0, g1, d0, d1)))
        assert (lo, hi) == (float(vlo[0]), float(vhi[0])), (g0, g1, d0, d1)
        samples = g0 * h00 + g1 * h01 + d0 * h10 + d1 * h11
        scale = 1e-12 * (abs(g0) + abs(g1) + abs(d0) + abs(d1)) + 1e-300
        assert samples.min() >= lo - scale and samples.max() <= hi + scale
        # the grid's spacing 5e-5 misses an interior extremum by at most max|H''| (5e-5)^2 / 8, with
        # |H''| <= 6 |g0 - g1| + 4 |d0| + 4 |d1| on [0, 1]
        slack = 3.2e-10 * (6.0 * abs(g0 - g1) + 4.0 * abs(d0) + 4.0 * abs(d1)) + scale
        assert samples.min() <= lo + slack and samples.max() >= hi - slack


def test_hermite_ranges_is_hermite_range_below_and_above_its_threshold():
    """hermite_ranges (element by element below HERMITE_VECTOR_FROM, for the in-step peak tests of
    _interval_peaks) gives hermite_range's floats exactly on both sides of its threshold, ties,
    zero slopes and vanishing cubic terms included: a branch taken differently fails."""
    from fmu_src.linear_response import HERMITE_VECTOR_FROM, hermite_range, hermite_ranges
    rng = np.random.default_rng(17)
    special = np.array([0.0, 1.0, -1.0, 2.0, 0.5])
    for size in (1, 2, 7, HERMITE_VECTOR_FROM - 1, HERMITE_VECTOR_FROM, 3 * HERMITE_VECTOR_FROM):
        for trial in range(200):
            args = [rng.normal(size=size) * 10.0 ** rng.integers(-6, 7, size=size) for _ in range(4)]
            if trial % 3 == 0:
                for a in args:
                    a[::2] = rng.choice(special, size=a[::2].size)
            lo, hi = hermite_ranges(*args)
            vlo, vhi = hermite_range(*args)
            assert lo.dtype == vlo.dtype and lo.shape == vlo.shape == (size,)
            assert np.array_equal(lo, vlo) and np.array_equal(hi, vhi), (size, trial)


def test_eigen_is_scipy_eig_bit_for_bit():
    """linear_response._eigen (every yield pattern's decomposition) gives scipy.linalg.eig's
    eigenvalues and eigenvectors bit for bit, dtype included: state matrices of shear buildings of
    1 to 20 storeys, yielding storeys at 5 % stiffness, undamped to overdamped (real eigenvalues:
    eig then keeps real eigenvectors); a non-finite matrix is refused as eig refuses it."""
    from scipy.linalg import eig
    from fmu_src.linear_response import ConfigurationConstants, _eigen
    rng = np.random.default_rng(3)
    kinds = set()
    for _ in range(400):
        n = int(rng.integers(1, 21))
        m = rng.uniform(1e5, 5e5, n)
        k = rng.uniform(1e7, 1e9, n) * np.where(rng.random(n) < 0.4, 0.05, 1.0)
        K = np.diag(k + np.append(k[1:], 0.0)) - np.diag(k[1:], 1) - np.diag(k[1:], -1)
        zeta = float(rng.choice([0.0, 0.02, 0.3, 50.0]))
        C = zeta * (0.01 * K + np.diag(m))
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -K / m[:, None]
        A[n:, n:] = -C / m[:, None]
        (lam0, V0), (lam1, V1) = eig(A), _eigen(A)
        assert V0.dtype == V1.dtype and np.array_equal(lam0, lam1) and np.array_equal(V0, V1)
        # with the building's LAPACK routine and workspace size (ConfigurationConstants)
        lam2, V2 = _eigen(A, ConfigurationConstants(m, C))
        assert V2.dtype == V0.dtype and lam2.tobytes() == lam0.tobytes() and V2.tobytes() == V0.tobytes()
        kinds.add(V1.dtype.kind)
    assert kinds == {"c", "f"}          # both kinds of basis met
    A[0, 0] = np.nan
    with pytest.raises(ValueError):
        _eigen(A)


def test_configuration_with_shared_constants_is_the_configuration_bit_for_bit():
    """A yield pattern's Configuration built from its building's ConfigurationConstants (the
    arrays every pattern shares, made once) has the arrays that the construction of each
    pattern from scratch gives (written out here as it was: K from np.diag, A by blocks, the
    tracked and watched rows by blocks, |lam|'s powers by column_stack), byte for byte (signed
    zeros included: a storey at zero tangent stiffness, alpha = 0); and so the same modal
    solution and segment map."""
    from fmu_src.linear_response import ConfigurationConstants
    rng = np.random.default_rng(8)
    for n, alpha in ((1, 0.05), (3, 0.0), (5, 0.05), (15, 0.05), (15, 0.0)):
        b = ShearBuilding.from_period(0.8, rng.uniform(2e5, 5e5, n), rng.uniform(0.5, 1.0, n), 0.05)
        shared = ConfigurationConstants(b.masses, b.C)
        for trial in range(3):
            kt = b.stiffnesses * np.where(rng.random(n) < 0.4, alpha, 1.0)
            cfg = Configuration(b.masses, b.C, kt, elastic=False, constants=shared)
            m = b.masses
            K = np.diag(kt + np.append(kt[1:], 0.0)) - np.diag(kt[1:], 1) - np.diag(kt[1:], -1)
            A = np.zeros((2 * n, 2 * n))
            A[:n, n:] = np.eye(n)
            A[n:, :n] = -K / m[:, None]
            A[n:, n:] = -b.C / m[:, None]
            D = np.eye(n) - np.eye(n, k=-1)
            F = np.zeros((3 * n, 2 * n))
            F[:n, :n] = np.eye(n)
            F[n:2 * n, :n] = D
            F[2 * n:, :] = A[n:, :]
            watch = np.zeros((4 * n, 2 * n))
            watch[:3 * n] = F
            watch[3 * n:, n:] = D
            B0 = np.zeros((2 * n, n + 2))
            B0[n:, 0] = -1.0
            B0[n:, 2:] = np.diag(1.0 / m)
            B1 = np.zeros((2 * n, n + 2))
            B1[n:, 1] = -1.0
            la = np.abs(cfg.lam)
            powers = np.column_stack([np.ones_like(la), la, la ** 2, la ** 3, la ** 4])
            for got, want in ((cfg.K, K), (cfg.A, A), (cfg.peak_rows, F), (cfg.watch_rows, watch), (cfg.B0, B0),
                              (cfg.B1, B1), (cfg.lam_powers, powers)):
                assert got.shape == want.shape and got.tobytes() == want.tobytes()
            assert cfg.rate == float(np.max(la)) and cfg.growth_rate == max(0.0, float(np.max(cfg.lam.real)))
            alone = Configuration(b.masses, b.C, kt, elastic=False)       # its own constants
            for name in ("lam", "V", "W", "WB0", "WB1", "peak_modal"):
                assert getattr(cfg, name).tobytes() == getattr(alone, name).tobytes(), name
            L = 0.01
            assert cfg.segment_map(L).stacked.tobytes() == alone.segment_map(L).stacked.tobytes()


def test_chord_event_test_never_clears_an_interval_with_an_event(monkeypatch):
    """ExactPiecewiseLinear._chord_quiet (the batch's test of the intervals tier 1 leaves, from
    both ends of each) in a yielding run (3 storeys, ductility about 3 under El Centro at 0.3 g,
    steps of 8 record intervals) against the modal solution sampled densely: an interval it
    clears has every elastic storey inside its elastic range and every yielding storey moving
    in its yield direction throughout; it meets real events among the intervals it is asked
    about, and clears a good part of them (it is what lets the batch go on)."""
    from fmu_src.building_response import ExactPiecewiseLinear
    from fmu_src.record_knots import step_knots
    rec, b, it = _ductile_three_storeys()
    n = len(b.masses)
    asked = []
    plain = ExactPiecewiseLinear._chord_quiet

    def watched(self, cfg, state, elastic, yielding, out, Y, z_end, js, rows, lengths):
        quiet = plain(self, cfg, state, elastic, yielding, out, Y, z_end, js, rows, lengths)
        for k, j in enumerate(np.asarray(js)[rows].tolist()):
            asked.append((cfg, Y[j].copy(), float(lengths[j]), state.mode.copy(), state.slip.copy(), bool(quiet[k])))
        return quiet
    monkeypatch.setattr(ExactPiecewiseLinear, "_chord_quiet", watched)
    state = it.initial_state(np.zeros(n), np.zeros(n))
    h = 0.16                                   # 8 intervals of the record's 0.02 s
    for i in range(60):
        kt, ka = step_knots(rec, h * i, h * (i + 1))
        it.advance(state, kt - h * i, ka, np.zeros(n))
    assert float(np.max(state.peak_drift / it.dy)) > 2.0          # it yields
    cleared = events = 0
    for cfg, y, length, mode, slip, quiet in asked:
        seg = ModalSegment(cfg, y[:2 * n], y[2 * n:])
        ts = np.linspace(0.0, length, 401)
        z = cfg.state_at(seg.q0, seg.beta0, seg.beta1, ts)            # (2n, 401)
        d = np.diff(np.vstack([np.zeros((1, ts.size)), z[:n]]), axis=0)
        dv = np.diff(np.vstack([np.zeros((1, ts.size)), z[n:]]), axis=0)
        ok = True
        for i in range(n):
            if mode[i] == 0:
                ok &= bool(np.all(np.abs(d[i] - slip[i]) < it.dy[i]))
            else:
                ok &= bool(np.all(mode[i] * dv[i, 1:] > 0.0))
        if not ok:
            events += 1
            assert not quiet
        cleared += quiet
    assert len(asked) > 50 and events > 5        # the test meets real events
    assert cleared > 0.2 * len(asked)


@pytest.mark.parametrize("mode", [(0, 0, 0), (1, 0, -1)])
def test_chord_event_test_holds_where_an_interval_peaks_inside(mode):
    """ExactPiecewiseLinear._chord_quiet on single intervals built to peak inside (random states
    scaled so that the largest |d - s| over the interval is 0.9 to 1.1 dy, intervals of 0.02 to
    0.1 s), against the modal solution sampled densely: every interval it clears is free of
    events, and among the samples are intervals whose ends are inside the elastic range (or
    whose ends move in the yield direction) but whose interior is not: only the curvature term
    keeps the test from clearing those (dropping it fails this test)."""
    from fmu_src.building_response import ExactPiecewiseLinear
    from fmu_src.hysteresis import StoreyHysteresis
    n = 3
    b = ShearBuilding.from_period(0.5, [3e5] * n, [1.0] * n, 0.05)
    fy = 0.1 * n * 3e5 * 9.80665 * np.linspace(1.0, 0.4, n)
    it = ExactPiecewiseLinear(b, StoreyHysteresis("bilinear", fy, 0.05))
    mode = np.array(mode, dtype=np.int64)
    elastic = mode == 0
    cfg = it.configuration(mode)
    rng = np.random.default_rng(11)
    ends_only = cleared = 0
    for trial in range(1000):
        L = float(rng.uniform(0.01, 0.06))
        smap = cfg.segment_map(L)
        tier1 = it._batch_plan(smap)[1]
        slip = np.where(elastic, rng.normal(size=n) * 0.2 * it.dy, 0.0)
        # drift rates of about dy w1, a yielding storey's biased to its yield direction
        rates = rng.normal(size=n) * it.dy * 12.0
        rates[~elastic] = mode[~elastic] * it.dy[~elastic] * 12.0 * rng.uniform(-0.2, 1.0, size=int((~elastic).sum()))
        y = np.concatenate([rng.normal(size=n) * it.dy, np.cumsum(rates),
                            [rng.normal() * 2.0, rng.normal() * (300.0 if trial % 2 else 3000.0)], np.zeros(n)])
        seg = ModalSegment(cfg, y[:2 * n], y[2 * n:])
        ts = np.linspace(0.0, L, 801)
        z = cfg.state_at(seg.q0, seg.beta0, seg.beta1, ts)
        d = np.diff(np.vstack([np.zeros((1, ts.size)), z[:n]]), axis=0)
        e = d - slip[:, None]
        scale = float(rng.uniform(0.6, 1.1)) / np.max(np.abs(e[elastic]) / it.dy[elastic, None])
        y[:2 * n] *= scale                     # the response is linear in the state (no forcing below)
        y[2 * n:] *= scale
        slip = slip * scale
        z *= scale
        state = it.initial_state(np.zeros(n), np.zeros(n))
        state.mode, state.slip = mode, slip
        Y = y[None, :]
        out = Y @ tier1.T
        quiet = bool(it._chord_quiet(cfg, state, elastic, bool(mode.any()), out, Y, smap.state @ y, [0],
                                     np.array([0]), [L])[0])
        d = np.diff(np.vstack([np.zeros((1, ts.size)), z[:n]]), axis=0)
        dv = np.diff(np.vstack([np.zeros((1, ts.size)), z[n:]]), axis=0)
        inside = np.abs(d - slip[:, None]) < it.dy[:, None]
        moving = mode[:, None] * dv > 0.0
        ok = np.where(elastic[:, None], inside, moving)
        if not ok.all():
            assert not quiet, trial
            ends_only += bool(ok[:, [0, -1]].all())
        cleared += quiet
    assert cleared > 0
    assert ends_only >= 5          # intervals only the curvature term refuses


@pytest.mark.parametrize("rho", [0.05, 0.5, 1.0, 2.0])
def test_taylor_scan_equals_the_segment_and_its_scan_vector(rho):
    """TaylorScan (an ad hoc segment's end state, scan vector and energies from its real Taylor
    coefficients) against TaylorSegment.state, Configuration.scan_vector and
    TaylorSegment.energies, at the segment's end and inside it (where an event cuts it): within
    1e-13 of each vector's largest entry and 1e-12 of the energies' magnitudes (round-off: the
    same sums in another order)."""
    from fmu_src.linear_response import TaylorScan
    b, cfg = yielding_configuration()
    n = cfg.n
    length = rho / cfg.rate
    assert TaylorScan.fits(cfg, length) and not TaylorScan.fits(cfg, 2.01 / cfg.rate)
    rng = np.random.default_rng(9)
    for trial in range(5):
        z0 = rng.normal(size=2 * n) * np.concatenate([np.full(n, 0.02), np.full(n, 0.2)])
        w = np.concatenate([[rng.normal() * 3.0, rng.normal() * 300.0], rng.normal(size=n) * 1e5])
        segment = TaylorSegment(cfg, z0, w, length)
        scan = TaylorScan(segment)
        for s in (length, 0.37 * length):
            z1, vector = scan.state_and_scan(s)
            want_z = segment.state(s)
            want = cfg.scan_vector(z0, want_z, w, s)
            assert np.max(np.abs(z1 - want_z)) <= 1e-13 * np.max(np.abs(want_z))
            assert np.max(np.abs(vector - want)) <= 1e-13 * np.max(np.abs(want))
            got_e, want_e = scan.energies(w, s), segment.energies(w, s)
            q0, b0, b1 = cfg.modal(z0, w)
            size = np.abs(cfg.energies(q0, b0, b1, w, s))
            for g, e, m in zip(got_e, want_e, size):
                assert abs(g - e) <= 1e-12 * max(m, abs(e))


def test_a_taylor_segments_scan_of_parts_is_the_scan_of_its_vector():
    """Scan.of_parts (the ad hoc path's Scan from TaylorScan.state_and_values' G and W z'(0),
    without the vector) against Scan of TaylorScan.state_and_scan's vector, at the end and
    inside, with and without a ground-acceleration slope: the same G and B, bit for bit (the
    same numbers in another container), and the same end state; the grid remembered for a
    span (Configuration.taylor_grid) gives the same numbers at its second use."""
    from fmu_src.linear_response import Scan, TaylorScan
    b, cfg = yielding_configuration()
    n = cfg.n
    length = 0.8 / cfg.rate
    rng = np.random.default_rng(11)
    for trial in range(4):
        z0 = rng.normal(size=2 * n) * np.concatenate([np.full(n, 0.02), np.full(n, 0.2)])
        slope = 0.0 if trial == 0 else rng.normal() * 300.0
        w = np.concatenate([[rng.normal() * 3.0, slope], rng.normal(size=n) * 1e5])
        poly = TaylorScan(TaylorSegment(cfg, z0, w, length))
        for s in (length, 0.37 * length, length):
            z1, vector = poly.state_and_scan(s)
            z2, G = poly.state_and_values(s)
            want, got = Scan(cfg, vector, slope, s), Scan.of_parts(cfg, G, poly.rate0, slope, s)
            np.testing.assert_array_equal(z1, z2)
            np.testing.assert_array_equal(got.G, want.G)
            np.testing.assert_array_equal(got.B, want.B)


def test_the_stacked_modal_forcing_gives_each_product_bit_for_bit():
    """Configuration.modal forms beta0 and beta1 by one product with [W B0; W B1]: the rows of a
    matrix-vector product are the same dot products whatever rows are stacked with them, so
    the values are those of the separate products (what the segment maps and every event
    time were computed from), bit for bit, for the elastic and a yielding configuration."""
    b, cfg = yielding_configuration()
    n = cfg.n
    elastic = Configuration(b.masses, b.C, b.stiffnesses)
    rng = np.random.default_rng(12)
    for c in (cfg, elastic):
        for trial in range(20):
            z0 = rng.normal(size=2 * n)
            w = np.concatenate([rng.normal(size=2) * 100.0, rng.normal(size=n) * 1e5])
            q0, beta0, beta1 = c.modal(z0, w)
            np.testing.assert_array_equal(q0, c.W @ z0)
            np.testing.assert_array_equal(beta0, (c.W @ c.B0) @ w)
            np.testing.assert_array_equal(beta1, (c.W @ c.B1) @ w)


def test_a_taylor_segments_start_values_are_the_modal_ones():
    """TaylorSegment.start_values (the slope and curvature at 0 from the Taylor coefficients, the
    magnitudes from the first three columns) against ModalSegment.start_values: the value at 0
    bit for bit (a search at its limit shifts its offset by it), the others within 1e-13 of
    their magnitudes (round-off of the same sums in another order; they only decide)."""
    b, cfg = yielding_configuration()
    n = cfg.n
    length = 1.2 / cfg.rate
    rng = np.random.default_rng(13)
    for trial in range(10):
        z0 = rng.normal(size=2 * n) * np.concatenate([np.full(n, 0.02), np.full(n, 0.2)])
        w = np.concatenate([[rng.normal() * 3.0, rng.normal() * 300.0], rng.normal(size=n) * 1e5])
        c = rng.normal(size=2 * n) @ cfg.V
        c_abs = np.abs(c)
        got, got_scale = TaylorSegment(cfg, z0, w, length).start_values(c, c_abs)
        want, want_scale = ModalSegment(cfg, z0, w).start_values(c, c_abs)
        assert got[0] == want[0]
        for k in (1, 2):
            assert abs(got[k] - want[k]) <= 1e-13 * want_scale[k]
        for g, m in zip(got_scale, want_scale):
            assert abs(g - m) <= 1e-13 * m
