"""Force laws of fmu_src.contact_laws against closed forms and their own definitions."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from fmu_src.contact_laws import (DAMPED_MODELS, HERTZDAMP_MODELS, MODELS, ContactLaw, crvk_constant,
                                  crvk_printed_constant, effective_mass, law_for, published_zeta, scaled_force,
                                  zeta_jankowski, zeta_kelvin_voigt)

RNG = np.random.default_rng(20240601)


def test_models_tuple_is_the_contract():
    assert MODELS == ("hertz", "kelvin_voigt", "jankowski", "barros2013", "hertzdamp", "ye",
                      "naderpour2013", "hunt_crossley", "gonthier", "crvk")


def test_kelvin_voigt_zeta_restores_cr_of_the_unclipped_linear_oscillator():
    # Closed form: a linear oscillator with damping ratio zeta < 1 returns to delta = 0 after
    # half a damped period with speed ratio exp(-zeta pi / sqrt(1 - zeta^2)); Eq 2.3 inverts it.
    for CR in (0.05, 0.3, 0.65, 0.99):
        z = zeta_kelvin_voigt(CR)
        assert math.exp(-z * math.pi / math.sqrt(1.0 - z * z)) == pytest.approx(CR, rel=1e-12)


def test_published_constants_at_cr_1_are_elastic_and_positive_below():
    for model in MODELS:
        assert published_zeta(model, 1.0) == 0.0
        if model != "hertz":
            assert published_zeta(model, 0.5) > 0.0


def test_jankowski_zeta_formula_value():
    # Jankowski 2006 quotes zeta ~= 0.35 for CR = 0.65 (concrete); Eq 2.4 gives 0.373.
    assert zeta_jankowski(0.65) == pytest.approx(0.3728, abs=1e-4)


@pytest.mark.parametrize("CR", [0.0, -0.1, 1.0001, math.nan])
def test_bad_cr_is_rejected_with_range(CR):
    with pytest.raises(ValueError, match="0 < CR <= 1"):
        published_zeta("jankowski", CR)


def test_bad_law_inputs_name_variable_and_range():
    with pytest.raises(ValueError, match="model = 'foo'"):
        law_for("foo", 1.0, 1.5, 1.0, 1.0, 0.5)
    with pytest.raises(ValueError, match="k = 0.0 is outside the allowed range k > 0"):
        ContactLaw("hertz", 0.0, 1.5, 1.0, 0.0)
    with pytest.raises(ValueError, match="m1 = -1.0 kg"):
        effective_mass(-1.0, 1.0)
    with pytest.raises(ValueError, match="zeta"):
        ContactLaw("ye", 1.0, 1.5, 1.0, -0.5)


def test_law_for_uses_published_constant_for_negative_or_missing_zeta():
    law = law_for("ye", 2e9, 1.5, 1e5, 3e5, 0.4, zeta=-1.0)
    assert law.zeta == published_zeta("ye", 0.4)
    assert law.m == pytest.approx(7.5e4)
    assert law_for("ye", 2e9, 1.5, 1e5, 3e5, 0.4, zeta=0.7).zeta == 0.7
    assert law_for("ye", 2e9, 1.5, 1e5, 3e5, 0.4).zeta == published_zeta("ye", 0.4)


@pytest.mark.parametrize("model", MODELS)
def test_force_is_zero_when_open_and_never_negative(model):
    law = law_for(model, 3e9, 1.5, 1e4, 2e4, 0.2)
    assert law.force(0.0, 1.0, 1.0) == 0.0
    assert law.force(-1e-3, 1.0, 1.0) == 0.0
    for _ in range(200):
        d, dd = RNG.uniform(0, 2e-3), RNG.uniform(-3.0, 3.0)
        assert law.force(d, dd, 1.0) >= 0.0


@pytest.mark.parametrize("model", MODELS)
def test_scaled_force_is_the_same_law(model):
    # F / (k L^n) at (delta / L, delta_dot / v) must equal the dimensionless kernel (scale invariance).
    for n in (1.0, 1.5):
        law = law_for(model, 2.3e9, n, 700.0, 300.0, 0.3)
        v = 2.7
        L = law.length_scale(v)
        for _ in range(50):
            d, u = RNG.uniform(1e-3, 1.5), RNG.uniform(-1.0, 1.0)
            F = law.force(d * L, u * v, v)
            assert F / (law.k * L ** n) == pytest.approx(scaled_force(model, law.zeta, n, d, u), rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("model", MODELS)
def test_derivatives_match_finite_differences(model):
    law = law_for(model, 2e9, 1.5, 500.0, 500.0, 0.5)
    v = 1.3
    L = law.length_scale(v)
    for d, u in ((0.3, 0.6), (0.8, 0.2), (0.9, -0.3), (0.5, -0.05)):
        delta, ddot = d * L, u * v
        F, Fd, Fv = law.force_and_derivatives(delta, ddot, v)
        assert F == law.force(delta, ddot, v)
        hd, hv = 1e-6 * L, 1e-6 * v
        # central differences: truncation ~ h^2, far below 1e-6 relative on these smooth branches
        num_d = (law.force(delta + hd, ddot, v) - law.force(delta - hd, ddot, v)) / (2 * hd)
        num_v = (law.force(delta, ddot + hv, v) - law.force(delta, ddot - hv, v)) / (2 * hv)
        scale = law.k * L ** 1.5
        assert Fd == pytest.approx(num_d, rel=1e-6, abs=1e-7 * scale / L)
        assert Fv == pytest.approx(num_v, rel=1e-6, abs=1e-7 * scale / v)


def test_approach_only_laws_switch_dashpot_off_in_restitution():
    for model in ("jankowski", "barros2013", "crvk"):
        law = law_for(model, 1e9, 1.5, 1.0, 1.0, 0.5)
        assert law.force(1e-3, -0.5, 1.0) == pytest.approx(1e9 * 1e-3 ** 1.5, rel=1e-14)
        assert law.force(1e-3, +0.5, 1.0) > 1e9 * 1e-3 ** 1.5
    for model in ("kelvin_voigt",) + HERTZDAMP_MODELS:
        law = law_for(model, 1e9, 1.5, 1.0, 1.0, 0.5)
        assert law.force(1e-3, -0.01, 1.0) < 1e9 * 1e-3 ** 1.5


def test_crvk_is_the_seed_law_with_acceleration_equal_to_force_over_mass():
    # Eq 3.9 with v_imp^2: damping force A k v^2 delta^(n-1) / |delta_ddot|; with |delta_ddot| = F/m
    # the regularised force must be a fixed point of F = k delta^n + A k m v^2 delta^(n-1) / F.
    k, m, n, v, CR = 1.8974e11, 100.0, 1.5, 10.0, 0.4
    law = law_for("crvk", k, n, 2 * m, 2 * m, CR)
    A = law.zeta
    for delta in (1e-6, 1e-4, 6e-4):
        F = law.force(delta, 1.0, v)
        assert F == pytest.approx(k * delta ** n + A * k * v * v * delta ** (n - 1) / (F / m), rel=1e-12)
    # the printed constant is 0.0159 (1 - CR) CR^0.2805
    assert crvk_printed_constant(0.4) == pytest.approx(0.0159 * 0.6 * 0.4 ** 0.2805, rel=1e-15)


@pytest.mark.parametrize("n", [1.0, 1.5])
def test_crvk_constant_against_adaptive_quadrature(n):
    # Independent check of the Gauss-Legendre calibration with scipy.integrate.quad + brentq.
    for CR in (0.05, 0.3, 0.7, 0.95):
        d_max = (0.5 * (n + 1.0) * CR * CR) ** (1.0 / (n + 1.0))

        def work(A):
            val, _ = quad(lambda d: math.sqrt(d ** (2 * n) + 4 * A * d ** (n - 1)), 0.0, d_max,
                          epsabs=1e-13, epsrel=1e-12, limit=200)
            return val - (1.0 - 0.5 * CR * CR)

        A_ref = brentq(work, 0.0, 1e4, xtol=1e-14, rtol=1e-12)
        assert crvk_constant(CR, n) == pytest.approx(A_ref, rel=1e-8)


def test_damped_models_list():
    assert set(DAMPED_MODELS) == set(MODELS) - {"hertz"}
