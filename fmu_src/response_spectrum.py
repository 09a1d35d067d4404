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
  recurrence ``q_{i+1} = lambda q_i + x_i`` (``lambda = exp(mu dt)``) instead of the 2x2 real
  one, ``u = -Im(q) / wd``, ``v = Re(q) - zeta w u``.  It runs in blocks of ``_BLOCK``
  intervals as one matrix product per block (the kernel ``lambda^k`` decays, so nothing
  grows) and a short carry loop between blocks: numpy only.
* **Between samples.**  The largest ``|u|`` is usually not at a sample (at ``T = 0.04 s`` and
  ``dt = 0.01 s`` sampling alone misses 7.6 % on El Centro).  On each interval ``u`` is a linear
  particular part plus a damped oscillation of known amplitude, which bounds ``|u|`` on the
  interval; only intervals whose bound exceeds the largest value found are searched, on a grid
  of at most ``Td / 8`` (``Td = 2 pi / wd``) and then by bisection on the sign change of the
  velocity (the closed-form state at any time inside the interval).
* **After the record.**  The oscillator keeps vibrating freely; the same search runs on
  intervals of ``dt`` after the last sample until the amplitude left cannot beat the peak.

The same machinery gives the exact peak of any weighted sum of oscillators under one record
(:func:`modal_sum_peak`): a linear building's floor displacement is the sum of its modal
responses, and the gap between two linear buildings closes by the difference of two such sums.
Turning points closer together than the grid (``Td / 8``) are resolved to the grid only.

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
_CHUNK = 1 << 20      # grid points x modes evaluated at once while searching (bounds the memory)
_TAIL_PERIODS = 1000  # free vibration searched for at most this many longest periods after the record


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


