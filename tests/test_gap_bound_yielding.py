"""The proof that a gap stays open through yielding storeys (cosim/master/gap_bound.py, *Through
yielding*) against the bilinear building itself.

The oracle is building.fmu's own exact bilinear integrator (``ExactPiecewiseLinear``: linear
between located yield and unloading events), fed with the knots of a real record (El Centro
1940 at 0.3 g) and a held floor force, sampled densely over the proof's horizon.  Its storey
law is checked first against an independent return-mapping of the kinematic-hardening law.
States are random: storeys elastic, yielding (at their yield limit, loading), at the limit
and unloading; ``alpha`` 0, 0.05 and 0.5; 3- and 5-storey buildings.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cosim.master.gap_bound import (GRID, KERNEL_SUBDIVISION, PLASTIC_MARGIN, ElasticRange, FloorMotion,
                                    ModalBound, OpenGaps, constant_bound, running_max_abs)
from fmu_src.building_response import ExactPiecewiseLinear
from fmu_src.ground_records import load_record
from fmu_src.hysteresis import StoreyHysteresis, bilinear_plastic_force
from fmu_src.shear_building import ShearBuilding

# the default_inelastic scene's buildings and strengths (cosim/scenes/default_inelastic.toml)
LEFT = (0.5, 3, [2.3e6, 1.7e6, 0.99e6])
RIGHT = (1.0, 5, [2.6e6, 2.3e6, 1.8e6, 1.3e6, 0.75e6])
ALPHAS = (0.0, 0.05, 0.5)
H = 0.33                     # s: the longest proof the master asks for (0.32 s step + a base step)
RECORD = load_record("elcentro1940")
SCALE = 2.942 / RECORD.pga   # to 0.3 g, as the scene


def drifts_of(u):
    d = np.array(u, dtype=float)
    d[..., 1:] -= np.asarray(u)[..., :-1]
    return d


def building(spec, damping="rayleigh"):
    T1, n, fy = spec
    return ShearBuilding.from_period(T1, [3e5] * n, [1.0] * n, 0.05, damping), np.array(fy)


def random_state(rng, b: ShearBuilding, law: StoreyHysteresis):
    """``(u, v, slip, mode)``: each storey elastic inside its range, yielding (at its limit,
    loading on), or at its limit and unloading, with drift rates of 0.05 to 0.5 m/s."""
    n = b.n
    dy = law.yield_drift(b.stiffnesses)
    slip = rng.normal(0.0, 0.5, n) * dy
    mode = np.zeros(n, dtype=np.int64)
    e = np.empty(n)
    rate = np.empty(n)
    for i in range(n):
        kind = rng.integers(3)
        sign = 1 if rng.random() < 0.5 else -1
        speed = rng.uniform(0.05, 0.5)
        if kind == 0:                            # elastic, anywhere in its range, either way
            e[i] = rng.uniform(-0.9, 0.9) * dy[i]
            rate[i] = sign * speed
        elif kind == 1:                          # yielding: at the limit, loading on
            e[i] = sign * dy[i]
            mode[i] = sign
            rate[i] = sign * speed
        else:                                    # at the limit (a hair inside), unloading
            e[i] = sign * dy[i] * (1.0 - 1e-9)
            rate[i] = -sign * speed
    return np.cumsum(slip + e), np.cumsum(rate), slip, mode


def record_window(rng, horizon=H):
    """Knots (times from 0, ag in m/s^2) of the scaled record over ``[t0, t0 + horizon]``, a random
    strong-motion start ``t0``."""
    times, values = RECORD.times, RECORD.acceleration * SCALE
    t0 = float(rng.uniform(1.0, 12.0))
    inside = (times > t0) & (times < t0 + horizon)
    knots = np.concatenate(([t0], times[inside], [t0 + horizon]))
    return knots - t0, np.interp(knots, times, values)


def exact_motion(b, law, u0, v0, slip, mode, knots, values, force, points):
    """Floor displacements (m, points x floors) and storey shears (N) of the bilinear building
    at ``points`` by building.fmu's exact integrator, and the events it took."""
    integ = ExactPiecewiseLinear(b, law)
    state = integ.initial_state(np.zeros(b.n), np.zeros(b.n))
    state.u, state.v, state.slip, state.mode, state.offset = u0.copy(), v0.copy(), slip.copy(), mode.copy(), None
    us, shears, events = [u0.copy()], [integ.storey_shear(state)], 0
    for a, c in zip(points[:-1], points[1:]):
        times = np.concatenate(([a], knots[(knots > a) & (knots < c)], [c]))
        events += integ.advance(state, times, np.interp(times, knots, values), force).events
        us.append(state.u.copy())
        shears.append(integ.storey_shear(state))
    return np.array(us), np.array(shears), events


