"""The proof with the ground's response computed (:class:`cosim.master.gap_bound._ExactPair`)
against the motion itself.

The oracle is the one ``tests/test_gap_bound.py`` checks (solve_ivp, DOP853, rtol 1e-11, of
``M u'' + C u' + K u = -M 1 ag + F`` with ``ag`` linear between its knots).  Checked here:

* the kernels (:meth:`ModalBound.ground_kernels`, ``floor_kernels``) give each mode's and each
  floor's displacement from rest at every grid point, for a ground linear between grid points,
  and :meth:`ModalBound.step_response` a held force's;
* what the proof bounds of the ground, ``max |ag - g_grid|`` (:meth:`GroundAhead.on_grid`),
  bounds it on a dense sampling, and is zero when every knot is a grid point;
* a proven horizon is never past the first closure, for random pairs of buildings, states,
  records with knots between the grid points and held forces, including gaps set just below
  and just above the largest penetration the motion reaches; and the proof is not vacuous:
  with the gap just wider than what the motion reaches (by a few grid intervals' rate slack)
  it proves the whole horizon.
"""
from __future__ import annotations

import numpy as np
import pytest

from cosim.master.gap_bound import GRID, GroundAhead, ModalBound, OpenGaps, running_max_abs
from fmu_src.shear_building import ShearBuilding
from test_gap_bound import motion


def building(rng, n):
    masses = list(rng.uniform(0.5, 2.0, n) * 1e5)
    stiffnesses = list(rng.uniform(0.5, 2.0, n))
    damping = "modal" if rng.random() < 0.5 else "rayleigh"
    return ShearBuilding.from_period(float(rng.uniform(0.2, 1.5)), masses, stiffnesses, 0.05, damping)


@pytest.mark.parametrize("seed", range(4))
def test_ground_kernels_are_the_modal_response(seed):
    """Modal and floor kernels, and the step response, against the oracle from rest."""
    rng = np.random.default_rng(seed)
    b = building(rng, int(rng.integers(1, 6)))
    bound = ModalBound(b)
    H = float(rng.choice([0.05, 0.33]))
    s = H * np.arange(GRID + 1) / GRID
    g = rng.normal(0.0, 3.0, GRID + 1)
    n = bound.n
    dense = motion(b, np.zeros(n), np.zeros(n), s, g, np.zeros(n), H, s)      # floors x points, transposed
    q = bound.to_modal @ dense.T
    # 1e-9 of the largest value: solve_ivp's tolerance (rtol 1e-11) on displacements of ~1 mm
    np.testing.assert_allclose(bound.ground_kernels(H) @ g, q, rtol=0, atol=1e-9 * np.abs(q).max())
    np.testing.assert_allclose(bound.floor_kernels(H) @ g, dense.T, rtol=0, atol=1e-9 * np.abs(dense).max())
    # a held force: the step response times the modal load
    force = rng.normal(0.0, 1e5, n)
    held = motion(b, np.zeros(n), np.zeros(n), np.array([-1.0, 2.0]), np.zeros(2), force, H, s)
    got = b.mode_shapes @ (bound.step_response(H) * (bound.phi.T @ force)[:, None])
    np.testing.assert_allclose(got, held.T, rtol=0, atol=1e-9 * np.abs(held).max())


def test_ground_on_grid_bounds_the_bend():
    rng = np.random.default_rng(2)
    times = np.arange(-0.1, 1.0, 0.01)
    values = rng.normal(0.0, 3.0, times.size)
    for t0, H in ((0.0123, 0.33), (0.2, 0.05), (0.5, 0.17)):
        ahead = GroundAhead(times, values, t0, H)
        g, rest, integral = ahead.on_grid()
        s = t0 + H * np.arange(GRID + 1) / GRID
        np.testing.assert_array_equal(g, np.interp(s, times, values))
        dense = np.linspace(t0, t0 + H, 20001)
        gap = np.abs(np.interp(dense, times, values) - np.interp(dense, s, g))
        k = np.minimum(np.searchsorted(s, dense, "left"), GRID)     # dense point <= s_k
        assert np.all(gap <= rest[k] + 1e-12)
        assert rest[-1] > 0.0                                       # knots between the grid points bend
        np.testing.assert_array_equal(ahead(), running_max_abs(times, values, t0, H))
        # the integral of |g_grid| up to each grid point, at least the dense trapezoid's (which
        # cuts the corners of |g_grid| at the grid points: 1e-5 of it covers that, a dropped
        # interval or a halved one would not be)
        dense_int = np.concatenate(([0.0], np.cumsum(0.5 * np.diff(dense) * (np.abs(np.interp(dense, s, g))[1:]
                                                                        + np.abs(np.interp(dense, s, g))[:-1]))))
        assert np.all(np.interp(s, dense, dense_int) <= integral * (1 + 1e-5) + 1e-12)
    # knots on the grid points: nothing but the round-off slack
    s = 0.1 + 0.32 * np.arange(GRID + 1) / GRID
    g, rest, _ = GroundAhead(s, rng.normal(0, 3, s.size), 0.1, 0.32).on_grid()
    assert rest.max() <= 1e-11


