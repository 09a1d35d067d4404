"""Storey hysteresis laws of a shear building: linear, bilinear (kinematic hardening), Bouc-Wen.

Storey ``i`` (between floors ``i-1`` and ``i``) has the drift ``d = u[i] - u[i-1]``, the
elastic stiffness ``k`` (N/m), the yield shear ``Fy`` (N, yield drift ``dy = Fy / k``) and the
post-yield stiffness ratio ``alpha`` (``0 <= alpha < 1``).  Its restoring (storey) shear is

* ``"linear"``:   ``V = k d``;
* ``"bilinear"``: ``V = alpha k d + q`` with ``q`` the force of an elastic-perfectly-plastic
  element of stiffness ``(1 - alpha) k`` and strength ``(1 - alpha) Fy`` in parallel with a
  linear spring ``alpha k``: ``q = (1 - alpha) k (d - s)``, ``|q| <= (1 - alpha) Fy``, the slip
  ``s`` follows ``d`` while the element yields.  This is the bilinear law with kinematic
  hardening (the elastic range keeps its width ``2 Fy`` and moves with the hardening line), the
  law of OpenSees ``Steel01`` without isotropic hardening (``b = alpha``).  The state of a storey
  is ``(s, mode)``: ``mode = 0`` elastic, ``+1``/``-1`` yielding in that direction;
* ``"bouc_wen"``: ``V = alpha k d + (1 - alpha) Fy z`` with the dimensionless hysteretic variable
  (Wen 1976, A = 1)

      dy z' = d' [1 - |z|^n (gamma + beta sgn(d' z))].

  ``z`` is bounded by ``z_u = (beta + gamma)^(-1/n)``: with ``beta + gamma = 1`` (the default
  0.5 + 0.5) the storey's strength is ``Fy`` (plus the hardening), as for the bilinear law, to
  which it tends for ``n -> inf``.

Energy (the "elastic part" and the hysteretic energy): the plastic element carries
``q = (1 - alpha) k e`` with the elastic deformation ``e = d - s`` (bilinear) or ``e = dy z``
(Bouc-Wen).  Its stored energy ``q e / 2`` plus ``alpha k d^2 / 2`` is the storey's strain energy
(``E_strain``); the rest of the work of ``V`` on ``d`` is dissipated: ``E_hysteretic =
int q (d' - e') dt``.  Bilinear: ``(1 - alpha) Fy |delta s|`` per yielding excursion.  Bouc-Wen:
rate ``(1 - alpha) Fy |z|^(n+1) |d'| (beta + gamma sgn(d' z))``.

Allowed parameters (refused otherwise, naming the parameter, the value and the range):

* ``Fy > 0`` for every storey of an inelastic building, ``0 <= alpha < 1``;
* Bouc-Wen ``beta + gamma > 0`` (bounded strength ``z_u``: otherwise ``z`` grows without bound
  on loading) and ``beta - gamma >= 0``: with the dissipation rate above, ``beta >= |gamma|`` is
  exactly the condition that no loading path gives negative dissipation (a model that creates
  energy).  These are the bounded-input bounded-output stable, passive parameter classes of
  Ikhouane, Manosa & Rodellar, "Dynamic properties of the hysteretic Bouc-Wen model", Systems &
  Control Letters 56 (2007) 197-205, and the thermodynamic admissibility condition of
  Erlicher & Point, "Thermodynamic admissibility of Bouc-Wen type hysteresis models", Comptes
  Rendus Mecanique 332 (2004) 51-57; Ismail, Ikhouane & Rodellar, "The hysteresis Bouc-Wen
  model, a survey", Arch. Comput. Methods Eng. 16 (2009) 161-188 review both;
* ``1 <= bw_n <= BOUC_WEN_MAX_N``: ``n >= 1`` keeps the rate Lipschitz in ``z`` (unique
  solutions; the analysis above assumes it); above 20 the law is a bilinear one to within
  ``(1/2)^20`` of the yield drift, which ``"bilinear"`` gives exactly and without the stiff
  transition that a large exponent imposes on the integrator;
* an initial drift within the elastic range (``|d0| <= dy``; Bouc-Wen ``|d0| / dy < z_u``): the
  initial state is the elastic one, ``s = 0`` and ``z = d0 / dy``.

Residual drift (output ``drift_residual``): the plastic part of the current drift,
``d - V / k``, the drift left when the storey is unloaded to zero shear at its elastic
stiffness.  For the bilinear law it equals the drift at which the storey comes to rest at zero
shear (bilinear: ``(1 - alpha) s``), as long as that unloading does not yield again in
reverse, i.e. ``|V| <= 2 Fy`` (always true for ductility below ``(1 + alpha) / alpha``).  At the
end of a record, when the building has come to rest, it is the residual drift of the
earthquake-engineering literature (for a building at rest every storey shear is zero).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

HYSTERESIS_MODELS = ("linear", "bilinear", "bouc_wen")
BOUC_WEN_MAX_N = 20.0


def _vector(values, n: int | None = None) -> np.ndarray:
    arr = np.array(values, dtype=float).reshape(-1)
    if n is not None and arr.size == 1 and n > 1:
        arr = np.full(n, float(arr[0]))
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class StoreyHysteresis:
    """Hysteresis law and strengths of the storeys of one building (see module docstring).

    Parameters
    ----------
    model : {"linear", "bilinear", "bouc_wen"}
    yield_shear : sequence of float
        ``Fy`` per storey (N), storey 1 first; ignored by ``"linear"``.
    alpha : float
        Post-yield over elastic stiffness (-).
    bw_n, bw_beta, bw_gamma : float
        Bouc-Wen exponent and shape parameters (-), A = 1.
    """

    model: str = "linear"
    yield_shear: np.ndarray = field(default_factory=lambda: np.zeros(0))
    alpha: float = 0.05
    bw_n: float = 2.0
    bw_beta: float = 0.5
    bw_gamma: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "yield_shear", _vector(self.yield_shear))
        for name in ("alpha", "bw_n", "bw_beta", "bw_gamma"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def inelastic(self) -> bool:
        return self.model != "linear"

    def problems(self, stiffnesses, damping_ratio: float = 0.05, initial_drifts=None) -> list[str]:
        """Every reason these parameters cannot be used with these storeys (empty if none).

        Messages name the FMU/scene parameter, its value and the allowed range.
        """
        return [message for _, message in self.parameter_problems(stiffnesses, damping_ratio, initial_drifts)]

    def parameter_problems(self, stiffnesses, damping_ratio: float = 0.05, initial_drifts=None) -> list[tuple[str, str]]:
        """:meth:`problems` as ``(parameter, message)`` pairs: the FMU parameter each is about
        (``"Fy[2]"``, ``"alpha"``, ``"x0[1]"``, ...; ``"bw_beta bw_gamma"`` for a rule on both),
        so that a scene can name its line."""
        out = []
        if self.model not in HYSTERESIS_MODELS:
            return [("hysteresis", f"hysteresis = {self.model!r} is not allowed: one of "
                     + ", ".join(repr(m) for m in HYSTERESIS_MODELS))]
        if not (math.isfinite(self.alpha) and 0.0 <= self.alpha < 1.0):
            out.append(("alpha", f"alpha = {self.alpha!r} is outside the allowed range 0 <= alpha < 1"))
        if not self.inelastic:
            return out
        k = np.asarray(stiffnesses, dtype=float)
        n = k.size
        fy = self.yield_shear
        if fy.size != n:
            out.append(("Fy", f"Fy has {fy.size} value(s) for {n} storeys: give one yield shear per storey"))
            return out
        for i, value in enumerate(fy, start=1):
            if not (math.isfinite(value) and value > 0.0):
                out.append((f"Fy[{i}]", f"Fy[{i}] = {float(value)!r} N is outside the allowed range 0 < Fy[{i}] "
                                        f"(hysteresis = {self.model!r} needs a yield shear for every storey)"))
        if n == 1 and k[0] == 0.0:
            out.append(("k[1]", f"hysteresis = {self.model!r} needs a storey stiffness: a free mass (k[1] = 0) "
                                f"has no storey to yield; use hysteresis = 'linear'"))
        if damping_ratio == 0.0 and self.alpha == 0.0:
            out.append(("alpha", "alpha = 0 with zeta = 0: a yielded storey without hardening and without damping "
                                 "is an undamped mechanism, whose state matrix is defective; give alpha > 0 or zeta > 0"))
        if self.model == "bouc_wen":
            b, g, nn = self.bw_beta, self.bw_gamma, self.bw_n
            if not (math.isfinite(nn) and 1.0 <= nn <= BOUC_WEN_MAX_N):
                out.append(("bw_n", f"bw_n = {nn!r} is outside the allowed range 1 <= bw_n <= {BOUC_WEN_MAX_N:g}"))
            if not (math.isfinite(b) and math.isfinite(g)):
                out.append(("bw_beta bw_gamma", f"bw_beta = {b!r}, bw_gamma = {g!r}: must be finite"))
            else:
                if not b + g > 0.0:
                    out.append(("bw_beta bw_gamma", f"bw_beta + bw_gamma = {b + g:.6g} is outside the allowed range "
                                           f"bw_beta + bw_gamma > 0 (unbounded hysteretic force otherwise)"))
                if not b - g >= 0.0:
                    out.append(("bw_beta bw_gamma", f"bw_beta - bw_gamma = {b - g:.6g} is outside the allowed range "
                                           f"bw_beta - bw_gamma >= 0 (negative dissipation on some loading paths otherwise)"))
        if out or initial_drifts is None:
            return out
        dy = self.yield_drift(k)
        d0 = np.asarray(initial_drifts, dtype=float)
        limit = dy if self.model == "bilinear" else dy * self.ultimate_z
        for i in range(n):
            inside = abs(d0[i]) <= limit[i] if self.model == "bilinear" else abs(d0[i]) < limit[i]
            if not inside:
                out.append((f"x0[{i + 1}]", f"the initial drift of storey {i + 1} (x0) is {float(d0[i])!r} m, beyond its "
                                            f"yield drift Fy[{i + 1}] / k[{i + 1}] = {dy[i]:.6g} m: the initial state must be elastic"))
        return out

    def check(self, stiffnesses, damping_ratio: float = 0.05, initial_drifts=None) -> None:
        """Raise ValueError with every problem (see :meth:`problems`)."""
        problems = self.problems(stiffnesses, damping_ratio, initial_drifts)
        if problems:
            raise ValueError("; ".join(problems))

    # -- derived quantities -------------------------------------------------------------------
    def yield_drift(self, stiffnesses) -> np.ndarray:
        """``dy = Fy / k`` per storey (m); inf for a linear building."""
        k = np.asarray(stiffnesses, dtype=float)
        if not self.inelastic:
            return np.full(k.size, np.inf)
        return self.yield_shear / k

    @property
    def ultimate_z(self) -> float:
        """Bouc-Wen bound of ``z``, ``(beta + gamma)^(-1/n)`` (-)."""
        return (self.bw_beta + self.bw_gamma) ** (-1.0 / self.bw_n)


# -- bilinear law (kinematic hardening), vectorised over storeys ------------------------------
def bilinear_plastic_force(k, fy, alpha, drift, slip, mode) -> np.ndarray:
    """Force ``q`` of the elastic-perfectly-plastic element (N) per storey."""
    elastic = (1.0 - alpha) * k * (drift - slip)
    return np.where(mode == 0, elastic, mode * (1.0 - alpha) * fy)


def bilinear_tangent(k, alpha, mode) -> np.ndarray:
    """Tangent storey stiffness (N/m): ``k`` elastic, ``alpha k`` yielding."""
    return np.where(mode == 0, k, alpha * k)


def bilinear_offset(k, fy, alpha, slip, mode) -> np.ndarray:
    """``V - kt d`` per storey (N): the constant part of the storey shear in a configuration."""
    return np.where(mode == 0, -(1.0 - alpha) * k * slip, mode * (1.0 - alpha) * fy)


def bilinear_strain_energy(k, alpha, drift, slip, mode, fy) -> float:
    """Stored energy (J): ``alpha k d^2 / 2 + q^2 / (2 (1 - alpha) k)`` summed over storeys."""
    q = bilinear_plastic_force(k, fy, alpha, drift, slip, mode)
    return float(np.sum(0.5 * alpha * k * drift * drift + 0.5 * q * q / ((1.0 - alpha) * k)))


# -- Bouc-Wen ---------------------------------------------------------------------------------
def bouc_wen_rate(z, drift_rate, dy, n, beta, gamma):
    """``z'`` (1/s) per storey: ``d' [1 - |z|^n (gamma + beta sgn(d' z))] / dy``."""
    zn = np.abs(z) ** n
    return drift_rate * (1.0 - zn * (gamma + beta * np.sign(drift_rate * z))) / dy


def bouc_wen_dissipation_rate(z, drift_rate, fy, alpha, n, beta, gamma):
    """Hysteretic dissipation rate (W) per storey, ``(1-alpha) Fy |z|^(n+1) |d'| (beta + gamma sgn(d' z))``."""
    return (1.0 - alpha) * fy * np.abs(z) ** (n + 1.0) * np.abs(drift_rate) * (
        beta + gamma * np.sign(drift_rate * z))
