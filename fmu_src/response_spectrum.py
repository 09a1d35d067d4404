"""Elastic response spectra of a ground-acceleration record, exact for the piecewise-linear signal.

An elastic single-degree-of-freedom (SDOF) oscillator of period ``T`` and damping ratio ``zeta``
on a ground accelerating with ``ag(t)`` obeys (Chopra, *Dynamics of Structures*, 4th ed., Ch. 6)

    u'' + 2 zeta w u' + w^2 u = -ag(t),        w = 2 pi / T,

with ``u`` the displacement relative to the ground.  The displacement spectrum is
``Sd(T) = max_t |u(t)|``, the pseudo-velocity ``PSv = w Sd`` (m/s) and the pseudo-acceleration
``PSa = w^2 Sd`` (m/s^2).  A record here is what :class:`fmu_src.ground_records.Record` plays:
samples ``a_i`` every ``dt``, linear in between, zero before the first and after the last
sample; the oscillator starts at rest.

Method (exact, no time-step error):

* **Samples.**  Over one interval the forcing is linear, so the state is advanced exactly:
  the recurrence of N. C. Nigam and P. C. Jennings, "Calculation of response spectra from
  strong-motion earthquake records", *Bull. Seismol. Soc. Am.* 59(2) (1969) 909-922.  It is
  written here for the complex state ``q = v + (zeta w - i wd) u`` (``wd = w sqrt(1 - zeta^2)``),
  which obeys ``q' = mu q - ag`` with ``mu = -zeta w - i wd``: one complex first-order
  recurrence ``q_{i+1} = lambda q_i + b0 a_i + b1 a_{i+1}`` (``lambda = exp(mu dt)``) instead of
  the 2x2 real one, ``u = -Im(q) / wd``, ``v = Re(q) - zeta w u``.  It runs in blocks of
  ``_BLOCK`` samples as one matrix product per block (the kernel ``lambda^k`` decays, so
  nothing grows) and a short carry loop between blocks: numpy only.
* **Between samples.**  The largest ``|u|`` is usually not at a sample (at ``T = 0.1 s`` and
  ``dt = 0.01 s`` sampling alone can miss up to 5 %).  On each interval ``u`` is a linear
  particular part plus a damped oscillation whose amplitude is known, which bounds ``|u|``
  on the interval; only intervals whose bound exceeds the largest sampled ``|u|`` are
  searched, on a grid of at most ``Td / 8`` (``Td = 2 pi / wd``) and then by bisection on the
  sign change of the velocity (exact closed-form state at any time inside the interval).
* **After the record.**  The oscillator keeps vibrating freely; its first turning point after
  the last sample is found in closed form (later ones are smaller).

Periods are limited to ``PERIOD_LIMITS`` and damping to ``0 <= zeta < 1``.  Everything is SI:
accelerations m/s^2, displacements m, periods and times s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEFAULT_DAMPING = 0.05
#: Shortest and longest oscillator period accepted (s).  Below 1 ms the oscillator is a rigid
#: body for any record (PSa = PGA); above 100 s the relative displacement is the ground's own.
PERIOD_LIMITS = (1e-3, 100.0)
#: The default period grid of a spectrum: DEFAULT_PERIOD_COUNT periods log-spaced over
#: DEFAULT_PERIOD_RANGE (s), the range of building periods and of design spectra.
DEFAULT_PERIOD_RANGE = (0.02, 10.0)
DEFAULT_PERIOD_COUNT = 100

_BLOCK = 64           # samples per block of the blocked recurrence (one 64x64 complex product)
_GRID_PER_TD = 8      # search grid: at least 8 points per damped period inside an interval
_BISECTIONS = 60      # halvings of a bracket: its width ends below 2^-60 of the grid spacing
_CHUNK = 1 << 20      # grid points evaluated at once while searching (bounds the memory)


def default_periods(count: int = DEFAULT_PERIOD_COUNT, lo: float = DEFAULT_PERIOD_RANGE[0],
                    hi: float = DEFAULT_PERIOD_RANGE[1]) -> np.ndarray:
    """``count`` periods (s) log-spaced from ``lo`` to ``hi``, a new array each call."""
    return np.geomspace(lo, hi, int(count))


# -- checks ------------------------------------------------------------------------------------------
def _check_record(acceleration, dt) -> tuple[np.ndarray, float]:
    a = np.asarray(acceleration, dtype=float).reshape(-1)
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"time step dt = {dt!r} s must be finite and > 0")
    if a.size < 2:
        raise ValueError(f"a record needs at least 2 samples; got {a.size}")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise ValueError(f"sample {int(bad[0])} of the record is {float(a[bad[0]])!r}, not finite")
    return a, dt


def _check_periods(periods) -> np.ndarray:
    T = np.array(periods, dtype=float, ndmin=1)   # a copy: the result freezes it
    if T.ndim != 1 or T.size == 0:
        raise ValueError("periods must be a non-empty list of periods (s)")
    lo, hi = PERIOD_LIMITS
    bad = np.flatnonzero(~((T >= lo) & (T <= hi)))   # also catches NaN
    if bad.size:
        raise ValueError(f"period T = {float(T[bad[0]])!r} s is outside the allowed range "
                         f"{lo:g} s <= T <= {hi:g} s")
    return T


def _check_damping(damping) -> float:
    zeta = float(damping)
    if not (math.isfinite(zeta) and 0.0 <= zeta < 1.0):
        raise ValueError(f"damping ratio {zeta!r} is outside the allowed range 0 <= damping < 1")
    return zeta


# -- the oscillator, exactly -------------------------------------------------------------------------
class _Oscillator:
    """Exact state of one SDOF oscillator under linear forcing, in the complex form of the module doc."""

    def __init__(self, period: float, zeta: float):
        self.period = period
        self.zeta = zeta
        self.w = 2.0 * math.pi / period
        self.wd = self.w * math.sqrt(1.0 - zeta * zeta)
        self.mu = complex(-zeta * self.w, -self.wd)

    def advance(self, q, a0, slope, s):
        """State after ``s`` (s) from ``q`` under ``ag = a0 + slope * t``: ``exp(mu s) q - int ...``.

        ``int_0^s exp(mu (s - t)) (a0 + slope t) dt = a0 expm1(mu s) / mu
        + slope (expm1(mu s) / mu^2 - s / mu)``, written without dividing by ``s``.
        """
        mu = self.mu
        e = np.expm1(mu * np.asarray(s, dtype=float))
        return (e + 1.0) * q - a0 * (e / mu) + slope * (s / mu - e / (mu * mu))

    def displacement(self, q):
        """``u = -Im(q) / wd`` (m)."""
        return -np.imag(q) / self.wd

    def velocity(self, q):
        """``v = Re(q) - zeta w u`` (m/s)."""
        return np.real(q) + (self.zeta * self.w / self.wd) * np.imag(q)

    def recurrence(self, dt: float) -> tuple[complex, complex, complex]:
        """``(lambda, b0, b1)`` of ``q_{i+1} = lambda q_i + b0 a_i + b1 a_{i+1}`` for a step ``dt``."""
        one = self.advance(1.0 + 0j, 0.0, 0.0, dt)                   # lambda
        with_a0 = self.advance(0j, 1.0, -1.0 / dt, dt)               # a_i = 1, a_{i+1} = 0
        with_a1 = self.advance(0j, 0.0, 1.0 / dt, dt)                # a_i = 0, a_{i+1} = 1
        return complex(one), complex(with_a0), complex(with_a1)

    def states_at_samples(self, a: np.ndarray, dt: float) -> np.ndarray:
        """Complex state at every sample, from rest at the first one (blocked recurrence)."""
        lam, b0, b1 = self.recurrence(dt)
        forcing = b0 * a[:-1] + b1 * a[1:]               # x_n, n = 0 .. N-2: q_{n+1} = lam q_n + x_n
        n = forcing.size
        blocks = -(-n // _BLOCK)
        x = np.zeros(blocks * _BLOCK, dtype=complex)
        x[:n] = forcing
        x = x.reshape(blocks, _BLOCK)
        k = np.arange(_BLOCK)
        lag = k[:, None] - k[None, :]
        # kernel[j, m] = lam^(j - m) for m <= j: exact powers, not repeated products
        kernel = np.where(lag >= 0, np.exp(self.mu * dt * np.maximum(lag, 0)), 0.0)
        within = x @ kernel.T                              # the response to each block's own forcing
        powers = np.exp(self.mu * dt * (k + 1))            # lam^(j + 1)
        carry = np.empty(blocks, dtype=complex)            # state just before each block
        c, lam_block = 0j, complex(powers[-1])
        last = within[:, -1].tolist()
        for b in range(blocks):
            carry[b] = c
            c = lam_block * c + last[b]
        q = np.empty(n + 1, dtype=complex)
        q[0] = 0.0
        q[1:] = (within + carry[:, None] * powers[None, :]).reshape(-1)[:n]
        return q


def sdof_history(acceleration, dt: float, period: float, damping: float = DEFAULT_DAMPING):
    """Relative displacement ``u`` (m) and velocity ``v`` (m/s) of the oscillator at every sample.

    ``acceleration``: ground acceleration samples (m/s^2) every ``dt`` (s), linear in between;
    the oscillator is at rest at the first sample.  Exact (Nigam & Jennings 1969) up to round-off.
    """
    a, dt = _check_record(acceleration, dt)
    osc = _Oscillator(float(_check_periods(period)[0]), _check_damping(damping))
    q = osc.states_at_samples(a, dt)
    return osc.displacement(q), osc.velocity(q)


# -- the spectrum -----------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ResponseSpectrum:
    """Elastic response spectrum of one record (see module docstring).

    Attributes
    ----------
    periods : ndarray
        Oscillator periods T (s).
    damping : float
        Damping ratio zeta (-).
    displacement : ndarray
        Sd(T) = max |u| (m), the peak relative displacement over the record and the free
        vibration after it.
    peak_time : ndarray
        When |u| reaches Sd, after the first sample (s).
    pga : float
        Peak ground acceleration max |a_i| (m/s^2), the limit of PSa as T -> 0.
    name : str
        What the record is called (labels of tables and plots).
    refined_intervals : int
        Cost counter: intervals searched between samples, over every period.
    """

    periods: np.ndarray
    damping: float
    displacement: np.ndarray
    peak_time: np.ndarray
    pga: float
    name: str = ""
    refined_intervals: int = 0

    @property
    def omegas(self) -> np.ndarray:
        """Circular frequencies w = 2 pi / T (rad/s)."""
        return 2.0 * np.pi / self.periods

    @property
    def pseudo_velocity(self) -> np.ndarray:
        """PSv = w Sd (m/s)."""
        return self.omegas * self.displacement

    @property
    def pseudo_acceleration(self) -> np.ndarray:
        """PSa = w^2 Sd (m/s^2)."""
        return self.omegas ** 2 * self.displacement


def _peak(osc: _Oscillator, a: np.ndarray, dt: float, q: np.ndarray) -> tuple[float, float, int]:
    """``(Sd, time of the peak, intervals searched)`` of one oscillator from its sampled states."""
    u = osc.displacement(q)
    i_best = int(np.argmax(np.abs(u)))
    best, t_best = float(abs(u[i_best])), i_best * dt

    # After the last sample: free vibration q(s) = exp(mu s) q_N.  The velocity vanishes where
    # the phase of q plus arccos(zeta) is a multiple of pi; the first such time is the largest
    # turning point (each later one is smaller by the decay of half a damped period).
    q_end = complex(q[-1])
    if q_end != 0.0:
        s = ((math.atan2(q_end.imag, q_end.real) + math.acos(osc.zeta)) % math.pi) / osc.wd
        u_tail = abs(float(osc.displacement(osc.advance(q_end, 0.0, 0.0, s))))
        if u_tail > best:
            best, t_best = u_tail, (a.size - 1) * dt + s

    # Inside intervals: u = particular (linear in t) + homogeneous (|.| <= |q_h| / wd), a bound
    # per interval; only intervals whose bound beats the sampled peak can hold a larger |u|.
    mu, wd = osc.mu, osc.wd
    slope = (a[1:] - a[:-1]) / dt
    p1 = slope / mu
    p0 = (a[:-1] + p1) / mu
    up0 = -np.imag(p0) / wd
    up1 = -np.imag(p0 + p1 * dt) / wd
    q0 = q[:-1]
    homogeneous = np.abs(q0 - p0) / wd
    # round-off slack of that difference (it cancels for long periods)
    slack = 1e-12 * (np.abs(q0) + np.abs(p0) + np.abs(p1) * dt) / wd
    bound = np.maximum(np.abs(up0), np.abs(up1)) + homogeneous + slack
    candidates = np.flatnonzero(bound > best)
    if candidates.size == 0:
        return best, t_best, 0
    points = 2 + int(math.ceil(_GRID_PER_TD * dt * wd / (2.0 * math.pi)))
    grid = np.linspace(0.0, dt, points)
    per_chunk = max(1, _CHUNK // points)
    for start in range(0, candidates.size, per_chunk):
        idx = candidates[start:start + per_chunk]
        qi, ai, ri = q0[idx, None], a[idx, None], slope[idx, None]
        states = osc.advance(qi, ai, ri, grid[None, :])
        ug = osc.displacement(states)
        j = np.unravel_index(int(np.argmax(np.abs(ug))), ug.shape)
        if abs(ug[j]) > best:
            best, t_best = float(abs(ug[j])), float(idx[j[0]] * dt + grid[j[1]])
        vg = osc.velocity(states)
        rows, cols = np.nonzero(vg[:, :-1] * vg[:, 1:] < 0.0)  # a turning point inside the cell
        if rows.size == 0:
            continue
        lo, hi = grid[cols].copy(), grid[cols + 1].copy()
        q_r, a_r, r_r = qi[rows, 0], ai[rows, 0], ri[rows, 0]
        v_lo = vg[rows, cols]
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            v_mid = osc.velocity(osc.advance(q_r, a_r, r_r, mid))
            same = np.sign(v_mid) == np.sign(v_lo)
            lo = np.where(same, mid, lo)
            hi = np.where(same, hi, mid)
        mid = 0.5 * (lo + hi)
        u_turn = np.abs(osc.displacement(osc.advance(q_r, a_r, r_r, mid)))
        k = int(np.argmax(u_turn))
        if u_turn[k] > best:
            best, t_best = float(u_turn[k]), float(idx[rows[k]] * dt + mid[k])
    return best, t_best, int(candidates.size)


def response_spectrum(acceleration, dt: float, periods=None, damping: float = DEFAULT_DAMPING,
                      name: str = "") -> ResponseSpectrum:
    """Elastic displacement, pseudo-velocity and pseudo-acceleration spectra of a record.

    Parameters
    ----------
    acceleration : array_like
        Ground acceleration samples (m/s^2), linear between samples, zero outside.
    dt : float
        Sampling interval (s).
    periods : array_like, optional
        Oscillator periods (s) within ``PERIOD_LIMITS``; default :func:`default_periods`.
    damping : float
        Damping ratio (-), ``0 <= damping < 1``; 0.05 by default.
    name : str
        Label of the record.
    """
    a, dt = _check_record(acceleration, dt)
    T = _check_periods(default_periods() if periods is None else periods)
    zeta = _check_damping(damping)
    sd = np.empty(T.size)
    when = np.empty(T.size)
    searched = 0
    for n, period in enumerate(T):
        osc = _Oscillator(float(period), zeta)
        sd[n], when[n], cost = _peak(osc, a, dt, osc.states_at_samples(a, dt))
        searched += cost
    for arr in (T, sd, when):
        arr.setflags(write=False)
    return ResponseSpectrum(T, zeta, sd, when, float(np.max(np.abs(a))), str(name), searched)


def pseudo_acceleration(acceleration, dt: float, period: float, damping: float = DEFAULT_DAMPING) -> float:
    """PSa (m/s^2) of a record at one period (s): ``(2 pi / T)^2 Sd(T)``."""
    return float(response_spectrum(acceleration, dt, [period], damping).pseudo_acceleration[0])
