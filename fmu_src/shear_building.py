"""Linear shear building: matrices, modes, damping and exact zero-order-hold stepping.

A shear building of ``n`` storeys is a chain of floor masses ``m[i]`` (floor 1 is the
lowest) joined by storey springs ``k[i]`` (storey ``i`` between floor ``i-1`` and floor
``i``; floor 0 is the ground).  Displacements ``u`` and velocities ``v`` are relative to the
ground, which accelerates with ``ag(t)``.  The equation of motion is (Chopra, *Dynamics of
Structures*, 4th ed., Sec. 9.4)

    M u'' + C u' + K u = -M 1 ag(t) + f(t)

with ``f`` the external floor forces (N, + along x), e.g. pounding.

Damping (``damping``):

* ``"rayleigh"``: ``C = a0 M + a1 K`` with the ratio ``damping_ratio`` realised exactly in
  mode 1 and mode ``min(2, n)`` (Chopra Eq. 11.4.9: ``a0 = 2 zeta w1 w2 / (w1 + w2)``,
  ``a1 = 2 zeta / (w1 + w2)``).  For ``n = 1`` both anchors are mode 1, the formula gives
  ``c = 2 zeta w1 m``.  Higher modes get more damping (stiffness-proportional part).
* ``"modal"``: every mode gets ``damping_ratio`` (Chopra Eq. 11.5.5,
  ``C = M Phi diag(2 zeta w_j) Phi' M`` with mass-normalised ``Phi``).

Time stepping (:class:`ZohPropagator`): for inputs ``ag`` and ``f`` held constant over a step
``[t, t + h]`` the state ``z = [u; v]`` obeys ``z' = A z + B w`` with ``w = [ag; f]``, whose
exact solution is ``z(t+h) = Ad z(t) + Bd w`` with ``[[Ad, Bd], [0, I]] = expm([[A, B], [0, 0]] h)``.
There is no truncation error: the only approximation is the hold of the inputs, which is
exact when the master feeds the step mean of a piecewise-linear record (velocity increments
are then exact) and the impulse-preserving mean contact force.

:class:`ModalZohPropagator` gives the same matrices from the classical modes (Rayleigh and modal
damping are classical) in closed form, without a matrix exponential: building.fmu's linear
step.  It is also the more accurate one on long steps of over-damped higher modes, where the
growing block of Van Loan's exponential cost :class:`ZohPropagator` digits (all of them at 8
storeys, Rayleigh zeta = 0.2, 80 times the fastest mode's 1/omega, measured against solve_ivp).

Energies (relative-motion formulation, Uang & Bertero 1990): over any interval

    E_input + E_external = dE_kinetic + dE_strain + E_damping

``E_input = -int v' M 1 ag dt`` (exact for constant ``ag``: ``-ag 1'M (u1 - u0)``),
``E_external = int v' f dt = f' (u1 - u0)``, ``E_damping = int v' C v dt`` (exact quadratic
integral of a linear system by Van Loan's block exponential: C. F. Van Loan, "Computing
integrals involving the matrix exponential", IEEE Trans. Automat. Contr. 23(3), 1978),
``E_kinetic = v' M v / 2`` and ``E_strain = u' K u / 2``.  Each term is computed on its own,
so the balance is an independent check of the propagator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.linalg import eigh, expm

DAMPING_MODELS = ("rayleigh", "modal")


def _as_vector(name: str, values) -> np.ndarray:
    arr = np.array(values, dtype=float).reshape(-1)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class ShearBuilding:
    """A linear shear building (see module docstring).

    Parameters
    ----------
    masses : sequence of float
        Floor masses (kg), floor 1 first; all > 0.
    stiffnesses : sequence of float
        Storey stiffnesses (N/m); ``stiffnesses[i-1]`` is storey ``i`` between floors ``i-1``
        and ``i``.  All > 0, except the *free mass*: one storey with ``k = 0`` and
        ``damping_ratio = 0`` (a rigid body, used for single-impact scenes).
    damping_ratio : float
        Viscous damping ratio (-), ``0 <= zeta < 1``.
    damping : {"rayleigh", "modal"}
        How ``damping_ratio`` is distributed over the modes.
    """

    masses: np.ndarray
    stiffnesses: np.ndarray
    damping_ratio: float = 0.05
    damping: str = "rayleigh"
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        m = _as_vector("masses", self.masses)
        k = _as_vector("stiffnesses", self.stiffnesses)
        object.__setattr__(self, "masses", m)
        object.__setattr__(self, "stiffnesses", k)
        object.__setattr__(self, "damping_ratio", float(self.damping_ratio))
        if m.size == 0:
            raise ValueError("a shear building needs at least one storey (masses is empty)")
        if k.size != m.size:
            raise ValueError(f"{m.size} masses but {k.size} stiffnesses: give one stiffness per storey")
        for i, mi in enumerate(m, start=1):
            if not (math.isfinite(mi) and mi > 0.0):
                raise ValueError(f"mass of floor {i}: m[{i}] = {float(mi)!r} kg, must be finite and > 0")
        for i, ki in enumerate(k, start=1):
            if not (math.isfinite(ki) and ki >= 0.0):
                raise ValueError(f"stiffness of storey {i}: k[{i}] = {float(ki)!r} N/m, must be finite and > 0")
        zeta = self.damping_ratio
        if not (math.isfinite(zeta) and 0.0 <= zeta < 1.0):
            raise ValueError(f"damping ratio zeta = {zeta!r} is outside the allowed range 0 <= zeta < 1")
        if self.damping not in DAMPING_MODELS:
            raise ValueError(f"damping = {self.damping!r} is not allowed: one of {', '.join(DAMPING_MODELS)}")
        if self.is_free_mass:
            if zeta != 0.0:
                raise ValueError(f"a free mass (1 storey, k[1] = 0) has no vibration mode to damp: "
                                 f"zeta = {zeta!r} must be 0")
        elif np.any(k == 0.0):
            i = int(np.flatnonzero(k == 0.0)[0]) + 1
            raise ValueError(f"stiffness of storey {i}: k[{i}] = 0 N/m makes the building a mechanism; "
                             f"k must be > 0 (only a 1-storey free mass may have k = 0)")

    # -- construction ----------------------------------------------------------------------------
    @classmethod
    def from_period(cls, T1: float, masses, stiffnesses, damping_ratio: float = 0.05,
                    damping: str = "rayleigh") -> "ShearBuilding":
        """Building whose stiffnesses are ``stiffnesses`` scaled so that the first period is ``T1`` (s).

        Only the stiffness *distribution* of ``stiffnesses`` matters (periods scale as
        ``1/sqrt(k)``), e.g. ``stiffnesses=[1, 1, 1]`` for a uniform building.
        """
        T1 = float(T1)
        if not (math.isfinite(T1) and T1 > 0.0):
            raise ValueError(f"fundamental period T1 = {T1!r} s must be finite and > 0")
        shape = cls(masses, stiffnesses, 0.0, damping)
        if shape.is_free_mass:
            raise ValueError("cannot scale a free mass (k[1] = 0) to a period T1: it has no stiffness")
        factor = (shape.periods[0] / T1) ** 2
        return cls(masses, shape.stiffnesses * factor, damping_ratio, damping)

    @classmethod
    def uniform(cls, n: int, mass: float, stiffness: float, damping_ratio: float = 0.05,
                damping: str = "rayleigh") -> "ShearBuilding":
        """``n`` equal floors and storeys."""
        if int(n) != n or n < 1:
            raise ValueError(f"number of storeys n = {n!r} must be an integer >= 1")
        return cls(np.full(int(n), mass), np.full(int(n), stiffness), damping_ratio, damping)

    # -- properties ------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of storeys."""
        return int(self.masses.size)

    @property
    def is_free_mass(self) -> bool:
        """True for the rigid one-storey body (k = 0) used in single-impact scenes."""
        return self.n == 1 and self.stiffnesses[0] == 0.0

    def _cached(self, key, make):
        if key not in self._cache:
            value = make()
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            self._cache[key] = value
        return self._cache[key]

    @property
    def M(self) -> np.ndarray:
        """Mass matrix (kg), diagonal."""
        return self._cached("M", lambda: np.diag(self.masses))

    @property
    def K(self) -> np.ndarray:
        """Stiffness matrix (N/m), tridiagonal."""
        def make():
            k = self.stiffnesses
            above = np.append(k[1:], 0.0)  # storey i+1 also bears on floor i
            return np.diag(k + above) - np.diag(k[1:], 1) - np.diag(k[1:], -1)
        return self._cached("K", make)

    @property
    def _modes(self):
        def make():
            w2, phi = eigh(self.K, self.M)  # phi' M phi = I
            w2 = np.clip(w2, 0.0, None)     # round-off on the free mass
            # Sign convention: the roof (top floor) component of each mode is positive.
            phi = phi * np.where(phi[-1] < 0.0, -1.0, 1.0)
            return np.sqrt(w2), phi
        return self._cached("modes", make)

    @property
    def omegas(self) -> np.ndarray:
        """Natural circular frequencies (rad/s), ascending."""
        return self._modes[0]

    @property
    def periods(self) -> np.ndarray:
        """Natural periods (s), descending (``inf`` for the free mass)."""
        with np.errstate(divide="ignore"):
            return 2.0 * np.pi / self.omegas

    @property
    def mode_shapes(self) -> np.ndarray:
        """Mass-normalised mode shapes (columns, ``Phi' M Phi = I``), roof component > 0."""
        return self._modes[1]

    @property
    def rayleigh_coefficients(self) -> tuple[float, float]:
        """``(a0, a1)`` of ``C = a0 M + a1 K`` for Rayleigh damping (1/s, s)."""
        w = self.omegas
        wi, wj = w[0], w[min(1, self.n - 1)]
        zeta = self.damping_ratio
        if wi + wj == 0.0:
            return 0.0, 0.0
        return 2.0 * zeta * wi * wj / (wi + wj), 2.0 * zeta / (wi + wj)

    @property
    def C(self) -> np.ndarray:
        """Damping matrix (N s/m)."""
        def make():
            if self.damping == "rayleigh":
                a0, a1 = self.rayleigh_coefficients
                return a0 * self.M + a1 * self.K
            w, phi = self._modes
            mphi = self.M @ phi
            return mphi @ np.diag(2.0 * self.damping_ratio * w) @ mphi.T
        return self._cached("C", make)

    @property
    def modal_damping_ratios(self) -> np.ndarray:
        """Damping ratio realised in each mode, ``phi_j' C phi_j / (2 w_j)`` (-)."""
        w, phi = self._modes
        c = np.einsum("ij,ik,kj->j", phi, self.C, phi)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(w > 0.0, c / (2.0 * w), 0.0)

    def kinetic_energy(self, v) -> float:
        """``v' M v / 2`` (J) with ``v`` the floor velocities relative to the ground (m/s)."""
        v = np.asarray(v, dtype=float)
        return 0.5 * float(v @ (self.masses * v))

    def strain_energy(self, u) -> float:
        """``u' K u / 2`` (J) with ``u`` the floor displacements relative to the ground (m)."""
        u = np.asarray(u, dtype=float)
        drift = np.diff(u, prepend=0.0)
        return 0.5 * float(self.stiffnesses @ (drift * drift))

    def drifts(self, u) -> np.ndarray:
        """Inter-storey drifts ``u[i] - u[i-1]`` (m), storey 1 first."""
        return np.diff(np.asarray(u, dtype=float), prepend=0.0)