# -- oscillators, exactly ---------------------------------------------------------------------------
class _Modes:
    """K oscillators (periods, damping ratios) on one ground motion, in the complex form of the
    module docstring; every method broadcasts over leading axes, the last axis is the mode."""

    def __init__(self, periods, dampings):
        self.periods = np.asarray(periods, dtype=float).reshape(-1)
        self.zeta = np.asarray(dampings, dtype=float).reshape(-1)
        self.w = 2.0 * np.pi / self.periods
        self.wd = self.w * np.sqrt(1.0 - self.zeta ** 2)
        self.mu = -self.zeta * self.w - 1j * self.wd

    def advance(self, q, a0, slope, s):
        """State after ``s`` (s) from ``q`` under ``ag = a0 + slope * t``: ``exp(mu s) q - int ...``.

        ``int_0^s exp(mu (s - t)) (a0 + slope t) dt = a0 expm1(mu s) / mu
        + slope (expm1(mu s) / mu^2 - s / mu)``, written without dividing by ``s``.
        """
        mu = self.mu
        e = np.expm1(mu * s)
        return (e + 1.0) * q - a0 * (e / mu) + slope * (s / mu - e / (mu * mu))

    def displacement(self, q):
        """``u = -Im(q) / wd`` (m), per mode."""
        return -np.imag(q) / self.wd

    def velocity(self, q):
        """``v = Re(q) - zeta w u`` (m/s), per mode."""
        return np.real(q) + (self.zeta * self.w / self.wd) * np.imag(q)

    def homogeneous_bound(self, q, a0, slope):
        """``(particular u at 0, its rate, bound of |homogeneous u|)`` per mode on an interval.

        Under ``ag = a0 + slope t`` the state is ``p0 + p1 t`` (``p1 = slope / mu``,
        ``p0 = (a0 + p1) / mu``) plus ``exp(mu t) (q - p0)``, whose displacement never exceeds
        ``|q - p0| / wd``.
        """
        p1 = slope / self.mu
        p0 = (a0 + p1) / self.mu
        # round-off slack of q - p0 (it cancels for long periods)
        slack = 1e-12 * (np.abs(q) + np.abs(p0)) / self.wd
        return self.displacement(p0), self.displacement(p1), np.abs(q - p0) / self.wd + slack

    def states(self, a0: np.ndarray, slope: np.ndarray, dt: float) -> np.ndarray:
        """State at the start of every interval and after the last one, from rest: ``(n + 1, K)``.

        ``q_{i+1} = lambda q_i + x_i`` is run in blocks of ``_BLOCK`` intervals: the response to
        a block's own forcing is one product with the decaying kernel ``lambda^(j - m)``, and
        the state entering each block is carried by a short loop.
        """
        n = a0.size
        out = np.empty((n + 1, self.mu.size), dtype=complex)
        blocks = -(-n // _BLOCK)
        k = np.arange(_BLOCK)
        lag = k[:, None] - k[None, :]
        for mode, mu in enumerate(self.mu.tolist()):
            e = np.expm1(mu * dt)
            forcing = -a0 * (e / mu) + slope * (dt / mu - e / (mu * mu))
            x = np.zeros(blocks * _BLOCK, dtype=complex)
            x[:n] = forcing
            x = x.reshape(blocks, _BLOCK)
            kernel = np.where(lag >= 0, np.exp(mu * dt * np.maximum(lag, 0)), 0.0)  # exact powers
            within = x @ kernel.T
            powers = np.exp(mu * dt * (k + 1))
            carry = np.empty(blocks, dtype=complex)
            c, lam_block = 0j, complex(powers[-1])
            for b, last in enumerate(within[:, -1].tolist()):
                carry[b] = c
                c = lam_block * c + last
            out[0, mode] = 0.0
            out[1:, mode] = (within + carry[:, None] * powers[None, :]).reshape(-1)[:n]
        return out


def _intervals(a: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(a at the start, slope)`` of each interval of the piecewise-linear record."""
    return a[:-1], (a[1:] - a[:-1]) / dt


def _search(modes: _Modes, weights: np.ndarray, q0, a0, slope, dt: float, signed: bool, best: float,
            t_best: float, first: int) -> tuple[float, float, int]:
    """Largest objective inside the intervals ``first, first + 1, ...`` (states ``q0`` at their
    starts) that can beat ``best``; returns ``(best, time, intervals searched)``."""
    up0, up1, hom = modes.homogeneous_bound(q0, a0[:, None], slope[:, None])
    p_start = up0 @ weights
    p_end = p_start + dt * (up1 @ weights)
    h = hom @ np.abs(weights)
    if signed:
        bound = np.maximum(p_start, p_end) + h
    else:
        bound = np.maximum(np.abs(p_start), np.abs(p_end)) + h
    candidates = np.flatnonzero(bound > best)
    if candidates.size == 0:
        return best, t_best, 0
    points = 2 + int(math.ceil(_GRID_PER_TD * dt * float(np.max(modes.wd)) / (2.0 * math.pi)))
    grid = np.linspace(0.0, dt, points)
    per_chunk = max(1, _CHUNK // (points * modes.mu.size))

    def objective(u):
        return u if signed else np.abs(u)

    for start in range(0, candidates.size, per_chunk):
        idx = candidates[start:start + per_chunk]
        qi = q0[idx, None, :]
        ai = a0[idx, None, None]
        ri = slope[idx, None, None]
        states = modes.advance(qi, ai, ri, grid[None, :, None])          # (cand, points, K)
        ug = objective(modes.displacement(states) @ weights)
        j = np.unravel_index(int(np.argmax(ug)), ug.shape)
        if ug[j] > best:
            best, t_best = float(ug[j]), (first + int(idx[j[0]])) * dt + float(grid[j[1]])
        vg = modes.velocity(states) @ weights
        rows, cols = np.nonzero(vg[:, :-1] * vg[:, 1:] < 0.0)            # a turning point inside a cell
        if rows.size == 0:
            continue
        lo, hi = grid[cols].copy(), grid[cols + 1].copy()
        q_r, a_r, r_r = qi[rows, 0, :], ai[rows, 0, :], ri[rows, 0, :]
        v_lo = vg[rows, cols]
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            v_mid = modes.velocity(modes.advance(q_r, a_r, r_r, mid[:, None])) @ weights
            same = np.sign(v_mid) == np.sign(v_lo)
            lo = np.where(same, mid, lo)
            hi = np.where(same, hi, mid)
        mid = 0.5 * (lo + hi)
        u_turn = objective(modes.displacement(modes.advance(q_r, a_r, r_r, mid[:, None])) @ weights)
        k = int(np.argmax(u_turn))
        if u_turn[k] > best:
            best, t_best = float(u_turn[k]), (first + int(idx[rows[k]])) * dt + float(mid[k])
    return best, t_best, int(candidates.size)


def _peak(modes: _Modes, weights, a: np.ndarray, dt: float, signed: bool = False) -> tuple[float, float, int]:
    """``(peak, time, intervals searched)`` of ``sum_k weights_k u_k(t)`` over the record and the
    free vibration after it: its largest value if ``signed``, else its largest magnitude."""
    weights = np.asarray(weights, dtype=float)
    a0, slope = _intervals(a, dt)
    q = modes.states(a0, slope, dt)
    u = modes.displacement(q) @ weights
    values = u if signed else np.abs(u)
    i_best = int(np.argmax(values))
    best, t_best = float(values[i_best]), i_best * dt
    best, t_best, searched = _search(modes, weights, q[:-1], a0, slope, dt, signed, best, t_best, 0)

    # After the last sample the ground is still: free vibration, searched in intervals of dt
    # until the homogeneous bound (it decays as exp(-zeta w t)) cannot beat the peak found.
    q_end = q[-1]
    span = max(1, int(math.ceil(float(np.max(modes.periods)) / dt)))
    first, limit = a.size - 1, a.size - 1 + int(math.ceil(_TAIL_PERIODS * float(np.max(modes.periods)) / dt))
    while True:
        steps = np.arange(span + 1)[:, None]
        q_tail = q_end[None, :] * np.exp(modes.mu[None, :] * dt * steps)
        zeros = np.zeros(span)
        best, t_best, cost = _search(modes, weights, q_tail[:-1], zeros, zeros, dt, signed, best, t_best, first)
        searched += cost
        q_end = q_tail[-1]
        first += span
        remaining = float((np.abs(q_end) / modes.wd) @ np.abs(weights))
        if remaining <= best * (1.0 + 1e-9):     # nothing later can beat it (to 1e-9)
            break
        if first >= limit:
            raise ValueError(f"the free vibration after the record still has an amplitude of {remaining:.6g} m "
                             f"after {first * dt - (a.size - 1) * dt:.6g} s ({_TAIL_PERIODS} longest periods), "
                             f"above the peak {best:.6g} m: damping ratios {modes.zeta.min():g} are too small "
                             f"for a peak over the free vibration")
    return best, t_best, searched


def sdof_history(acceleration, dt: float, period: float, damping: float = DEFAULT_DAMPING):
    """Relative displacement ``u`` (m) and velocity ``v`` (m/s) of the oscillator at every sample.

    ``acceleration``: ground acceleration samples (m/s^2) every ``dt`` (s), linear in between;
    the oscillator is at rest at the first sample.  Exact (Nigam & Jennings 1969) up to round-off.
    """
    a, dt = _check_record(acceleration, dt)
    modes = _Modes(_check_periods(period)[:1], [_check_damping(damping)])
    q = modes.states(*_intervals(a, dt), dt)
    return modes.displacement(q)[:, 0], modes.velocity(q)[:, 0]


def modal_sum_peak(acceleration, dt: float, periods, dampings, weights, signed: bool = False) -> tuple[float, float]:
    """Peak over time of ``sum_k weights_k D_k(t)``, ``D_k`` the displacement (m) of oscillator k
    (period ``periods[k]`` s, damping ``dampings[k]``) under the record, exact (see module doc).

    A building's floor displacement is such a sum over its modes (weights: participation factor
    times mode shape), and so is the difference of two buildings' floors.  ``signed``: the
    largest value (e.g. the closing of a gap); otherwise the largest magnitude.  Returns
    ``(peak, time after the first sample in s)``.  Damping ratios must be > 0 (0 < zeta < 1):
    undamped modes never stop after the record.
    """
    a, dt = _check_record(acceleration, dt)
    T = _check_periods(periods)
    zeta = np.array(dampings, dtype=float, ndmin=1)
    w = np.array(weights, dtype=float, ndmin=1)
    if not (zeta.shape == T.shape == w.shape):
        raise ValueError(f"periods, dampings and weights must have one value per mode; got "
                         f"{T.size}, {zeta.size} and {w.size}")
    for z in zeta:
        if _check_damping(z) == 0.0:
            raise ValueError("a damping ratio of 0 never lets the free vibration after the record decay; "
                             "modal_sum_peak needs 0 < damping < 1")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"weights must be finite; got {w.tolist()}")
    peak, time, _ = _peak(_Modes(T, zeta), w, a, dt, signed)
    return peak, time


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
        sd[n], when[n], cost = _peak(_Modes([period], [zeta]), [1.0], a, dt)
        searched += cost
    for arr in (T, sd, when):
        arr.setflags(write=False)
    return ResponseSpectrum(T, zeta, sd, when, float(np.max(np.abs(a))), str(name), searched)


def pseudo_acceleration(acceleration, dt: float, period: float, damping: float = DEFAULT_DAMPING) -> float:
    """PSa (m/s^2) of a record at one period (s): ``(2 pi / T)^2 Sd(T)``."""
    return float(response_spectrum(acceleration, dt, [period], damping).pseudo_acceleration[0])