def cases(count=24, seed=0):
    rng = np.random.default_rng(seed)
    for case in range(count):
        spec = LEFT if case % 2 == 0 else RIGHT
        b, fy = building(spec, "modal" if case % 4 == 3 else "rayleigh")
        alpha = ALPHAS[case % 3]
        law = StoreyHysteresis("bilinear", fy * rng.uniform(0.7, 1.3), alpha)
        u0, v0, slip, mode = random_state(rng, b, law)
        knots, values = record_window(rng)
        force = np.zeros(b.n)
        force[-1] = rng.normal(0.0, 5e5)          # a contact force at the top, held
        yield case, b, law, alpha, u0, v0, slip, mode, knots, values, force


def violations(bound, u0, v0, knots, values, force, dense, true):
    """How far (m, per floor) the exact motion passes the bound's envelope, at most (> 0: broken)."""
    fm = FloorMotion(bound, u0, v0, H, running_max_abs(knots, values, 0.0, H), force)
    s = H * np.arange(GRID + 1) / GRID
    k = np.minimum((dense / H * GRID).astype(int), GRID - 1)
    worst = []
    for f in range(u0.size):
        free, forced, rate = fm.floor(f)
        chord = free[k] + (free[k + 1] - free[k]) * (dense - s[k]) / (s[k + 1] - s[k])
        worst.append(np.max(np.abs(true[:, f] - chord) - (0.5 * rate * (H / GRID) + forced[k + 1])))
    return np.array(worst)


DENSE = np.linspace(0.0, H, 331)     # 1 ms apart: the record's knots are 20 ms apart


@pytest.fixture(scope="module")
def motions():
    out = []
    for case, b, law, alpha, u0, v0, slip, mode, knots, values, force in cases():
        true, shears, events = exact_motion(b, law, u0, v0, slip, mode, knots, values, force, DENSE)
        out.append((case, b, law, alpha, u0, v0, slip, mode, knots, values, force, true, shears, events))
    return out


def test_storey_law_oracle():
    """An independent return-mapping of the kinematic-hardening law along a random drift history
    (reversals, yielding both ways): the storey shear is ``alpha k d + rho`` with ``|rho| <= (1 -
    alpha) Fy``, ``rho`` reaches that limit, and hysteresis.bilinear_plastic_force gives the same
    ``rho`` from the oracle's (slip, mode)."""
    rng = np.random.default_rng(3)
    k, fy = 1.2e8, 1.5e6
    dy = fy / k
    for alpha in ALPHAS:
        d = np.cumsum(rng.normal(0.0, 0.15, 4000)) * dy          # wanders over several yield drifts
        s, at_limit = 0.0, 0
        for di in d:
            e = di - s
            mode = 0
            if abs(e) >= dy:                     # the plastic element slips: its force stays at the limit
                mode = 1 if e > 0 else -1
                s = di - mode * dy
            rho = (1.0 - alpha) * k * (di - s)
            V = alpha * k * di + rho
            assert abs(V - alpha * k * di) <= (1.0 - alpha) * fy * (1.0 + 1e-12)   # round-off of d - s
            law = bilinear_plastic_force(k, fy, alpha, di, s, mode)
            assert law == pytest.approx(rho, rel=1e-9, abs=1e-9 * fy)
            at_limit += mode != 0
        assert at_limit > 100                    # the history did yield, many times


