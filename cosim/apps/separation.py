"""How far apart two buildings must stand so that they do not pound, and what building codes say.

The gap at a pounding level closes by ``x_left(t) - x_right(t)`` (floor displacements relative
to the ground, the left building on the negative side; ``delta = x_left - x_right - gap``).
While the buildings do not touch they move independently, so the separation that avoids
contact is

    S = max(0, max_t (x_left(t) - x_right(t)))

of the two *uncoupled* responses: with a gap above ``S`` they never meet, below it they meet
(the uncoupled motion is the true motion until the first contact).  For linear buildings
:func:`uncoupled_separation` computes it exactly: each floor's displacement is a sum of modal
responses (classical damping: Rayleigh and modal both are), so ``x_left - x_right`` is one
weighted sum of oscillators whose peak over the record and the free vibration after it is
found exactly by :func:`fmu_src.response_spectrum.modal_sum_peak`.  :func:`required_separation`
does the same from sampled histories (a lower bound when the samples miss the peak).

Building codes estimate ``S`` from the two buildings' peak displacements ``u1``, ``u2`` at that
level (:data:`RULES`):

* ABS ``u1 + u2`` (both peaks at the same instant, in opposite directions);
* SRSS ``sqrt(u1^2 + u2^2)``: ASCE/SEI 7-16 Sec. 12.12.3; EN 1998-1 (Eurocode 8) 4.4.2.7(2);
* EC8 ``0.7 sqrt(u1^2 + u2^2)``: EN 1998-1 4.4.2.7(3), where the floor levels coincide;
* DDC, the double difference combination ``sqrt(u1^2 + u2^2 - 2 rho u1 u2)``: S.-K. Jeng,
  K. Kasai, B. F. Maison, "A spectral difference method to estimate building separations to
  avoid pounding", *Earthquake Spectra* 8(2) (1992) 201-223; J. Penzien, "Evaluation of
  building separation distance required to prevent pounding during strong earthquakes",
  *Earthq. Eng. Struct. Dyn.* 26 (1997) 849-858.  ``rho`` is the correlation of the two
  buildings' fundamental modes (:func:`correlation`, A. Der Kiureghian 1981).

The peaks ``u1``, ``u2`` come from the time histories (:func:`peak_displacement`, exact) or
from the record's response spectrum (:func:`spectral_peak_displacement`: participation factor
times mode shape times ``Sd(T1)``, the first mode by default).  SI units throughout.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from fmu_src.response_spectrum import modal_sum_peak, response_spectrum
from fmu_src.shear_building import ShearBuilding


# -- the exact answer ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Separation:
    """The separation that avoids contact at one level.

    Attributes
    ----------
    gap : float
        Smallest gap (m) at which the floors never touch: ``max(0, max_t (x_left - x_right))``.
    time : float
        When ``x_left - x_right`` is largest (s after the first sample; ``nan`` if it never
        exceeds 0, the buildings only move apart).
    """

    gap: float
    time: float


def required_separation(time, x_left, x_right) -> Separation:
    """:class:`Separation` from two sampled floor histories (m) on one time grid (s)."""
    t = np.asarray(time, dtype=float)
    left, right = np.asarray(x_left, dtype=float), np.asarray(x_right, dtype=float)
    if not (t.ndim == left.ndim == right.ndim == 1 and t.size == left.size == right.size > 0):
        raise ValueError(f"time, x_left and x_right must be 1-d of one length; got shapes "
                         f"{np.shape(time)}, {np.shape(x_left)}, {np.shape(x_right)}")
    closing = left - right
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(closing))):
        raise ValueError("time and floor histories must be finite")
    i = int(np.argmax(closing))
    if closing[i] <= 0.0:
        return Separation(0.0, math.nan)
    return Separation(float(closing[i]), float(t[i]))


def _modal_weights(building: ShearBuilding, floor: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(periods, damping ratios, weights)`` with ``x_floor(t) = sum_j weights_j D_j(t)``.

    With mass-normalised modes ``phi_j``, ``M u'' + C u' + K u = -M 1 ag`` decouples into
    ``q_j'' + 2 zeta_j w_j q_j' + w_j^2 q_j = -Gamma_j ag``, ``Gamma_j = phi_j' M 1`` (Chopra
    Sec. 13.1), so ``q_j = Gamma_j D_j`` with ``D_j`` the SDOF response of mode j and
    ``x_floor = sum_j phi_floor,j Gamma_j D_j``.
    """
    if building.is_free_mass:
        raise ValueError("a free mass (k = 0) has no vibration mode: no separation can be computed for it")
    if not 1 <= floor <= building.n:
        raise ValueError(f"floor {floor} is not a floor of a {building.n}-storey building (1..{building.n})")
    phi = building.mode_shapes
    gamma = phi.T @ building.masses
    return building.periods.copy(), building.modal_damping_ratios.copy(), phi[floor - 1] * gamma