def acceleration(building: ShearBuilding, u, v, ag: float, forces=None) -> np.ndarray:
    """Floor accelerations relative to the ground (m/s^2): ``M a = f - C v - K u - M 1 ag``.

    ``u`` (m), ``v`` (m/s) relative to the ground, ``ag`` ground acceleration (m/s^2),
    ``forces`` external floor forces (N) or None.
    """
    return absolute_acceleration(building, u, v, forces) - ag


def absolute_acceleration(building: ShearBuilding, u, v, forces=None) -> np.ndarray:
    """Absolute floor accelerations (m/s^2): ``M (a + 1 ag) = f - C v - K u`` (independent of ``ag``)."""
    r = -(building.C @ np.asarray(v, dtype=float)) - building.K @ np.asarray(u, dtype=float)
    if forces is not None:
        r = r + np.asarray(forces, dtype=float)
    return r / building.masses


@dataclass(frozen=True)
class StepResult:
    """State after one :meth:`ZohPropagator.step` and the energy increments of that step (J)."""

    u: np.ndarray
    v: np.ndarray
    E_input: float
    E_external: float
    E_damping: float


def _step_length(h) -> float:
    """``h`` (s) as a float, refused unless finite and > 0 (both propagators' one check)."""
    h = float(h)
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"step size h = {h!r} s must be finite and > 0")
    return h


