"""Separation that avoids pounding (cosim/apps/separation.py): exact answer, code rules, correlation."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import solve_continuous_lyapunov

from cosim.peers.reference import Contact, scene_inputs, solve_reference
from cosim.master.loader import load_scene
from cosim.apps.separation import (RULE_NAMES, RULES, _modal_weights, code_separations, correlation,
                              peak_displacement, required_separation, separation_estimates,
                              spectral_peak_displacement, uncoupled_separation)
from fmu_src.ground_records import Record, load_record
from fmu_src.response_spectrum import response_spectrum
from fmu_src.shear_building import ShearBuilding


def white_noise_correlation(t1, t2, z1, z2):
    """Correlation of two oscillators' displacements under stationary white noise: the
    covariance P of the 4-state system solves A P + P A' + B B' = 0 (Lyapunov)."""
    w1, w2 = 2 * math.pi / t1, 2 * math.pi / t2
    A = np.array([[0, 1, 0, 0], [-w1 ** 2, -2 * z1 * w1, 0, 0], [0, 0, 0, 1], [0, 0, -w2 ** 2, -2 * z2 * w2]])
    B = np.array([[0.0], [-1.0], [0.0], [-1.0]])
    P = solve_continuous_lyapunov(A, -B @ B.T)
    return P[0, 2] / math.sqrt(P[0, 0] * P[2, 2])


# -- Der Kiureghian's correlation coefficient ------------------------------------------------------------
@pytest.mark.parametrize("t1, t2, z1, z2", [(1.0, 1.0, 0.05, 0.05), (1.0, 1.1, 0.05, 0.05), (0.5, 1.0, 0.05, 0.05),
                                            (0.5, 1.0, 0.02, 0.1), (1.0, 0.5, 0.02, 0.1), (1.0, 1.0, 0.02, 0.1),
                                            (0.3, 3.0, 0.2, 0.01), (1.5, 0.8, 0.05, 0.05)])
def test_correlation_is_the_white_noise_correlation(t1, t2, z1, z2):
    # both closed forms in double precision: 1e-12
    assert correlation(t1, t2, z1, z2) == pytest.approx(white_noise_correlation(t1, t2, z1, z2), rel=1e-12)


def test_correlation_properties():
    for zeta in (0.01, 0.05, 0.2):
        assert correlation(0.7, 0.7, zeta, zeta) == pytest.approx(1.0, rel=1e-15)
        ratios = np.linspace(1.0, 5.0, 81)
        rho = np.array([correlation(1.0 * r, 1.0, zeta, zeta) for r in ratios])
        assert np.all(np.diff(rho) < 0.0), "rho must fall as the periods part"
        assert np.all((rho > 0.0) & (rho <= 1.0 + 1e-15))
    # swapping the two buildings (period and damping together) changes nothing
    assert correlation(0.5, 1.2, 0.02, 0.07) == pytest.approx(correlation(1.2, 0.5, 0.07, 0.02), rel=1e-14)
    # equal periods, unequal damping: 2 sqrt(z1 z2) / (z1 + z2)
    assert correlation(1.0, 1.0, 0.02, 0.1) == pytest.approx(2 * math.sqrt(0.002) / 0.12, rel=1e-14)
    # the default pair (T1 = 0.5 s and 1.0 s, 5 %): nearly uncorrelated
    assert correlation(0.5, 1.0, 0.05, 0.05) == pytest.approx(0.018486, abs=5e-7)
    with pytest.raises(ValueError, match=r"damping_1 = 0.0 is outside the allowed range 0 < damping < 1"):
        correlation(1.0, 1.0, 0.0, 0.05)
    with pytest.raises(ValueError, match=r"period_2 = -1.0 s must be finite and > 0"):
        correlation(1.0, -1.0, 0.05, 0.05)


# -- code rules ---------------------------------------------------------------------------------------
def test_code_rules_closed_forms():
    assert RULE_NAMES == ("ABS", "SRSS", "EC8", "DDC")
    assert all(rule.formula and rule.source for rule in RULES)
    s = code_separations(0.03, 0.04, 0.25)
    assert s["ABS"] == pytest.approx(0.07, rel=1e-15)
    assert s["SRSS"] == pytest.approx(0.05, rel=1e-15)
    assert s["EC8"] == pytest.approx(0.035, rel=1e-15)
    assert s["DDC"] == pytest.approx(math.sqrt(0.0025 - 2 * 0.25 * 0.0012), rel=1e-15)
    assert code_separations(0.03, 0.04, 1.0)["DDC"] == pytest.approx(0.01, rel=1e-12)   # in phase: |u1 - u2|
    assert code_separations(0.03, 0.04, 0.0)["DDC"] == pytest.approx(0.05, rel=1e-15)   # uncorrelated: SRSS
    assert code_separations(0.03, 0.04, -1.0)["DDC"] == pytest.approx(0.07, rel=1e-15)  # opposed: ABS
    with pytest.raises(ValueError, match=r"u2 = -0.1 m must be a finite peak displacement >= 0"):
        code_separations(0.1, -0.1, 0.5)
    with pytest.raises(ValueError, match=r"rho = 1.5 is outside the allowed range -1 <= rho <= 1"):
        code_separations(0.1, 0.1, 1.5)


# -- from histories -------------------------------------------------------------------------------------
def test_required_separation_from_histories():
    t = np.linspace(0.0, 2.0, 2001)
    w = 2 * math.pi
    sep = required_separation(t, 0.03 * np.sin(w * t), -0.02 * np.sin(w * t))
    assert sep.gap == pytest.approx(0.05, rel=1e-12) and sep.time == pytest.approx(0.25, abs=1e-12)
    apart = required_separation(t, -0.01 * np.ones_like(t), np.zeros_like(t))
    assert apart.gap == 0.0 and math.isnan(apart.time)
    with pytest.raises(ValueError, match="must be 1-d of one length"):
        required_separation(t, t[:-1], t)


# -- exact, for linear buildings ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def default_pair():
    """The default scene's buildings and the first 8 s of its record (El Centro at 0.3 g)."""
    inputs = scene_inputs(load_scene("default"))
    left, right = inputs["buildings"]
    rec = inputs["ground"]
    return left, right, Record("elcentro8", rec.dt, rec.acceleration[:801]), inputs["contacts"][0]