def uncoupled_separation(left: ShearBuilding, right: ShearBuilding, floor_left: int, floor_right: int,
                         acceleration, dt: float) -> Separation:
    """Exact :class:`Separation` of two linear buildings at floors ``floor_left``/``floor_right``
    under a record (samples in m/s^2 every ``dt`` s, linear between samples, both at rest
    at the first sample)."""
    tl, zl, wl = _modal_weights(left, floor_left)
    tr, zr, wr = _modal_weights(right, floor_right)
    peak, time = modal_sum_peak(acceleration, dt, np.concatenate([tl, tr]), np.concatenate([zl, zr]),
                                np.concatenate([wl, -wr]), signed=True)
    if peak <= 0.0:
        return Separation(0.0, math.nan)
    return Separation(peak, time)


def peak_displacement(building: ShearBuilding, floor: int, acceleration, dt: float) -> float:
    """Exact peak ``max_t |x_floor(t)|`` (m) of a linear building under a record (no contact)."""
    periods, dampings, weights = _modal_weights(building, floor)
    return modal_sum_peak(acceleration, dt, periods, dampings, weights)[0]


def spectral_peak_displacement(building: ShearBuilding, floor: int, acceleration, dt: float,
                               modes: int = 1) -> float:
    """Peak floor displacement (m) estimated from the record's displacement spectrum.

    ``modes = 1``: ``|Gamma_1 phi_floor,1| Sd(T1, zeta_1)``, the code practice for regular
    buildings.  More modes are combined by CQC with :func:`correlation`
    (``sqrt(sum_ij rho_ij u_i u_j)``, Der Kiureghian 1981).
    """
    periods, dampings, weights = _modal_weights(building, floor)
    if not (isinstance(modes, int) and 1 <= modes <= periods.size):
        raise ValueError(f"modes = {modes!r} must be an integer from 1 to {periods.size}")
    modal = np.empty(modes)
    for j in range(modes):  # one spectrum per mode: each has its own damping ratio
        spec = response_spectrum(acceleration, dt, [periods[j]], dampings[j])
        modal[j] = weights[j] * spec.displacement[0]
    rho = np.array([[correlation(periods[i], periods[j], dampings[i], dampings[j]) for j in range(modes)]
                    for i in range(modes)])
    return float(math.sqrt(max(0.0, modal @ rho @ modal)))


# -- code rules ---------------------------------------------------------------------------------------
def correlation(period_1: float, period_2: float, damping_1: float, damping_2: float) -> float:
    """Correlation coefficient of two oscillators' displacements (Der Kiureghian 1981).

    With ``r = w2 / w1 = T1 / T2``:

        rho = 8 sqrt(z1 z2) (z1 + r z2) r^(3/2)
              / ((1 - r^2)^2 + 4 z1 z2 r (1 + r^2) + 4 (z1^2 + z2^2) r^2)

    A. Der Kiureghian, "A response spectrum method for random vibration analysis of MDF
    systems", *Earthq. Eng. Struct. Dyn.* 9 (1981) 419-435; the same coefficient as the CQC
    rule (Wilson, Der Kiureghian & Bayo 1981).  It is the exact correlation of the two
    displacements under stationary white noise.  1 for equal periods and damping;
    ``2 sqrt(z1 z2) / (z1 + z2)`` for equal periods; unchanged when the two oscillators are
    swapped.
    """
    t1, t2, z1, z2 = (float(x) for x in (period_1, period_2, damping_1, damping_2))
    for name, value in (("period_1", t1), ("period_2", t2)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} = {value!r} s must be finite and > 0")
    for name, value in (("damping_1", z1), ("damping_2", z2)):
        if not (math.isfinite(value) and 0.0 < value < 1.0):
            raise ValueError(f"{name} = {value!r} is outside the allowed range 0 < damping < 1")
    r = t1 / t2
    numerator = 8.0 * math.sqrt(z1 * z2) * (z1 + r * z2) * r ** 1.5
    denominator = (1.0 - r * r) ** 2 + 4.0 * z1 * z2 * r * (1.0 + r * r) + 4.0 * (z1 * z1 + z2 * z2) * r * r
    return numerator / denominator


