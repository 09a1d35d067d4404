"""Shear building physics against closed forms, an energy balance and solve_ivp."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fmu_src.shear_building import (PropagatorCache, ShearBuilding, ZohPropagator, absolute_acceleration,
                                    acceleration)


def run(building, h, steps, u0=None, v0=None, ag=None, forces=None):
    """Propagate with per-step inputs ``ag[i]`` and ``forces[i]``; return u, v histories and energies."""
    n = building.n
    prop = ZohPropagator(building, h)
    u = np.zeros(n) if u0 is None else np.asarray(u0, float)
    v = np.zeros(n) if v0 is None else np.asarray(v0, float)
    us, vs = [u], [v]
    energy = dict(E_input=0.0, E_external=0.0, E_damping=0.0)
    for i in range(steps):
        r = prop.step(u, v, 0.0 if ag is None else ag[i], None if forces is None else forces[i])
        u, v = r.u, r.v
        us.append(u)
        vs.append(v)
        for key in energy:
            energy[key] += getattr(r, key)
    return np.array(us), np.array(vs), energy


def sdof_free(t, w, zeta, u0, v0):
    """Damped free vibration (Chopra Eq. 2.2.4)."""
    wd = w * np.sqrt(1 - zeta ** 2)
    return np.exp(-zeta * w * t) * (u0 * np.cos(wd * t) + (v0 + zeta * w * u0) / wd * np.sin(wd * t))


@pytest.mark.parametrize("damping", ["rayleigh", "modal"])
def test_sdof_damped_free_vibration_matches_closed_form(damping):
    m, T, zeta = 2.0e5, 0.4, 0.05
    w = 2 * np.pi / T
    b = ShearBuilding([m], [m * w * w], zeta, damping)
    h, steps = 0.01, 400
    us, vs, _ = run(b, h, steps, u0=[0.02], v0=[-0.1])
    t = h * np.arange(steps + 1)
    # The propagator is exact; only round-off of expm and of 400 products remains (~1e-15 each).
    np.testing.assert_allclose(us[:, 0], sdof_free(t, w, zeta, 0.02, -0.1), rtol=0, atol=1e-12)


def test_sdof_harmonic_ground_motion_steady_state_plus_transient():
    """u'' + 2 zeta w u' + w^2 u = -A sin(W t) from rest (Chopra Sec. 3.2), fed the exact step mean of ag."""
    m, w, zeta, A, W = 1.0e5, 2 * np.pi / 0.5, 0.05, 2.0, 2 * np.pi * 1.5
    b = ShearBuilding([m], [m * w * w], zeta)
    h, steps = 1e-3, 4000
    t = h * np.arange(steps + 1)
    ag_mean = A * (np.cos(W * t[:-1]) - np.cos(W * t[1:])) / (W * h)   # exact mean of A sin(W t) per step
    us, _, _ = run(b, h, steps, ag=ag_mean)

    r = W / w
    den = (1 - r * r) ** 2 + (2 * zeta * r) ** 2
    C = (-A / w ** 2) * (1 - r * r) / den
    D = (-A / w ** 2) * (-2 * zeta * r) / den
    wd = w * np.sqrt(1 - zeta ** 2)
    A1 = -D
    B1 = (zeta * w * A1 - C * W) / wd
    exact = np.exp(-zeta * w * t) * (A1 * np.cos(wd * t) + B1 * np.sin(wd * t)) + C * np.sin(W * t) + D * np.cos(W * t)
    # Holding the step mean is exact for velocity increments; the displacement error is of order
    # (W h)^2 / 12 ~ 7e-6 relative to the amplitude.  1e-4 leaves margin and still fails for any
    # phase, sign or frequency error.
    peak = np.max(np.abs(exact))
    assert np.max(np.abs(us[:, 0] - exact)) < 1e-4 * peak


