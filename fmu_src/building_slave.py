"""building.fmu: a linear shear building integrated exactly for zero-order-hold inputs.

Storey count: the FMU has a fixed capacity of ``N_MAX = 20`` storeys (FMI 2.0 has no
variable-size arrays, so every ``m[i]``, ``k[i]``, ``x0[i]``, ``v0[i]``, ``F[i]``, ``x[i]``,
... exists for i = 1..20).  The Integer parameter ``n_storeys`` (1..N_MAX) selects how many
are used: elements above ``n_storeys`` are ignored (neither checked nor used) and their
outputs stay 0.

Physics (``fmu_src/shear_building.py``): ``M u'' + C u' + K u = -M 1 ag + F`` with ``u``
relative to the ground; ``T1 > 0`` scales the given ``k`` to that fundamental period;
``damping`` = ``rayleigh`` (modes 1 and min(2, n)) or ``modal``.  A one-storey building with
``k[1] = 0`` and ``zeta = 0`` is a free mass.

Each doStep is one matrix-vector product with a matrix precomputed per step size (cached in
the instance; an adaptive master uses a handful of step sizes), plus the quadratic form of
the exact damping energy.  Inputs ``ag`` and ``F[i]`` are taken as constant over the step
(feed the ground FMU's ``ag_mean`` and the contact FMU's impulse-preserving mean ``F``).
Outputs are at the end of the step; ``a[i]`` is the absolute acceleration with the step's
inputs.  Energies ``E_input``, ``E_external`` and ``E_damping`` accumulate from the start;
``E_kinetic`` and ``E_strain`` are instantaneous, so that
``E_input + E_external + E0 = E_kinetic + E_strain + E_damping`` with ``E0`` the initial
kinetic + strain energy.
"""
from __future__ import annotations

import math

import numpy as np

from .fmi_slave import SlaveBase as Fmi2Slave, SlaveError, Variable, array
from .shear_building import DAMPING_MODELS, ShearBuilding, ZohPropagator

N_MAX = 20  # build-time storey capacity
_MAX_CACHED_STEPS = 64
# Default storey stiffness: 1e5 kg * (2 pi / 0.5 s)^2, i.e. the default 1-storey building has T1 = 0.5 s.
_K_DEFAULT = 1e5 * (2.0 * math.pi / 0.5) ** 2