def record(rng, times):
    """An accelerogram-like polyline (m/s^2): a few tones of 0.5 to 8 Hz, peak ~3 m/s^2, sampled
    at the knots (white noise at 100 Hz would bend at every knot far more than a record does)."""
    f = rng.uniform(0.5, 8.0, 5)
    phase = rng.uniform(0, 2 * np.pi, 5)
    amp = rng.uniform(0.2, 1.0, 5)
    return 3.0 * (amp[:, None] * np.sin(2 * np.pi * f[:, None] * times + phase[:, None])).sum(0) / amp.sum()


def _pair(rng):
    nl, nr = int(rng.integers(1, 6)), int(rng.integers(1, 6))
    bl, br = building(rng, nl), building(rng, nr)
    ix_l, iv_l = np.arange(nl), nl + np.arange(nl)
    ix_r, iv_r = 2 * nl + np.arange(nr), 2 * nl + nr + np.arange(nr)
    buildings = {"left": (ModalBound(bl), ix_l, iv_l), "right": (ModalBound(br), ix_r, iv_r)}
    return nl, nr, bl, br, buildings


def closure_case(seed: int) -> dict:
    """A random pair of buildings, a record, a start state and (half the time) held forces, with
    the relative motion of floor ``f`` over the horizon (seeded: the same case in any process)."""
    rng = np.random.default_rng(100 + seed)
    nl, nr, bl, br, buildings = _pair(rng)
    m = min(nl, nr)
    f = int(rng.integers(m))
    H = float(rng.choice([0.09, 0.17, 0.33]))
    t0 = float(rng.uniform(0.0, 0.05))
    times = np.arange(0.0, 1.0, 0.01) + float(rng.uniform(0, 0.01))   # knots between the grid points
    times[0] = -0.1
    values = record(rng, times)
    ul, vl = rng.normal(0.0, 0.01, nl), rng.normal(0.0, 0.1, nl)
    ur, vr = rng.normal(0.0, 0.01, nr), rng.normal(0.0, 0.1, nr)
    force = rng.random() < 0.5
    Fl = np.where(np.arange(nl) == f, -1e5 * rng.random(), 0.0) if force else np.zeros(nl)
    Fr = np.where(np.arange(nr) == f, 1e5 * rng.random(), 0.0) if force else np.zeros(nr)
    dense = np.linspace(0.0, H, 1601)
    shifted = times - t0
    rel = (motion(bl, ul, vl, shifted, values, Fl, H, dense)[:, f]
           - motion(br, ur, vr, shifted, values, Fr, H, dense)[:, f])
    return dict(buildings=buildings, f=f, H=H, t0=t0, times=times, values=values, dense=dense, rel=rel,
                y=np.concatenate((ul, vl, ur, vr)), forces={"left": Fl, "right": Fr} if force else None)


def _horizon(case: dict, gap: float) -> float:
    gaps = OpenGaps(case["buildings"], [("left", case["f"], "right", case["f"], float(gap))])
    return gaps.horizons(case["y"], case["H"], GroundAhead(case["times"], case["values"], case["t0"], case["H"]),
                         case["forces"])[0]


@pytest.mark.parametrize("seed", range(10))
def test_exact_proof_never_passes_a_closure(seed):
    case = closure_case(seed)
    rel, dense = case["rel"], case["dense"]
    reach = rel.max()
    for gap, closes in ((reach - 1e-4, True), (reach - 0.3 * (reach - rel[0]), True), (reach + 1e-4, False)):
        if gap <= rel[0]:
            continue
        s = _horizon(case, gap)
        if closes:
            closing = dense[np.argmax(rel - gap >= 0.0)]
            assert s <= closing, (gap, s, closing)
        # the gap is open over what the proof says
        assert np.all(rel[dense <= s] - gap < 0.0)


