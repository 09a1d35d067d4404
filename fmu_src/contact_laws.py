"""Impact force laws of the pounding contact element (pure physics, SI units, no FMI).

Conventions (as in the seed paper, Naderpour et al. c. 2016, and its sources):

* penetration ``delta`` [m] > 0 while the bodies overlap (``delta = x1 - x2 - gap``);
* penetration rate ``delta_dot`` [m/s] > 0 while the bodies approach;
* the contact force ``F`` [N] is compressive and never negative (contact cannot pull);
* ``k`` [N/m^n] is the contact stiffness, ``n`` [-] its exponent (1 linear, 1.5 Hertz);
* ``m = m1 m2 / (m1 + m2)`` [kg] is the effective mass of the two colliding bodies;
* ``v_imp`` [m/s] is the approach speed latched at contact onset;
* ``CR`` [-] is the coefficient of restitution, rebound speed / approach speed.

Every law is a spring ``k delta^n`` plus a dissipative term governed by one dimensionless
damping constant ``zeta``.  The laws are registered in ONE table, :data:`LAWS` (name ->
:class:`LawSpec`): its force shape, when the dashpot acts, how the contact ends, the
published constant from CR, labels and the peers' equivalents.  Every consumer (this
module's :class:`ContactLaw`, the in-step resolver's scaled kernels, the reference solver,
the report, the OpenSees peer) reads the table; an unknown name is an error everywhere
(:func:`law_spec`).  Adding a law of an existing shape is one entry (plus its tests); a
new shape is one :class:`ForceShape` subclass.  The shapes:

``DASHPOT`` (``kelvin_voigt``, ``jankowski``, ``barros2013``)
    ``F = k delta^n + c delta_dot`` with ``c = 2 zeta sqrt(k m delta^(n-1))``.
    For n = 1 this is Anagnostopoulos' ``c = 2 zeta sqrt(k m)`` (seed Eq 2.3); for
    n = 1.5 it is Jankowski's ``c = 2 zeta sqrt(k sqrt(delta) m)`` (Eq 2.4).  The same
    generalisation keeps every law scale invariant for any n.

``HERTZDAMP`` (``hertzdamp``, ``ye``, ``naderpour2013``, ``hunt_crossley``, ``gonthier``)
    ``F = k delta^n (1 + chi delta_dot)`` with ``chi = zeta / v_imp``; the seed writes
    ``c = zeta_paper delta^n`` with ``zeta_paper = k chi``.  Here ``zeta = chi v_imp`` is the
    dimensionless constant of each published formula.

``CRVK`` (the seed paper's proposed model, Eqs 3.1, 3.4-3.9, regularised)
    Written out, Eqs 3.4, 3.5 and 3.9 give the damping force ``c delta_dot =
    A k v_imp^2 delta^(n-1) / delta_ddot`` with ``A = 0.0159 (1 - CR) CR^0.2805`` (the
    printed ``delta_imp^2`` must be ``v_imp^2`` for F to be a force).  Literally it is 0/0 at
    onset, infinite at maximum penetration and an algebraic loop.  During an isolated impact
    ``|delta_ddot| = F / m``, which turns it into the quadratic
    ``F^2 - k delta^n F - A k m v_imp^2 delta^(n-1) = 0`` in approach (positive root) and
    ``F = k delta^n`` in restitution (Eq 3.1: dashpot only while approaching).  ``zeta`` is
    then the constant ``A``, calibrated so that the impact reaches the requested CR
    (:func:`crvk_constant`, exact to quadrature accuracy; see ``docs/contact_models.md``).

``ELASTIC`` (``hertz``): ``F = k delta^n``, no dashpot.

Scale invariance: with ``L = (m v_imp^2 / k)^(1/(n+1))``, ``T = L / v_imp`` and
``F0 = k L^n`` every law above becomes a function of ``delta/L`` and ``delta_dot/v_imp``
only, so the achieved CR depends on ``(model, zeta, n)`` and not on mass, stiffness or
impact velocity.  :meth:`ForceShape.scaled_kernel` is that dimensionless form;
the in-step impact resolver integrates it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Callable

import numpy as np
from scipy.optimize import brentq

#: the constant printed in the seed's Eq 3.9, A = 0.0159 (1 - CR) CR^0.2805
CRVK_PRINTED_FACTOR = 0.0159
CRVK_PRINTED_EXPONENT = 0.2805

#: latched approach speeds below this [m/s] count as this speed: the Hertz-damp dashpot divides
#: by v_imp and the impact scales L, T ~ v_imp^(-1/5) need v_imp > 0; a grazing touch at
#: 1e-6 m/s exchanges no measurable impulse.  (v_imp <= 0, no latched approach, switches the
#: Hertz-damp dashpot off.)
MIN_IMPACT_SPEED = 1e-6

#: when the dissipative term acts (LawSpec.dashpot)
NONE, ALWAYS, APPROACH = "none", "always", "approach"
#: how a contact ends (LawSpec.separation): where the penetration returns to 0; where the raw
#: force reaches 0 first (a dashpot pulling in restitution); or the latter only while an
#: external force pulls the bodies apart (the Hertz-damp factor 1 + zeta u cannot change sign
#: in a free impact)
PENETRATION, FORCE, FORCE_WHEN_PULLED = "penetration", "force", "force_when_pulled"


# ----------------------------------------------------------------------------------------------
# published damping constants
# ----------------------------------------------------------------------------------------------
def _check_cr(CR: float) -> float:
    CR = float(CR)
    if not (0.0 < CR <= 1.0):
        raise ValueError(f"CR = {CR!r} is outside the allowed range 0 < CR <= 1")
    return CR


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


def zeta_hertzdamp(CR: float) -> float:
    """Muthukumar & DesRoches (2006), seed Eq 2.6: ``zeta = 3 (1 - CR^2) / 4``."""
    return 0.75 * (1.0 - CR * CR)


def zeta_ye(CR: float) -> float:
    """Ye, Li & Zhu (2009), seed Eq 2.7: ``zeta = 8 (1 - CR) / (5 CR)``."""
    return 1.6 * (1.0 - CR) / CR


def zeta_naderpour2013(CR: float) -> float:
    """Seed Eq 2.8 as printed, divided by k: ``zeta = 2 / (5 CR^2) sqrt((1 - CR) / (1 + CR))``."""
    return 0.4 / (CR * CR) * math.sqrt((1.0 - CR) / (1.0 + CR))


def zeta_hunt_crossley(CR: float) -> float:
    """Hunt & Crossley (1975): ``zeta = 3 (1 - CR) / 2``."""
    return 1.5 * (1.0 - CR)


def zeta_gonthier(CR: float) -> float:
    """Gonthier et al. (2004): ``zeta = (1 - CR^2) / CR``."""
    return (1.0 - CR * CR) / CR


def zeta_elastic(CR: float) -> float:
    """The elastic Hertz law has no damping constant: 0."""
    return 0.0


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
# force shapes: the arithmetic of each family, dimensional and scaled, on its damped branch
# ----------------------------------------------------------------------------------------------
class ForceShape:
    """The force of one family of laws on its *damped* branch (the dashpot acting).

    :class:`LawSpec` decides when that branch applies (``dashpot``); outside it, and for
    ``zeta = 0``, every law is the spring ``k delta^n``.  Methods, for ``delta > 0``:

    * :meth:`raw_force`: ``F`` [N] before clipping at 0, from the clipped penetration
      ``d = max(delta, 0)`` [m], the spring force ``k d^n`` [N], ``delta_dot`` [m/s] and the
      latched ``v_imp`` [m/s];
    * :meth:`derivatives`: ``(dF/d delta, dF/d delta_dot)`` [N/m, N s/m];
    * :meth:`scaled_kernel`: ``f(d, u) -> force`` in the impact's scales (``d = delta / L``,
      ``u = delta_dot / v_imp``, force ``F / (k L^n)`` clipped at 0; a bare float: the resolver
      calls it seven times per internal step, and books the dissipated energy from the
      trajectory's ends, not from the power);
    * :meth:`release`: ``g(d, u)`` with the sign of the scaled raw force (< 0: the force has
      been clipped, the contact has released), or None if it cannot change sign.

    Each expression is the one the package has always evaluated (bit for bit).

    ``drops_at_rest``: the damped branch keeps a force above the spring's at ``delta_dot = 0``
    (crvk), so a law that switches it off in restitution has a force drop there, and a
    contact pushed together with a force between the two branches sticks
    (:attr:`LawSpec.sticks`).
    """

    name = "shape"
    drops_at_rest = False

    def raw_force(self, law: "ContactLaw", d: float, spring: float, delta_dot: float, v_imp: float) -> float:
        raise NotImplementedError

    def derivatives(self, law: "ContactLaw", d: float, spring: float, dspring: float, delta_dot: float,
                    v_imp: float) -> tuple[float, float]:
        raise NotImplementedError

    def scaled_kernel(self, zeta: float, n: float):
        raise NotImplementedError

    def release(self, zeta: float, n: float):
        return None

    def __repr__(self) -> str:
        return self.name.upper()


def elastic_kernel(n: float):
    """``f(d, u) -> d^n``: the spring alone, scaled (no dissipation)."""
    def f(d, u):
        return d ** n if d > 0.0 else 0.0
    return f


class Elastic(ForceShape):
    """``F = k delta^n``: no damped branch (``hertz``)."""

    name = "elastic"

    def raw_force(self, law, d, spring, delta_dot, v_imp):
        return spring

    def derivatives(self, law, d, spring, dspring, delta_dot, v_imp):
        return dspring, 0.0

    def scaled_kernel(self, zeta, n):
        return elastic_kernel(n)


class Dashpot(ForceShape):
    """``F = k delta^n + c delta_dot``, ``c = 2 zeta sqrt(k m delta^(n-1))``; scaled
    ``f = d^n + 2 zeta d^((n-1)/2) u``.  It turns negative in restitution (clipped)."""

    name = "dashpot"

    def raw_force(self, law, d, spring, delta_dot, v_imp):
        c = 2.0 * law.zeta * math.sqrt(law.k * law.m * _pow_or_limit(d, law.n - 1.0))
        return spring + c * delta_dot

    def derivatives(self, law, d, spring, dspring, delta_dot, v_imp):
        n = law.n
        c = 2.0 * law.zeta * math.sqrt(law.k * law.m * d ** (n - 1.0))
        dc = 0.5 * (n - 1.0) * c / d
        return dspring + dc * delta_dot, c

    def scaled_kernel(self, zeta, n):
        half = 0.5 * (n - 1.0)
        two_zeta = 2.0 * zeta

        def f(d, u):
            if d <= 0.0:
                return 0.0
            x = d ** n + two_zeta * d ** half * u
            return x if x > 0.0 else 0.0
        return f

    def release(self, zeta, n):
        half = 0.5 * (n - 1.0)

        def g(d, u):
            return d ** n + 2.0 * zeta * d ** half * u
        return g


class HertzDamp(ForceShape):
    """``F = k delta^n (1 + zeta delta_dot / v_imp)``; ``v_imp <= 0`` (no latched approach)
    switches the dashpot off.  Scaled ``f = d^n (1 + zeta u)``: negative only when
    ``1 + zeta u < 0``."""

    name = "hertzdamp"

    def raw_force(self, law, d, spring, delta_dot, v_imp):
        if v_imp <= 0.0:
            return spring
        return spring * (1.0 + law.zeta * delta_dot / max(v_imp, MIN_IMPACT_SPEED))

    def derivatives(self, law, d, spring, dspring, delta_dot, v_imp):
        if v_imp <= 0.0:
            return dspring, 0.0
        chi = law.zeta / max(v_imp, MIN_IMPACT_SPEED)
        return dspring * (1.0 + chi * delta_dot), spring * chi

    def scaled_kernel(self, zeta, n):
        def f(d, u):
            if d <= 0.0:
                return 0.0
            x = d ** n * (1.0 + zeta * u)
            return x if x > 0.0 else 0.0
        return f

    def release(self, zeta, n):
        def g(d, u):
            return 1.0 + zeta * u
        return g


class Crvk(ForceShape):
    """``F = (k delta^n + sqrt(k^2 delta^(2n) + 4 zeta k m v_imp^2 delta^(n-1))) / 2``;
    scaled ``f = (d^n + sqrt(d^(2n) + 4 zeta d^(n-1))) / 2``.  Never negative."""

    name = "crvk"
    drops_at_rest = True     # f(d, 0) = (d^n + sqrt(d^2n + 4 zeta d^(n-1))) / 2 > d^n

    def raw_force(self, law, d, spring, delta_dot, v_imp):
        q = law.zeta * law.k * law.m * v_imp * v_imp * _pow_or_limit(d, law.n - 1.0)
        return 0.5 * (spring + math.sqrt(spring * spring + 4.0 * q))

    def derivatives(self, law, d, spring, dspring, delta_dot, v_imp):
        n = law.n
        a = law.zeta * law.k * law.m * v_imp * v_imp
        q = a * d ** (n - 1.0)
        dq = (n - 1.0) * a * d ** (n - 2.0)
        root = math.sqrt(spring * spring + 4.0 * q)
        return 0.5 * (dspring + (spring * dspring + 2.0 * dq) / root), 0.0

    def scaled_kernel(self, zeta, n):
        four_a = 4.0 * zeta
        n1 = n - 1.0

        def f(d, u):
            if d <= 0.0:
                return 0.0
            s = d ** n
            return 0.5 * (s + math.sqrt(s * s + four_a * d ** n1))
        return f


ELASTIC, DASHPOT, HERTZDAMP, CRVK = Elastic(), Dashpot(), HertzDamp(), Crvk()


# ----------------------------------------------------------------------------------------------
# the table
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LawSpec:
    """Everything the package knows about one impact law (one entry of :data:`LAWS`).

    Attributes
    ----------
    name : str
        The ``model`` value of ``pounding.fmu`` and of scenes.
    shape : ForceShape
        Force on the damped branch (:data:`DASHPOT`, :data:`HERTZDAMP`, :data:`CRVK`, ...).
    dashpot : str
        When the dissipative term acts: ``"always"``, ``"approach"`` (``delta_dot > 0``:
        restitution is the bare spring) or ``"none"``.
    separation : str
        How a contact ends: ``"penetration"`` (``delta`` back to 0), ``"force"`` (the raw
        force reaches 0 first) or ``"force_when_pulled"`` (only under an external pull).
    published : callable
        The law's own damping constant from CR: ``published(CR)``, or ``published(CR, n)``
        when ``constant_depends_on_n``.
    source : str
        Where the law and its constant come from (formula, reference).
    label : str
        Label of the law with its published constant in reports and plots.
    printed : callable or None
        The constant *as printed in the seed paper* when it differs from ``published``
        (crvk: the printed Eq 3.9 constant; ``published`` is the exact calibration).
    opensees : str or None
        The OpenSees ``uniaxialMaterial`` that reproduces the law (the OpenSees peer).
    """

    name: str
    shape: ForceShape
    dashpot: str
    separation: str
    published: Callable[..., float]
    source: str
    label: str
    printed: Callable[[float], float] | None = None
    opensees: str | None = None
    constant_depends_on_n: bool = False

    def __post_init__(self):
        if self.dashpot not in (NONE, ALWAYS, APPROACH):
            raise ValueError(f"law {self.name!r}: dashpot = {self.dashpot!r} is not one of none, always, approach")
        if self.separation not in (PENETRATION, FORCE, FORCE_WHEN_PULLED):
            raise ValueError(f"law {self.name!r}: separation = {self.separation!r} is not one of "
                             f"{PENETRATION}, {FORCE}, {FORCE_WHEN_PULLED}")

    @property
    def damped(self) -> bool:
        """True if the law has a damping constant (every law except the elastic Hertz law)."""
        return self.dashpot != NONE

    @property
    def approach_only(self) -> bool:
        """True if the dissipative term acts only while ``delta_dot > 0``."""
        return self.dashpot == APPROACH

    @property
    def clipped(self) -> bool:
        """True if the raw force can turn negative in restitution (it is clipped at 0)."""
        return self.separation != PENETRATION

    @property
    def sticks(self) -> bool:
        """True if a contact can stick at ``delta_dot = 0``: the force drops there from the
        approach branch to the restitution branch (an approach-only dashpot whose shape
        ``drops_at_rest``), so a push between the two forces at the same penetration fits
        neither branch; the contact is held (Filippov's sliding motion) until the push leaves
        that band.  The resolver and the reference solver hold it; for ``zeta = 0`` the band
        is empty."""
        return self.dashpot == APPROACH and self.shape.drops_at_rest

    def dashpot_acts(self, approaching: bool) -> bool:
        """True on the damped branch: the dashpot acts always, or in approach only."""
        return self.dashpot == ALWAYS or (self.dashpot == APPROACH and approaching)

    def constant(self, CR: float, n: float = 1.5) -> float:
        """The published damping constant at ``CR`` (checked), exponent ``n``."""
        CR = _check_cr(CR)
        return self.published(CR, n) if self.constant_depends_on_n else self.published(CR)

    def printed_constant(self, CR: float, n: float = 1.5) -> float:
        """The constant as the seed paper prints it (the published one unless ``printed``)."""
        return self.printed(CR) if self.printed is not None else self.constant(CR, n)

    def kernel(self, zeta: float, n: float, approaching: bool):
        """Scaled ``f(d, u) -> force`` of the branch (see :class:`ForceShape`)."""
        if zeta == 0.0 or not self.dashpot_acts(approaching):
            return elastic_kernel(n)
        return self.shape.scaled_kernel(zeta, n)

    def separation_function(self, zeta: float, n: float, pulled: bool = False):
        """Scaled ``g(d, u)``, > 0 in contact, of the restitution branch.

        The contact ends where ``d`` reaches 0, or where the raw force does first: for a
        ``"force"`` law whenever ``zeta > 0``, for a ``"force_when_pulled"`` law only with
        ``pulled`` (an external pull; in a free impact the Hertz-damp factor decays towards
        0 without reaching it, where round-off alone would flip its sign).
        """
        release = None
        if zeta > 0.0 and (self.separation == FORCE or (self.separation == FORCE_WHEN_PULLED and pulled)):
            release = self.shape.release(zeta, n)
        if release is None:
            def g(d, u):
                return d
            return g

        def g(d, u):
            if d <= 0.0:
                return d
            return min(d, release(d, u))
        return g


LAWS = MappingProxyType({spec.name: spec for spec in (
    LawSpec("hertz", ELASTIC, NONE, PENETRATION, zeta_elastic,
            "Hertz (elastic), zeta = 0", "Hertz (elastic)"),
    LawSpec("kelvin_voigt", DASHPOT, ALWAYS, FORCE, zeta_kelvin_voigt,
            "-ln CR / sqrt(pi^2 + ln^2 CR), Anagnostopoulos, seed Eq 2.3", "Eq 2.3 Anagnostopoulos"),
    LawSpec("jankowski", DASHPOT, APPROACH, PENETRATION, zeta_jankowski,
            "9 sqrt5 (1-CR^2) / (2 CR (CR(9pi-16)+16)), Jankowski 2006, Eq 2.4", "Eq 2.4 Jankowski",
            opensees="JankowskiImpact"),
    LawSpec("barros2013", DASHPOT, APPROACH, PENETRATION, zeta_barros2013,
            "Eq 2.5 as printed, \"Barros et al. 2013\"", "Eq 2.5 Barros 2013", opensees="JankowskiImpact"),
    LawSpec("hertzdamp", HERTZDAMP, ALWAYS, FORCE_WHEN_PULLED, zeta_hertzdamp,
            "3 (1 - CR^2) / 4, Muthukumar & DesRoches 2006, Eq 2.6", "Eq 2.6 Muthukumar-DesRoches",
            opensees="Hertzdamp"),
    LawSpec("ye", HERTZDAMP, ALWAYS, FORCE_WHEN_PULLED, zeta_ye,
            "8 (1 - CR) / (5 CR), Ye, Li & Zhu 2009, Eq 2.7", "Eq 2.7 Ye", opensees="Hertzdamp"),
    LawSpec("naderpour2013", HERTZDAMP, ALWAYS, FORCE_WHEN_PULLED, zeta_naderpour2013,
            "2 / (5 CR^2) sqrt((1-CR)/(1+CR)), Eq 2.8 as printed, divided by k", "Eq 2.8 Naderpour 2013",
            opensees="Hertzdamp"),
    LawSpec("hunt_crossley", HERTZDAMP, ALWAYS, FORCE_WHEN_PULLED, zeta_hunt_crossley,
            "3 (1 - CR) / 2, Hunt & Crossley 1975", "Hunt-Crossley 1975", opensees="Hertzdamp"),
    LawSpec("gonthier", HERTZDAMP, ALWAYS, FORCE_WHEN_PULLED, zeta_gonthier,
            "(1 - CR^2) / CR, Gonthier et al. 2004", "Gonthier 2004", opensees="Hertzdamp"),
    LawSpec("crvk", CRVK, APPROACH, PENETRATION, crvk_constant,
            "A(CR, n) calibrated (crvk_constant); printed: 0.0159 (1 - CR) CR^0.2805, seed Eq 3.9",
            "Eq 3.9 crvk (printed constant)", printed=crvk_printed_constant, constant_depends_on_n=True),
)})

#: every law's name, in the order of the table (the ``model`` parameter's allowed values)
MODELS = tuple(LAWS)
#: laws of the form k delta^n + c(delta) delta_dot
DASHPOT_MODELS = tuple(name for name, spec in LAWS.items() if spec.shape is DASHPOT)
#: laws of the form k delta^n (1 + zeta delta_dot / v_imp)
HERTZDAMP_MODELS = tuple(name for name, spec in LAWS.items() if spec.shape is HERTZDAMP)
#: laws whose dissipative term acts only while the bodies approach (delta_dot > 0)
APPROACH_ONLY_MODELS = tuple(name for name, spec in LAWS.items() if spec.approach_only)
#: laws with a free damping constant (everything except the elastic Hertz law)
DAMPED_MODELS = tuple(name for name, spec in LAWS.items() if spec.damped)
#: laws whose raw force can turn negative in restitution (clipped at 0: the bodies may part early)
CLIPPED_MODELS = tuple(name for name, spec in LAWS.items() if spec.clipped)


def law_spec(model: str) -> LawSpec:
    """The table entry of ``model``; a ValueError naming the allowed values for any other name."""
    try:
        return LAWS[model]
    except (KeyError, TypeError):
        raise ValueError(f"model = {model!r} is not allowed: one of {', '.join(MODELS)}") from None


def _check_model(model: str) -> str:
    law_spec(model)
    return model


def published_zeta(model: str, CR: float, n: float = 1.5) -> float:
    """Dimensionless damping constant of ``model`` for restitution ``CR`` by its published formula.

    The formulas are the table's (:data:`LAWS`, ``LawSpec.source``)::

        hertz           0                                        Hertz (elastic)
        kelvin_voigt    -ln CR / sqrt(pi^2 + ln^2 CR)            Anagnostopoulos, seed Eq 2.3
        jankowski       9 sqrt5 (1-CR^2) / (2 CR (CR(9pi-16)+16))  Jankowski 2006, Eq 2.4
        barros2013      Eq 2.5 as printed                        "Barros et al. 2013"
        hertzdamp       3 (1 - CR^2) / 4                         Muthukumar & DesRoches 2006, Eq 2.6
        ye              8 (1 - CR) / (5 CR)                      Ye, Li & Zhu 2009, Eq 2.7
        naderpour2013   2 / (5 CR^2) sqrt((1-CR)/(1+CR))         Eq 2.8 as printed, divided by k
        hunt_crossley   3 (1 - CR) / 2                           Hunt & Crossley 1975
        gonthier        (1 - CR^2) / CR                          Gonthier et al. 2004
        crvk            A(CR, n) calibrated                      :func:`crvk_constant`

    For the Hertz-damp family the value is ``chi * v_imp`` (``chi`` in s/m).  ``n`` only
    matters for crvk, whose constant is calibrated for the exponent in use.
    """
    return law_spec(model).constant(CR, n)


def published_label(model: str) -> str:
    """Report label of ``model`` with its published constant (ValueError for an unknown name)."""
    return law_spec(model).label


# ----------------------------------------------------------------------------------------------
# the force laws
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ContactLaw:
    """One impact force law with its constants (immutable).

    Parameters
    ----------
    model : str
        One of :data:`MODELS` (its entry of :data:`LAWS` is ``spec``).
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
    spec: LawSpec = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "spec", law_spec(self.model))
        for name in ("k", "n", "m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} = {value!r} is outside the allowed range {name} > 0")
        if not (math.isfinite(self.zeta) and self.zeta >= 0.0):
            raise ValueError(f"zeta = {self.zeta!r} is outside the allowed range zeta >= 0")

    def __reduce__(self):   # pickled by name: the table entry is looked up again
        return ContactLaw, (self.model, self.k, self.n, self.m, self.zeta)

    def __deepcopy__(self, memo):   # immutable: an FMU state copy shares it
        return self

    # -- dashpot rules ------------------------------------------------------------------------
    @property
    def approach_only(self) -> bool:
        """True if the dissipative term acts only while ``delta_dot > 0``."""
        return self.spec.approach_only

    @property
    def releases_before_unloading(self) -> bool:
        """True if, in an isolated impact, the force reaches zero while ``delta > 0``.

        Only a dashpot acting in restitution does (``k delta^n + c delta_dot`` crosses zero
        in restitution: separation rule ``"force"``).  For the Hertz-damp family
        ``w = 1 + zeta delta_dot / v_imp`` obeys ``dw/dt = -(zeta k delta^n / (m v_imp)) w``,
        so ``w`` decays but never changes sign: contact ends at ``delta = 0``.
        """
        return self.spec.separation == FORCE and self.zeta > 0.0

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
        spring = self.k * d ** self.n
        if self.zeta == 0.0 or not self.spec.dashpot_acts(approaching):
            return spring
        return self.spec.shape.raw_force(self, d, spring, delta_dot, v_imp)

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
        k, n, d = self.k, self.n, delta
        spring = k * d ** n
        dspring = n * k * d ** (n - 1.0)
        if self.zeta == 0.0 or not self.spec.dashpot_acts(delta_dot > 0.0):
            return F, dspring, 0.0
        dF_dd, dF_dv = self.spec.shape.derivatives(self, d, spring, dspring, delta_dot, v_imp)
        return F, dF_dd, dF_dv


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
    spec = law_spec(model)
    CR = _check_cr(CR)
    if zeta is None or zeta < 0.0:
        zeta = spec.constant(CR, n)
    if not spec.damped:
        zeta = 0.0
    return ContactLaw(model=model, k=float(k), n=float(n), m=effective_mass(m1, m2), zeta=float(zeta))


def scaled_force(model: str, zeta: float, n: float, d: float, dd: float,
                 approaching: bool | None = None) -> float:
    """Dimensionless force ``F / (k L^n)`` at ``d = delta / L``, ``dd = delta_dot / v_imp``.

    Same law as :meth:`ContactLaw.force` in the scales of an impact at ``v_imp``
    (module docstring); clipped at 0: the resolver's kernel (:meth:`LawSpec.kernel`).
    """
    if d <= 0.0:
        return 0.0
    if approaching is None:
        approaching = dd > 0.0
    return law_spec(model).kernel(zeta, n, approaching)(d, dd)