class ZohPropagator:
    """Exact one-step map of a shear building for inputs held constant over a step ``h`` (s).

    Attributes
    ----------
    transition : (2n, 2n) array
        ``Ad = expm(A h)`` acting on ``z = [u; v]``.
    input_matrix : (2n, n+1) array
        ``Bd = int_0^h expm(A s) ds B`` acting on ``w = [ag; f]``.
    step_matrix : (2n, 3n+1) array
        ``[Ad, Bd]``, so that ``z1 = step_matrix @ [z0; w]``.
    damping_form : (3n+1, 3n+1) array
        Symmetric ``Q`` with ``int_0^h v' C v dt = y0' Q y0``, ``y0 = [z0; w]`` (Van Loan 1978).

    A propagator is immutable and tied to one step size: callers that vary the step (the
    adaptive master uses dyadic fractions of a base step) keep one per ``h`` in their own cache
    (see :class:`PropagatorCache`).
    """

    def __init__(self, building: ShearBuilding, h: float):
        h = _step_length(h)
        self.building = building
        self.h = h
        n = building.n
        minv = 1.0 / building.masses
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -minv[:, None] * building.K
        A[n:, n:] = -minv[:, None] * building.C
        B = np.zeros((2 * n, n + 1))
        B[n:, 0] = -1.0                  # -1 ag (relative formulation)
        B[n:, 1:] = np.diag(minv)        # M^-1 f
        # Augmented autonomous system y = [z; w], y' = F y (w constant).
        size = 3 * n + 1
        F = np.zeros((size, size))
        F[:2 * n, :2 * n] = A
        F[:2 * n, 2 * n:] = B
        # Van Loan: expm([[-F', Q], [0, F]] h) = [[., G12], [0, G22]], int_0^h e^{F't} Q e^{Ft} dt = G22' G12.
        Q = np.zeros((size, size))
        Q[n:2 * n, n:2 * n] = building.C
        big = np.zeros((2 * size, 2 * size))
        big[:size, :size] = -F.T
        big[:size, size:] = Q
        big[size:, size:] = F
        G = expm(big * h)
        eFh = G[size:, size:]
        form = eFh.T @ G[:size, size:]
        self.damping_form = 0.5 * (form + form.T)
        self.step_matrix = np.ascontiguousarray(eFh[:2 * n, :])
        self.transition = self.step_matrix[:, :2 * n]
        self.input_matrix = self.step_matrix[:, 2 * n:]
        for arr in (self.damping_form, self.step_matrix):
            arr.setflags(write=False)

    def step(self, u, v, ag: float = 0.0, forces=None) -> StepResult:
        """Advance ``(u, v)`` by ``h`` with ``ag`` (m/s^2) and ``forces`` (N) held constant."""
        n = self.building.n
        y = np.empty(3 * n + 1)
        y[:n] = u
        y[n:2 * n] = v
        y[2 * n] = ag
        y[2 * n + 1:] = 0.0 if forces is None else forces
        z1 = self.step_matrix @ y
        du = z1[:n] - y[:n]
        f = y[2 * n + 1:]
        return StepResult(
            u=z1[:n], v=z1[n:],
            E_input=-float(ag) * float(self.building.masses @ du),
            E_external=float(f @ du),
            E_damping=float(y @ self.damping_form @ y),
        )