def test_the_integrator_keeps_the_plastic_force_bounded(motions):
    """Along building.fmu's exact bilinear motion, ``rho = V - alpha k d`` never passes ``(1 -
    alpha) Fy`` (to PLASTIC_MARGIN, which covers an event's location), and reaches it: the cases yield."""
    reached = 0
    for case, b, law, alpha, *_rest, true, shears, events in motions:
        k = b.stiffnesses
        rho = shears - alpha * k * drifts_of(true)
        limit = (1.0 - alpha) * law.yield_shear
        assert np.all(np.abs(rho) <= limit * (1.0 + PLASTIC_MARGIN)), case
        reached += int(np.sum(np.abs(rho) >= limit * (1.0 - 1e-9)))
    assert reached > 1000


def test_bound_holds_through_yielding(motions):
    """Every floor of the exact bilinear motion stays inside the bound through yielding, over the
    longest horizon (0.33 s), for every case; the motions do yield and unload inside it."""
    events = 0
    for case, b, law, alpha, u0, v0, slip, mode, knots, values, force, true, shears, ev in motions:
        bound = ModalBound.through_yielding(b, alpha, law.yield_shear)
        # 1e-10 m: the integrator's round-off over a few hundred steps (displacements of cm)
        assert np.all(violations(bound, u0, v0, knots, values, force, DENSE, true) <= 1e-10), case
        events += ev
    assert events >= 2 * len(motions)


def test_bound_without_the_plastic_term_fails(motions):
    """The same check with the storey forces left out (the alpha-K building alone, rho = 0) is
    broken in most cases: the test above can fail."""
    broken = 0
    for case, b, law, alpha, u0, v0, slip, mode, knots, values, force, true, shears, ev in motions:
        bound = ModalBound(b, alpha, np.zeros(b.n))
        broken += bool(np.any(violations(bound, u0, v0, knots, values, force, DENSE, true) > 1e-6))
    assert broken >= len(motions) // 2