def test_exact_proof_cases_reach_the_whole_horizon():
    """The proof is not vacuous: of the cases above, most prove a gap 20 % of the motion's range
    wider than what it reaches for the whole horizon (a proof that always answered 0 would pass
    the asserts above).  The cases are made again here: no test depends on another having run
    in the same process (the suite runs on several workers)."""
    whole = []
    for seed in range(10):
        case = closure_case(seed)
        rel = case["rel"]
        reach = rel.max()
        wide = reach + 0.2 * (reach - min(rel.min(), reach - 0.01))
        whole.append(_horizon(case, wide) == case["H"])
    assert sum(whole) >= 6, whole


def test_exact_proof_is_longer_than_the_bound_of_the_whole_ground():
    """Under a strong record over a long horizon the former proof (the whole ground bounded)
    stops early; the exact one reaches the closure within a grid interval or two."""
    rng = np.random.default_rng(11)
    nl, nr, bl, br, buildings = _pair(rng)
    H = 0.33
    times = np.arange(-0.1, 1.0, 0.01) + 0.004
    values = record(rng, times)
    y = np.concatenate((np.zeros(nl), np.full(nl, 0.05), np.zeros(nr), np.full(nr, -0.05)))
    gap = 0.04
    gaps = OpenGaps(buildings, [("left", 0, "right", 0, gap)])
    exact = gaps.horizons(y, H, GroundAhead(times, values, 0.0, H))[0]
    bounded = gaps.horizons(y, H, running_max_abs(times, values, 0.0, H))[0]
    dense = np.linspace(0.0, H, 3301)
    rel = (motion(bl, y[:nl], y[nl:2 * nl], times, values, np.zeros(nl), H, dense)[:, 0]
           - motion(br, y[2 * nl:2 * nl + nr], y[2 * nl + nr:], times, values, np.zeros(nr), H, dense)[:, 0])
    closing = dense[np.argmax(rel - gap >= 0.0)] if np.any(rel >= gap) else H
    assert bounded < exact <= closing
    assert exact >= closing - 3 * H / GRID


def _rest_pair():
    left = ShearBuilding.from_period(0.5, [3e5] * 3, [1.0] * 3, 0.05)
    right = ShearBuilding.from_period(1.0, [3e5] * 5, [1.0] * 5, 0.05)
    buildings = {"left": (ModalBound(left), np.arange(3), 3 + np.arange(3)),
                 "right": (ModalBound(right), 6 + np.arange(5), 11 + np.arange(5))}
    return left, right, buildings


def test_held_force_moves_the_floors():
    """Buildings at rest, no ground motion, a force held on the left building's level floor
    towards the right one: the gap closes, and the proof stops before (a proof that left the
    force out would see no motion at all)."""
    left, right, buildings = _rest_pair()
    H = 0.33
    times, values = np.array([-1.0, 2.0]), np.zeros(2)
    Fl = np.array([0.0, 0.0, 3e5])
    dense = np.linspace(0.0, H, 1601)
    x = motion(left, np.zeros(3), np.zeros(3), times, values, Fl, H, dense)[:, 2]
    gap = 0.5 * x.max()
    closing = dense[np.argmax(x >= gap)]
    gaps = OpenGaps(buildings, [("left", 2, "right", 2, gap)])
    s = gaps.horizons(np.zeros(16), H, GroundAhead(times, values, 0.0, H), {"left": Fl, "right": np.zeros(5)})[0]
    assert 0.5 * closing < s <= closing