# Gauss-Legendre quadrature of ModalZohPropagator's integrals: 10 points per chunk, chunks no
# longer than 2 / (the fastest modal rate), as linear_response's energy quadrature (its module
# docstring bounds the truncation error below 1e-18 relative: exact to round-off)
_ZOH_GAUSS_POINTS = 10
_ZOH_CHUNK_RATE = 2.0
MAX_ZOH_CHUNKS = 4096        # a longer step takes ZohPropagator (expm, no quadrature)
_GX, _GW = np.polynomial.legendre.leggauss(_ZOH_GAUSS_POINTS)


def _oscillator_functions(omega: np.ndarray, sigma: np.ndarray, t: np.ndarray):
    """``(x_q, x_v, v_q, v_v)`` at times ``t`` (s) for modes of circular frequency ``omega``
    (rad/s) and decay rate ``sigma = zeta omega`` (1/s) (arrays broadcast together): the free
    response ``q(t) = x_q q0 + x_v q0'``, ``q'(t) = v_q q0 + v_v q0'`` of ``q'' + 2 sigma q' +
    omega^2 q = 0``, in every regime without cancellation between large terms:

    * under-damped (``omega_d^2 = omega^2 - sigma^2 > 0``): ``e^{-sigma t}`` times ``cos`` and
      ``sin(omega_d t) / omega_d``;
    * ``kappa t < 1`` with ``kappa^2 = sigma^2 - omega^2 >= 0`` (critical or near it): ``cosh`` and
      ``sinh(kappa t) / kappa`` (``t`` at ``kappa = 0``);
    * over-damped with ``kappa t >= 1``: the two real roots ``r1 = -omega^2 / (sigma + kappa)``
      (the slow one, written without the cancellation of ``-sigma + kappa``) and ``r2 = -(sigma +
      kappa)``, each exponential on its own (``cosh`` would overflow where ``e^{-sigma t}``
      underflows).
    """
    w2 = omega * omega
    d2 = w2 - sigma * sigma                      # omega_d^2; < 0 over-damped
    wd = np.sqrt(np.abs(d2))
    decay = np.exp(-sigma * t)
    arg = wd * t
    under = d2 > 0.0
    if under.all():
        # every mode under-damped (every building of the bundled scenes): the first regime alone,
        # the same values as the general path below without its selections
        es = decay * (np.sin(arg) / wd)
        ec = decay * np.cos(arg)
        return ec + sigma * es, es, -w2 * es, ec - sigma * es
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        c = np.where(under, np.cos(arg), np.cosh(np.minimum(arg, 1.0)))
        s = np.where(wd > 0.0, np.where(under, np.sin(arg), np.sinh(np.minimum(arg, 1.0))) / wd, t)
        es = decay * s                           # e^{-sigma t} s(t): the impulse response
        ec = decay * c
        far = ~under & (arg >= 1.0)
        if np.any(far):
            r1 = -w2 / (sigma + wd)
            r2 = -(sigma + wd)
            e1, e2 = np.exp(r1 * t), np.exp(r2 * t)
            es = np.where(far, (e1 - e2) / (2.0 * wd), es)
            ec = np.where(far, 0.5 * (e1 + e2), ec)
            # x(0) = 1, x'(0) = 0: (sigma + kappa) / (2 kappa) e1 + r1 / (2 kappa) e2
            xq_far = ((sigma + wd) * e1 + r1 * e2) / (2.0 * wd)
            vv_far = (r1 * e1 - r2 * e2) / (2.0 * wd)
        else:
            xq_far = vv_far = None
    x_q = ec + sigma * es
    v_v = ec - sigma * es
    if xq_far is not None:
        x_q = np.where(far, xq_far, x_q)
        v_v = np.where(far, vv_far, v_v)
    return x_q, es, -w2 * es, v_v


