"""Response spectra (fmu_src/response_spectrum.py) against closed forms, quadrature, solve_ivp and eqsig."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from fmu_src.ground_records import load_record
from fmu_src.response_spectrum import (PERIOD_LIMITS, _Modes, default_periods, modal_sum_peak,
                                       pseudo_acceleration, response_spectrum, sdof_history)

eqsig_sdof = pytest.importorskip("eqsig.sdof")  # in the test extra; a missing one must not pass silently
# eqsig writes 2 pi as 6.2831853 (relative error 1.2e-8): its oscillator of "period" T has
# w = 6.2831853 / T.  Passing T * 6.2831853 / (2 pi) gives it exactly our w.
EQSIG_TWO_PI = 6.2831853


def eqsig_periods(periods):
    return np.asarray(periods) * EQSIG_TWO_PI / (2.0 * np.pi)


def random_record(seed=3, n=400, dt=0.01, end_at_rest=False):
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 2.0, n) * np.hanning(n) ** 0.3
    if end_at_rest:
        a[-1] = 0.0
    return a, dt


# -- the one-step map --------------------------------------------------------------------------------
# quad may warn on an undamped 1 ms oscillator over 20 ms: 80 pieces whose sum cancels to 1e-3
# of each; the agreement asserted below is the check
@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@pytest.mark.parametrize("period", [1e-3, 0.05, 1.0, 100.0])
@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.5, 0.95])
@pytest.mark.parametrize("dt", [0.005, 0.02])
def test_recurrence_coefficients_are_the_duhamel_integrals(period, zeta, dt):
    """lambda, b0, b1 against adaptive quadrature of q(h) = -int exp(mu (h - t)) a(t) dt.

    (scipy's expm of the augmented real system is itself off by up to 40 % at T = 1 ms,
    zeta = 0.5, dt = 0.02 s, where its entries span 12 orders: quadrature is the oracle.)
    """
    osc = _Modes([period], [zeta])
    lam = complex(osc.advance(1.0 + 0j, 0.0, 0.0, dt)[0])
    b0 = complex(osc.advance(0j, 1.0, -1.0 / dt, dt)[0])        # a_i = 1, a_{i+1} = 0
    b1 = complex(osc.advance(0j, 0.0, 1.0 / dt, dt)[0])         # a_i = 0, a_{i+1} = 1
    mu = complex(osc.mu[0])

    # breakpoints every quarter of a damped period: a smooth integrand on each piece
    quarter = np.linspace(0.0, dt, int(4 * dt / (2 * math.pi / osc.wd[0])) + 2)

    def duhamel(shape):
        parts = [sum(quad(lambda t, f=f: f(-np.exp(mu * (dt - t)) * shape(t)), lo, hi,
                          epsabs=1e-22, epsrel=1e-12)[0] for lo, hi in zip(quarter[:-1], quarter[1:]))
                 for f in (np.real, np.imag)]
        return complex(*parts)

    assert abs(lam - np.exp(mu * dt)) <= 1e-15
    # 1e-12: expm1 keeps the closed form accurate to eps / |mu dt| (1.8e-13 at T = 100 s,
    # dt = 5 ms, where s/mu - expm1(mu s)/mu^2 cancels); quadrature is asked for 1e-12 relative
    # (or 1e-22 absolute, 1e-16 of the smallest coefficient, b0 = 1.3e-6 at T = 1 ms).
    assert b0 == pytest.approx(duhamel(lambda t: 1.0 - t / dt), rel=1e-12)
    assert b1 == pytest.approx(duhamel(lambda t: t / dt), rel=1e-12)


def test_history_is_exact_for_the_piecewise_linear_record():
    """Against solve_ivp (DOP853, rtol 1e-12) on the same interpolated signal, knot by knot."""
    a, dt = random_record(n=200)
    period, zeta = 0.3, 0.05
    w = 2 * math.pi / period
    t = dt * np.arange(a.size)

    def rhs(time, y):
        ag = np.interp(time, t, a)
        return [y[1], -ag - 2 * zeta * w * y[1] - w * w * y[0]]

    u_ref = np.zeros(a.size)
    v_ref = np.zeros(a.size)
    y = [0.0, 0.0]
    for i in range(a.size - 1):  # one solve per interval: the kink of the input is at each knot
        sol = solve_ivp(rhs, (t[i], t[i + 1]), y, method="DOP853", rtol=1e-12, atol=1e-15)
        y = sol.y[:, -1]
        u_ref[i + 1], v_ref[i + 1] = y
    u, v = sdof_history(a, dt, period, zeta)
    # rtol 1e-12 per interval over 200 intervals, relative to the peak
    assert np.max(np.abs(u - u_ref)) <= 1e-9 * np.max(np.abs(u_ref))
    assert np.max(np.abs(v - v_ref)) <= 1e-9 * np.max(np.abs(v_ref))


def test_history_matches_eqsig_nigam_jennings_on_el_centro():
    """eqsig 1.2 implements the same recurrence (real 2x2 form); its u and v have the opposite sign."""
    rec = load_record("elcentro1940")
    for period, zeta in [(0.05, 0.05), (0.5, 0.05), (2.0, 0.02), (5.0, 0.2)]:
        u, v = sdof_history(rec.acceleration, rec.dt, period, zeta)
        ue, ve, _ = eqsig_sdof.response_series(rec.acceleration, rec.dt, eqsig_periods([period]), zeta)
        # two round-off paths over 3948 steps; 1e-10 of the peak
        assert np.max(np.abs(u + ue[0])) <= 1e-10 * np.max(np.abs(u))
        assert np.max(np.abs(v + ve[0])) <= 1e-10 * np.max(np.abs(v))


# -- peaks ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("period, zeta, dt", [(1.0, 0.05, 0.01), (0.1, 0.05, 0.037), (0.01, 0.02, 0.037),
                                              (0.5, 0.0, 0.013), (2.0, 0.5, 0.05)])
def test_step_input_closed_form(period, zeta, dt):
    """ag = a0 from t = 0 (a record of constant samples): the first peak, at pi / wd, is
    (a0 / w^2) (1 + exp(-zeta pi / sqrt(1 - zeta^2))) (Chopra Eq. 4.3.3); the knots miss it."""
    a0 = 2.5
    w = 2 * math.pi / period
    wd = w * math.sqrt(1 - zeta * zeta)
    n = int(math.ceil(3 * math.pi / wd / dt)) + 2            # the record lasts beyond the first peak
    spec = response_spectrum(np.full(n, a0), dt, [period], zeta)
    exact = a0 / w ** 2 * (1 + math.exp(-zeta * math.pi / math.sqrt(1 - zeta * zeta)))
    assert spec.displacement[0] == pytest.approx(exact, rel=1e-11)   # bisection to 2^-60 of a cell
    assert spec.peak_time[0] == pytest.approx(math.pi / wd, rel=1e-6)  # u' = 0 there: t known to sqrt(eps)
    sampled = np.max(np.abs(sdof_history(np.full(n, a0), dt, period, zeta)[0]))
    if (math.pi / wd) % dt > 1e-3 * dt:
        assert sampled < spec.displacement[0]


@pytest.mark.parametrize("zeta", [0.05, 0.2])
def test_harmonic_input_at_resonance(zeta):
    """ag = A sin(w t) sampled at T/200: linear interpolation passes the fundamental with the
    gain sinc^2(w dt / 2) (convolution with a triangle), the oscillator amplifies it by 1 / (2 zeta);
    from rest at resonance the envelope grows monotonically to that steady amplitude."""
    period, amplitude = 1.0, 1.0
    w = 2 * math.pi / period
    dt = period / 200
    t = np.arange(0.0, 60.0, dt)                  # zeta w t = 19 at the end: transient e^-19
    spec = response_spectrum(amplitude * np.sin(w * t), dt, [period], zeta)
    steady = amplitude * np.sinc(w * dt / (2 * math.pi)) ** 2 / (2 * zeta * w * w)
    # 1e-6: the interpolation's harmonics at 199 w and 201 w reach the oscillator attenuated by
    # 1/199^2 relative to the resonant part times 2 zeta, below 1e-6
    assert spec.displacement[0] == pytest.approx(steady, rel=1e-6)
    assert spec.pseudo_acceleration[0] == pytest.approx(w * w * steady, rel=1e-6)
    assert spec.pseudo_velocity[0] == pytest.approx(w * steady, rel=1e-6)


def test_free_vibration_after_the_record_counts():
    """A pulse that ends while the oscillator moves: the peak comes after the last sample.
    Brute force: the exact state at the end, then the free vibration sampled every Td / 20000."""
    dt, period, zeta = 0.02, 2.0, 0.05
    a = np.array([0.0, 3.0, 3.0, 1.0])           # ends at 1 m/s^2: a jump to 0 after the record
    spec = response_spectrum(a, dt, [period], zeta)
    assert spec.peak_time[0] > 3 * dt
    osc = _Modes([period], [zeta])
    a0, slope = a[:-1], np.diff(a) / dt
    q_end = osc.states(a0, slope, dt)[-1]
    s = np.linspace(0.0, 2 * period, 80001)[:, None]
    brute = np.max(np.abs(osc.displacement(np.exp(osc.mu * s) * q_end)))
    # the grid misses the peak by at most (w ds)^2 / 8 relative (free vibration: u'' = -w^2 u at a peak)
    assert brute <= spec.displacement[0] <= brute * (1 + (2 * math.pi / period * s[1]) ** 2 / 8 + 1e-12)


@pytest.mark.parametrize("period", [0.005, 0.02, 0.07, 0.3, 1.5])
def test_peak_between_samples_against_a_1000_fold_subdivision(period):
    """Linear interpolation of the record is the same signal, so the exact recurrence on a
    record subdivided 1000 times samples the same u every h = dt / 1000; its maximum is below the
    exact peak by at most (PGA + w^2 Sd) h^2 / 8 (|u''| at a peak, where u' = 0)."""
    a, dt = random_record(seed=7, n=150, dt=0.02, end_at_rest=True)
    fine_dt = dt / 1000
    fine = np.interp(np.arange(0, (a.size - 1) * 1000 + 1) * fine_dt, dt * np.arange(a.size), a)
    fine = np.concatenate([fine, np.zeros(int(3 * period / fine_dt))])  # the free vibration after it
    brute = np.max(np.abs(sdof_history(fine, fine_dt, period, 0.05)[0]))
    spec = response_spectrum(a, dt, [period], 0.05)
    w = 2 * math.pi / period
    slack = (np.max(np.abs(a)) + w * w * brute) * fine_dt ** 2 / 8
    assert brute * (1 - 1e-9) <= spec.displacement[0] <= brute * (1 + 1e-9) + slack


def test_el_centro_spectrum_against_eqsig():
    """eqsig's spectra take the peak at the samples only.  Ours can only be larger, and equals
    eqsig run on the record linearly subdivided 20 times (the same signal) within that
    sampling's bound: at a peak u' = 0 and |u''| = |ag + w^2 u| <= PGA + w^2 Sd, so samples
    h apart miss it by at most (PGA + w^2 Sd) h^2 / 8."""
    rec = load_record("elcentro1940")
    periods = default_periods(40)
    spec = response_spectrum(rec.acceleration, rec.dt, periods)
    m = 20
    fine_dt = rec.dt / m
    fine = np.interp(np.arange((rec.npts - 1) * m + 1) * fine_dt, rec.times, rec.acceleration)
    # the record ends at a small value (|a| = 1.4e-3 m/s^2); the free vibration after it: zeros
    # (a ramp to 0 over dt / 20 instead of a jump: 1.4e-3 * 5e-4 / 2 m/s of velocity, negligible)
    fine = np.concatenate([fine, np.zeros(int(2 * periods[-1] / fine_dt))])
    sd_fine = eqsig_sdof.pseudo_response_spectra(fine, fine_dt, eqsig_periods(periods), 0.05)[0]
    bound = ((2 * np.pi / periods) ** 2 + rec.pga / spec.displacement) * fine_dt ** 2 / 8
    assert np.all(spec.displacement >= sd_fine * (1 - 1e-9))
    assert np.all(spec.displacement <= sd_fine * (1 + bound + 1e-8))
    sd_samples = eqsig_sdof.pseudo_response_spectra(rec.acceleration, rec.dt, eqsig_periods(periods), 0.05)[0]
    assert np.all(spec.displacement >= sd_samples * (1 - 1e-9))
    # at 0.04 s the samples alone are 7.6 % low (printed in the report of the change)
    worst = np.max(spec.displacement / sd_samples - 1)
    assert 0.05 < worst < 0.10


# -- properties ----------------------------------------------------------------------------------------
def test_rigid_and_flexible_limits_and_linearity():
    rec = load_record("kobe1995")
    spec = response_spectrum(rec.acceleration, rec.dt, [PERIOD_LIMITS[0], 0.5])
    # T = 1 ms (w = 6283 rad/s) under 20 ms samples: the oscillator follows the ground,
    # PSa = PGA (1 + O(2 zeta |da/dt| / (w PGA))) and |da/dt| < 2 PGA / dt here: < 0.2 %
    assert spec.pseudo_acceleration[0] == pytest.approx(rec.pga, rel=2e-3)
    doubled = response_spectrum(-2.0 * rec.acceleration, rec.dt, [0.5])
    assert doubled.displacement[0] == pytest.approx(2.0 * spec.displacement[1], rel=1e-13)
    assert pseudo_acceleration(rec.acceleration, rec.dt, 0.5) == pytest.approx(spec.pseudo_acceleration[1],
                                                                                rel=1e-15)
    more_damping = response_spectrum(rec.acceleration, rec.dt, [0.5], damping=0.2)
    assert more_damping.displacement[0] < spec.displacement[1]


def test_result_is_read_only_and_inputs_are_checked():
    periods = np.array([0.2, 1.0])
    spec = response_spectrum([0.0, 1.0, 0.0], 0.01, periods, name="pulse")
    assert spec.name == "pulse" and spec.damping == 0.05 and spec.pga == 1.0
    with pytest.raises(ValueError):
        spec.displacement[0] = 1.0
    periods[0] = 5.0  # the caller's array stays theirs
    assert spec.periods[0] == 0.2
    with pytest.raises(ValueError, match=r"period T = 0.0 s is outside the allowed range 0.001 s <= T <= 100 s"):
        response_spectrum([0.0, 1.0], 0.01, [0.0])
    with pytest.raises(ValueError, match=r"damping ratio 1.0 is outside the allowed range 0 <= damping < 1"):
        response_spectrum([0.0, 1.0], 0.01, [1.0], damping=1.0)
    with pytest.raises(ValueError, match=r"sample 1 of the record is nan"):
        response_spectrum([0.0, float("nan")], 0.01, [1.0])
    with pytest.raises(ValueError, match=r"dt = 0.0 s must be finite and > 0"):
        response_spectrum([0.0, 1.0], 0.0, [1.0])
    assert default_periods()[0] == pytest.approx(0.02) and default_periods()[-1] == pytest.approx(10.0)


# -- weighted sums of modes ------------------------------------------------------------------------------
def test_modal_sum_peak_against_a_1000_fold_subdivision():
    """Two modes with weights of both signs, signed and absolute peaks, against the exact
    recurrence on the record subdivided 1000 times (sampling bound as above)."""
    a, dt = random_record(seed=11, n=120, dt=0.02, end_at_rest=True)
    periods, dampings, weights = [0.9, 0.25], [0.05, 0.08], [1.3, -0.4]
    fine_dt = dt / 1000
    fine = np.interp(np.arange(0, (a.size - 1) * 1000 + 1) * fine_dt, dt * np.arange(a.size), a)
    fine = np.concatenate([fine, np.zeros(int(4 * max(periods) / fine_dt))])
    total = sum(w * sdof_history(fine, fine_dt, t, z)[0] for t, z, w in zip(periods, dampings, weights))
    w_max = 2 * math.pi / min(periods)
    slack = (np.max(np.abs(a)) * sum(map(abs, weights)) + w_max ** 2 * np.max(np.abs(total))) * fine_dt ** 2 / 8
    for signed, brute in ((True, np.max(total)), (False, np.max(np.abs(total)))):
        peak, when = modal_sum_peak(a, dt, periods, dampings, weights, signed=signed)
        assert brute * (1 - 1e-9) <= peak <= brute * (1 + 1e-9) + slack
        k = int(np.argmax(total if signed else np.abs(total)))
        assert when == pytest.approx(k * fine_dt, abs=0.01)
    with pytest.raises(ValueError, match="one value per mode; got 2, 1 and 2"):
        modal_sum_peak(a, dt, periods, [0.05], weights)
    with pytest.raises(ValueError, match="a damping ratio of 0 never lets the free vibration"):
        modal_sum_peak(a, dt, periods, [0.0, 0.05], weights)


def test_free_vibration_that_does_not_decay_in_time_is_refused():
    """A pulse leaves two nearly undamped modes (zeta = 1e-13) of equal amplitude with periods
    in the golden ratio: their sum approaches twice the amplitude only slowly (best phase
    match within 1000 periods ~ 2 pi / (sqrt(5) 1000) rad, 1 - cos of it 4e-6), while the
    amplitude left decays by 6e-10: nothing can settle it to 1e-9, and the search stops at
    1000 longest periods, saying so."""
    periods = [1.0, (1 + math.sqrt(5)) / 2]
    weights = [2 * math.pi / t for t in periods]        # a pulse gives mode k an amplitude ~ 1 / w_k
    with pytest.raises(ValueError, match=r"the free vibration after the record still has an amplitude of "
                                         r"\S+ m after \S+ s \(1000 longest periods\), above the peak"):
        modal_sum_peak([0.0, 1.0, 0.0], 0.01, periods, [1e-13, 1e-13], weights)
