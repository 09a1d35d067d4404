"""Proof that a gap stays open: how far the floors can move over a step, from the buildings' modes.

The adaptive master takes a long step only where every gap provably stays open, and leaves a
contact FMU dormant over a step only where its gap provably stays open
(:mod:`cosim.master.coupling.adaptive`, :mod:`cosim.master.dormancy`).  The proof is a bound on
the penetration ``delta(t + s) = u_L(t + s) - u_R(t + s) - gap`` of each contact level over
``0 <= s <= H``, from the buildings' states at ``t`` and a bound on what drives them over the step.

A linear shear building with classical damping (Rayleigh ``C = a0 M + a1 K`` or modal damping
are both classical) decouples into modes ``q = Phi' M u`` (mass-normalised ``Phi``)::

    q_j'' + 2 zeta_j w_j q_j' + w_j^2 q_j = p_j(t),   p_j = -Gamma_j ag(t) + phi_j' F,   Gamma_j = phi_j' M 1

so a floor's displacement over the step is ``u_f(t + s) = sum_j Phi_fj (q_j_free(s) + q_j_forced(s))``:

* ``q_j_free(s)``, the damped free motion from ``q_j(t), q_j'(t)``, is known exactly;
* ``|q_j_forced(s)| <= P_j G_j(s)`` with ``P_j >= max |p_j|`` over the step and
  ``G_j(s) = int_0^s min(r, 1 / w_j) dr``: the impulse response ``h_j`` starts at 0 with unit
  slope (``|h_j(r)| <= r``) and never holds more than the energy of a unit impulse
  (``(h_j'^2 + w_j^2 h_j^2) / 2 <= 1/2`` under any damping ``>= 0``, so ``|h_j| <= 1 / w_j``).

Hence ``delta(t + s) <= delta_free(s) + B(s)`` with ``B`` the two buildings' forced bounds
(increasing in ``s``).  The free part is checked on a grid of ``N`` intervals; between grid
points it cannot exceed the mean of its end values by more than ``L dS / 2``, ``L`` a bound on
its rate (the free modal energy never grows: ``|q_j_free'| <= sqrt(w_j^2 q_j^2 + q_j'^2)``).
The ground acceleration's bound is the largest ``|ag|`` of the record's polyline up to each
grid point (the ground FMU's knots, :mod:`cosim.master.knots`); a contact force held over the
step enters as ``|phi_j' F|``.

Yielding storeys (bilinear, kinematic hardening: :mod:`fmu_src.hysteresis`).  A storey whose
elastic element does not yield, ``|d - s| < dy`` with its slip ``s`` fixed, has the shear
``V = k d - (1 - alpha) k s``: the building is the linear one (initial stiffness ``K``, the
same classical damping) loaded by the constant floor forces ``D' (1 - alpha) k s``.  Their
static response ``u_s`` has the storey drifts ``D u_s = (1 - alpha) s``, the residual drifts
``r`` the building FMU publishes (``drift_residual``), so ``u_s = cumsum(r)`` and ``w = u - u_s``
moves as the linear building does.  The proof bounds ``w`` as above and, with the same modal
bound on the drifts ``D w = D Phi q``, proves that every storey stays elastic over the horizon:
``|w_i - alpha s_i| < dy_i`` (since ``d - s = w - alpha s``), with a margin (:data:`ELASTIC_MARGIN`)
that excludes a storey yielding now (``|d - s| = dy``).  A horizon is then the shorter of the
gaps' and the storeys': over it the building *is* linear and its floors' bound holds.

Through yielding (:meth:`ModalBound.through_yielding`).  Whatever a bilinear storey does, its
shear is ``V = alpha k d + rho`` with ``rho = (1 - alpha) k (d - s)``, the force of its
elastic-perfectly-plastic element, and ``|rho| <= (1 - alpha) Fy``: building.fmu keeps ``|d -
s| <= dy`` (an elastic storey leaves that range only through a located yield event, after
which ``d - s = mode dy`` while it yields; unloading restarts it from the limit), so ``rho``
is bounded by the element's strength (``tests/test_gap_bound_yielding.py`` checks both on the
integrator's motion and on an independent return-mapping of the law).  With ``D' K_s D = K``
the floors obey the *linear* building::

    M u'' + C u' + alpha K u = -M 1 ag + F - D' rho(t),     |rho_i(t)| <= (1 - alpha) Fy_i

``alpha K`` has the modes of ``K`` (``w_j sqrt(alpha)``) and ``C``, Rayleigh or modal on the
initial stiffness, is still diagonal in them (``c_j = phi_j' C phi_j``, a ratio ``c_j / (2 w_j
sqrt(alpha))`` that may exceed 1: the free motion has the overdamped branch; ``alpha = 0``
leaves damped masses, ``q = q0 + q0' (1 - exp(-c s)) / c``).  The free motion from ``u, v`` is
again exact and the rest is a response to bounded loads: floor ``f`` moves by ``int_0^s
K_f(s - r) ag(r) dr + sum_i int_0^s H_fi(s - r) rho_i(r) dr`` (and the held force, bounded as
above), with the impulse responses ``K_f = sum_j Phi_fj Gamma_j h_j`` and ``H_fi = sum_j Phi_fj
(D phi_j)_i h_j`` (``h_j`` mode j's, of this building), so::

    |forced_f(s)| <= max|ag| over [0, s] int_0^s |K_f| + sum_i (1 - alpha) Fy_i int_0^s |H_fi|

These integrals of each floor's own response are far tighter than the sum over modes of
``|Phi_fj Gamma_j| G_j`` (the modes' early responses cancel: ``sum_j Phi_fj (D phi_j)_i`` is
``(M^-1 D')_fi``, zero but for the storeys next to the floor); they are bounded from above on a
sub-grid (:meth:`ModalBound._kernel_integrals`) and capped by the modal sums.  The bound holds
whatever the storeys do, so a level's proof takes, on each grid interval and for each floor,
the tighter of the two bounds that hold there: the linear one while the building is proven
linear, the one through yielding always (:meth:`OpenGaps._through_yielding`, computed only
for levels that the linear proof leaves short).  Bouc-Wen storeys (``V = alpha k d + (1 -
alpha) Fy z``) have no elastic range, but the same bound through yielding: ``|z| <= z_u =
(beta + gamma)^(-1/n)`` (:mod:`fmu_src.hysteresis`; from an initial ``|z| < z_u``, which the
FMU demands, ``z' = 0`` at ``|z| = z_u`` while loading and ``|z|`` falls while unloading), so
``|rho| <= (1 - alpha) Fy z_u``; their proof is that one alone.
"""
from __future__ import annotations

import functools
import math
from typing import Sequence

import numpy as np

from fmu_src.shear_building import ShearBuilding

#: grid intervals over a horizon: with relative speeds of ~0.5 m/s and a 0.32 s horizon the
#: free motion's slack between grid points is ~1 mm, a few % of a building gap
GRID = 64
#: a storey is proven elastic while ``|d - s| <= (1 - ELASTIC_MARGIN) dy``: a yielding storey sits
#: at ``|d - s| = dy`` to round-off (~1e-16 dy: the master reads ``s`` through ``drift_residual``),
#: which this margin refuses; it costs 1e-6 of the elastic range
ELASTIC_MARGIN = 1e-6
#: a storey is taken as yielding now, without a proof, when its drift lies this fraction of its yield
#: drift beyond the elastic range (a yielding storey lies ELASTIC_MARGIN beyond it; the drift's
#: round-off, ~1e-15 of the floor displacements, is far below 1e-9 of a yield drift)
YIELDING_SLACK = 1e-9
#: the storey force bound of a yielding building is widened by this fraction:
#: ``|q| = (1 - alpha) k |d - s|`` may pass ``(1 - alpha) Fy`` by the overshoot of a located yield
#: event (building.fmu locates it to 1e-12 of the step: ``|d'| 1e-12 h``, below 1e-9 of a yield
#: drift) and by the round-off of ``d - s`` (~1e-15 of the drifts)
PLASTIC_MARGIN = 1e-6
#: sub-intervals per grid interval of the impulse-response integrals of a proof through yielding
#: (:meth:`ModalBound._kernel_integrals`): their tent slack is at most ``L dt^2 / 4`` per piece,
#: 0.1 % of ``int |K|`` at 8, measured (computed once per horizon)
KERNEL_SUBDIVISION = 8
#: an overdamped mode's ``cosh(ws s)`` is evaluated as such below this argument (far from overflow)
_COSH_SAFE = 300.0
#: a Bouc-Wen storey's ``|z|`` is taken as at most ``z_u`` widened by this fraction: ``z_u`` is the
#: exact solution's bound (``z' = 0`` there while loading, ``|z|`` falls while unloading), and
#: building.fmu's Runge-Kutta integrator (rtol 1e-8) stays within 1e-8 of it (measured: at most
#: ``z_u`` to round-off under El Centro at 0.4 g, n = 1 to 10)
BOUC_WEN_Z_MARGIN = 1e-4
#: absolute slack (m) on a gap proven with the ground's exact response (:class:`_ExactPair`): the
#: computed motion's round-off (closed forms cancel to ~1e-11 of a ramp response over one grid
#: interval, ~1e-13 m; the FMU's own to ~1e-15 of the displacements) stays below it for modes up
#: to 10 s at 20 % damping (1.6e-10 m, tests/test_gap_bound_fuzz.py). The ramp's closed form loses
#: digits as zeta / w^3: 3e-9 m at T = 30 s, 1.5e-7 m at T1_MAX = 100 s (measured), above this
#: margin but ~1e3 times below the rate slack every proof adds (mm), which is what keeps such
#: slow buildings' proofs sound up to T1_MAX. Periods set through small stiffnesses (T1 = 0) are not
#: bounded: far beyond 100 s this margin would want to scale with the slowest mode (known limit)
EXACT_MARGIN = 1e-9
#: absolute slack (m) below zero that the coarse bound of a level's penetration over a whole horizon
#: (:meth:`_LinearPair.open_throughout`) must keep before the proof on the grid is skipped: that
#: proof's bound lies under the coarse one in exact arithmetic, and their round-off (~1e-15 of the
#: floors' displacements, ~1e-16 m) is far below this
COARSE_MARGIN = 1e-9
#: linear buildings' proofs compute the ground's response (:class:`_ExactPair`) where the ground
#: motion ahead is known (:class:`GroundAhead`) and every mode has stiffness
EXACT_GROUND = True
#: shorter horizons (s) keep the bound of the whole ground: over a few hundredths of a second it
#: is nearly as tight, and cheaper (the held forces' one-step proofs of kasai_maison, 0.01 s).
#: Measured: default 411 -> 411 steps, kasai_maison 415 -> 416 against exact proofs everywhere
EXACT_MIN_HORIZON = 0.04
#: relative round-off (of the largest |ag|) added to the part of the ground a proof bounds
#: (:meth:`GroundAhead.on_grid`): the chord through the grid values is computed to a few ulps
GROUND_ROUNDOFF = 1e-12
#: level groupings :meth:`OpenGaps._pairs` keeps (subsets of the levels a run asks for)
_PAIRS_KEPT = 256
#: the grid's point numbers ``k`` (the grid is ``s_k = H k / GRID``, computed in that order)
_POINTS = np.arange(GRID + 1, dtype=float)
_ZERO = np.zeros(1)
#: ``ndarray.all/any`` without their Python wrappers (a proof makes a few dozen small numpy calls:
#: their overhead is its cost)
_ALL, _ANY, _AND, _MAX = np.logical_and.reduce, np.logical_or.reduce, np.logical_and, np.maximum
#: ``_ANY`` of each part of an array's rows, in one call (``_ANY_EACH(a, starts)``: the parts
#: begin at ``starts``)
_ANY_EACH = np.logical_or.reduceat
#: ``np.cumsum`` of a vector without its Python wrapper
_SUM_UP = np.add.accumulate
try:    # np.interp's compiled core, without its Python wrapper (which only dispatches on complex values)
    from numpy._core.multiarray import interp as _interp
except ImportError:     # pragma: no cover - numpy < 2
    _interp = np.interp