def _modal_zoh_parts(building: ShearBuilding):
    """What :class:`ModalZohPropagator` needs of a building whatever the step length, made once
    per building (a run meets a dozen lengths): ``(sigma, rate, T)``, the modal decay rates
    (1/s), a rate at least every root's modulus (1/s), and ``T[j]`` the rows giving mode j's
    ``(q0, q0', P)`` from ``y = [u0; v0; ag; f]``."""
    n = building.n
    m = building.masses
    omega, phi = building.omegas, building.mode_shapes
    sigma = 0.5 * np.einsum("ij,ik,kj->j", phi, building.C, phi)        # diag(Phi' C Phi) / 2
    rate = float(np.max(np.maximum(omega, 2.0 * sigma))) if n else 0.0  # >= every |root|
    # modal coordinates of y = [u0; v0; ag; f]: T[j] = rows (q0_j, q0'_j, P_j)
    mphi = phi * m[:, None]                                   # M Phi
    size = 3 * n + 1
    T = np.zeros((n, 3, size))
    T[:, 0, :n] = mphi.T
    T[:, 1, n:2 * n] = mphi.T
    T[:, 2, 2 * n] = -(mphi.sum(axis=0))                      # Phi' (-M 1)
    T[:, 2, 2 * n + 1:] = phi.T
    for arr in (sigma, T):
        arr.setflags(write=False)
    return sigma, rate, T