def test_kernel_integrals_bound_a_fine_quadrature():
    """ModalBound._kernel_integrals is an upper bound of ``int_0^s |K|``, over it by no more than
    its tent slack ``L s dt / 4`` and, for the floors' response to the ground (the kernels that
    do not start at zero slope), within 1 % at the horizon: checked against a quadrature 64
    times finer."""
    b, fy = building(RIGHT)
    for alpha in ALPHAS:
        bound = ModalBound.through_yielding(b, alpha, fy)
        weights = np.vstack((bound.phi * bound.gamma, bound.phi * bound.drift_phi[2]))
        got = np.vstack(bound._kernel_integrals(H, weights))
        m = GRID * KERNEL_SUBDIVISION * 64
        t = H * np.arange(m + 1) / m
        K = np.abs(weights @ bound._free_tables(t)[1])
        fine = np.concatenate((np.zeros((K.shape[0], 1)), np.cumsum(0.5 * (K[:, 1:] + K[:, :-1]), axis=1) * H / m),
                              axis=1)[:, ::m // GRID]
        # 1e-9: the fine quadrature's own error (trapezoid of a smooth kernel, 2e4 pieces)
        assert np.all(got >= fine * (1.0 - 1e-9))
        s = H * np.arange(GRID + 1) / GRID
        slack = 0.25 * np.abs(weights).sum(axis=1)[:, None] * s * (H / (GRID * KERNEL_SUBDIVISION))
        # 1e-14 s^2: the round-off of 512 summed pieces of up to 1e-3 s^2
        assert np.all(got <= fine * (1.0 + 1e-9) + slack + 1e-14)
        assert np.all(got[:b.n, -1] <= 1.01 * fine[:b.n, -1])


def test_zero_stiffness_modes_move_as_damped_masses():
    """alpha = 0: every mode of the yielded building has w = 0 with its damping c > 0; the free
    motion is ``q0 + q0' (1 - exp(-c s)) / c`` exactly (solve_ivp of M u'' + C u' = 0)."""
    b, fy = building(LEFT)
    bound = ModalBound.through_yielding(b, 0.0, fy)
    assert np.all(bound.w == 0.0) and np.all(bound.damping > 0.0)
    u0, v0 = np.array([0.01, 0.03, 0.04]), np.array([0.3, -0.2, 0.5])
    fm = FloorMotion(bound, u0, v0, H, constant_bound(0.0), None)
    s = H * np.arange(GRID + 1) / GRID
    n, M, C = b.n, b.masses, b.C
    sol = solve_ivp(lambda t, z: np.concatenate((z[n:], -(C @ z[n:]) / M)), (0.0, H), np.concatenate((u0, v0)),
                    method="DOP853", rtol=1e-12, atol=1e-14, t_eval=s)
    for f in range(n):
        free, _, rate = fm.floor(f)
        # 1e-10 m: solve_ivp's tolerance on displacements of cm
        np.testing.assert_allclose(free, sol.y[f], rtol=0, atol=1e-10)
        assert np.all(np.abs(sol.y[n + f]) <= rate * (1 + 1e-12))


@pytest.mark.parametrize("alpha", (0.01, 0.05, 0.5))
def test_free_motion_of_the_yielded_building(alpha):
    """The free motion of the ``alpha K`` building with the initial stiffness's damping (a 15-storey
    Rayleigh-damped building: at alpha = 0.01 its higher modes are overdamped) is exact
    (solve_ivp of M u'' + C u' + alpha K u = 0), and its rate bound holds."""
    n = 15
    b = ShearBuilding.from_period(1.5, [9e5] * n, np.linspace(15.0, 4.0, n), 0.05)
    bound = ModalBound.through_yielding(b, alpha, np.full(n, 5e6))
    if alpha == 0.01:
        assert np.any(bound.zeta > 1.0) and np.any(bound.zeta < 1.0)
    rng = np.random.default_rng(5)
    u0, v0 = rng.normal(0.0, 0.02, n), rng.normal(0.0, 0.3, n)
    fm = FloorMotion(bound, u0, v0, H, constant_bound(0.0), None)
    s = H * np.arange(GRID + 1) / GRID
    M, C, K = b.masses, b.C, b.K
    sol = solve_ivp(lambda t, z: np.concatenate((z[n:], -(C @ z[n:] + alpha * (K @ z[:n])) / M)), (0.0, H),
                    np.concatenate((u0, v0)), method="DOP853", rtol=1e-12, atol=1e-14, t_eval=s)
    free, _, rate = fm.floors()
    # 1e-10 m: solve_ivp's tolerance on displacements of cm
    np.testing.assert_allclose(free, sol.y[:n], rtol=0, atol=1e-10)
    assert np.all(np.abs(sol.y[n:]) <= rate[:, None] * (1 + 1e-12))


def two_buildings(rng, alpha):
    """An OpenGaps of the scene's two buildings (level: left floor 3, right floor 3) with ``y``
    laid out as (x, v, residual drift) per building, the states random and yielding."""
    names, specs = ("left", "right"), (LEFT, RIGHT)
    buildings, elastic, yielded, y, states = {}, {}, {}, [], []
    offset = 0
    for name, spec in zip(names, specs):
        b, fy = building(spec)
        law = StoreyHysteresis("bilinear", fy, alpha)
        u0, v0, slip, mode = random_state(rng, b, law)
        n = b.n
        ix, iv, ir = (offset + np.arange(n) + k * n for k in range(3))
        offset += 3 * n
        buildings[name] = (ModalBound(b), ix, iv)
        elastic[name] = ElasticRange(alpha, law.yield_drift(b.stiffnesses), ir)
        yielded[name] = ModalBound.through_yielding(b, alpha, fy)
        y += [u0, v0, (1.0 - alpha) * slip]
        states.append((b, law, u0, v0, slip, mode))
    return buildings, elastic, yielded, np.concatenate(y), states


@pytest.mark.parametrize("alpha", ALPHAS)
def test_open_gaps_through_yielding_is_a_proof(alpha):
    """OpenGaps.horizons with the proof through yielding, on random yielding states of the two
    scene buildings: the gap (random, 1 to 5 cm beyond the floors' distance) stays open in the
    exact motion over the proven horizon; the proof is at least the linear one's, and longer
    than it in most cases (the linear proof gives 0 while a storey yields)."""
    rng = np.random.default_rng(11 + int(100 * alpha))
    longer = 0
    for case in range(10):
        buildings, elastic, yielded, y, states = two_buildings(rng, alpha)
        knots, values = record_window(rng)
        (bl, lawl, ul, vl, sl, ml), (br, lawr, ur, vr, sr, mr) = states
        gap = float(ul[2] - ur[2] + rng.uniform(0.01, 0.05))
        levels = [("left", 2, "right", 2, gap)]
        ground = running_max_abs(knots, values, 0.0, H)
        proven = OpenGaps(buildings, levels, elastic, yielded).horizons(y, H, ground)[0]
        linear_only = OpenGaps(buildings, levels, elastic).horizons(y, H, ground)[0]
        assert proven >= linear_only
        longer += proven > linear_only
        if proven > 0.0:
            dense = np.linspace(0.0, proven, 201)
            left = exact_motion(bl, lawl, ul, vl, sl, ml, knots, values, np.zeros(3), dense)[0]
            right = exact_motion(br, lawr, ur, vr, sr, mr, knots, values, np.zeros(5), dense)[0]
            assert np.all(left[:, 2] - right[:, 2] - gap < 0.0), case
    assert longer >= 5


@pytest.mark.parametrize("overrides, rel, steps", [
    (("left.alpha=0", "right.alpha=0"), 1e-9, 0.2),
    (("left.alpha=0.5", "right.alpha=0.5", "pounding.gap=0.02"), 1e-9, 0.2),
    (("left.hysteresis=bouc_wen", "right.hysteresis=bouc_wen"), 1e-6, 0.3)])
def test_master_through_yielding_keeps_the_impacts(catalog, overrides, rel, steps):
    """default_inelastic with no hardening (alpha = 0: the proof's damped free masses), with
    strong hardening and a narrower gap, and with Bouc-Wen storeys (before, base steps and every
    contact awake: no elastic range): the default run (long steps and sleeping contacts
    through yielding) against base steps with every contact awake.  The same impacts; peak
    force and energy to ``rel``: a bilinear building integrates the record's knots exactly
    either way (measured 2e-14 to 5e-14), a Bouc-Wen one to its Runge-Kutta tolerance over
    other step pieces (measured 2e-7); no closure inside an unsaved step, no rollback, and
    most steps long.  Measured: 398, 603 and 746 steps, 69, 223 and 76 contact doSteps (4, 11
    and 3 impacts), against 4000 to 4007."""
    from cosim.master.results import summarize
    from scenario_checks import simulate_scene

    long = simulate_scene(catalog, "default_inelastic", overrides, record="summary", output_interval=None)
    base = simulate_scene(catalog, "default_inelastic", overrides, record="summary", output_interval=None,
                          long_steps=False, dormancy=False)
    a, b = summarize(base), summarize(long)
    assert b.impacts == a.impacts > 0
    for c in a.contacts:
        assert b.contacts[c].peak_force_N == pytest.approx(a.contacts[c].peak_force_N, rel=rel)
        assert b.contacts[c].dissipated_energy_J == pytest.approx(a.contacts[c].dissipated_energy_J, rel=rel)
    assert long.stats["missed_events"] == 0 and long.cost.rollbacks == 0
    assert long.cost.communication_steps < steps * base.cost.communication_steps
    assert long.cost.do_steps["pounding_3"] < 0.1 * base.cost.do_steps["pounding_3"]


# -- Bouc-Wen storeys: V = alpha k d + (1 - alpha) Fy z, |z| <= z_u ---------------------------------------
BOUC_WEN = ((2.0, 0.5, 0.5), (1.0, 0.9, 0.1), (10.0, 0.5, 0.5), (1.5, 0.3, 0.3))


def bouc_wen_motion(b, law, u0, v0, z0, knots, values, force, points):
    """Floor displacements (m) and storey shears (N) at ``points`` by building.fmu's Bouc-Wen
    integrator (Runge-Kutta with error control, rtol 1e-8) from ``u0, v0, z0``."""
    from fmu_src.building_response import BoucWenRK

    integ = BoucWenRK(b, law)
    state = integ.initial_state(np.zeros(b.n), np.zeros(b.n))
    state.u, state.v, state.z = u0.copy(), v0.copy(), z0.copy()
    us, shears = [u0.copy()], [integ.storey_shear(state)]
    for a, c in zip(points[:-1], points[1:]):
        times = np.concatenate(([a], knots[(knots > a) & (knots < c)], [c]))
        integ.advance(state, times, np.interp(times, knots, values), force)
        us.append(state.u.copy())
        shears.append(integ.storey_shear(state))
    return np.array(us), np.array(shears)


def test_bound_holds_through_bouc_wen_storeys():
    """A Bouc-Wen building (n = 1 to 10, several beta, gamma; alpha 0, 0.05, 0.5) from random
    states, some storeys at ``|z| = z_u`` loading on: ``rho = V - alpha k d`` stays within ``(1 -
    alpha) Fy z_u`` (to BOUC_WEN_Z_MARGIN) and reaches it, and every floor stays inside the bound
    through yielding with that strength (OpenGaps.build's), over 0.33 s of the record; without
    the storey forces the bound is broken."""
    from cosim.master.gap_bound import BOUC_WEN_Z_MARGIN

    rng = np.random.default_rng(21)
    reached = broken = 0
    dense = np.linspace(0.0, H, 166)                 # 2 ms apart
    for case in range(8):
        spec = LEFT if case % 2 == 0 else RIGHT
        b, fy = building(spec)
        alpha = ALPHAS[case % 3]
        n_, beta, gamma = BOUC_WEN[case % 4]
        law = StoreyHysteresis("bouc_wen", fy * rng.uniform(0.7, 1.3), alpha, n_, beta, gamma)
        zu = law.ultimate_z
        z0 = rng.uniform(-0.99, 0.99, b.n) * zu
        at_limit = rng.random(b.n) < 0.4
        z0[at_limit] = np.sign(z0[at_limit]) * zu * (1.0 - 1e-12)
        dy = law.yield_drift(b.stiffnesses)
        u0 = np.cumsum(rng.normal(0.0, 1.0, b.n) * dy)
        rate = rng.uniform(0.05, 0.5, b.n) * np.where(at_limit, np.sign(z0), rng.choice([-1.0, 1.0], b.n))
        v0 = np.cumsum(rate)
        knots, values = record_window(rng)
        force = np.zeros(b.n)
        force[-1] = rng.normal(0.0, 5e5)
        true, shears = bouc_wen_motion(b, law, u0, v0, z0, knots, values, force, dense)
        strength = law.yield_shear * zu * (1.0 + BOUC_WEN_Z_MARGIN)
        rho = shears - alpha * b.stiffnesses * drifts_of(true)
        assert np.all(np.abs(rho) <= (1.0 - alpha) * strength), case
        reached += int(np.sum(np.abs(rho) >= (1.0 - alpha) * law.yield_shear * zu * (1.0 - 1e-3)))
        bound = ModalBound.through_yielding(b, alpha, strength)
        # 1e-9 m: the Runge-Kutta integrator's tolerance (rtol 1e-8) on displacements of cm
        assert np.all(violations(bound, u0, v0, knots, values, force, dense, true) <= 1e-9), case
        # the same without the storey forces is broken (measured: in all 8 cases, by up to 7 cm)
        broken += bool(np.any(violations(ModalBound(b, alpha, np.zeros(b.n)), u0, v0, knots, values, force, dense,
                                         true) > 1e-6))
    assert reached > 100
    assert broken >= 4