def test_modal_weights_add_up_to_one_on_every_floor(default_pair):
    """sum_j Gamma_j phi_ij = 1: a rigid ground displacement moves every floor by itself."""
    for building in default_pair[:2]:
        for floor in range(1, building.n + 1):
            assert np.sum(_modal_weights(building, floor)[2]) == pytest.approx(1.0, rel=1e-12)


def test_uncoupled_separation_against_the_monolithic_reference(default_pair):
    """The reference integrates the full MDOF equations (solve_ivp DOP853, rtol 1e-10), no
    modes; its output every 10 us around the peak leaves a sampling error below
    |d2/dt2 (x1 - x2)| h^2 / 8 < 20 m/s^2 * 1.25e-11 s^2 = 2.5e-10 m."""
    left, right, rec, _ = default_pair
    sep = uncoupled_separation(left, right, 3, 3, rec.acceleration, rec.dt)
    assert sep.gap == pytest.approx(0.1368, abs=5e-5) and 4.8 < sep.time < 5.0
    t_out = np.concatenate([np.arange(0.0, 10.0, 1e-3), sep.time + np.arange(-0.01, 0.01, 1e-5)])
    t_out = np.unique(np.clip(t_out, 0.0, 10.0))
    ref = solve_reference([left, right], rec, [], 10.0, t_output=t_out)
    brute = required_separation(ref.t, ref.displacements(0)[:, 2], ref.displacements(1)[:, 2])
    assert sep.gap == pytest.approx(brute.gap, rel=2e-9)
    assert sep.time == pytest.approx(brute.time, abs=2e-5)
    # the peaks of each building, the same way (their peaks lie elsewhere: the 1 ms grid, whose
    # sampling error is below a^2 ... |x''| h^2 / 8 < 20 * 1e-6 / 8 = 2.5e-6 m)
    for b, building in enumerate((left, right)):
        exact = peak_displacement(building, 3, rec.acceleration, rec.dt)
        sampled = np.max(np.abs(ref.displacements(b)[:, 2]))
        assert sampled - 1e-9 <= exact <= sampled + 2.5e-6