class ModalBound:
    """A linear building's modes, for bounding its floors' motion over a step (module docstring).

    ``stiffness_factor`` and ``plastic_shear`` make the bound of a yielding building
    (:meth:`through_yielding`): the stiffness ``stiffness_factor K`` with the damping ``C`` of
    the building (the same modes, ``w_j sqrt(factor)``), loaded besides by storey forces of at
    most ``plastic_shear`` (N, per storey) in size, whatever their history."""

    def __init__(self, building: ShearBuilding, stiffness_factor: float = 1.0,
                 plastic_shear: np.ndarray | None = None):
        phi = np.asarray(building.mode_shapes, dtype=float)
        w = np.asarray(building.omegas, dtype=float)
        if stiffness_factor != 1.0:
            w = w * math.sqrt(stiffness_factor)
        masses = np.asarray(building.masses, dtype=float)
        modal_c = phi.T @ building.C @ phi
        off = modal_c - np.diag(np.diag(modal_c))
        if np.max(np.abs(off), initial=0.0) > 1e-9 * max(np.max(np.abs(modal_c)), 1e-300):
            raise ValueError("damping is not classical: the modes do not decouple")
        self.n = w.size
        self.phi = phi
        self.to_modal = phi.T * masses            # q = to_modal @ u
        self.gamma = phi.T @ masses               # Gamma_j = phi_j' M 1
        self.w = w
        c = np.diag(modal_c)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.zeta = np.where(w > 0.0, c / (2.0 * np.where(w > 0.0, w, 1.0)), 0.0)
        # zeta w = c / 2; a zero-stiffness mode (w = 0) keeps its damping c there: q'' + c q' = 0
        self.damping = np.where(w > 0.0, 0.0, np.maximum(c, 0.0))
        self.zeta_w = np.where(w > 0.0, self.zeta * self.w, 0.5 * self.damping)
        self.drift_phi = phi.copy()                # storey drifts d = D u: D Phi
        self.drift_phi[1:] -= phi[:-1]
        self.abs_phi = np.abs(phi)
        self.abs_drift_phi = np.abs(self.drift_phi)
        self.rows = np.vstack((phi, self.drift_phi))     # floors then storey drifts, in one product
        self.abs_rows = np.abs(self.rows)
        # the bound on each mode's share of the storey forces D' rho, |rho_i| <= plastic_shear_i:
        # sum_i |(D phi_j)_i| plastic_shear_i (N per unit modal mass, m/s^2 in modal units)
        self.plastic_shear = None if plastic_shear is None else np.asarray(plastic_shear, dtype=float)
        self.plastic = None if plastic_shear is None else self.abs_drift_phi.T @ self.plastic_shear
        self._tables: dict[float, tuple[np.ndarray, ...]] = {}
        self._ground_kernels: dict[float, tuple] = {}       # H -> the closed forms (_exact_tables)
        self._full_kernels: dict[float, np.ndarray] = {}    # H -> ground_kernels
        self._kernel_columns: dict[float, tuple] = {}       # H -> floor_kernel_columns

    @classmethod
    def through_yielding(cls, building: ShearBuilding, alpha: float, yield_shear) -> "ModalBound":
        """The bound of a bilinear building (kinematic hardening, :mod:`fmu_src.hysteresis`) that
        holds whatever its storeys do: ``V = alpha k d + rho`` with ``|rho| <= (1 - alpha) Fy``
        (module docstring, *Through yielding*), widened by :data:`PLASTIC_MARGIN`."""
        plastic = (1.0 - float(alpha)) * np.asarray(yield_shear, dtype=float) * (1.0 + PLASTIC_MARGIN)
        return cls(building, float(alpha), plastic)

    def _free_tables(self, s: np.ndarray, impulse_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(Ac, As)`` at the times ``s`` (modes x points): the free motion is ``Ac q0 + As (q0' +
        zeta w q0)``; ``As`` is each mode's unit impulse response ``h_j(s)`` (``impulse_only``: the
        underdamped modes' ``Ac`` is not computed, left at 1)."""
        Ac = np.ones((self.n, s.size))
        As = np.tile(s, (self.n, 1))
        # the underdamped modes (every mode of a linear building) at once, one call each for all
        # of them; the loop below takes the others (zero stiffness, overdamped, critical)
        under = np.flatnonzero((self.w > 0.0) & (self.zeta < 1.0))
        if under.size:
            w, z = self.w[under], self.zeta[under]
            decay = np.exp((-z * w)[:, None] * s)
            wd = (w * np.sqrt(1.0 - z * z))[:, None]
            if not impulse_only:
                Ac[under] = decay * np.cos(wd * s)
            As[under] = decay * np.sin(wd * s) / wd
        if under.size == self.n:                   # every mode underdamped: nothing left below
            return Ac, As
        for j in range(self.n):
            wj, zj = self.w[j], self.zeta[j]
            if wj > 0.0 and zj < 1.0:
                continue                           # above
            if wj == 0.0:
                cj = self.damping[j]
                if cj > 0.0:                       # q'' + c q' = 0: q = q0 + q0' (1 - exp(-c s)) / c
                    As[j] = -np.expm1(-cj * s) / cj
                    Ac[j] = 1.0 - self.zeta_w[j] * As[j]
                continue                           # undamped, a free mass: q = q0 + q0' s
            decay = np.exp(-zj * wj * s)
            if zj > 1.0:
                ws = wj * math.sqrt(zj * zj - 1.0)
                if ws * s[-1] < _COSH_SAFE:
                    Ac[j] = decay * np.cosh(ws * s)
                    As[j] = decay * np.sinh(ws * s) / ws
                else:                              # cosh would overflow: the two exponentials
                    slow, fast = np.exp((ws - zj * wj) * s), np.exp(-(ws + zj * wj) * s)
                    Ac[j] = 0.5 * (slow + fast)
                    As[j] = 0.5 * (slow - fast) / ws
            else:
                Ac[j] = decay
                As[j] = decay * s
        return Ac, As

    # -- the free motion and the forced bound on a grid of s = H k / GRID ------------------------------
    def _cached(self, H: float) -> tuple[np.ndarray, ...]:
        """``(s, Ac, As, G, ...)`` on ``s_k = H k / GRID``, cached per ``H``: ``q_free = Ac q0 + As
        (q0' + zeta w q0)`` and ``G_j(s_k)`` (modes x points), then what the forced bound of a
        unit ground acceleration is on every floor, ``sum_j |Phi_fj Gamma_j| G_j(s_k)`` (floors x
        points), and on every floor then every storey drift (:attr:`rows`): a proof scales them by its ground bound
        (a run's proofs use a few horizons only: computed once per horizon, not per proof).  A
        bound through yielding (:attr:`plastic` set) has its floors' ground bound from their
        impulse responses where tighter, and last the storey forces' bound on every floor
        (floors x points; None otherwise)."""
        cached = self._tables.get(H)
        if cached is not None:
            return cached
        s = H * _POINTS / GRID
        Ac, As = self._free_tables(s)
        G = np.tile(0.5 * s * s, (self.n, 1))     # |h| <= r: an undamped free mass has no other bound
        # beyond r = 1/w, |h| <= 1/w; a damped free mass: h = (1 - exp(-c r)) / c <= 1/c (every
        # mode at once: the same elementwise operations as mode by mode)
        rate = np.where(self.w > 0.0, self.w, self.damping)
        bounded = np.flatnonzero(rate > 0.0)
        if bounded.size:
            knee = (1.0 / rate[bounded])[:, None]
            G[bounded] = np.where(s <= knee, 0.5 * s * s, 0.5 * knee * knee + (s - knee) * knee)
        if len(self._tables) > 64:                # a bounded number of distinct step lengths
            self._tables.pop(next(iter(self._tables)))
        gamma = np.abs(self.gamma)
        floors_ground = (self.abs_phi * gamma) @ G
        plastic = None
        if self.plastic is not None:
            # through yielding: each floor's response to the ground and to every storey force
            # bounded by the integral of its own impulse response, not mode by mode
            n = self.n
            ground_kernel, storey_kernels = self._kernel_integrals(H, np.vstack((
                self.phi * self.gamma, (self.phi[:, None, :] * self.drift_phi[None, :, :]).reshape(n * n, n))))
            floors_ground = np.minimum(floors_ground, ground_kernel[:n])
            plastic = np.minimum((self.abs_phi * self.plastic) @ G,
                                 np.einsum("fik,i->fk", storey_kernels.reshape(n, n, -1), self.plastic_shear))
        out = self._tables[H] = (s, Ac, As, G, floors_ground, (self.abs_rows * gamma) @ G, plastic)
        return out

    def step_response(self, H: float) -> np.ndarray:
        """Each mode's displacement from rest under a unit modal load held from ``s = 0`` on the
        grid ``s_k = H k / GRID`` (modes x points): ``S = (1 - Ac - zeta w As) / w^2`` (the static
        displacement less the free motion that starts from it).  Only where every mode has
        stiffness (:meth:`ground_kernels`)."""
        return self._exact_tables(H)[0]

    def ground_kernels(self, H: float) -> np.ndarray:
        """Each mode's exact displacement from rest at every grid point ``s_k = H k / GRID`` under
        a ground acceleration linear between the grid points (*Exact ground response*,
        :class:`_ExactPair`): ``K`` (modes x points x points) with ``K @ g`` the modal
        displacements for the grid values ``g`` (m/s^2).  Only where every mode has stiffness.
        Cached per ``H``.

        Built from closed forms of each mode's response to a unit step, ``S`` (:meth:`step_response`),
        and to a unit ramp, ``R = (s - 2 zeta / w) / w^2 + 2 zeta / w^3 Ac + (2 zeta^2 - 1) / w^2
        As`` (the particular solution plus the free motion that starts it from rest), with the
        free motion's tables: a hat function on grid point ``i`` is ``(ramp(s - s_(i-1)) - 2
        ramp(s - s_i) + ramp(s - s_(i+1))) / dS``, the first grid point's half hat ``step(s) -
        (ramp(s) - ramp(s - dS)) / dS``."""
        kernels = self._full_kernels.get(H)
        if kernels is not None:
            return kernels
        _, full, half = self._exact_tables(H)
        k = np.arange(GRID + 1)
        d = k[:, None] - k[None, :]                  # k - i (points x points)
        kernels = np.where((d >= 0)[None], full[:, np.clip(d, 0, GRID)], 0.0)
        kernels[:, :, 0] = half
        kernels *= -self.gamma[:, None, None]        # modal load -Gamma_j ag
        if len(self._full_kernels) > 16:             # a bounded number of distinct horizons
            self._full_kernels.pop(next(iter(self._full_kernels)))
        self._full_kernels[H] = kernels
        return kernels

    def floor_kernels(self, H: float) -> np.ndarray:
        """:meth:`ground_kernels` on the floors, ``Phi K`` (floors x points x points)."""
        n = self.n
        return (self.phi @ self.ground_kernels(H).reshape(n, -1)).reshape(n, GRID + 1, GRID + 1)

    def floor_kernel_columns(self, H: float) -> tuple[np.ndarray, np.ndarray]:
        """``floor_kernels(H)[:, :, 0]`` and ``[:, :, 1]`` (floors x points): each floor's response
        to the first grid value's half hat and to the hat at point 1, which by lag ``k - 1`` is the
        response to every later hat (the kernels are Toeplitz there).  What :class:`_ExactPair`
        takes, from the closed forms without the full kernels (points times fewer products).
        Cached per ``H``."""
        columns = self._kernel_columns.get(H)
        if columns is not None:
            return columns
        _, full, half = self._exact_tables(H)
        scale = -self.gamma[:, None]                 # modal load -Gamma_j ag
        first = half * scale
        second = np.empty_like(first)
        second[:, 0] = 0.0                           # k - 1 < 0: before the hat
        second[:, 1:] = full[:, :GRID]               # lag d = k - 1
        second *= scale
        if len(self._kernel_columns) > 16:           # a bounded number of distinct horizons
            self._kernel_columns.pop(next(iter(self._kernel_columns)))
        columns = self._kernel_columns[H] = (self.phi @ first, self.phi @ second)
        return columns

    def _exact_tables(self, H: float) -> tuple:
        """``(S, full, half)`` at ``H`` (modes x points, :meth:`ground_kernels`): the step
        response, each mode's response to a hat at ``i >= 1`` by lag ``d = k - i``, and to the
        first grid value's half hat by point ``k`` (before the modal load's ``-Gamma_j``)."""
        tables = self._ground_kernels.get(H)
        if tables is not None:
            return tables
        if not np.all(self.w > 0.0):
            raise ValueError("a mode without stiffness has no static displacement: no exact ground response")
        cached = self._cached(H)
        s, Ac, As = cached[0], cached[1], cached[2]
        dS = H / GRID
        w = self.w[:, None]
        z = self.zeta[:, None]
        w2 = w * w
        S = (1.0 - Ac - self.zeta_w[:, None] * As) / w2
        R = (s - 2.0 * z / w) / w2 + (2.0 * z / (w2 * w)) * Ac + ((2.0 * z * z - 1.0) / w2) * As
        R[:, 0] = 0.0                                # exactly 0 at s = 0 (round-off of the closed form)
        n = self.n
        padded = np.concatenate((np.zeros((n, 1)), R, np.zeros((n, 1))), axis=1)   # padded[:, d + 1] = R(d)
        full = (padded[:, 2:] - 2.0 * padded[:, 1:-1] + padded[:, :-2]) / dS      # hat at i >= 1, by d = k - i
        full[:, -1] = 0.0                            # d = GRID would need R(GRID + 1); it does not occur
        half = S - (padded[:, 1:-1] - padded[:, :-2]) / dS                         # half hat at i = 0, by k
        if len(self._ground_kernels) > 16:           # a bounded number of distinct horizons
            self._ground_kernels.pop(next(iter(self._ground_kernels)))
        tables = self._ground_kernels[H] = (S, full, half)
        return tables

    def _kernel_integrals(self, H: float, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``int_0^s_k |K_r(t)| dt`` on the grid (rows x points) of the impulse responses
        ``K_r = sum_j weights_rj h_j`` (the response of row ``r`` to a unit impulse, as a sum of
        the modes'), split as ``(rows[:n], rows[n:])``.

        An upper bound, not a quadrature: on a sub-grid of :data:`KERNEL_SUBDIVISION` pieces per
        grid interval of width ``dt``, ``|K_r|`` lies under the tent ``min(a + L t, b + L (dt -
        t))`` of its end values ``a``, ``b`` with the slope bound ``L = sum_j |weights_rj|``
        (``|h_j'| <= 1``: the energy of a unit impulse never grows), whose area is
        ``dt (a + b) / 2 + (L^2 dt^2 - (a - b)^2) / (4 L)`` (exact where ``K`` is a line of slope
        ``L``, as at ``t = 0``)."""
        m = GRID * KERNEL_SUBDIVISION
        t = H * np.arange(m + 1, dtype=float) / m
        K = weights @ self._free_tables(t, impulse_only=True)[1]
        np.abs(K, out=K)
        dt = H / m
        slope = np.abs(weights).sum(axis=1)[:, None]
        pieces = K[:, :-1] + K[:, 1:]
        pieces *= 0.5 * dt
        step = K[:, 1:] - K[:, :-1]
        # the tent's excess over the chord; >= 0 (|a - b| <= L dt but for round-off); 0 if L = 0
        if _ALL(slope > 0.0):       # every row: the same numbers in place (no 0 / 0 to mask)
            step *= step
            np.subtract(slope * slope * dt * dt, step, out=step)
            step /= 4.0 * slope
            excess = np.maximum(step, 0.0, out=step)
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                excess = np.maximum(np.where(slope > 0.0, (slope * slope * dt * dt - step * step) / (4.0 * slope),
                                             0.0), 0.0)
        pieces += excess
        total = np.zeros((weights.shape[0], GRID + 1))
        total[:, 1:] = np.cumsum(pieces, axis=1)[:, KERNEL_SUBDIVISION - 1::KERNEL_SUBDIVISION]
        return total[:self.n], total[self.n:]

    def modal_state(self, u: np.ndarray, v: np.ndarray) -> list:
        """What a free motion needs from the floors' state, whatever the horizon: ``[q, q' +
        zeta w q]`` as columns (modal units), the bound ``sqrt(w_j^2 q_j^2 + q_j'^2)`` on each
        mode's free rate, and a slot for the rows' rate bound (:class:`FloorMotion` fills it)."""
        q = self.to_modal @ u
        qd = self.to_modal @ v
        return [q[:, None], (qd + self.zeta_w * q)[:, None], np.sqrt((self.w * q) ** 2 + qd * qd), None]


class FloorMotion:
    """One building's motion over a horizon ``H``, as the contact levels ask for it.

    Every floor (and, about a static ``shift``, every storey drift) is computed at once, on
    first use: one matrix product per part instead of one per floor and level."""

    def __init__(self, bound: ModalBound, u: np.ndarray, v: np.ndarray, H: float,
                 ground_bound: np.ndarray, force: np.ndarray | None, shift: np.ndarray | None = None,
                 about: np.ndarray | None = None, modal: list | None = None):
        """``ground_bound[k]`` (m/s^2) bounds ``|ag|`` over ``[0, s_k]``; ``force`` (N, per floor)
        is held over the horizon (None: no force); ``shift`` (m, per floor) the static
        displacement the modes move about (yielding storeys' slips, module docstring; None: 0);
        ``about``, if given, is ``u - shift`` already computed, ``modal`` what
        :meth:`ModalBound.modal_state` gave for it (the same numbers, not again)."""
        self.bound = bound
        self.shift = shift
        cached = bound._cached(H)
        if modal is None:
            w = u if shift is None else (u - shift if about is None else about)
            modal = bound.modal_state(w, v)
        self._modal = modal
        self.Q = cached[1] * modal[0] + cached[2] * modal[1]
        self.speed = modal[2]
        self.G = cached[3]
        self.ground = ground_bound
        # the rows computed: the floors, and the storey drifts about a shift
        if shift is None:
            self._rows, self._abs_rows, self._rows_ground = bound.phi, bound.abs_phi, cached[4]
        else:
            self._rows, self._abs_rows, self._rows_ground = bound.rows, bound.abs_rows, cached[5]
        self.modal_force = np.abs(bound.phi.T @ force) if force is not None and _ANY(force) else None
        # a yielding building's storey forces (ModalBound.through_yielding), on the floors only
        self._plastic = cached[6] if shift is None else None
        self._all = self._floors = None

    def _rows_motion(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._all is None:
            free = self._rows @ self.Q
            forced = self._rows_ground * self.ground
            if self.modal_force is not None:
                forced = forced + (self._abs_rows * self.modal_force) @ self.G
            if self._plastic is not None:
                forced = forced + self._plastic
            rate = self._modal[3]
            if rate is None:                # the rows' rate bound: the same for every horizon
                rate = self._modal[3] = self._abs_rows @ self.speed
            self._all = (free, forced, rate)
        return self._all

    def floors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every floor: free displacement on the grid (m, floors x points), forced bound on the
        grid (m, increasing) and the bound on the free rate (m/s, per floor)."""
        if self._floors is None:
            free, forced, rate = self._rows_motion()
            n = self.bound.n
            self._floors = (free, forced, rate) if self.shift is None else \
                (free[:n] + self.shift[:, None], forced[:n], rate[:n])
        return self._floors

    def floor(self, f: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Floor ``f`` (0-based): free displacement on the grid (m), forced bound on the grid (m,
        increasing) and the bound on the free rate (m/s)."""
        free, forced, rate = self.floors()
        return free[f], forced[f], float(rate[f])

    def drifts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every storey's drift about the static shift, ``D w`` (module docstring): free part on the
        grid (m, storeys x points), forced bound on the grid (m, increasing) and the bound on the
        free rate (m/s, per storey)."""
        n = self.bound.n
        if self.shift is not None:
            free, forced, rate = self._rows_motion()
            return free[n:], forced[n:], rate[n:]
        bound = self.bound
        forced = (bound.abs_drift_phi * np.abs(bound.gamma)) @ self.G * self.ground
        if self.modal_force is not None:
            forced = forced + (bound.abs_drift_phi * self.modal_force) @ self.G
        if bound.plastic is not None:
            forced = forced + (bound.abs_drift_phi * bound.plastic) @ self.G
        return bound.drift_phi @ self.Q, forced, bound.abs_drift_phi @ self.speed


def _answer(upper: np.ndarray, now: np.ndarray, positions, out: list, dS: float, H: float, limit: float,
            closed: float | None = None) -> None:
    """Each level's horizon into ``out`` at its position from its grid intervals' upper bounds
    ``upper`` (levels x intervals) and its penetration ``now`` (m): up to its first interval that
    may close, else ``H``, at most ``limit`` (s); a gap closed now gets ``closed`` (None: left as
    it is, the caller's 0)."""
    bad = upper >= 0.0
    first = bad.argmax(axis=1).tolist()
    hit = _ANY(bad, axis=1).tolist()
    for pos, c, f, h in zip(positions, (now >= 0.0).tolist(), first, hit):
        if not c:
            out[pos] = min(limit, float(f) * dS if h else H)
        elif closed is not None:
            out[pos] = closed


#: horizons whose stacked tables a pair keeps (a run's proofs use a few: the dyadic steps' nominal
#: lengths and the quiet proofs' reach)
_HORIZONS_KEPT = 64


def _stacked_tables(cache: dict, key, bounds, parts) -> tuple:
    """``cache[key]``: the tables of two buildings' :meth:`ModalBound._cached` at a horizon stacked,
    left rows then right, one array per part; made the first time (the horizon is ``key``, or its
    last element) and kept while the cache holds at most :data:`_HORIZONS_KEPT` (the oldest goes).
    ``parts`` takes both buildings' cached tuples and returns the pairs of arrays to stack."""
    tables = cache.get(key)
    if tables is None:
        if len(cache) > _HORIZONS_KEPT:
            cache.pop(next(iter(cache)))
        H = key[-1] if isinstance(key, tuple) else key
        tables = cache[key] = tuple(np.vstack(pair) for pair in parts(*(b._cached(H) for b in bounds)))
    return tables


def _answer_rows(points: np.ndarray) -> np.ndarray:
    """Rows of values on the grid (rows x points) in a proof's answer layout (rows x GRID + 2): the
    value now, each interval's mean of its ends, 0 (for the last 1)."""
    rows = np.zeros((points.shape[0], GRID + 2))
    rows[:, 0] = points[:, 0]
    rows[:, 1:-1] = 0.5 * (points[:, :-1] + points[:, 1:])
    return rows


class _LinearPair:
    """The levels between two linear buildings, proven as :meth:`OpenGaps.horizons` does with
    fewer numpy calls (each ~1 us: their count is a proof's cost); the same bounds, summed in
    another order (round-off only: tests/test_gap_bound_fast.py finds the same horizons):

    * both buildings' floors read in one gather, their modal state (:meth:`ModalBound.modal_state`)
      computed into one stacked vector (the products per building, written in place; the
      elementwise parts once for both), kept while the reads are the same (a step proves its
      gaps over a few horizons from one state);
    * what is linear in the state, one product per proof in the answer's layout: with ``s = [q,
      q' + zeta w q, A, 1]`` and the levels' mode shapes ``S`` (left less right; ``|P|`` for the
      free rate bounds ``A``; one column per level for the constant), ``(S * s) @ modes`` is each
      level's penetration now and, on every grid interval, the mean of its ends' free part plus
      the free rate's slack ``|P| A dS / 2`` less the gap (``modes``: the free motion's tables
      ``Ac``, ``As`` per horizon, in the same layout);
    * the ground's forced bound of the levels' floors only (an elementwise product), stacked;
    * per level ``delta(0)``, the grid intervals' upper bounds and a sentinel ``1`` in one row:
      one comparison and one ``argmax`` say whether the gap is closed now, the first interval
      that may close, or none."""

    def __init__(self, gaps: "OpenGaps", left: str, right: str, positions: list, fl: np.ndarray,
                 fr: np.ndarray, gap: np.ndarray):
        self.left, self.right, self.positions, self.fl, self.fr, self.gap = left, right, positions, fl, fr, gap
        self.bounds = (gaps.buildings[left][0], gaps.buildings[right][0])
        bl, br = self.bounds
        self.nl, n = bl.n, bl.n + br.n
        # the floors' displacements (row 0) and velocities (row 1) of both buildings, left then right
        (_, xl, vl), (_, xr, vr) = gaps.buildings[left], gaps.buildings[right]
        self.reads = np.vstack((np.concatenate((xl, xr)), np.concatenate((vl, vr))))
        self.w = np.concatenate((bl.w, br.w))
        self.zeta_w = np.concatenate((bl.zeta_w, br.zeta_w))
        m = fl.size
        self.m = m
        # each level's gain of the coarse bound (open_throughout) per unit of |ag|: sum_j |Phi_fj
        # Gamma_j| of both floors, the forced bound's weights on G_j(s) <= s^2 / 2
        self._coarse_ground = (bl.abs_phi @ np.abs(bl.gamma))[fl] + (br.abs_phi @ np.abs(br.gamma))[fr]
        # and its weights on each mode's free rate bound A_j for the free acceleration:
        # |q_j''| = |c_j q_j' + w_j (w_j q_j)| <= sqrt(c_j^2 + w_j^2) A_j, c_j = 2 zeta_j w_j
        self._coarse_accel = tuple(b.abs_phi[f] * np.sqrt(b.w * b.w + 4.0 * b.zeta_w * b.zeta_w)
                                   for b, f in ((bl, fl), (br, fr)))
        # the coarse bound's products: each level's floors' difference (left less right) of the
        # reads' rows (displacements, velocities), and from the speeds A its free acceleration
        # bound and half rate (as columns)
        n = bl.n + br.n
        self._coarse_difference = np.zeros((n, m))
        self._coarse_difference[fl, np.arange(m)] = 1.0
        self._coarse_difference[bl.n + fr, np.arange(m)] = -1.0
        self._coarse_speeds = np.hstack(self._coarse_accel).T      # (n, m); the half rates joined below
        self._coarse_rows = (bl.abs_phi[fl], br.abs_phi[fr])        # the levels' |phi| (held forces)
        # buffers every proof writes into, and the views of them it reads (made once: a view
        # costs about as much as a small numpy operation)
        nl = self.nl
        self._reads = np.empty(self.reads.shape)
        # both buildings' q = to_modal @ u (and q' from v) in one product: the block-diagonal
        # to_modal, transposed (the reads are rows)
        self._to_modal_t = np.zeros((n, n))
        self._to_modal_t[:nl, :nl] = bl.to_modal.T
        self._to_modal_t[nl:, nl:] = br.to_modal.T
        # the state's product (:meth:`prove`): s = [q | q' + zeta w q | A | 1 per level | (g_0 per
        # level, _ExactPair)]; _state writes q, b and the speeds A through views of it
        self._s = np.empty(3 * n + (2 if self._half_hat else 1) * m)
        s = self._s
        s[3 * n:3 * n + m] = 1.0
        self.q, self._b, self._speed = s[:n], s[n:2 * n], s[2 * n:3 * n]
        self._modal_pair = s[:2 * n].reshape(2, n)    # [q; q'], then q' + zeta w q in place
        self.qd, self._square = s[n:2 * n], np.empty(n)
        # the levels' mode shapes for q and q' + zeta w q (left less right), |.| for the rates, and
        # one column per level for the constant (and g_0)
        shapes = np.hstack((bl.phi[fl], -br.phi[fr]))
        rates = np.hstack((bl.abs_phi[fl], br.abs_phi[fr]))
        self._shapes = np.hstack((shapes, shapes, rates) + (np.eye(m),) * (2 if self._half_hat else 1))
        self._weighted = np.empty(self._shapes.shape)
        self._half_rates = 0.5 * rates      # each level's 0.5 (rate_l + rate_r) from the speeds A
        self._coarse_speeds = np.hstack((self._coarse_speeds, self._half_rates.T))
        self._coarse_reads, self._coarse_rates = np.empty((2, m)), np.empty(2 * m)
        self._forced = np.empty((2 * m, GRID))
        self._forced_parts = (self._forced[:m], self._forced[m:])
        self.answer = np.empty((m, GRID + 2))
        self.answer[:, -1] = 1.0
        self._upper, self._answer_now = self.answer[:, 1:-1], self.answer[:, 0]
        self.bad = np.empty((m, GRID + 2), dtype=bool)
        self._by_h: dict = {}           # H -> (stacked Ac, stacked As, stacked ground rows of the levels)
        self._key = None                # the reads (bytes) of the state below

    #: the state's product carries each level's g_0 (:class:`_ExactPair`'s first grid value)
    _half_hat = False

    def _free_rows(self, H: float, slack: float) -> np.ndarray:
        """The state's table for ``q``, ``q' + zeta w q`` and the speeds ``A`` (rows) in the
        answer's layout (:func:`_answer_rows`): each mode's free motion ``Ac`` then ``As`` (both
        buildings stacked), and the free rates' slack ``A slack / 2`` on every interval."""
        cl, cr = self.bounds[0]._cached(H), self.bounds[1]._cached(H)
        rates = np.zeros((self.w.size, GRID + 2))
        rates[:, 1:-1] = 0.5 * slack
        return np.vstack((_answer_rows(np.vstack((cl[1], cr[1], cl[2], cr[2]))), rates))

    def _constant_rows(self, margin: float = 0.0) -> np.ndarray:
        """The levels' constant in the answer's layout: less the gap, on every interval plus
        ``margin``, and the last 1 (no interval closes: ``H``)."""
        constant = np.zeros((self.m, GRID + 2))
        constant[:, :-1] = -self.gap
        constant[:, 1:-1] += margin
        constant[:, -1] = 1.0
        return constant

    def _tables(self, H: float) -> tuple:
        """``(modes, ground rows of the levels' floors)`` at ``H``: the state's table
        (:meth:`prove`) and both buildings' forced bound per unit ``|ag|``, stacked."""
        tables = self._by_h.get(H)
        if tables is None:
            if len(self._by_h) > _HORIZONS_KEPT:
                self._by_h.pop(next(iter(self._by_h)))
            cl, cr = self.bounds[0]._cached(H), self.bounds[1]._cached(H)
            tables = self._by_h[H] = (np.vstack((self._free_rows(H, H / GRID), self._constant_rows())),
                                      np.vstack((cl[4][self.fl, 1:], cr[4][self.fr, 1:])))
        return tables

    def _state(self, y: np.ndarray) -> None:
        """The modal state of both buildings (:meth:`ModalBound.modal_state`) and every floor's
        free rate bound (``|phi| @ speed``, as :class:`FloorMotion`), if the reads changed."""
        reads = self._reads
        y.take(self.reads, out=reads)
        key = reads.tobytes()
        if key == self._key:
            return
        q, qd, speed = self.q, self.qd, self._speed
        np.matmul(reads, self._to_modal_t, out=self._modal_pair)    # q, q' (qd and b share a place)
        np.multiply(self.w, q, out=speed)
        np.square(speed, out=speed)
        square = self._square
        np.multiply(qd, qd, out=square)
        speed += square
        np.sqrt(speed, out=speed)
        np.multiply(self.zeta_w, q, out=square)
        qd += square                                                # b = q' + zeta w q
        self._key = key

    def open_throughout(self, y: np.ndarray, H: float, peak: float, forces: dict) -> bool:
        """True when every level's gap provably stays open over all of ``[0, H]`` (s) by the coarse
        bound (:meth:`coarse_bound`) with :data:`COARSE_MARGIN` to spare: :meth:`prove` then answers
        ``H`` for every level, and need not be made."""
        return bool(_ALL(self.coarse_bound(y, H, peak, forces) < -COARSE_MARGIN))

    def coarse_bound(self, y: np.ndarray, H: float, peak: float, forces: dict) -> np.ndarray:
        """Each level's penetration over ``[0, H]`` (s) is at most this (m), and :meth:`prove`'s
        bound on every grid interval too.  It costs the modal state (which :meth:`prove` keeps)
        and a few operations on the levels, no motion on the grid.

        The free part ``d(s)`` of the penetration starts at ``d0 = x_l - x_r - gap`` with the rate
        ``v0 = v_l - v_r`` and an acceleration of at most ``a = sum_j |Phi_fj| sqrt(c_j^2 + w_j^2)
        A_j`` over both floors (``q'' = -(c q' + w (w q))``, ``A_j = sqrt(w_j^2 q_j^2 + q_j'^2)``
        never grows), so on every grid interval the mean of its ends is at most the largest of
        the convex ``d0 + v0 s + a s^2 / 2``, which is at ``s = 0`` or ``s = H``.  :meth:`prove`
        adds ``R dS / 2`` (the same term) and the forced part, each mode's ``G_j(s) <= s^2 / 2``
        times its load: at most ``P H^2 / 2``, ``P = sum_j |Phi_fj| (|Gamma_j| peak + |phi_j' F|)``
        with ``peak`` (m/s^2) at least ``|ag|`` over the horizon.  So in exact arithmetic its
        bound on every interval lies under ``max(d0, d0 + v0 H + a H^2 / 2) + R dS / 2 + P H^2 / 2``."""
        self._state(y)
        m = self.m
        diff, rates = self._coarse_reads, self._coarse_rates
        np.matmul(self._reads, self._coarse_difference, out=diff)     # x_l - x_r, v_l - v_r
        np.matmul(self._speed, self._coarse_speeds, out=rates)        # a, then R / 2
        d0 = diff[0] - self.gap[:, 0]
        free = rates[:m] * (0.5 * H * H)
        free += diff[1] * H
        free += d0
        bound = _MAX(d0, free, out=free)
        bound += rates[m:] * (H / GRID)
        load = self._coarse_ground * peak
        if forces:
            for name, modes, rows in ((self.left, self.bounds[0], self._coarse_rows[0]),
                                      (self.right, self.bounds[1], self._coarse_rows[1])):
                force = forces.get(name)
                if force is not None and _ANY(force):
                    load += rows @ np.abs(modes.phi.T @ force)
        load *= 0.5 * H * H
        bound += load
        return bound

    def prove(self, y: np.ndarray, H: float, ground: np.ndarray, forces: dict, out: list) -> None:
        """Each level's horizon (s, <= H) into ``out`` at its position (:meth:`OpenGaps.horizons`)."""
        self._state(y)
        modes, ground_rows = self._tables(H)
        dS = H / GRID
        # each level's penetration now and, on each interval, the free part's mean of its ends plus
        # L dS / 2 (its largest value is at most that), less the gap (the state's product)
        np.multiply(self._shapes, self._s, out=self._weighted)
        np.matmul(self._weighted, modes, out=self.answer)
        # the forced bound of the levels' floors at each interval's end: FloorMotion's ground term
        # (an elementwise product: the levels' rows alone) plus, with a held force, its modal term
        # (a matrix product: every floor's, then the levels')
        forced = self._forced
        np.multiply(ground_rows, ground[1:], out=forced)
        forced_l, forced_r = self._forced_parts
        if forces:
            for name, bound, floors, part in ((self.left, self.bounds[0], self.fl, forced_l),
                                              (self.right, self.bounds[1], self.fr, forced_r)):
                force = forces.get(name)
                if force is not None and _ANY(force):
                    part += ((bound.abs_phi * np.abs(bound.phi.T @ force)) @ bound._cached(H)[3])[floors, 1:]
        upper = self._upper
        upper += forced_l
        upper += forced_r
        np.greater_equal(self.answer, 0.0, out=self.bad)
        for pos, f in zip(self.positions, self.bad.argmax(axis=1).tolist()):
            if f:                               # f = 0: closed now (0 s)
                out[pos] = min(H, float(f - 1) * dS if f <= GRID else H)


class _ExactPair(_LinearPair):
    """The levels between two linear buildings whose modes all have stiffness, proven with the
    ground's response computed, not bounded (*Exact ground response*).

    The ground acceleration over the horizon is the polyline of the knots read ahead
    (:class:`GroundAhead`).  Split it into ``g_grid``, the polyline through its values at the grid
    points, and the rest ``r = ag - g_grid`` (zero at the grid points, largest at a knot inside a
    grid interval).  The floors' response to ``g_grid`` is exact at the grid points
    (:meth:`ModalBound.floor_kernels`), and so is a force's held over the horizon (a step load:
    ``phi_j' F`` times each mode's step response); with the free motion, the levels'
    penetration is known there.  ``r``'s response is bounded as the whole ground's was
    (``sum_j |Phi_fj Gamma_j| G_j(s) max |r|``).  Between grid points the known part exceeds the
    mean of its ends by at most ``L dS / 2``, ``L`` a bound on its rate: ``|x_f'| <= sum_j |Phi_fj|
    A_j`` with ``A_j = sqrt(w_j^2 q_j^2 + q_j'^2)``, which damping only lowers and the modal load
    raises by at most its integral, so ``A_j(s) <= A_j(0) + |Gamma_j| int_0^s |g_grid| + |phi_j'
    F| s``.  :data:`EXACT_MARGIN` covers the round-off of the computed motion.

    Each level's row of :attr:`answer` (its penetration now, on every grid interval the mean of
    the ends' known penetration plus the free rate's slack less the gap plus :data:`EXACT_MARGIN`,
    and a last 1: no interval may close, ``H``) is two small matrix products per proof, with tables
    made once per horizon (:meth:`_table`).  The ground's response is a convolution: the floor
    kernels are Toeplitz (the response at point ``k`` to the hat at point ``i >= 1`` depends on
    ``k - i`` only), so each level's response to ``g`` is ``F @ M`` with ``F`` (levels x lags)
    its kernel's column and ``M[d, k] = g[k - d]`` a view of ``g`` padded with zeros (a few kB
    instead of the levels' full kernel, levels x points x points: a proof touches less memory).
    The first grid value's half hat, the free motion (``q``, ``q' + zeta w q``), the free rates'
    slack (``|P| A``) and the gap are the state's product, ``(S * s) @ modes`` with ``s = [q, q' +
    zeta w q, A, g_0, 1]`` and ``S`` the levels' mode shapes (``|P|`` for the rates, one column
    per level for ``g_0`` and 1).  The terms that vary along the grid with the ground (its
    integral in the rate bound, the bend's bound) are added to it."""

    def __init__(self, gaps: "OpenGaps", left: str, right: str, positions: list, fl: np.ndarray,
                 fr: np.ndarray, gap: np.ndarray):
        super().__init__(gaps, left, right, positions, fl, fr, gap)
        bl, br = self.bounds
        # each level's rate gain per unit of int |g|: (|phi_l| |Gamma_l|)[fl] + (...)[fr], halved
        # as the free rate's slack is (the slack is L dS / 2)
        self._ground_gain = (0.5 * ((bl.abs_phi @ np.abs(bl.gamma))[fl] + (br.abs_phi @ np.abs(br.gamma))[fr]))[:, None]
        self._exact: dict = {}          # H -> (lags, modes, the ground's rate gain times dS, the bend's rows)
        m = self.m
        # the ground on the grid after GRID zeros: M[d, k] = g[k - d] is a view of it (rows d = 0..GRID
        # start at GRID - d), filled by GroundAhead.on_grid
        padded = np.zeros(GRID + GRID + 1)
        self._ground = padded[GRID:]
        self._toeplitz = np.lib.stride_tricks.sliding_window_view(padded, GRID + 1)[GRID::-1]
        self._convolved = np.empty((m, GRID + 1))
        self._g0 = self._s[-m:]         # g_0 once per level (the state's product, _LinearPair)
        self._intervals = np.empty((m, GRID))

    _half_hat = True

    def _table(self, H: float) -> tuple:
        """``(lags, modes, gain, bend)`` at horizon ``H`` (class docstring): ``lags`` (levels x
        lags) the ground's convolution, in the intervals' means (``lags @ M`` at point ``k >= 1``
        is the mean of the response at ``k - 1`` and ``k``); ``gain`` (levels x 1) times ``int
        |g|`` the rate bound's ground part, ``bend`` (levels x intervals) times the bend's bound
        its response's (both buildings' rows summed).  Made once per horizon."""
        tables = self._exact.get(H)
        if tables is not None:
            return tables
        if len(self._exact) > 16:
            self._exact.pop(next(iter(self._exact)))
        bl, br = self.bounds
        fl, fr, m, p = self.fl, self.fr, self.m, GRID + 1
        dS = H / GRID
        slack = dS                      # the rate bound's slack is L dS / 2 (the gains hold the half)
        cl, cr = bl._cached(H), br._cached(H)
        # the levels' kernels' columns (levels x points k): the first grid value's half hat, and the
        # hat at i = 1, by lag k - 1 every later hat's (ModalBound.floor_kernel_columns)
        (l0, l1), (r0, r1) = bl.floor_kernel_columns(H), br.floor_kernel_columns(H)
        first, second = l0[fl] - r0[fr], l1[fl] - r1[fr]
        lag = np.zeros((m, p))
        lag[:, :GRID] = second[:, 1:]                 # lag d = k - 1 of the hat at i = 1; lag GRID: 0
        lags = 0.5 * lag
        lags[:, 1:] += 0.5 * lag[:, :-1]              # the mean of lags d and d - 1: an interval's mean
        # the first grid value's half hat, less what the convolution gave it (the lag's column)
        half = _answer_rows(first - lag)
        half[:, 0] = first[:, 0] - lags[:, 0]         # point 0: the convolution gave it lags[:, 0] g_0
        # the state's table: each mode's free motion, the rate slack, the constant, g_0 (_LinearPair)
        modes = np.vstack((self._free_rows(H, slack), self._constant_rows(EXACT_MARGIN), half))
        # the bend's response: each building's bound of the whole ground's, levels' rows summed
        bend = cl[4][fl, 1:] + cr[4][fr, 1:]
        tables = self._exact[H] = (lags, modes, self._ground_gain * slack, bend)
        return tables

    def prove(self, y: np.ndarray, H: float, ground: "GroundAhead", forces: dict, out: list) -> None:
        """Each level's horizon (s, <= H) into ``out`` at its position (:meth:`OpenGaps.horizons`)."""
        self._state(y)
        lags, modes, gain, bend = self._table(H)
        g, rest, integral = ground.on_grid(self._ground)
        self._g0[:] = g[0]
        np.multiply(self._shapes, self._s, out=self._weighted)
        np.matmul(self._weighted, modes, out=self.answer)
        convolved = self._convolved
        np.matmul(lags, self._toeplitz, out=convolved)
        self.answer[:, :-1] += convolved
        upper = self._upper
        # what the ground adds to the rate bound by each interval's end, and the bend's response
        extra = self._intervals
        np.multiply(gain, integral[1:], out=extra)
        upper += extra
        np.multiply(bend, rest[1:], out=extra)
        upper += extra
        dS = H / GRID
        if forces:
            (bl, br) = self.bounds
            s = _grid(H)
            for name, bound, floors, sign in ((self.left, bl, self.fl, 1.0), (self.right, br, self.fr, -1.0)):
                force = forces.get(name)
                if force is None or not _ANY(force):
                    continue
                load = bound.phi.T @ force                       # modal load (held)
                step = bound.step_response(H)                     # modes x points
                moved = bound.phi[floors] @ (step * load[:, None])
                moved *= sign
                self._answer_now[:] += moved[:, 0]
                upper += 0.5 * (moved[:, :-1] + moved[:, 1:])
                upper += (0.5 * dS * (bound.abs_phi[floors] @ np.abs(load)))[:, None] * s[1:]
        # the first entry >= 0: 0 closed now, 1..GRID the first interval that may close, GRID + 1
        # the last 1 (none)
        np.greater_equal(self.answer, 0.0, out=self.bad)
        for pos, f in zip(self.positions, self.bad.argmax(axis=1).tolist()):
            out[pos] = 0.0 if not f else min(H, float(f - 1) * dS) if f <= GRID else H


class _BilinearPair:
    """The levels between two bilinear buildings with no held force, proven as :meth:`OpenGaps.horizons`
    does (each building's linear proof about its static shift while its storeys are proven
    elastic, the gaps' linear proof, then the proof through yielding of the levels it leaves short),
    with both buildings' elementwise arithmetic stacked (each numpy call costs about a microsecond,
    whatever its size): the same operations on the same numbers, so the same horizons to the last
    bit.  The matrix products stay per building, each with the shape :class:`FloorMotion` gives it
    (OpenBLAS computes a product's rows alike only for some row counts).

    Stacked layout: the left building's floors (or storeys) then the right's (``n = nl + nr``);
    ``F``, each building's rows ``[floors; storey drifts]`` one after the other (``2 n`` rows)."""

    def __init__(self, gaps: "OpenGaps", left: str, right: str, positions: list, fl: np.ndarray,
                 fr: np.ndarray, gap: np.ndarray):
        self.positions, self.gap = positions, gap
        bl, br = gaps.buildings[left][0], gaps.buildings[right][0]
        el, er = gaps.elastic[left], gaps.elastic[right]
        self.bounds, self.yielded = (bl, br), (gaps.yielded[left], gaps.yielded[right])
        nl, nr = bl.n, br.n
        n = nl + nr
        self.nl, self.n = nl, n
        (_, xl, vl), (_, xr, vr) = gaps.buildings[left], gaps.buildings[right]
        # one gather: floors' x, then v, then residual drifts, each left then right
        self.reads = np.concatenate((xl, xr, vl, vr, el.residual, er.residual))
        self.centre_factor = np.concatenate((np.full(nl, el._centre_factor), np.full(nr, er._centre_factor)))
        self.yielding_limit = np.concatenate((el._yielding_limit, er._yielding_limit))
        self.half_width = np.concatenate((el.half_width, er.half_width))
        self.w = np.concatenate((bl.w, br.w))
        self.zeta_w = np.concatenate((bl.zeta_w, br.zeta_w))
        yl, yr = self.yielded
        self.w_y = np.concatenate((yl.w, yr.w))
        self.zeta_w_y = np.concatenate((yl.zeta_w, yr.zeta_w))
        # rows: the levels' floors in F (left, right) and in the stacked floors; every storey drift in F
        self.fl, self.fr = fl, fr
        self.F_l, self.F_r = fl, 2 * nl + fr
        self.S_r = nl + fr
        self.drift_rows = np.concatenate((np.arange(nl, 2 * nl), np.arange(2 * nl + nr, 2 * n)))
        self._by_h: dict = {}           # H -> stacked tables
        self._key = None                # the reads (bytes) of the state below (_read)
        self._parts = np.array([0, nl], dtype=np.intp)      # the stacked rows' buildings begin here
        self._yielding = None
        self._levels_shift = None
        self._bad = np.empty((len(positions), GRID + 1), dtype=bool)     # every level's intervals
        self._motion: dict = {}         # H -> the free linear motion of this state
        self._yielded_state = None      # the modal state of the bounds through yielding (when asked)
        self._yielded_motion: dict = {}  # H -> their free motion's interval means
        # the bounds through yielding have the buildings' modes (ModalBound.through_yielding: the
        # same building), so the same q' = to_modal @ v: computed once where their to_modal agree
        # to the bit (else again, as for any other bound)
        self._same_modes = all(b.to_modal.tobytes() == y.to_modal.tobytes() for b, y in zip(self.bounds, self.yielded))
        # the ground's response computed while both buildings are proven linear (_ExactPair's
        # argument, about the static shift): every mode has stiffness
        self.stiff = bool(np.all(bl.w > 0.0) and np.all(br.w > 0.0))
        if self.stiff:
            self._rows_gain = np.concatenate((bl.abs_rows @ np.abs(bl.gamma), br.abs_rows @ np.abs(br.gamma)))[:, None]
        self._row_kernels: dict = {}    # H -> every row's ground kernel columns, both buildings stacked
        # the ground on the grid after GRID zeros, and the Toeplitz view of it the rows' kernel
        # columns are multiplied by (as _ExactPair's: M[d, k] = g[k - d])
        padded = np.zeros(GRID + GRID + 1)
        self._ground = padded[GRID:]
        self._toeplitz = np.lib.stride_tricks.sliding_window_view(padded, GRID + 1)[GRID::-1]

    def _tables(self, H: float) -> tuple:
        """``(Ac, As, ground rows of every floor and storey drift)`` of both buildings, stacked."""
        return self._by_h.get(H) or _stacked_tables(self._by_h, H, self.bounds, lambda cl, cr: ((cl[1], cr[1]), (cl[2], cr[2]),
                                                                          (cl[5], cr[5])))

    def _yielded_tables(self, H: float) -> tuple:
        """``(Ac, As, floors' ground bound, floors' storey-force bound)`` of both bounds through
        yielding, stacked."""
        return self._by_h.get(("yielded", H)) or _stacked_tables(self._by_h, ("yielded", H), self.yielded, lambda cl, cr: (
            (cl[1], cr[1]), (cl[2], cr[2]), (cl[4], cr[4]), (cl[6], cr[6])))

    def _read(self, y: np.ndarray) -> None:
        """The state from the reads (:meth:`OpenGaps._state` of both buildings, stacked), kept in
        attributes (a proof reads them without unpacking a tuple)."""
        reads = y[self.reads]
        key = reads.tobytes()
        if key == self._key:
            return
        n, nl = self.n, self.nl
        u, v, r = reads[:n], reads[n:2 * n], reads[2 * n:]
        shift = np.empty(n)
        _SUM_UP(r[:nl], out=shift[:nl])                 # ElasticRange.shift_of (a cumsum), per building
        _SUM_UP(r[nl:], out=shift[nl:])
        centre = self.centre_factor * r
        w = u - shift
        # ElasticRange.yielding: d = D w - centre, |d| >= the limit (D w's first storey is w_0 - 0.0,
        # w_0 to the bit: each building's first storey keeps its floor's w)
        d = w.copy()
        d[1:] -= w[:-1]
        d[nl] = w[nl]
        d -= centre
        bad = np.abs(d, out=d) >= self.yielding_limit
        self._yielding = _ANY_EACH(bad, self._parts).tolist()    # per building: [left, right]
        (bl, br), q, qd = self.bounds, np.empty(n), np.empty(n)
        np.matmul(bl.to_modal, w[:nl], out=q[:nl])       # ModalBound.modal_state(w, v), per building
        np.matmul(bl.to_modal, v[:nl], out=qd[:nl])
        np.matmul(br.to_modal, w[nl:], out=q[nl:])
        np.matmul(br.to_modal, v[nl:], out=qd[nl:])
        b = qd + self.zeta_w * q
        square = qd * qd                                # kept: the bound through yielding's speed too
        speed = self.w * q
        speed *= speed                                  # (w q) ** 2: the same product
        speed += square
        np.sqrt(speed, out=speed)
        rate = np.empty(2 * n)                          # FloorMotion's rows' rate bound, per building
        np.matmul(bl.abs_rows, speed[:nl], out=rate[:2 * nl])
        np.matmul(br.abs_rows, speed[nl:], out=rate[2 * nl:])
        self._shift, self._u, self._v, self._qd, self._qd_square = shift, u, v, qd, square
        self._q, self._b, self._rate = q[:, None], b[:, None], rate
        self._lo, self._hi = centre - self.half_width, centre + self.half_width
        self._key = key
        self._levels_shift = None       # the levels' floors' shifts, as columns (when asked)
        self._motion = {}
        self._yielded_state = None
        self._yielded_motion = {}

    def _kernels(self, H: float) -> tuple[np.ndarray, np.ndarray]:
        """``(lags, first)`` at ``H`` (rows x points, both buildings' rows stacked): every row's
        response at point ``k`` to the hat at grid point ``i >= 1`` by its lag ``d = k - i``
        (:meth:`ModalBound.ground_kernels` is Toeplitz there), and to the first grid value's half
        hat by point less ``lags[:, k]`` (what the convolution gives ``g_0``).  The rows' response
        to ``g`` is then ``lags @ M + first g_0`` with ``M[d, k] = g[k - d]`` (zero for ``k < d``):
        :meth:`ModalBound.ground_kernels` applied, summed in another order (round-off, well
        inside :data:`EXACT_MARGIN`), without the rows' full kernels (rows x points x points,
        1.5 MB on kasai_maison_inelastic, read at every proof).  Made once per horizon."""
        kernels = self._row_kernels.get(H)
        if kernels is None:
            if len(self._row_kernels) > 16:
                self._row_kernels.pop(next(iter(self._row_kernels)))
            lags, first = [], []
            for bound in self.bounds:
                _, full, half = bound._exact_tables(H)
                scale = -bound.gamma[:, None]           # modal load -Gamma_j ag
                lag = bound.rows @ (full * scale)
                lags.append(lag)
                first.append(bound.rows @ (half * scale) - lag)
            kernels = self._row_kernels[H] = (np.vstack(lags), np.vstack(first))
        return kernels

    def _linear(self, H: float, ground: np.ndarray, ahead: "GroundAhead | None" = None) -> tuple:
        """``(F, forced, (s_left, s_right), rate)``: the linear motion of both buildings about
        their shifts (:class:`FloorMotion`; the free part kept per state and horizon, the forced
        part of this ground bound) and how long each provably stays linear (0 while yielding);
        ``rate`` the rows' rate bounds (per row, or per row and interval).  With the ground
        ahead (``ahead``), its response to the grid polyline is computed and only the bend
        between grid points bounded, the rate bound growing with the load (:class:`_ExactPair`)."""
        rate = self._rate
        tables = self._by_h.get(H) or self._tables(H)
        F = self._motion.get(H)             # the free motion: this state's, per horizon
        if F is None:
            (bl, br), nl = self.bounds, self.nl
            Q = tables[0] * self._q
            Q += tables[1] * self._b
            F = np.empty((2 * self.n, GRID + 1))
            np.matmul(bl.rows, Q[:nl], out=F[:2 * nl])
            np.matmul(br.rows, Q[nl:], out=F[2 * nl:])
            if len(self._motion) > 8:
                self._motion.pop(next(iter(self._motion)))
            self._motion[H] = F
        dS = H / GRID
        rows = self.drift_rows
        if ahead is None:
            forced = tables[2] * ground
            slack = 0.5 * dS * rate[rows][:, None] + forced[rows, 1:]
        else:
            g, rest, integral = ahead.on_grid(self._ground)
            lags, first = self._row_kernels.get(H) or self._kernels(H)
            response = lags @ self._toeplitz
            response += first * g[0]
            F = F + response
            forced = tables[2] * rest
            rate = self._rows_gain * integral[1:]
            rate += self._rate[:, None]                 # rate[:, None] + gain * integral: the same sum
            slack = 0.5 * dS * rate[rows] + forced[rows, 1:]
            slack += EXACT_MARGIN
        # band_horizon of both buildings' storeys at once (each building's answer its own)
        D = F[rows]
        x0 = D[:, 0]
        lo, hi = self._lo, self._hi
        inside = _AND(x0 > lo, x0 < hi)
        mid = D[:, :-1] + D[:, 1:]
        mid *= 0.5
        bad = mid + slack >= hi[:, None]
        mid -= slack
        bad |= mid <= lo[:, None]
        yielding = self._yielding
        if not (yielding[0] or yielding[1]) and _ALL(inside):     # both inside: one reduction each way
            first_bad = _ANY_EACH(bad, self._parts)             # per building: [left rows; right rows]
            first = first_bad.argmax(axis=1).tolist()
            hit = first_bad[0, first[0]], first_bad[1, first[1]]
            spans = (float(first[0]) * dS if hit[0] else H, float(first[1]) * dS if hit[1] else H)
            return F, forced, spans, rate
        spans = []
        for part, y_b in ((slice(0, self.nl), yielding[0]), (slice(self.nl, self.n), yielding[1])):
            if y_b or not _ALL(inside[part]):
                spans.append(0.0)
                continue
            first_bad = _ANY(bad[part], axis=0)
            first = int(first_bad.argmax())
            spans.append(float(first) * dS if first_bad[first] else H)
        return F, forced, tuple(spans), rate

    def _through(self, H: float, ground: np.ndarray) -> tuple:
        """``(mid, slack)`` of both buildings' floors through yielding (:meth:`ModalBound.through_yielding`,
        from the floors' x and v): on each grid interval the mean of the free motion's ends, and the
        free rate's slack plus the forced part at the interval's end (floors x intervals, stacked)."""
        (yl, yr), nl, n = self.yielded, self.nl, self.n
        if self._yielded_state is None:
            u = self._u
            q = np.empty(n)
            np.matmul(yl.to_modal, u[:nl], out=q[:nl])
            np.matmul(yr.to_modal, u[nl:], out=q[nl:])
            if self._same_modes:        # q' is the linear bound's (to_modal @ v), and so is its square
                qd, square = self._qd, self._qd_square
            else:
                v, qd = self._v, np.empty(n)
                np.matmul(yl.to_modal, v[:nl], out=qd[:nl])
                np.matmul(yr.to_modal, v[nl:], out=qd[nl:])
                square = qd * qd
            b = qd + self.zeta_w_y * q
            speed = self.w_y * q
            speed *= speed
            speed += square
            np.sqrt(speed, out=speed)
            rate = np.empty(n)
            np.matmul(yl.abs_phi, speed[:nl], out=rate[:nl])
            np.matmul(yr.abs_phi, speed[nl:], out=rate[nl:])
            self._yielded_state = (q[:, None], b[:, None], rate)
        q, b, rate = self._yielded_state
        Ac, As, floors_ground, plastic = self._by_h.get(("yielded", H)) or self._yielded_tables(H)
        mid = self._yielded_motion.get(H)  # the free motion's means: this state's, per horizon
        if mid is None:
            Q = Ac * q
            Q += As * b
            free = np.empty((n, GRID + 1))
            np.matmul(yl.phi, Q[:nl], out=free[:nl])
            np.matmul(yr.phi, Q[nl:], out=free[nl:])
            mid = free[:, :-1] + free[:, 1:]
            mid *= 0.5
            if len(self._yielded_motion) > 8:
                self._yielded_motion.pop(next(iter(self._yielded_motion)))
            self._yielded_motion[H] = mid
        forced = floors_ground * ground
        forced += plastic
        slack = (0.5 * (H / GRID) * rate)[:, None] + forced[:, 1:]
        return mid, slack

    def prove(self, y: np.ndarray, H: float, ground, out: list, ahead: "GroundAhead | None" = None) -> None:
        """Each level's horizon (s, <= H) into ``out`` at its position (:meth:`OpenGaps.horizons`).
        ``ground`` bounds ``|ag|`` on the grid, or with ``ahead`` (the ground ahead, whose response
        the linear proof then computes) returns that bound when called."""
        self._read(y)
        dS = H / GRID
        positions = self.positions
        yielding = self._yielding
        if yielding[0] and yielding[1]:
            s_l = s_r = 0.0
        else:
            F, forced, (s_l, s_r), rate = self._linear(H, ground, ahead)
        # each side's linear bound of the levels' floors ``(x, rate, forced at the intervals' ends)``,
        # read once by the gaps' linear proof and by the envelopes through yielding (the same
        # gathers and sums as either made them), only for a building proven linear a while
        sides = [None, None]
        if s_l != 0.0 or s_r != 0.0:
            if self._levels_shift is None:
                shift = self._shift
                self._levels_shift = (shift[self.fl][:, None], shift[self.S_r][:, None])
            for side, (s_b, rows) in enumerate(((s_l, self.F_l), (s_r, self.F_r))):
                if s_b != 0.0:
                    x = F[rows]
                    x += self._levels_shift[side]       # F[rows] + shift[floors][:, None]
                    sides[side] = (x, rate[rows], forced[rows, 1:])
        exact = ahead is not None
        if s_l != 0.0 and s_r != 0.0:
            (xl, rl, fl_end), (xr, rr, fr_end) = sides
            delta = xl - xr
            delta -= self.gap
            upper = delta[:, :-1] + delta[:, 1:]
            upper *= 0.5
            if exact:
                upper += 0.5 * dS * (rl + rr)
            else:
                upper += (0.5 * (rl + rr) * dS)[:, None]
            upper += fl_end
            upper += fr_end
            if exact:
                upper += EXACT_MARGIN
            _answer(upper, delta[:, 0], positions, out, dS, H, min(s_l, s_r))
        short = [i for i, pos in enumerate(positions) if out[pos] < H]
        if not short:
            return
        # through yielding (OpenGaps._through_yielding): each floor's envelope, the tighter of its
        # linear bound (over the intervals its building provably stays linear) and its bound
        # through yielding (any time)
        mid_y, slack_y = self._through(H, ground() if exact else ground)
        every = len(short) == len(positions)
        half = 0.5 * dS
        envelopes = []
        for sign, rows_y, s_b, linear in ((1.0, self.fl, s_l, sides[0]), (-1.0, self.S_r, s_r, sides[1])):
            if not every:
                rows_y = rows_y[short]
            # the bound through yielding (valid over every interval): sign * mid + slack
            edge = mid_y[rows_y] + slack_y[rows_y] if sign > 0.0 else slack_y[rows_y] - mid_y[rows_y]
            if linear is not None:      # the linear bound's intervals: those ending by s_b
                x, r, f_end = linear if every else (part[short] for part in linear)
                mid = x[:, :-1] + x[:, 1:]
                mid *= 0.5
                slack = (half * r if r.ndim == 2 else (half * r)[:, None]) + f_end
                if r.ndim == 2:
                    slack += EXACT_MARGIN
                linear = mid + slack if sign > 0.0 else slack - mid
                valid = int(round(s_b / dS))
                if valid < GRID:
                    linear[:, valid:] = np.inf
                edge = np.minimum(linear, edge, out=edge)
            envelopes.append(edge)
        # up - lo - gap, lo = -(the right envelope): up + env_r is up - lo to the bit; the first
        # interval that may close (a last column of True: none, H)
        bad = self._bad if every else np.empty((len(short), GRID + 1), dtype=bool)
        total = envelopes[0]
        total += envelopes[1]
        total -= self.gap if every else self.gap[short]
        np.greater_equal(total, 0.0, out=bad[:, :GRID])
        bad[:, GRID] = True
        for i, f in zip(short, bad.argmax(axis=1).tolist()):
            pos = positions[i]
            out[pos] = max(out[pos], float(f) * dS if f < GRID else H)

def open_horizon(left: tuple[np.ndarray, np.ndarray, float], right: tuple[np.ndarray, np.ndarray, float],
                 gap: float, H: float) -> float:
    """Longest ``s <= H`` (s) over which ``delta = u_left - u_right - gap`` provably stays < 0,
    from :meth:`FloorMotion.floor` of the two floors (0 if the gap is not open now)."""
    xl, bl, ll = left
    xr, br, lr = right
    delta = xl - xr - gap
    if delta[0] >= 0.0:
        return 0.0
    dS = H / GRID
    # interval k: the free part's largest value <= mean of its ends + L dS / 2; forced part at its end
    upper = 0.5 * (delta[:-1] + delta[1:]) + 0.5 * (ll + lr) * dS + bl[1:] + br[1:]
    bad = np.flatnonzero(upper >= 0.0)
    return H if bad.size == 0 else float(bad[0]) * dS


def band_horizon(free: np.ndarray, forced: np.ndarray, rate: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 H: float) -> float:
    """Longest ``s <= H`` (s) over which every row's ``x = free + forced part`` provably stays
    inside ``(lo, hi)``, from :meth:`FloorMotion.drifts` (rows x points, per row) and the
    bounds ``lo``, ``hi`` per row (0 if a row is not inside now)."""
    x0 = free[:, 0]
    if not _ALL(_AND(x0 > lo, x0 < hi)):
        return 0.0
    dS = H / GRID
    # interval k: the free part within its rate bound of the chord's mean, the forced at its end
    mid = free[:, :-1] + free[:, 1:]
    mid *= 0.5
    slack = 0.5 * dS * rate[:, None] + forced[:, 1:]
    bad = mid + slack >= hi[:, None]
    bad |= mid - slack <= lo[:, None]
    bad = _ANY(bad, axis=0)
    first = int(bad.argmax())
    return float(first) * dS if bad[first] else H


class ElasticRange:
    """What proves a bilinear building's storeys elastic (module docstring): ``alpha``, the
    yield drifts ``dy`` (m) and where the residual drifts ``r`` live in ``System.y``."""

    def __init__(self, alpha: float, yield_drift: np.ndarray, residual: np.ndarray):
        self.alpha = float(alpha)
        self.half_width = (1.0 - ELASTIC_MARGIN) * np.asarray(yield_drift, dtype=float)
        self.slack = YIELDING_SLACK * np.asarray(yield_drift, dtype=float)
        self.residual = residual
        # computed once, not per proof (the same numbers: ``centre = factor * r`` and the sum
        # of two constants)
        self._centre_factor = self.alpha / (1.0 - self.alpha)
        self._yielding_limit = self.half_width + self.slack

    def shift(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(u_s, alpha s)``: the floors' static displacement about which the storeys are
        linear (m) and the centre of each storey's elastic range in ``D w`` (m)."""
        return self.shift_of(y[self.residual])

    def shift_of(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`shift` from the residual drifts ``r`` (m) already read."""
        return r.cumsum(), self._centre_factor * r

    def band(self, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each storey's elastic range ``(lo, hi)`` in ``D w`` (m) about its ``centre``."""
        return centre - self.half_width, centre + self.half_width

    def yielding(self, w: np.ndarray, centre: np.ndarray) -> bool:
        """A storey yields now, beyond doubt: its drift about the shift, from the floors' ``w =
        u - u_s`` (m), lies outside its elastic range by more than :data:`YIELDING_SLACK` of the
        yield drift.  :meth:`horizon` would then say 0 (its drifts come through the modes, which
        differ from ``D w`` by round-off, ~1e-15 of the displacements); checked first, because
        a yielding building is proven again at every step and fails at once."""
        d = w.copy()
        d[1:] -= w[:-1]
        d -= centre
        return bool(_ANY(np.abs(d, out=d) >= self._yielding_limit))

    def horizon(self, motion: FloorMotion, centre: np.ndarray, H: float) -> float:
        """Longest ``s <= H`` (s) over which every storey provably stays elastic."""
        return band_horizon(*motion.drifts(), *self.band(centre), H)


@functools.lru_cache(maxsize=64)
def _grid(H: float) -> np.ndarray:
    """The grid's offsets ``s_k = H k / GRID`` (s), computed once per horizon (read-only: shared)."""
    grid = H * _POINTS / GRID
    grid.flags.writeable = False
    return grid


def running_max_abs(times: np.ndarray, values: np.ndarray, t0: float, H: float,
                    at_grid: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """``max |a|`` over ``[t0, t0 + s_k]`` of the polyline through ``(times, values)`` (which
    must cover ``[t0, t0 + H]``), on the grid ``s_k = H k / GRID`` (m/s^2).  ``at_grid``: the
    grid's times ``t0 + s_k`` and ``|a|`` there, if already computed (:meth:`GroundAhead.on_grid`:
    the same numbers, not again)."""
    if at_grid is None:
        s = t0 + _grid(H)
        out = _interp(s, times, values)
        np.abs(out, out=out)
        _MAX.accumulate(out, out=out)
    else:
        s, size = at_grid
        out = _MAX.accumulate(size)
    lo = times.searchsorted(t0, "left")
    hi = times.searchsorted(t0 + H, "right")
    if hi > lo:
        # a knot's value counts from the first grid point at or after it: the largest |value|
        # of the knots up to each grid point (a prefix maximum, sampled where each grid point falls)
        knots = times[lo:hi]
        prefix = np.abs(values[lo:hi])
        _MAX.accumulate(prefix, out=prefix)
        # the grid points at or after the first knot (k > 0 there: k counts the knots at or
        # before each grid point, and grows along the grid)
        first = s.searchsorted(knots[0], "left")
        k = knots.searchsorted(s[first:], "right")
        k -= 1
        tail = out[first:]
        _MAX(tail, prefix[k], out=tail)
    return out


class GroundAhead:
    """The ground motion over a proof's horizon ``[t0, t0 + H]``: the polyline through ``(times,
    values)`` (m/s^2; the knots read ahead, :mod:`cosim.master.knots`), which must cover it.
    Called, the bound on ``|ag|`` on the grid (:func:`running_max_abs`); :meth:`on_grid`, what
    :class:`_ExactPair` takes."""

    __slots__ = ("times", "values", "t0", "H", "_at_grid")

    def __init__(self, times: np.ndarray, values: np.ndarray, t0: float, H: float):
        self.times, self.values, self.t0, self.H = times, values, t0, H
        self._at_grid = None            # (t0 + s_k, |ag| there) once on_grid computed them

    def __call__(self) -> np.ndarray:
        return running_max_abs(self.times, self.values, self.t0, self.H, self._at_grid)

    def peak(self) -> float:
        """A bound on ``|ag|`` over the whole horizon (m/s^2): the largest ``|value|`` of the knots
        from the last at or before ``t0`` to the first at or after ``t0 + H`` (the polyline
        between two knots lies between their values)."""
        times = self.times
        lo = max(int(times.searchsorted(self.t0, "right")) - 1, 0)
        hi = int(times.searchsorted(self.t0 + self.H, "left")) + 1
        return float(_MAX.reduce(np.abs(self.values[lo:hi])))

    def on_grid(self, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(g, rest, integral)``: the ground acceleration at the grid points ``t0 + s_k``
        (m/s^2), ``max |ag - g_grid|`` over ``[t0, t0 + s_k]`` (m/s^2), ``g_grid`` the polyline
        through ``g``, and a bound on ``int_0^s_k |g_grid|`` (m/s).  What lies between them is the polyline's bend at the knots inside a grid
        interval, largest at a knot, widened by :data:`GROUND_ROUNDOFF` of the largest ``|g|``.
        ``out``: where ``g`` is written too (GRID + 1 values)."""
        times, values, t0 = self.times, self.values, self.t0
        s = t0 + _grid(self.H)
        g = _interp(s, times, values)
        if out is not None:
            out[:] = g
        lo = times.searchsorted(s[0], "right")
        hi = times.searchsorted(s[-1], "left")
        if hi > lo:
            knots = times[lo:hi]
            # the bend at each knot: its value less g_grid's there (the chord of its grid interval)
            bend = values[lo:hi] - _interp(knots, s, g)
            np.abs(bend, out=bend)
            _MAX.accumulate(bend, out=bend)
            # grid point k: the largest bend of the knots before it (none: 0)
            rest = np.concatenate((_ZERO, bend))[knots.searchsorted(s, "left")]
        else:
            rest = np.zeros(GRID + 1)
        size = np.abs(g)
        self._at_grid = (s, size)       # what the bound on |ag| starts from (__call__)
        rest += GROUND_ROUNDOFF * float(_MAX.reduce(size))     # size.max() without its Python wrapper
        # int_0^s_k |g_grid|: on each interval at most the mean of its ends' sizes (exact where g
        # keeps its sign), times dS
        integral = np.zeros(GRID + 1)
        pieces = size[:-1] + size[1:]
        pieces *= 0.5 * self.H / GRID
        _SUM_UP(pieces, out=integral[1:])
        return g, rest, integral


def constant_bound(value: float) -> np.ndarray:
    """A ground bound of ``value`` over the whole grid (e.g. 0 without ground motion)."""
    return np.full(GRID + 1, float(value))


def floor_forces(n: int, contributions: Sequence[tuple[int, float]]) -> np.ndarray | None:
    """The force vector (N) of ``n`` floors from ``(floor index, force)`` pairs, None if all zero."""
    if not contributions:
        return None
    f = np.zeros(n)
    for i, value in contributions:
        f[i] += value
    return f if np.any(f) else None


class _Plan(list):
    """The pairs of one grouping of levels (:meth:`OpenGaps._linear_plan`) and how many horizons
    they answer (counted once, not at every proof)."""

    answers = 0


class OpenGaps:
    """Every contact level of a system with what proves its gap open (module docstring):
    each building's :class:`ModalBound` and where its floors' states live in ``System.y``.

    :meth:`build` returns None when a building has no such bound (non-classical damping): the
    master then neither takes long steps nor lets contacts sleep.  A bilinear building's linear
    proof holds while its storeys are proven elastic (:class:`ElasticRange`); its proof through
    yielding (``yielded``, :meth:`ModalBound.through_yielding`) at any time.  A Bouc-Wen
    building (in ``yielded``, not in ``elastic``) has the proof through yielding only.
    """

    def __init__(self, buildings: dict, levels: list, elastic: dict | None = None, yielded: dict | None = None):
        self.buildings = buildings          # name -> (ModalBound, x index array, v index array)
        self.levels = levels                # (left, floor index, right, floor index, gap), per contact level
        self.elastic = elastic or {}        # name -> ElasticRange, for the bilinear buildings
        self.yielded = yielded or {}        # name -> ModalBound.through_yielding, for the inelastic buildings
        # the inelastic buildings without an elastic range (Bouc-Wen): never proven linear
        self._never_linear = frozenset(b for b in self.yielded if b not in self.elastic)
        self._grouped: dict = {}            # which levels (None: all) -> _pairs
        # what a building's proof reads from System.y, in one gather: floors' x, v, residual drifts
        self._reads = {b: np.concatenate((ix, iv) + ((self.elastic[b].residual,) if b in self.elastic else ()))
                       for b, (_, ix, iv) in buildings.items()}
        # building -> (its reads as bytes, _BuildingState): a step proves its gaps over a few
        # horizons from the same state (the long step, the quiet horizon, the step)
        self._states: dict = {}
        # every building linear (no elastic range, no bound through yielding): the proof is
        # :meth:`_linear_horizons`, with the per-building and per-pair work it caches below
        self._all_linear = not self.elastic and not self.yielded
        # which levels (None: all) -> per pair, what the linear proof reuses (:meth:`_linear_plan`),
        # and the stacked proof of two bilinear buildings (:meth:`_bilinear_plan`)
        self._plans: dict = {}
        #: two bilinear buildings with no held force are proven by :class:`_BilinearPair` (False:
        #: by the per-building pieces, as its test compares)
        self.stacked = True

    @classmethod
    def build(cls, system, contact_levels) -> "OpenGaps | None":
        from .models import shear_building, storey_hysteresis, storeys_are_linear
        from .names import column, element_name

        index = {c: i for i, c in enumerate(system.columns[:system.y.size])}
        buildings, elastic, yielded = {}, {}, {}
        for node in system.buildings:
            linear = storeys_are_linear(node.spec)
            try:
                building = shear_building(node.spec)
                bound = ModalBound(building)
            except ValueError:
                return None
            n = bound.n

            def floors(name):
                return np.array([index[column(node.name, element_name(name, i))] for i in range(1, n + 1)])
            buildings[node.name] = (bound, floors("x"), floors("v"))
            if not linear:
                law = storey_hysteresis(node.spec)
                if law.model == "bilinear":
                    elastic[node.name] = ElasticRange(law.alpha, law.yield_drift(building.stiffnesses),
                                                      floors("drift_residual"))
                    strength = law.yield_shear
                else:                       # Bouc-Wen: (1 - alpha) Fy z, |z| <= z_u (module docstring)
                    strength = law.yield_shear * law.ultimate_z * (1.0 + BOUC_WEN_Z_MARGIN)
                yielded[node.name] = ModalBound.through_yielding(building, law.alpha, strength)
        where = {lv.instance: lv for lv in system.scene.levels}
        levels = []
        for lv in contact_levels:
            level = where[lv.name]
            levels.append((level.left, level.floor_left - 1, level.right, level.floor_right - 1, lv.gap))
        return cls(buildings, levels, elastic, yielded)

    def columns(self, system) -> list[str]:
        """The Real outputs the proof reads: every floor's displacement and velocity, and the
        residual drifts of yielding buildings."""
        out = [system.columns[i] for _, x, v in self.buildings.values() for i in np.concatenate((x, v))]
        return out + [system.columns[i] for e in self.elastic.values() for i in e.residual]

    def _pairs(self, which: Sequence[int] | None) -> list[tuple[str, str, list[int], np.ndarray, np.ndarray, np.ndarray]]:
        """The levels (or those in ``which``) grouped by their two buildings: ``(left, right,
        positions in the answer, left floors, right floors, gaps)``; each grouping once (a run
        asks for all levels and a few subsets of them, at most ``2**levels``, kept while fewer
        than :data:`_PAIRS_KEPT`)."""
        key = None if which is None else tuple(which)
        pairs = self._grouped.get(key)
        if pairs is not None:
            return pairs
        groups: dict = {}
        for pos, k in enumerate(range(len(self.levels)) if which is None else which):
            left, fl, right, fr, gap = self.levels[k]
            g = groups.setdefault((left, right), ([], [], [], []))
            g[0].append(pos)
            g[1].append(fl)
            g[2].append(fr)
            g[3].append(gap)
        pairs = [(left, right, pos, np.array(fl, dtype=np.intp), np.array(fr, dtype=np.intp),
                  np.array(gap, dtype=float)[:, None])
                 for (left, right), (pos, fl, fr, gap) in groups.items()]
        if len(self._grouped) < _PAIRS_KEPT:
            self._grouped[key] = pairs
        return pairs

    def _state(self, b: str, bound: ModalBound, reads: np.ndarray) -> tuple:
        """``(yielding, shift, w, v, modal, band)`` of building ``b`` from its reads (floors' x,
        v and residual drifts): whether a storey yields now, the static shift (None for a
        linear building), the floors' displacement about the shift, their velocities,
        :meth:`ModalBound.modal_state` (None if yielding) and each storey's elastic range
        ``(lo, hi)`` in ``D w`` (None for a linear building or a yielding one)."""
        n = bound.n
        u, v = reads[:n], reads[n:2 * n]
        elastic = self.elastic.get(b)
        if elastic is None:
            if b in self._never_linear:
                return True, None, u, v, None, None
            return False, None, u, v, bound.modal_state(u, v), None
        r = reads[2 * n:]
        shift, centre = elastic.shift_of(r)
        w = u - shift
        if elastic.yielding(w, centre):
            return True, shift, w, v, None, None
        return False, shift, w, v, bound.modal_state(w, v), elastic.band(centre)

    def horizons(self, y: np.ndarray, H: float, ground: np.ndarray, forces: dict | None = None,
                 which: Sequence[int] | None = None) -> list[float]:
        """For each contact level (or those in ``which``): how long (s, <= ``H``) its gap provably
        stays open from now, with ``ground[k]`` bounding ``|ag|`` up to grid point ``k`` and
        ``forces`` (building -> force per floor, N) held over the horizon.  ``ground`` may be
        a function that returns it: called once, only if a building's motion is needed (a
        yielding building ends the linear proof before).

        The levels between the same two buildings are proven together (one array operation
        each, as :func:`open_horizon` does for one level, with the same arithmetic).  A level
        of a bilinear building that this linear proof leaves short of ``H`` is proven again
        through yielding (:meth:`_through_yielding`), and keeps the longer horizon.  Two bilinear
        buildings with no held force are proven by :class:`_BilinearPair` (the same arithmetic,
        both buildings stacked), every building linear by :meth:`_linear_horizons`."""
        forces = forces or {}
        if self._all_linear:
            return self._linear_horizons(y, H, ground, forces, which)
        motions = {}
        linear = {}                         # building -> how long it provably stays linear (s)
        pairs = self._pairs(which)
        out = [0.0] * sum(len(p[2]) for p in pairs)
        dS = H / GRID
        bounds = [ground]                   # the ground bound, once evaluated

        def ground_bound():
            if callable(bounds[0]):
                bounds[0] = bounds[0]()
            return bounds[0]

        def prove_linear(b: str) -> float:
            """How long building b provably stays linear (a yielding one ends the proof before its
            motion, and the ground bound, is computed); its motion kept in ``motions``."""
            s = linear.get(b)
            if s is not None:
                return s
            bound, ix, iv = self.buildings[b]
            reads = y[self._reads[b]]
            key = reads.tobytes()
            known = self._states.get(b)
            if known is not None and known[0] == key:
                state = known[1]
            else:
                state = self._state(b, bound, reads)
                self._states[b] = (key, state)
            yielding, shift, w, v, modal, band = state
            if yielding:
                s = linear[b] = 0.0         # no linear proof
            else:
                motions[b] = FloorMotion(bound, w, v, H, ground_bound(), forces.get(b), shift, about=w, modal=modal)
                # ElasticRange.horizon, with the elastic ranges this state keeps
                s = linear[b] = H if band is None else band_horizon(*motions[b].drifts(), *band, H)
            return s

        yielded = self.yielded
        fast = self._bilinear_plan(which) if self.stacked else [None] * len(pairs)
        for k, (left, right, positions, fl, fr, gap) in enumerate(pairs):
            if fast[k] is not None and left not in forces and right not in forces:
                # the same arithmetic, stacked; with the ground ahead known, its response computed
                ahead = ground if (EXACT_GROUND and H >= EXACT_MIN_HORIZON and isinstance(ground, GroundAhead)
                                   and fast[k].stiff) else None
                fast[k].prove(y, H, ground_bound() if ahead is None else ground_bound, out, ahead)
                continue
            if prove_linear(left) != 0.0 and prove_linear(right) != 0.0:
                s = min(linear[left], linear[right])
                xl, bl, ll = motions[left].floors()
                xr, br, lr = motions[right].floors()
                delta = xl[fl] - xr[fr] - gap
                # interval k: the free part's largest value <= mean of its ends + L dS / 2; forced part at its end
                upper = delta[:, :-1] + delta[:, 1:]
                upper *= 0.5
                upper += (0.5 * (ll[fl] + lr[fr]) * dS)[:, None]
                upper += bl[fl, 1:]
                upper += br[fr, 1:]
                _answer(upper, delta[:, 0], positions, out, dS, H, s)
            if yielded and (left in yielded or right in yielded):
                short = [i for i, pos in enumerate(positions) if out[pos] < H]
                if short:
                    through = self._through_yielding(y, H, ground_bound(), forces, prove_linear, motions,
                                                     left, right, fl[short], fr[short], gap[short])
                    for i, s in zip(short, through):
                        pos = positions[i]
                        out[pos] = max(out[pos], s)
        return out

    # -- linear buildings: the same arithmetic as :meth:`horizons`' linear proof, in fewer calls ----
    def _linear_plan(self, which: Sequence[int] | None, exact: bool = False) -> list:
        """Per pair of :meth:`_pairs`, a :class:`_LinearPair`, or with ``exact`` an
        :class:`_ExactPair` where every mode of both buildings has stiffness (kept per grouping,
        as :meth:`_pairs`)."""
        key = (None if which is None else tuple(which), exact)
        plan = self._plans.get(key)
        if plan is not None:
            return plan
        plan = _Plan()
        for pair in self._pairs(which):
            stiff = exact and all(np.all(self.buildings[b][0].w > 0.0) for b in pair[:2])
            plan.append((_ExactPair if stiff else _LinearPair)(self, *pair))
        plan.answers = sum(len(p.positions) for p in plan)
        if len(self._plans) < _PAIRS_KEPT:
            self._plans[key] = plan
        return plan

    def _bilinear_plan(self, which: Sequence[int] | None) -> list:
        """Per pair of :meth:`_pairs`, a :class:`_BilinearPair` where both buildings are bilinear
        with a bound through yielding (else None), kept per grouping as :meth:`_pairs`."""
        key = ("bilinear", None if which is None else tuple(which))
        plan = self._plans.get(key)
        if plan is not None:
            return plan
        stacked = set(self.elastic) & set(self.yielded)
        plan = [_BilinearPair(self, *pair) if pair[0] in stacked and pair[1] in stacked else None
                for pair in self._pairs(which)]
        if len(self._plans) < _PAIRS_KEPT:
            self._plans[key] = plan
        return plan

    def _linear_horizons(self, y: np.ndarray, H: float, ground, forces: dict,
                         which: Sequence[int] | None) -> list[float]:
        """:meth:`horizons` when every building is linear (:class:`_LinearPair`): the same bounds
        as :meth:`horizons` and :class:`FloorMotion` in fewer calls (round-off aside: the same
        horizons, tests/test_gap_bound_fast.py)."""
        exact = EXACT_GROUND and H >= EXACT_MIN_HORIZON and isinstance(ground, GroundAhead)
        plan = self._linear_plan(which, exact)
        out = [0.0] * plan.answers
        bound = peak = None
        # the coarse bound (_LinearPair.open_throughout) is tried on the levels of sleeping contacts
        # while others are awake (a proper subset): those lie away from the contacts and mostly pass
        # (kasai_maison: 144 of 190); with every level asked for, a gap is about to close and the
        # coarse bound mostly fails (33 of 34), which then costs a third of a proof more
        coarse = which is not None and len(which) < len(self.levels)
        for pair in plan:
            if isinstance(pair, _ExactPair):
                pair.prove(y, H, ground, forces, out)
                continue
            if coarse:
                if peak is None:        # the coarse bound needs only the ground's peak over the horizon
                    if isinstance(ground, GroundAhead):
                        peak = ground.peak()
                    else:
                        bound = ground() if callable(ground) else ground
                        peak = float(_MAX.reduce(bound))
                if pair.open_throughout(y, H, peak, forces):
                    for pos in pair.positions:  # what the proof on the grid would answer
                        out[pos] = H
                    continue
            if bound is None:
                bound = ground() if callable(ground) else ground
            pair.prove(y, H, bound, forces, out)
        return out

    def _through_yielding(self, y: np.ndarray, H: float, ground: np.ndarray, forces: dict, prove_linear,
                          motions: dict, left: str, right: str, fl: np.ndarray, fr: np.ndarray,
                          gap: np.ndarray) -> list[float]:
        """The levels ``fl``/``fr`` between ``left`` and ``right`` (floors, gaps as a column)
        proven with each building's floors bounded, on every grid interval, by the tighter of
        its linear bound (over the intervals where it provably stays linear) and its bound
        through yielding (:meth:`ModalBound.through_yielding`, any time; a linear building:
        its linear bound only).  Returns each level's horizon (s)."""
        dS = H / GRID

        def envelope(b: str, floors: np.ndarray, sign: float) -> np.ndarray:
            # sign * the upper (sign = 1) or lower (-1) bound of each floor over each grid
            # interval, the tighter of its parts: the free part within its rate bound of its
            # chord's mean, the forced part at the interval's end
            out = None
            parts = []
            s = prove_linear(b)
            if s > 0.0:                     # the linear bound's intervals: those ending by s
                parts.append((motions[b], int(round(s / dS))))
            bound = self.yielded.get(b)
            if bound is not None:
                _, ix, iv = self.buildings[b]
                parts.append((FloorMotion(bound, y[ix], y[iv], H, ground, forces.get(b)), GRID))
            for motion, valid in parts:
                free, forced, rate = motion.floors()
                x = free[floors]
                mid = x[:, :-1] + x[:, 1:]
                mid *= 0.5
                slack = (0.5 * dS * rate[floors])[:, None] + forced[floors, 1:]
                # sign * mid + slack, without the product (exact either way: -mid + slack is slack - mid)
                edge = mid + slack if sign > 0.0 else slack - mid
                if valid < GRID:
                    edge[:, valid:] = np.inf
                out = edge if out is None else np.minimum(out, edge)
            return out

        up = envelope(left, fl, 1.0)
        lo = -envelope(right, fr, -1.0)
        bad = up - lo - gap >= 0.0
        first = bad.argmax(axis=1).tolist()
        hit = _ANY(bad, axis=1).tolist()
        return [float(f) * dS if h else H for f, h in zip(first, hit)]