def test_ground_between_the_grid_points_moves_the_floors():
    """A record that is zero at every grid point and peaks between them (knots at the grid
    points and their midpoints): the polyline through the grid values is zero, so only the
    bound of the rest (GroundAhead.on_grid) sees the motion; the proof stops before the
    closure."""
    left, right, buildings = _rest_pair()
    H = 0.33
    s = H * np.arange(GRID + 1) / GRID
    mid = 0.5 * (s[:-1] + s[1:])
    times = np.concatenate((s, mid, [-1.0, 2.0]))
    values = np.concatenate((np.zeros(s.size), np.full(mid.size, 6.0), [0.0, 0.0]))
    order = np.argsort(times)
    times, values = times[order], values[order]
    dense = np.linspace(0.0, H, 1601)
    # ag > 0 pushes every floor towards -x, the softer right building's floor 3 further than the
    # left roof: the gap between them narrows
    xl = motion(left, np.zeros(3), np.zeros(3), times, values, np.zeros(3), H, dense)[:, 2]
    xr = motion(right, np.zeros(5), np.zeros(5), times, values, np.zeros(5), H, dense)[:, 2]
    rel = xl - xr
    assert rel.max() > 1e-4                            # the floors do move apart of rest
    gap = 0.5 * rel.max()
    closing = dense[np.argmax(rel >= gap)]
    gaps = OpenGaps(buildings, [("left", 2, "right", 2, gap)])
    got = gaps.horizons(np.zeros(16), H, GroundAhead(times, values, 0.0, H))[0]
    assert got <= closing


def elastic_buildings(rng, alpha):
    """The default_inelastic scene's two buildings (tests/test_gap_bound_yielding.py) in random
    elastic states: slips of up to a yield drift, every storey inside its elastic range, drift
    rates of 0.01 to 0.1 m/s; ``y`` laid out as (x, v, residual drift) per building."""
    from cosim.master.gap_bound import ElasticRange
    from fmu_src.hysteresis import StoreyHysteresis
    from test_gap_bound_yielding import LEFT, RIGHT, building as scene_building
    buildings, elastic, yielded, y, states = {}, {}, {}, [], []
    offset = 0
    for name, spec in (("left", LEFT), ("right", RIGHT)):
        b, fy = scene_building(spec)
        law = StoreyHysteresis("bilinear", fy, alpha)
        n = b.n
        dy = law.yield_drift(b.stiffnesses)
        slip = rng.uniform(-1.0, 1.0, n) * dy
        u0 = np.cumsum(slip + rng.uniform(-0.5, 0.5, n) * dy)
        v0 = np.cumsum(rng.uniform(0.01, 0.1, n) * np.where(rng.random(n) < 0.5, -1.0, 1.0))
        ix, iv, ir = (offset + np.arange(n) + k * n for k in range(3))
        offset += 3 * n
        buildings[name] = (ModalBound(b), ix, iv)
        elastic[name] = ElasticRange(alpha, law.yield_drift(b.stiffnesses), ir)
        yielded[name] = ModalBound.through_yielding(b, alpha, fy)
        y += [u0, v0, (1.0 - alpha) * slip]
        states.append((b, law, u0, v0, slip, np.zeros(n, dtype=np.int64)))
    return buildings, elastic, yielded, np.concatenate(y), states


@pytest.mark.parametrize("alpha", (0.0, 0.05, 0.5))
def test_exact_proof_of_yielding_buildings_is_a_proof(alpha):
    """Two bilinear buildings (the default_inelastic scene's, tests/test_gap_bound_yielding.py's
    oracle: building.fmu's exact motion through yielding), elastic or yielding: with the ground
    ahead the proof computes its response while both buildings are proven elastic
    (_BilinearPair), and through yielding keeps the bound of the whole ground.  The gap stays
    open over the proven horizon, for gaps from wide to just below what the motion reaches; on
    elastic states the exact proof is longer than the bounded one in most open cases."""
    from test_gap_bound_yielding import H, exact_motion, record_window, two_buildings
    rng = np.random.default_rng(31 + int(100 * alpha))
    longer = cases = 0
    for case in range(12):
        make = elastic_buildings if case % 3 else two_buildings
        buildings, elastic, yielded, y, states = make(rng, alpha)
        knots, values = record_window(rng)
        (bl, lawl, ul, vl, sl, ml), (br, lawr, ur, vr, sr, mr) = states
        dense = np.linspace(0.0, H, 661)
        left = exact_motion(bl, lawl, ul, vl, sl, ml, knots, values, np.zeros(3), dense)[0]
        right = exact_motion(br, lawr, ur, vr, sr, mr, knots, values, np.zeros(5), dense)[0]
        rel = left[:, 2] - right[:, 2]
        for gap in (float(rel.max() + rng.uniform(0.001, 0.02)), float(rel.max() - 1e-4)):
            if gap <= rel[0]:
                continue
            levels = [("left", 2, "right", 2, gap)]
            gaps = OpenGaps(buildings, levels, elastic, yielded)
            assert gaps.stacked
            proven = gaps.horizons(y, H, GroundAhead(knots, values, 0.0, H))[0]
            bounded = OpenGaps(buildings, levels, elastic, yielded).horizons(
                y, H, running_max_abs(knots, values, 0.0, H))[0]
            assert np.all(rel[dense <= proven] - gap < 0.0), (case, gap, proven)
            if gap > rel.max() and make is elastic_buildings:
                cases += 1
                longer += proven > bounded
    assert cases and longer >= cases / 2, (longer, cases)


