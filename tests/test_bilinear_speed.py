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
