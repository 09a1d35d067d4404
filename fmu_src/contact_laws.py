"""Impact force laws of the pounding contact element (pure physics, SI units, no FMI).

Conventions (as in the seed paper, Naderpour et al. c. 2016, and its sources):

* penetration ``delta`` [m] > 0 while the bodies overlap (``delta = x1 - x2 - gap``);
* penetration rate ``delta_dot`` [m/s] > 0 while the bodies approach;
* the contact force ``F`` [N] is compressive and never negative (contact cannot pull);
* ``k`` [N/m^n] is the contact stiffness, ``n`` [-] its exponent (1 linear, 1.5 Hertz);
* ``m = m1 m2 / (m1 + m2)`` [kg] is the effective mass of the two colliding bodies;
* ``v_imp`` [m/s] is the approach speed latched at contact onset;
* ``CR`` [-] is the coefficient of restitution, rebound speed / approach speed.

Every model below is a spring ``k delta^n`` plus a dissipative term governed by one
dimensionless damping constant ``zeta``.  Two families:

``kelvin_voigt``, ``jankowski``, ``barros2013`` (dashpot ``c delta_dot``)
    ``F = k delta^n + c delta_dot`` with ``c = 2 zeta sqrt(k m delta^(n-1))``.
    For n = 1 this is Anagnostopoulos' ``c = 2 zeta sqrt(k m)`` (seed Eq 2.3); for
    n = 1.5 it is Jankowski's ``c = 2 zeta sqrt(k sqrt(delta) m)`` (Eq 2.4).  The same
    generalisation keeps every law scale invariant for any n.

``hertzdamp``, ``ye``, ``naderpour2013``, ``hunt_crossley``, ``gonthier`` (Hertz-damp)
    ``F = k delta^n (1 + chi delta_dot)`` with ``chi = zeta / v_imp``; the seed writes
    ``c = zeta_paper delta^n`` with ``zeta_paper = k chi``.  Here ``zeta = chi v_imp`` is the
    dimensionless constant of each published formula.

``crvk`` (the seed paper's proposed model, Eqs 3.1, 3.4-3.9, regularised)
    Written out, Eqs 3.4, 3.5 and 3.9 give the damping force ``c delta_dot =
    A k v_imp^2 delta^(n-1) / delta_ddot`` with ``A = 0.0159 (1 - CR) CR^0.2805`` (the
    printed ``delta_imp^2`` must be ``v_imp^2`` for F to be a force).  Literally it is 0/0 at
    onset, infinite at maximum penetration and an algebraic loop.  During an isolated impact
    ``|delta_ddot| = F / m``, which turns it into the quadratic
    ``F^2 - k delta^n F - A k m v_imp^2 delta^(n-1) = 0`` in approach (positive root) and
    ``F = k delta^n`` in restitution (Eq 3.1: dashpot only while approaching).  ``zeta`` is
    then the constant ``A``, calibrated so that the impact reaches the requested CR
    (:func:`crvk_constant`, exact to quadrature accuracy; see ``docs/contact_models.md``).

Scale invariance: with ``L = (m v_imp^2 / k)^(1/(n+1))``, ``T = L / v_imp`` and
``F0 = k L^n`` every law above becomes a function of ``delta/L`` and ``delta_dot/v_imp``
only, so the achieved CR depends on ``(model, zeta, n)`` and not on mass, stiffness or
impact velocity.  :func:`scaled_force` is that dimensionless form; the in-step impact
resolver integrates it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

MODELS = ("hertz", "kelvin_voigt", "jankowski", "barros2013", "hertzdamp", "ye",
          "naderpour2013", "hunt_crossley", "gonthier", "crvk")

#: models of the form k delta^n + c(delta) delta_dot
DASHPOT_MODELS = ("kelvin_voigt", "jankowski", "barros2013")
#: models of the form k delta^n (1 + zeta delta_dot / v_imp)
HERTZDAMP_MODELS = ("hertzdamp", "ye", "naderpour2013", "hunt_crossley", "gonthier")
#: models whose dissipative term acts only while the bodies approach (delta_dot > 0)
APPROACH_ONLY_MODELS = ("jankowski", "barros2013", "crvk")
#: models with a free damping constant (everything except the elastic Hertz law)
DAMPED_MODELS = tuple(m for m in MODELS if m != "hertz")

#: the constant printed in the seed's Eq 3.9, A = 0.0159 (1 - CR) CR^0.2805
CRVK_PRINTED_FACTOR = 0.0159
CRVK_PRINTED_EXPONENT = 0.2805

#: latched approach speeds below this [m/s] count as this speed: the Hertz-damp dashpot divides
#: by v_imp and the impact scales L, T ~ v_imp^(-1/5) need v_imp > 0; a grazing touch at
#: 1e-6 m/s exchanges no measurable impulse.  (v_imp <= 0, no latched approach, switches the
#: Hertz-damp dashpot off.)
MIN_IMPACT_SPEED = 1e-6


# ----------------------------------------------------------------------------------------------
# published damping constants
# ----------------------------------------------------------------------------------------------
def _check_cr(CR: float) -> float:
    CR = float(CR)
    if not (0.0 < CR <= 1.0):
        raise ValueError(f"CR = {CR!r} is outside the allowed range 0 < CR <= 1")
    return CR


def _check_model(model: str) -> str:
    if model not in MODELS:
        raise ValueError(f"model = {model!r} is not allowed: one of {', '.join(MODELS)}")
    return model


def zeta_kelvin_voigt(CR: float) -> float:
    """Anagnostopoulos (1988, 2004), seed Eq 2.3: ``zeta = -ln CR / sqrt(pi^2 + ln^2 CR)``.

    Exact for the linear oscillator (n = 1) *including* its tension phase; with the
    force clipped at zero the achieved CR is higher than the target (see the CR table).
    """
    L = math.log(_check_cr(CR))
    return abs(L) / math.sqrt(math.pi ** 2 + L * L)


def zeta_jankowski(CR: float) -> float:
    """Jankowski (2006), seed Eq 2.4: ``zeta = 9 sqrt5 / 2 (1 - CR^2) / (CR [CR (9 pi - 16) + 16])``.

    Derived for n = 1.5 with the dashpot active in approach only.
    """
    CR = _check_cr(CR)
    return 4.5 * math.sqrt(5.0) * (1.0 - CR * CR) / (CR * (CR * (9.0 * math.pi - 16.0) + 16.0))


def zeta_barros2013(CR: float) -> float:
    """"Barros et al. 2013", seed Eq 2.5 as printed:
    ``zeta = ((1 - CR^2) / (CR [sqrt(pi) (CR/2 + 1/pi) - CR]))^2``.

    The original could not be checked; used with Jankowski's law (approach-only dashpot).
    As printed it misses its target CR badly (see the CR table).
    """
    CR = _check_cr(CR)
    return ((1.0 - CR * CR) / (CR * (math.sqrt(math.pi) * (0.5 * CR + 1.0 / math.pi) - CR))) ** 2


def published_zeta(model: str, CR: float, n: float = 1.5) -> float:
    """Dimensionless damping constant of ``model`` for restitution ``CR`` by its published formula.

    ======================  =====================================  ==============================
    model                   zeta                                   source
    ======================  =====================================  ==============================
    hertz                   0                                      Hertz (elastic)
    kelvin_voigt            -ln CR / sqrt(pi^2 + ln^2 CR)          Anagnostopoulos, seed Eq 2.3
    jankowski               9 sqrt5 (1-CR^2) / (2 CR (CR(9pi-16)+16))  Jankowski 2006, Eq 2.4
    barros2013              Eq 2.5 as printed                      "Barros et al. 2013"
    hertzdamp               3 (1 - CR^2) / 4                       Muthukumar & DesRoches 2006, Eq 2.6
    ye                      8 (1 - CR) / (5 CR)                    Ye, Li & Zhu 2009, Eq 2.7
    naderpour2013           2 / (5 CR^2) sqrt((1-CR)/(1+CR))       Eq 2.8 as printed, divided by k
    hunt_crossley           3 (1 - CR) / 2                         Hunt & Crossley 1975
    gonthier                (1 - CR^2) / CR                        Gonthier et al. 2004
    crvk                    A(CR, n) calibrated                    :func:`crvk_constant`
    ======================  =====================================  ==============================

    For the Hertz-damp family the value is ``chi * v_imp`` (``chi`` in s/m).  ``n`` only
    matters for crvk, whose constant is calibrated for the exponent in use.
    """
    _check_model(model)
    CR = _check_cr(CR)
    if model == "hertz":
        return 0.0
    if model == "kelvin_voigt":
        return zeta_kelvin_voigt(CR)
    if model == "jankowski":
        return zeta_jankowski(CR)
    if model == "barros2013":
        return zeta_barros2013(CR)
    if model == "hertzdamp":
        return 0.75 * (1.0 - CR * CR)
    if model == "ye":
        return 1.6 * (1.0 - CR) / CR
    if model == "naderpour2013":
        return 0.4 / (CR * CR) * math.sqrt((1.0 - CR) / (1.0 + CR))
    if model == "hunt_crossley":
        return 1.5 * (1.0 - CR)
    if model == "gonthier":
        return (1.0 - CR * CR) / CR
    return crvk_constant(CR, n)


def crvk_printed_constant(CR: float) -> float:
    """The seed's Eq 3.9 constant ``A = 0.0159 (1 - CR) CR^0.2805`` (v_imp^2 for delta_imp^2).

    With it the regularised crvk law dissipates a small fraction of Goldsmith's loss at
    any CR; kept only to document that fault (CR table in docs/contact_models.md).
    """
    CR = _check_cr(CR)
    return CRVK_PRINTED_FACTOR * (1.0 - CR) * CR ** CRVK_PRINTED_EXPONENT


# ----------------------------------------------------------------------------------------------
# crvk calibration: exact energy quadrature, no time integration needed
# ----------------------------------------------------------------------------------------------
def _gauss_legendre_01(order: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(order)
    s, ws = 0.5 * (x + 1.0), 0.5 * w
    s.setflags(write=False)
    ws.setflags(write=False)
    return s, ws


_GL_NODES, _GL_WEIGHTS = _gauss_legendre_01(96)   # read-only arrays (no mutable module state)
# d = d_max s^4 removes the d^((n-1)/2) singularity of the crvk approach force at onset.
_SUBST_POWER = 4.0


def _crvk_approach_integral(A: float, d_max: float, n: float) -> float:
    """Integral over 0 <= d <= d_max of sqrt(d^(2n) + 4 A d^(n-1)) (dimensionless)."""
    s = _GL_NODES
    p = _SUBST_POWER
    d = d_max * s ** p
    integrand = np.sqrt(d ** (2.0 * n) + 4.0 * A * d ** (n - 1.0)) * (p * d_max * s ** (p - 1.0))
    return float(np.dot(_GL_WEIGHTS, integrand))


def crvk_constant(CR: float, n: float = 1.5) -> float:
    """Constant ``A`` of the regularised crvk law that gives restitution ``CR`` exactly.

    Derivation (dimensionless, ``d = delta/L``, ``f = F/(k L^n)``, ``d'(0) = 1``): in approach
    the force depends on ``d`` only, ``f = (d^n + sqrt(d^(2n) + 4 A d^(n-1))) / 2``, so the
    approach work equals the initial kinetic energy, ``int_0^dmax f dd = 1/2``; restitution
    is elastic, so ``CR^2 = 2 dmax^(n+1) / (n+1)``.  Hence ``dmax`` follows from CR and ``A``
    solves ``int_0^dmax sqrt(d^(2n) + 4 A d^(n-1)) dd = 1 - CR^2 / 2`` (monotone in A), by
    96-point Gauss-Legendre quadrature (substitution ``d = dmax s^4``) and brentq.  Costs
    well under a millisecond; depends only on (CR, n), by scale invariance.
    """
    CR = _check_cr(CR)
    n = float(n)
    if not (n > 0.0 and math.isfinite(n)):
        raise ValueError(f"n = {n!r} is outside the allowed range n > 0")
    if CR == 1.0:
        return 0.0
    d_max = (0.5 * (n + 1.0) * CR * CR) ** (1.0 / (n + 1.0))
    target = 1.0 - 0.5 * CR * CR

    def residual(A: float) -> float:
        return _crvk_approach_integral(A, d_max, n) - target

    hi = 1.0
    while residual(hi) < 0.0:
        hi *= 4.0
        if hi > 1e12:
            raise ValueError(f"crvk: CR = {CR!r} not reachable with n = {n!r} (A > 1e12)")
    return brentq(residual, 0.0, hi, xtol=1e-15, rtol=1e-13, maxiter=200)


# ----------------------------------------------------------------------------------------------
# the force laws
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ContactLaw:
    """One impact force law with its constants (immutable).

    Parameters
    ----------
    model : str
        One of :data:`MODELS`.
    k : float
        Contact stiffness [N/m^n].
    n : float
        Stiffness exponent [-] (1: linear, 1.5: Hertz).
    m : float
        Effective mass ``m1 m2 / (m1 + m2)`` [kg].
    zeta : float
        Dimensionless damping constant [-] (meaning per model: module docstring).

    Notes
    -----
    Per model, the force for ``delta > 0`` (``F = 0`` for ``delta <= 0``) is

    * ``hertz``: ``k delta^n``; elastic, CR = 1 whatever the requested CR.
    * ``kelvin_voigt``: ``k delta^n + c delta_dot``, ``c = 2 zeta sqrt(k m delta^(n-1))``,
      dashpot over the whole contact.  For n = 1 the force jumps to ``c v_imp`` at onset,
      and without clipping it would pull at the end of restitution; clipped at ``F >= 0``
      the bodies separate where ``k delta + c delta_dot = 0`` (``delta > 0``), which skips
      the tension phase and gives a *higher* CR than the target (CR table).
    * ``jankowski``, ``barros2013``: ``k delta^n + c delta_dot`` in approach
      (``delta_dot > 0``), ``k delta^n`` in restitution; F is continuous at maximum
      penetration because ``c delta_dot`` vanishes there; dF/d(delta) is infinite at onset
      for n > 1 (``c ~ delta^((n-1)/2)``).  Eq 2.4 was derived for n = 1.5.
    * Hertz-damp family: ``k delta^n (1 + zeta delta_dot / v_imp)`` over the whole contact;
      continuous at onset; clipped at zero in restitution when ``zeta delta_dot < -v_imp``
      (large ``zeta``, i.e. small CR with ``ye`` / ``naderpour2013`` / ``gonthier``).
      ``v_imp <= 0`` (no latched approach) switches the dashpot off.
    * ``crvk``: ``(k delta^n + sqrt(k^2 delta^(2n) + 4 zeta k m v_imp^2 delta^(n-1))) / 2`` in
      approach, ``k delta^n`` in restitution.  The force *drops* at maximum penetration
      (``delta_dot`` changing sign): a solver must locate that event.  For n = 1 it jumps
      to ``sqrt(zeta k m) v_imp`` at onset; for n = 1.5 it rises like ``delta^(1/4)``.
    """

    model: str
    k: float
    n: float
    m: float
    zeta: float

    def __post_init__(self):
        _check_model(self.model)
        for name in ("k", "n", "m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} = {value!r} is outside the allowed range {name} > 0")
        if not (math.isfinite(self.zeta) and self.zeta >= 0.0):
            raise ValueError(f"zeta = {self.zeta!r} is outside the allowed range zeta >= 0")

    # -- dashpot rules ------------------------------------------------------------------------
    @property
    def approach_only(self) -> bool:
        """True if the dissipative term acts only while ``delta_dot > 0``."""
        return self.model in APPROACH_ONLY_MODELS

    @property
    def releases_before_unloading(self) -> bool:
        """True if, in an isolated impact, the force reaches zero while ``delta > 0``.

        Only the Kelvin-Voigt dashpot does (``k delta^n + c delta_dot`` crosses zero in
        restitution).  For the Hertz-damp family ``w = 1 + zeta delta_dot / v_imp`` obeys
        ``dw/dt = -(zeta k delta^n / (m v_imp)) w``,
        so ``w`` decays but never changes sign: contact ends at ``delta = 0``.
        """
        return self.model == "kelvin_voigt" and self.zeta > 0.0

    def length_scale(self, v_imp: float) -> float:
        """``L = (m v_imp^2 / k)^(1/(n+1))`` [m]: penetration scale of an impact at ``v_imp``."""
        return (self.m * v_imp * v_imp / self.k) ** (1.0 / (self.n + 1.0))

    def elastic_energy(self, delta: float) -> float:
        """Energy stored in the spring ``k delta^(n+1) / (n+1)`` [J] (0 when open)."""
        if delta <= 0.0:
            return 0.0
        return self.k * delta ** (self.n + 1.0) / (self.n + 1.0)

    def raw_force(self, delta: float, delta_dot: float, v_imp: float,
                  approaching: bool | None = None) -> float:
        """Force law before clipping at zero [N]; ``delta`` is clipped at 0 (no spring in tension).

        Its sign change during restitution is the separation event of clipped laws.
        ``approaching`` selects the branch of approach-only laws (default: ``delta_dot > 0``);
        an integrator passes it explicitly so that each phase sees a smooth right-hand side
        up to the maximum-penetration event.
        """
        if approaching is None:
            approaching = delta_dot > 0.0
        d = delta if delta > 0.0 else 0.0
        model, k, n = self.model, self.k, self.n
        spring = k * d ** n
        if model == "hertz" or self.zeta == 0.0:
            return spring
        if model in DASHPOT_MODELS:
            if model != "kelvin_voigt" and not approaching:
                return spring
            c = 2.0 * self.zeta * math.sqrt(k * self.m * _pow_or_limit(d, n - 1.0))
            return spring + c * delta_dot
        if model in HERTZDAMP_MODELS:
            if v_imp <= 0.0:
                return spring
            return spring * (1.0 + self.zeta * delta_dot / max(v_imp, MIN_IMPACT_SPEED))
        # crvk
        if not approaching:
            return spring
        q = self.zeta * k * self.m * v_imp * v_imp * _pow_or_limit(d, n - 1.0)
        return 0.5 * (spring + math.sqrt(spring * spring + 4.0 * q))

    def force(self, delta: float, delta_dot: float, v_imp: float,
              approaching: bool | None = None) -> float:
        """Contact force [N] >= 0; 0 when ``delta <= 0``.

        ``delta`` [m] penetration, ``delta_dot`` [m/s] (> 0 approaching), ``v_imp`` [m/s]
        approach speed latched at contact onset; ``approaching`` as in :meth:`raw_force`.
        """
        if not delta > 0.0:
            return 0.0
        f = self.raw_force(delta, delta_dot, v_imp, approaching)
        return f if f > 0.0 else 0.0

    def force_and_derivatives(self, delta: float, delta_dot: float, v_imp: float) -> tuple[float, float, float]:
        """``(F, dF/d delta, dF/d delta_dot)`` in N, N/m, N s/m.

        Derivatives are those of the active branch (approach or restitution for
        approach-only models, 0 where the force is clipped or the contact is open); they
        can be infinite at onset for laws with ``delta^(n-1)`` terms and n < 2.
        """
        if not delta > 0.0:
            return 0.0, 0.0, 0.0
        F = self.raw_force(delta, delta_dot, v_imp)
        if F <= 0.0:
            return 0.0, 0.0, 0.0
        model, k, n, d, z = self.model, self.k, self.n, delta, self.zeta
        spring = k * d ** n
        dspring = n * k * d ** (n - 1.0)
        if model == "hertz" or z == 0.0:
            return F, dspring, 0.0
        if model in DASHPOT_MODELS:
            if model != "kelvin_voigt" and delta_dot <= 0.0:
                return F, dspring, 0.0
            c = 2.0 * z * math.sqrt(k * self.m * d ** (n - 1.0))
            dc = 0.5 * (n - 1.0) * c / d
            return F, dspring + dc * delta_dot, c
        if model in HERTZDAMP_MODELS:
            if v_imp <= 0.0:
                return F, dspring, 0.0
            chi = z / max(v_imp, MIN_IMPACT_SPEED)
            return F, dspring * (1.0 + chi * delta_dot), spring * chi
        if delta_dot <= 0.0:
            return F, dspring, 0.0
        a = z * k * self.m * v_imp * v_imp
        q = a * d ** (n - 1.0)
        dq = (n - 1.0) * a * d ** (n - 2.0)
        root = math.sqrt(spring * spring + 4.0 * q)
        return F, 0.5 * (dspring + (spring * dspring + 2.0 * dq) / root), 0.0


def _pow_or_limit(d: float, p: float) -> float:
    """``d**p`` with the limits 0**0 = 1 and 0**negative = inf kept finite (d = 0 -> 0 for p > 0)."""
    if d == 0.0:
        return 1.0 if p == 0.0 else (0.0 if p > 0.0 else math.inf)
    return d ** p


def effective_mass(m1: float, m2: float) -> float:
    """``m1 m2 / (m1 + m2)`` [kg]."""
    for name, value in (("m1", m1), ("m2", m2)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} = {value!r} kg is outside the allowed range {name} > 0")
    return m1 * m2 / (m1 + m2)


def law_for(model: str, k: float, n: float, m1: float, m2: float, CR: float,
            zeta: float | None = None) -> ContactLaw:
    """Build the :class:`ContactLaw` of ``model``; ``zeta`` None or < 0 -> :func:`published_zeta`."""
    _check_model(model)
    CR = _check_cr(CR)
    if zeta is None or zeta < 0.0:
        zeta = published_zeta(model, CR, n)
    if model == "hertz":
        zeta = 0.0
    return ContactLaw(model=model, k=float(k), n=float(n), m=effective_mass(m1, m2), zeta=float(zeta))


def scaled_force(model: str, zeta: float, n: float, d: float, dd: float,
                 approaching: bool | None = None) -> float:
    """Dimensionless force ``F / (k L^n)`` at ``d = delta / L``, ``dd = delta_dot / v_imp``.

    Same law as :meth:`ContactLaw.force` in the scales of an impact at ``v_imp``
    (module docstring); clipped at 0.  Used by the in-step impact resolver.
    """
    if d <= 0.0:
        return 0.0
    if approaching is None:
        approaching = dd > 0.0
    spring = d ** n
    if zeta == 0.0 or model == "hertz":
        return spring
    if model in HERTZDAMP_MODELS:
        f = spring * (1.0 + zeta * dd)
    elif model == "crvk":
        if not approaching:
            return spring
        f = 0.5 * (spring + math.sqrt(spring * spring + 4.0 * zeta * d ** (n - 1.0)))
    else:
        if not approaching and model != "kelvin_voigt":
            return spring
        f = spring + 2.0 * zeta * d ** (0.5 * (n - 1.0)) * dd
    return f if f > 0.0 else 0.0