def test_sdof_piecewise_constant_input_matches_nigam_jennings_recurrence():
    """Exact recurrence for step-wise constant force (Chopra Sec. 5.2, Table 5.2.1 with p_i = p_i+1)."""
    m, w, zeta, h = 3.0e4, 9.0, 0.07, 0.02
    k = m * w * w
    b = ShearBuilding([m], [k], zeta)
    rng = np.random.default_rng(1)
    ag = rng.normal(scale=2.0, size=300)
    us, vs, _ = run(b, h, ag.size, ag=ag)
    wd = w * np.sqrt(1 - zeta ** 2)
    e, s, c = np.exp(-zeta * w * h), np.sin(wd * h), np.cos(wd * h)
    A = e * (zeta / np.sqrt(1 - zeta ** 2) * s + c)
    B = e * s / wd
    Ap = -e * w / np.sqrt(1 - zeta ** 2) * s
    Bp = e * (c - zeta / np.sqrt(1 - zeta ** 2) * s)
    u, v = 0.0, 0.0
    for i, a in enumerate(ag):
        p = -m * a
        u, v = A * u + B * v + (1 - A) * p / k, Ap * u + Bp * v - Ap * p / k
        np.testing.assert_allclose([us[i + 1, 0], vs[i + 1, 0]], [u, v], rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("n", [3, 10])
def test_uniform_building_periods_closed_form(n):
    m, k = 2.5e5, 3.0e8
    b = ShearBuilding.uniform(n, m, k)
    j = np.arange(1, n + 1)
    omega = 2 * np.sqrt(k / m) * np.sin((2 * j - 1) * np.pi / (2 * (2 * n + 1)))
    np.testing.assert_allclose(b.omegas, omega, rtol=1e-12)
    np.testing.assert_allclose(b.periods, 2 * np.pi / omega, rtol=1e-12)
    # Independent solver: eigenvalues of M^-1 K by the general (non-symmetric) routine.
    lam = np.sort(np.linalg.eigvals(np.linalg.solve(b.M, b.K)).real)
    np.testing.assert_allclose(b.omegas ** 2, lam, rtol=1e-10)
    phi = b.mode_shapes
    np.testing.assert_allclose(phi.T @ b.M @ phi, np.eye(n), atol=1e-12)
    assert np.all(phi[-1] > 0)


def test_from_period_scales_stiffness_to_T1_and_keeps_the_distribution():
    b = ShearBuilding.from_period(0.8, [3e5, 2e5, 1e5], [3.0, 2.0, 1.0], 0.03, "modal")
    assert b.periods[0] == pytest.approx(0.8, rel=1e-12)
    np.testing.assert_allclose(b.stiffnesses / b.stiffnesses[0], [1.0, 2 / 3, 1 / 3], rtol=1e-14)
    with pytest.raises(ValueError, match="T1"):
        ShearBuilding.from_period(0.0, [1.0], [1.0])


def test_rayleigh_and_modal_damping_ratios_realised():
    b = ShearBuilding.uniform(5, 1e5, 2e8, 0.05, "rayleigh")
    w = b.omegas
    a0, a1 = b.rayleigh_coefficients
    zr = b.modal_damping_ratios
    np.testing.assert_allclose(zr[:2], 0.05, rtol=1e-12)
    np.testing.assert_allclose(zr, a0 / (2 * w) + a1 * w / 2, rtol=1e-12)  # Chopra Eq. 11.4.8
    assert np.all(zr[2:] > 0.05)
    bm = ShearBuilding.uniform(5, 1e5, 2e8, 0.05, "modal")
    np.testing.assert_allclose(bm.modal_damping_ratios, 0.05, rtol=1e-12)
    # Classical damping: the modal damping matrix is diagonal.
    for bb in (b, bm):
        Cm = bb.mode_shapes.T @ bb.C @ bb.mode_shapes
        assert np.max(np.abs(Cm - np.diag(np.diag(Cm)))) < 1e-10 * np.max(np.abs(Cm))


@pytest.mark.parametrize("damping, mode", [("rayleigh", 0), ("rayleigh", 1), ("rayleigh", 2), ("modal", 3)])
def test_mode_decays_with_its_damping_ratio(damping, mode):
    """Released in one mode shape, the building stays in it and decays like an SDOF with (w_j, zeta_j)."""
    b = ShearBuilding.uniform(4, 1e5, 1.5e8, 0.04, damping)
    phi, w = b.mode_shapes[:, mode], b.omegas[mode]
    zeta = b.modal_damping_ratios[mode] if damping == "rayleigh" else 0.04
    h, steps = 0.005, 600
    us, _, _ = run(b, h, steps, u0=0.01 * phi)
    q = us @ b.M @ phi                      # modal coordinate
    t = h * np.arange(steps + 1)
    # Exact propagation; round-off of expm and 600 products leaves ~1e-10 of the 0.01 amplitude,
    # while any leakage to other modes or a wrong zeta_j shows at the 1e-4 level or more.
    np.testing.assert_allclose(q, sdof_free(t, w, zeta, 0.01, 0.0), rtol=0, atol=1e-11)
    np.testing.assert_allclose(us, np.outer(q, phi), rtol=0, atol=1e-11 * np.max(np.abs(phi)))


def test_energy_balance_closes_to_round_off():
    b = ShearBuilding.from_period(0.6, [2e5, 2e5, 1.5e5], [3, 2.5, 2], 0.05, "rayleigh")
    rng = np.random.default_rng(7)
    steps = 2000
    ag = rng.normal(scale=3.0, size=steps)
    forces = rng.normal(scale=2e5, size=(steps, 3))
    u0, v0 = np.array([0.01, 0.02, 0.025]), np.array([0.1, -0.05, 0.0])
    us, vs, e = run(b, 0.01, steps, u0=u0, v0=v0, ag=ag, forces=forces)
    e0 = b.kinetic_energy(v0) + b.strain_energy(u0)
    lhs = e["E_input"] + e["E_external"] + e0
    rhs = b.kinetic_energy(vs[-1]) + b.strain_energy(us[-1]) + e["E_damping"]
    scale = abs(e["E_input"]) + abs(e["E_external"]) + e["E_damping"]
    # Each term is computed independently; 2000 steps of round-off on terms of size `scale`.
    assert abs(lhs - rhs) < 1e-10 * scale
    assert e["E_damping"] > 0


def test_zoh_propagator_matches_solve_ivp_with_piecewise_constant_input():
    b = ShearBuilding.from_period(0.5, [1e5, 1e5, 8e4], [2, 1.5, 1], 0.05, "modal")
    n, h, steps = 3, 0.02, 60
    rng = np.random.default_rng(3)
    ag = rng.normal(scale=3.0, size=steps)
    forces = rng.normal(scale=1e5, size=(steps, n))
    us, vs, e = run(b, h, steps, ag=ag, forces=forces)

    def rhs(t, y, a_g, f):
        u, v = y[:n], y[n:2 * n]
        return np.concatenate([v, acceleration(b, u, v, a_g, f), [v @ b.C @ v]])

    y = np.zeros(2 * n + 1)
    for i in range(steps):
        sol = solve_ivp(rhs, (i * h, (i + 1) * h), y, args=(ag[i], forces[i]), method="DOP853",
                        rtol=1e-12, atol=1e-15)
        y = sol.y[:, -1]
        # solve_ivp at rtol 1e-12 over 60 restarts: agreement to ~1e-9 of the response amplitude.
        np.testing.assert_allclose(us[i + 1], y[:n], rtol=0, atol=1e-9 * np.max(np.abs(us)))
        np.testing.assert_allclose(vs[i + 1], y[n:2 * n], rtol=0, atol=1e-9 * np.max(np.abs(vs)))
    assert e["E_damping"] == pytest.approx(y[-1], rel=1e-8)


def test_acceleration_is_the_propagator_derivative():
    b = ShearBuilding.uniform(3, 1e5, 1e8, 0.05)
    rng = np.random.default_rng(5)
    u, v, f = rng.normal(size=3) * 0.01, rng.normal(size=3) * 0.1, rng.normal(size=3) * 1e5
    ag = 2.5
    h = 1e-6
    r = ZohPropagator(b, h).step(u, v, ag, f)
    a = acceleration(b, u, v, ag, f)
    # Forward difference error ~ h * |a'| relative; 1e-4 is generous and still catches any sign error.
    np.testing.assert_allclose((r.v - v) / h, a, rtol=1e-4, atol=1e-4 * np.max(np.abs(a)))
    np.testing.assert_allclose(absolute_acceleration(b, u, v, f), a + ag, rtol=1e-14)


def test_free_mass_under_constant_force():
    m, F, h = 500.0, 1e3, 0.01
    b = ShearBuilding([m], [0.0], 0.0)
    assert np.isinf(b.periods[0])
    us, vs, e = run(b, h, 100, v0=[0.5], forces=np.full((100, 1), F))
    t = 1.0
    assert us[-1, 0] == pytest.approx(0.5 * t + F * t * t / (2 * m), rel=1e-13)
    assert vs[-1, 0] == pytest.approx(0.5 + F * t / m, rel=1e-13)
    assert e["E_external"] == pytest.approx(0.5 * m * vs[-1, 0] ** 2 - 0.5 * m * 0.25, rel=1e-12)
    assert e["E_damping"] == 0.0


@pytest.mark.parametrize("args, match", [
    (([1e5, -1.0], [1e8, 1e8]), r"m\[2\] = -1"),
    (([1e5, 1e5], [1e8, 0.0]), r"k\[2\] = 0"),
    (([1e5], [-5.0]), r"k\[1\] = -5"),
    (([1e5], [0.0], 0.05), r"free mass.*zeta"),
    (([1e5], [1e8], 1.0), r"zeta = 1.0 .*0 <= zeta < 1"),
    (([1e5], [1e8], 0.05, "viscous"), r"damping = 'viscous'.*rayleigh, modal"),
    (([1e5, 1e5], [1e8]), r"2 masses but 1 stiffnesses"),
    (([], []), r"at least one storey"),
    (([np.nan], [1e8]), r"m\[1\] = nan"),
])
def test_invalid_buildings_are_rejected_with_named_values(args, match):
    with pytest.raises(ValueError, match=match):
        ShearBuilding(*args)


def test_propagator_cache_reuses_per_step_size():
    cache = PropagatorCache(ShearBuilding.uniform(2, 1e5, 1e8), maxsize=2)
    p = cache(0.01)
    assert cache(0.01) is p and cache.builds == 1
    cache(0.005)
    cache(0.0025)
    assert len(cache) == 2 and cache.builds == 3
    with pytest.raises(ValueError, match="step size"):
        ZohPropagator(cache.building, 0.0)


# -- ModalZohPropagator: the step matrix and damping form from the modes, without expm ----------------------
def _random_buildings(seed: int, count: int, zetas=(0.0, 0.02, 0.05, 0.2, 0.99)):
    """``(building, h)`` pairs: 1 to 20 storeys, masses and stiffnesses spread by 10 (irregular
    modes), Rayleigh (higher modes over-damped from zeta = 0.2 on) and modal damping, steps of
    1e-3 to 30 times the fastest mode's period / 2 pi."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n = int(rng.integers(1, 21))
        m = 1e5 * 10 ** rng.uniform(-0.5, 0.5, n)
        k = 10 ** rng.uniform(-0.5, 0.5, n)
        zeta = float(rng.choice(zetas))
        damping = str(rng.choice(["rayleigh", "modal"]))
        b = ShearBuilding.from_period(float(rng.uniform(0.1, 3.0)), m, k, zeta, damping)
        yield b, float(10 ** rng.uniform(-3, 1.5)) / float(b.omegas.max())


def _augmented(b):
    """``F`` of ``y' = F y``, ``y = [u; v; ag; f]`` (ag and f held)."""
    n = b.n
    F = np.zeros((3 * n + 1, 3 * n + 1))
    F[:n, n:2 * n] = np.eye(n)
    F[n:2 * n, :n] = -b.K / b.masses[:, None]
    F[n:2 * n, n:2 * n] = -b.C / b.masses[:, None]
    F[n:2 * n, 2 * n] = -1.0
    F[n:2 * n, 2 * n + 1:] = np.diag(1.0 / b.masses)
    return F


def test_modal_step_matrix_equals_the_matrix_exponential():
    """Every column of the modal step matrix (z0, ag and f: of different units) within 1e-12 of
    its largest entry of scipy's expm of the augmented system (itself within 5e-15 of a
    long-double exponential on these buildings, measured); 200 random buildings and steps,
    near-critical and over-damped modes included.  Dropping any term of the closed form (the
    decay in the free response, the forced response g, a velocity term) fails by far more."""
    from scipy.linalg import expm

    from fmu_src.shear_building import ModalZohPropagator
    worst = 0.0
    for b, h in _random_buildings(1, 200):
        n = b.n
        reference = expm(_augmented(b) * h)[:2 * n]
        S = ModalZohPropagator(b, h).step_matrix
        worst = max(worst, float(np.max(np.abs(S - reference).max(axis=0) / np.abs(reference).max(axis=0))))
    assert worst < 1e-12, worst


def _expm_long_double(A):
    """``expm(A)`` in extended precision (np.longdouble): Taylor to 24 terms of ``A / 2^s`` with
    norm <= 0.05 (remainder < 1e-40), squared back ``s`` times."""
    A = A.astype(np.longdouble)
    s = max(0, int(np.ceil(np.log2(max(float(np.abs(A).sum(axis=1).max()), 1e-300) / 0.05))))
    A = A / np.longdouble(2.0) ** s
    E = np.eye(A.shape[0], dtype=np.longdouble)
    term = E.copy()
    for k in range(1, 25):
        term = term @ A / k
        E = E + term
    for _ in range(s):
        E = E @ E
    return E


@pytest.mark.skipif(np.finfo(np.longdouble).eps > 1e-18, reason="needs an extended-precision long double")
def test_modal_damping_form_equals_van_loans():
    """The damping form against Van Loan's block exponential (ZohPropagator's formula) taken in
    extended precision, where it is accurate (its growing block exp(-F' h) stays below e^2:
    rate h <= 1 and zeta <= 0.2; in double precision it lost 1e-7 of Q here, and all digits on
    long steps of over-damped modes), entry (i, j) relative to sqrt(Q_ii Q_jj) (a bound of
    |Q_ij|, Q being positive semi-definite): within 1e-11.  (Measured: 2.6e-12 at worst, in the
    cross terms of the ground acceleration, which reaches the modes through the participation
    factors Phi' M 1: the higher modes' small ones carry the eigenvectors' round-off, weighted by
    those modes' large Rayleigh damping; every other entry within 6e-13.)  The oracle itself:
    its exponential within 1e-14 of scipy's on a well-scaled matrix."""
    from scipy.linalg import expm

    from fmu_src.shear_building import ModalZohPropagator
    probe = np.random.default_rng(0).normal(size=(6, 6))
    assert np.abs(_expm_long_double(probe).astype(float) - expm(probe)).max() < 1e-14 * np.abs(expm(probe)).max()
    worst = 0.0
    checked = 0
    for b, h in _random_buildings(2, 200, zetas=(0.02, 0.05, 0.2)):
        if h * float(b.omegas.max()) > 1.0:
            continue
        n = b.n
        size = 3 * n + 1
        F = _augmented(b)
        Qc = np.zeros((size, size))
        Qc[n:2 * n, n:2 * n] = b.C
        big = np.zeros((2 * size, 2 * size))
        big[:size, :size] = -F.T
        big[:size, size:] = Qc
        big[size:, size:] = F
        G = _expm_long_double(big * h)
        reference = G[size:, size:].T @ G[:size, size:]
        reference = (0.5 * (reference + reference.T)).astype(float)
        Q = ModalZohPropagator(b, h).damping_form
        d = np.sqrt(np.diag(reference))
        scale = np.outer(d, d)
        worst = max(worst, float(np.max(np.abs(Q - reference) / np.where(scale > 0.0, scale, 1.0))))
        checked += 1
    assert checked > 50 and worst < 1e-11, (checked, worst)


def test_modal_propagator_energy_balance_over_long_steps():
    """Where Van Loan's form is not trusted (long steps, over-damped modes): E_damping from the
    modal form closes the energy balance of the modal step, E_input + E_external = dE_kinetic +
    dE_strain + E_damping, to 1e-12 of the terms' magnitude (random states and inputs)."""
    from fmu_src.shear_building import ModalZohPropagator
    rng = np.random.default_rng(3)
    worst = 0.0
    for b, h in _random_buildings(3, 200, zetas=(0.05, 0.2, 0.99)):
        if h * float(b.omegas.max()) < 1.0:
            continue             # the balance's terms cancel to 2 zeta w h of each other: short steps above
        n = b.n
        prop = ModalZohPropagator(b, h)
        u0, v0 = rng.normal(size=n) * 0.01, rng.normal(size=n) * 0.1
        ag, f = float(rng.normal()), rng.normal(size=n) * 1e4
        r = prop.step(u0, v0, ag, f)
        d_energy = b.kinetic_energy(r.v) + b.strain_energy(r.u) - b.kinetic_energy(v0) - b.strain_energy(u0)
        terms = abs(r.E_input) + abs(r.E_external) + abs(d_energy) + abs(r.E_damping)
        worst = max(worst, abs(r.E_input + r.E_external - d_energy - r.E_damping) / terms)
    assert worst < 1e-12, worst


def test_modal_propagator_refuses_a_step_beyond_its_quadrature():
    from fmu_src.shear_building import MAX_ZOH_CHUNKS, ModalZohPropagator
    b = ShearBuilding.uniform(3, 1e5, 1e8, 0.05)
    h = 2.0 * (MAX_ZOH_CHUNKS + 1) / float(b.omegas.max())
    with pytest.raises(ValueError, match="limit is 4096"):
        ModalZohPropagator(b, h)