class ModalZohPropagator:
    """:class:`ZohPropagator`'s matrices (``step_matrix``, ``damping_form``, ``transition``,
    ``input_matrix``; the same meaning) from the building's classical modes, without a matrix
    exponential: a new step length costs a few vector operations on ``n`` modes.

    Rayleigh and modal damping are classical (``Phi' C Phi = diag(2 sigma_j)``), so every mode is
    a damped oscillator ``q'' + 2 sigma q' + omega^2 q = P`` with ``q0 = Phi' M u0``, ``q0' = Phi'
    M v0`` and the held modal force ``P = Phi' (f - M 1 ag)``; its free response is closed-form
    (:func:`_oscillator_functions`), its response to ``P`` is ``q' = g'(t) P`` with ``g'`` the
    impulse response and ``g(h) = int_0^h g'``; ``E_damping = int v' C v = sum_j 2 sigma_j int
    q_j'^2``, a 3 x 3 form per mode in ``(q0, q0', P)``.  The two integrals are Gauss-Legendre
    quadratures of the closed forms (exact to round-off, see ``_ZOH_CHUNK_RATE``).  Tested
    against the block exponential (tests/test_shear_building.py).
    """

    def __init__(self, building: ShearBuilding, h: float):
        h = _step_length(h)
        self.building = building
        self.h = h
        n = building.n
        omega, phi = building.omegas, building.mode_shapes
        sigma, rate, T = building._cached("modal_zoh", lambda: _modal_zoh_parts(building))
        chunks = max(1, int(math.ceil(rate * h / _ZOH_CHUNK_RATE)))
        if chunks > MAX_ZOH_CHUNKS:
            raise ValueError(f"a step of {h!r} s spans {chunks} quadrature chunks of the fastest mode; "
                             f"the limit is {MAX_ZOH_CHUNKS}")
        width = h / chunks
        half = 0.5 * width
        # the end of the step and the nodes, every mode at once: (n, 1 + K)
        times = np.empty(1 + chunks * _ZOH_GAUSS_POINTS)
        times[0] = h
        if chunks == 1:               # (most steps: no tiling of the nodes over chunks)
            times[1:] = half * (_GX + 1.0)
            weights = half * _GW
        else:
            times[1:] = ((width * np.arange(chunks))[:, None] + half * (_GX + 1.0)[None, :]).ravel()
            weights = np.tile(half * _GW, chunks)
        x_q, x_v, v_q, v_v = _oscillator_functions(omega[:, None], sigma[:, None], times[None, :])
        size = 3 * n + 1
        # q(h) = x_q q0 + x_v q0' + g P; q'(h) = v_q q0 + v_v q0' + g'(h) P, with g = int_0^h g'(t)
        # dt: one (2, n, 3) array of both ends' coefficients, one product for both halves of the step
        ends = np.empty((2, n, 3))
        ends[0, :, 0] = x_q[:, 0]
        ends[0, :, 1] = x_v[:, 0]
        ends[0, :, 2] = x_v[:, 1:] @ weights
        ends[1, :, 0] = v_q[:, 0]
        ends[1, :, 1] = v_v[:, 0]
        ends[1, :, 2] = x_v[:, 0]
        step = (phi @ np.einsum("kja,jas->kjs", ends, T)).reshape(2 * n, size)
        # int q_j'^2 = [q0, q0', P] G_j [q0, q0', P]' with G_j = sum_k w_k r_k r_k', r = (v_q, v_v, g')
        rows = np.empty((n, 3, times.size - 1))
        rows[:, 0] = v_q[:, 1:]
        rows[:, 1] = v_v[:, 1:]
        rows[:, 2] = x_v[:, 1:]
        gram = np.einsum("jak,jbk,k->jab", rows, rows, weights) * (2.0 * sigma)[:, None, None]
        form = T.reshape(3 * n, size).T @ np.einsum("jab,jbs->jas", gram, T).reshape(3 * n, size)
        self.damping_form = 0.5 * (form + form.T)
        self.step_matrix = np.ascontiguousarray(step)
        self.transition = self.step_matrix[:, :2 * n]
        self.input_matrix = self.step_matrix[:, 2 * n:]
        for arr in (self.damping_form, self.step_matrix):
            arr.setflags(write=False)

    step = ZohPropagator.step


class PropagatorCache:
    """Per-instance cache of :class:`ZohPropagator` by step size (no module-level state).

    ``maxsize`` bounds the memory when a master uses many different step sizes; the oldest
    entry is dropped first.
    """

    def __init__(self, building: ShearBuilding, maxsize: int = 64):
        self.building = building
        self.maxsize = int(maxsize)
        self._by_step: dict[float, ZohPropagator] = {}
        self.builds = 0  # cost counter: number of matrix exponentials computed

    def __call__(self, h: float) -> ZohPropagator:
        prop = self._by_step.get(h)
        if prop is None:
            if len(self._by_step) >= self.maxsize:
                self._by_step.pop(next(iter(self._by_step)))
            prop = self._by_step[h] = ZohPropagator(self.building, h)
            self.builds += 1
        return prop

    def __len__(self) -> int:
        return len(self._by_step)