@pytest.mark.parametrize("seed", range(4))
def test_floor_kernel_columns_are_the_full_kernels_columns(seed):
    """What _ExactPair takes without the full kernels: the floor kernels' columns 0 (the first grid
    value's half hat) and 1 (the hat at point 1), and by the Toeplitz structure every later hat's
    column is column 1 shifted by its lag (the structure _ExactPair's convolution relies on)."""
    rng = np.random.default_rng(seed)
    b = building(rng, int(rng.integers(1, 6)))
    bound = ModalBound(b)
    H = float(rng.choice([0.05, 0.33]))
    full = bound.floor_kernels(H)
    first, second = bound.floor_kernel_columns(H)
    scale = np.abs(full).max()
    # round-off only: the same products summed by another blocking of the matrix product
    np.testing.assert_allclose(first, full[:, :, 0], rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(second, full[:, :, 1], rtol=0, atol=1e-13 * scale)
    for i in (2, GRID // 2, GRID):
        np.testing.assert_allclose(full[:, i:, i], second[:, 1:GRID + 2 - i], rtol=0, atol=1e-13 * scale)
        assert not full[:, :i, i].any()             # before the hat: nothing


@pytest.mark.parametrize("seed", range(3))
def test_bilinear_pair_ground_response_is_the_full_kernels(seed):
    """_BilinearPair's response of every row (floors and storey drifts, both buildings) to the
    ground on the grid, from its kernel columns by the Toeplitz convolution, is the full kernels'
    (:meth:`ModalBound.ground_kernels`, rows applied) to round-off, far inside EXACT_MARGIN: a
    lag shifted by one, a dropped half hat or a missing ``-Gamma`` would be off by the response
    itself."""
    from cosim.master import gap_bound
    from cosim.master.gap_bound import _BilinearPair
    rng = np.random.default_rng(70 + seed)
    buildings, elastic, yielded, y, _ = elastic_buildings(rng, 0.05)
    gaps = OpenGaps(buildings, [("left", 2, "right", 2, 0.05)], elastic, yielded)
    pair = _BilinearPair(gaps, *gaps._pairs(None)[0])
    H = float(rng.choice([0.05, 0.33]))
    g = rng.normal(0.0, 3.0, GRID + 1)
    pair._ground[:] = g
    lags, first = pair._kernels(H)
    got = lags @ pair._toeplitz + first * g[0]
    want = np.vstack([(b.rows @ b.ground_kernels(H).reshape(b.n, -1)).reshape(-1, GRID + 1, GRID + 1) @ g
                      for b in pair.bounds])
    assert np.abs(want).max() > 1e3 * gap_bound.EXACT_MARGIN       # a response worth the name
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("seed", range(4))
def test_ground_bound_after_on_grid_is_running_max_abs_bit_for_bit(seed):
    """GroundAhead's bound on |ag| (called by a proof through yielding after the linear proof took
    on_grid) starts from on_grid's |g| at the grid points instead of interpolating again: the same
    numbers, bit for bit, as running_max_abs from scratch and as a fresh GroundAhead; horizons
    with knots inside grid intervals, none, and t0 on a knot."""
    rng = np.random.default_rng(600 + seed)
    knots = np.concatenate(([-1.0], np.sort(rng.uniform(0.0, 3.0, 80)), [5.0]))
    values = rng.normal(0.0, 3.0, knots.size)
    for k in range(40):
        H = float(rng.choice([0.01, 0.05, 0.33, 0.65, 0.17 + 1e-15]))
        t0 = float(knots[int(rng.integers(1, 70))]) if k % 5 == 0 else float(rng.uniform(0.0, 2.3))
        want = running_max_abs(knots, values, t0, H)
        ground = GroundAhead(knots, values, t0, H)
        assert ground().tobytes() == want.tobytes()                 # before on_grid
        ground = GroundAhead(knots, values, t0, H)
        ground.on_grid(np.empty(GRID + 1))
        assert ground().tobytes() == want.tobytes(), (seed, k, H, t0)