@dataclass(frozen=True)
class CombinationRule:
    """A code rule that estimates the separation from the two peak displacements."""

    name: str
    formula: str
    source: str
    combine: Callable[[float, float, float], float]   # (u1, u2, rho) -> separation (m)


RULES = (
    CombinationRule("ABS", "u1 + u2", "absolute sum: peaks at the same instant in opposite directions",
                    lambda u1, u2, rho: u1 + u2),
    CombinationRule("SRSS", "sqrt(u1^2 + u2^2)", "ASCE/SEI 7-16 12.12.3; EN 1998-1 4.4.2.7(2)",
                    lambda u1, u2, rho: math.hypot(u1, u2)),
    CombinationRule("EC8", "0.7 sqrt(u1^2 + u2^2)", "EN 1998-1 4.4.2.7(3): floor levels coincide",
                    lambda u1, u2, rho: 0.7 * math.hypot(u1, u2)),
    CombinationRule("DDC", "sqrt(u1^2 + u2^2 - 2 rho u1 u2)",
                    "Jeng, Kasai & Maison 1992; Penzien 1997; rho: Der Kiureghian 1981",
                    lambda u1, u2, rho: math.sqrt(max(0.0, u1 * u1 + u2 * u2 - 2.0 * rho * u1 * u2))),
)
RULE_NAMES = tuple(rule.name for rule in RULES)


def code_separations(u1: float, u2: float, rho: float) -> dict[str, float]:
    """Every rule of :data:`RULES` for peak displacements ``u1``, ``u2`` (m, >= 0) and the
    correlation ``rho`` (-1..1) of the two buildings: ``{name: separation in m}``."""
    for name, value in (("u1", u1), ("u2", u2)):
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name} = {value!r} m must be a finite peak displacement >= 0")
    if not (math.isfinite(rho) and -1.0 <= rho <= 1.0):
        raise ValueError(f"rho = {rho!r} is outside the allowed range -1 <= rho <= 1")
    return {rule.name: rule.combine(float(u1), float(u2), float(rho)) for rule in RULES}


# -- everything for one pair, one level, one record ----------------------------------------------------
@dataclass(frozen=True)
class SeparationEstimate:
    """The exact separation beside the code rules, for one pounding level and one record.

    Attributes
    ----------
    exact : Separation
        From the uncoupled responses (exact for linear buildings).
    peaks_history : tuple of float
        Peak floor displacements (m) of the left and right building, from the histories.
    peaks_spectrum : tuple of float
        The same from the response spectrum (first mode).
    rho : float
        Correlation of the two fundamental modes (:func:`correlation`).
    rules_history, rules_spectrum : dict
        ``{rule name: separation (m)}`` from either pair of peaks.
    """

    exact: Separation
    peaks_history: tuple[float, float]
    peaks_spectrum: tuple[float, float]
    rho: float
    rules_history: dict
    rules_spectrum: dict


def separation_estimates(left: ShearBuilding, right: ShearBuilding, floor_left: int, floor_right: int,
                         acceleration, dt: float) -> SeparationEstimate:
    """:class:`SeparationEstimate` of two linear buildings under one record (m/s^2 every dt s)."""
    exact = uncoupled_separation(left, right, floor_left, floor_right, acceleration, dt)
    history = (peak_displacement(left, floor_left, acceleration, dt),
               peak_displacement(right, floor_right, acceleration, dt))
    spectrum = (spectral_peak_displacement(left, floor_left, acceleration, dt),
                spectral_peak_displacement(right, floor_right, acceleration, dt))
    rho = correlation(left.periods[0], right.periods[0], left.modal_damping_ratios[0],
                      right.modal_damping_ratios[0])
    return SeparationEstimate(exact, history, spectrum, rho, code_separations(*history, rho),
                              code_separations(*spectrum, rho))