class Building(Fmi2Slave):
    """Linear shear building, 1 to N_MAX storeys (see module docstring)."""

    DESCRIPTION = f"Linear shear building (1..{N_MAX} storeys), exact zero-order-hold integration"
    DEFAULT_EXPERIMENT = (0.0, 10.0, 0.01)
    VARIABLES = (
        Variable("n_storeys", "Integer", start=1, low=1, high=N_MAX,
                 description=f"number of storeys used (capacity {N_MAX})"),
        *array("m", N_MAX, start=1e5, unit="kg", low=0.0, low_open=True, description="floor mass"),
        *array("k", N_MAX, start=_K_DEFAULT, unit="N/m", low=0.0,
               description="storey stiffness between floor i-1 and i (scaled if T1 > 0)"),
        Variable("T1", start=0.0, unit="s", low=0.0,
                 description="fundamental period the stiffnesses are scaled to; 0 = use k as given"),
        Variable("zeta", start=0.05, low=0.0, high=1.0, high_open=True, description="viscous damping ratio"),
        Variable("damping", "String", start="rayleigh", choices=DAMPING_MODELS,
                 description="damping model: rayleigh (modes 1 and 2) or modal (every mode)"),
        *array("x0", N_MAX, start=0.0, unit="m", description="initial floor displacement relative to the ground"),
        *array("v0", N_MAX, start=0.0, unit="m/s", description="initial floor velocity relative to the ground"),
        Variable("ag", causality="input", start=0.0, unit="m/s2",
                 description="ground acceleration, held constant over the step"),
        *array("F", N_MAX, causality="input", start=0.0, unit="N",
               description="external force on the floor, + along x, held constant over the step"),
        *array("x", N_MAX, causality="output", unit="m", description="floor displacement relative to the ground"),
        *array("v", N_MAX, causality="output", unit="m/s", description="floor velocity relative to the ground"),
        *array("a", N_MAX, causality="output", unit="m/s2", description="absolute floor acceleration"),
        *array("drift", N_MAX, causality="output", unit="m", description="inter-storey drift x[i] - x[i-1]"),
        Variable("base_shear", causality="output", unit="N", description="elastic shear of storey 1, k[1] x[1]"),
        Variable("E_kinetic", causality="output", unit="J", description="kinetic energy of the relative motion"),
        Variable("E_strain", causality="output", unit="J", description="strain energy of the storey springs"),
        Variable("E_damping", causality="output", unit="J", description="energy dissipated by viscous damping"),
        Variable("E_input", causality="output", unit="J",
                 description="relative input energy of the ground motion, -int v' M 1 ag dt"),
        Variable("E_external", causality="output", unit="J", description="work of the external forces F"),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # Storey elements are checked only up to n_storeys (in validate): unused ones are ignored.
        self._element_checks = tuple(slot for slot in self._checked if slot[2] is not None)
        self._checked = [slot for slot in self._checked if slot[2] is None]
        # The finite-input check is done in step(), vectorised over the active storeys: the
        # per-variable loop of the base class costs more than the step itself (21 inputs).
        self._real_inputs = []
        self._building: ShearBuilding | None = None
        self._steps: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    def validate(self):
        n = int(self.n_storeys)
        for var, attr, idx in self._element_checks:
            if idx < n:
                msg = var.violation(getattr(self, attr)[idx])
                if msg:
                    yield msg

    def initialize(self) -> None:
        n = int(self.n_storeys)
        masses, stiffnesses = self.m[:n].copy(), self.k[:n].copy()
        try:
            if self.T1 > 0.0:
                building = ShearBuilding.from_period(self.T1, masses, stiffnesses, self.zeta, self.damping)
            else:
                building = ShearBuilding(masses, stiffnesses, self.zeta, self.damping)
        except ValueError as exc:
            raise SlaveError(f"invalid parameters: {exc}") from None
        self._building = building
        self._n = n
        self._y = np.zeros(3 * n + 1)  # work buffer [u; v; ag; f]
        # Absolute acceleration = R z + f / m with z = [u; v].
        self._R = -np.hstack([building.K, building.C]) / building.masses[:, None]
        self._steps = {}
        for out in (self.x, self.v, self.a, self.drift):
            out[:] = 0.0
        self.x[:n] = self.x0[:n]
        self.v[:n] = self.v0[:n]
        self.E_input = self.E_external = self.E_damping = 0.0
        u, v = self.x[:n], self.v[:n]
        self.a[:n] = self._R @ np.concatenate([u, v]) + self.F[:n] / building.masses
        self.drift[:n] = building.drifts(u)
        self.base_shear = float(building.stiffnesses[0] * u[0])
        self.E_kinetic = building.kinetic_energy(v)
        self.E_strain = building.strain_energy(u)

    def _step_matrix(self, h: float) -> np.ndarray:
        """``G`` with ``G @ y`` = [u1; v1; a1; drift1; du; m' du; Q y; sqrt(m) v1; sqrt(k) drift1].

        ``y = [u0; v0; ag; f]``; ``Q`` is the exact damping-energy form (``E_damping = y' Q y``).
        Everything a step needs is one matrix-vector product and three dot products.
        """
        b, n = self._building, self._n
        prop = ZohPropagator(b, h)
        S = prop.step_matrix                       # [u1; v1] = S y
        Su = S[:n]
        accel = self._R @ S
        accel[:, 2 * n + 1:] += np.diag(1.0 / b.masses)
        D = np.eye(n) - np.eye(n, k=-1)            # drift = D u
        du = Su - np.eye(n, 3 * n + 1)
        G = np.vstack([S, accel, D @ Su, du, b.masses @ du, prop.damping_form,
                       np.sqrt(b.masses)[:, None] * S[n:], np.sqrt(b.stiffnesses)[:, None] * (D @ Su)])
        if len(self._steps) >= _MAX_CACHED_STEPS:
            self._steps.pop(next(iter(self._steps)))
        G = self._steps[h] = np.ascontiguousarray(G)
        return G

    @staticmethod
    def _non_finite_input(ag: float, f: np.ndarray) -> str:
        if not math.isfinite(ag):
            return f"input ag = {ag!r} m/s2 is not finite"
        i = int(np.flatnonzero(~np.isfinite(f))[0])
        return f"input F[{i + 1}] = {float(f[i])!r} N is not finite"

    def step(self, current_time: float, step_size: float) -> None:
        G = self._steps.get(step_size)
        if G is None:
            G = self._step_matrix(step_size)
        n = self._n
        ag = self.ag
        f = self.F[:n]
        if not (math.isfinite(ag) and np.isfinite(f).all()):
            raise SlaveError(self._non_finite_input(ag, f))
        y = self._y
        y[:n] = self.x[:n]
        y[n:2 * n] = self.v[:n]
        y[2 * n] = ag
        y[2 * n + 1:] = f
        w = G @ y
        i = 4 * n
        self.x[:n] = w[:n]
        self.v[:n] = w[n:2 * n]
        self.a[:n] = w[2 * n:3 * n]
        self.drift[:n] = w[3 * n:i]
        self.base_shear = float(self._building.stiffnesses[0] * w[0])
        self.E_external += float(f @ w[i:i + n])
        self.E_input -= ag * float(w[i + n])
        j = i + n + 1
        k = j + 3 * n + 1
        self.E_damping += float(y @ w[j:k])
        self.E_kinetic = 0.5 * float(w[k:k + n] @ w[k:k + n])
        self.E_strain = 0.5 * float(w[k + n:] @ w[k + n:])