def test_gaps_just_below_and_above_the_separation(default_pair):
    """With a gap of 0.99 S the floors meet once (the reference's impact), with 1.01 S never."""
    left, right, rec, contact = default_pair
    sep = uncoupled_separation(left, right, 3, 3, rec.acceleration, rec.dt)
    impacts = {}
    for factor in (0.99, 1.01):
        c = Contact(0, 3, 1, 3, contact.law, factor * sep.gap)
        result = solve_reference([left, right], rec, [c], 10.0, output_dt=1e-2)
        impacts[factor] = result.impacts
        if result.impacts:
            # the first contact is where the uncoupled motions first close to 0.99 S
            assert result.impact_list[0].t_onset < sep.time
    assert impacts[0.99] >= 1 and impacts[1.01] == 0


def test_one_storey_buildings_are_their_spectrum():
    """A one-storey building is one oscillator (Gamma phi = 1): both peak estimates are Sd."""
    rec = load_record("kobe1995", target_pga_g=0.3)
    sdof = ShearBuilding([2e5], [1.0], 0.05).from_period(0.6, [2e5], [1.0], 0.05)
    sd = response_spectrum(rec.acceleration, rec.dt, [0.6]).displacement[0]
    assert peak_displacement(sdof, 1, rec.acceleration, rec.dt) == pytest.approx(sd, rel=1e-12)
    assert spectral_peak_displacement(sdof, 1, rec.acceleration, rec.dt) == pytest.approx(sd, rel=1e-12)
    twin = uncoupled_separation(sdof, sdof, 1, 1, rec.acceleration, rec.dt)
    assert twin.gap < 1e-15                                    # identical buildings move together (round-off)
    other = ShearBuilding.from_period(1.1, [3e5], [1.0], 0.05)
    sep = uncoupled_separation(sdof, other, 1, 1, rec.acceleration, rec.dt)
    u2 = peak_displacement(other, 1, rec.acceleration, rec.dt)
    assert 0.0 < sep.gap <= sd + u2                            # never more than ABS


def test_estimates_for_the_default_pair_under_the_seed_records():
    """The exact separation is bounded by ABS; first-mode spectral peaks are near the history
    peaks of these first-mode-dominated buildings; DDC ~ SRSS at rho = 0.018."""
    scene = load_scene("default")
    left, right = scene_inputs(scene)["buildings"]
    for name in ("elcentro1940", "kobe1995", "sanfernando1971", "parkfield1966"):
        rec = load_record(name, target_pga_g=0.3)
        est = separation_estimates(left, right, 3, 3, rec.acceleration, rec.dt)
        assert est.rho == pytest.approx(correlation(0.5, 1.0, 0.05, 0.05), rel=1e-9)
        assert 0.0 < est.exact.gap <= est.rules_history["ABS"] * (1 + 1e-12)
        for history, spectral in zip(est.peaks_history, est.peaks_spectrum):
            assert spectral == pytest.approx(history, rel=0.05)   # higher modes: a few % here
        assert est.rules_history["DDC"] <= est.rules_history["SRSS"] <= est.rules_history["ABS"]


def test_exact_peak_is_below_the_absolute_sum_of_modal_peaks():
    inputs = scene_inputs(load_scene("kasai_maison"))
    rec = inputs["ground"]
    tall = inputs["buildings"][0]
    periods, dampings, weights = _modal_weights(tall, 8)
    spec_peaks = [abs(w) * response_spectrum(rec.acceleration, rec.dt, [t], z).displacement[0]
                  for t, z, w in zip(periods, dampings, weights)]
    exact = peak_displacement(tall, 8, rec.acceleration, rec.dt)
    assert spec_peaks[0] * 0.5 < exact <= sum(spec_peaks)
    cqc = spectral_peak_displacement(tall, 8, rec.acceleration, rec.dt, modes=tall.n)
    assert cqc <= sum(spec_peaks)
    with pytest.raises(ValueError, match=r"modes = 16 must be an integer from 1 to 15"):
        spectral_peak_displacement(tall, 8, rec.acceleration, rec.dt, modes=16)
    with pytest.raises(ValueError, match=r"floor 16 is not a floor of a 15-storey building"):
        peak_displacement(tall, 16, rec.acceleration, rec.dt)
