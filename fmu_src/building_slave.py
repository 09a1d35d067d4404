"""building.fmu: a shear building with linear, bilinear or Bouc-Wen storeys.

Storey count: the FMU has a fixed capacity of ``N_MAX = 20`` storeys (FMI 2.0 has no
variable-size arrays, so every ``m[i]``, ``k[i]``, ``x0[i]``, ``v0[i]``, ``F[i]``, ``x[i]``,
... exists for i = 1..20).  The Integer parameter ``n_storeys`` (1..N_MAX) selects how many
are used: elements above ``n_storeys`` are ignored (neither checked nor used) and their
outputs stay 0.

Physics (``fmu_src/shear_building.py``, ``fmu_src/hysteresis.py``): ``M u'' + C u' + D' V = -M 1
ag + F`` with ``u`` relative to the ground and ``V`` the storey shears; ``T1 > 0`` scales the
given ``k`` to that fundamental period; ``damping`` = ``rayleigh`` (modes 1 and min(2, n)) or
``modal``, always on the initial (elastic) stiffness, also while storeys yield.  A one-storey
linear building with ``k[1] = 0`` and ``zeta = 0`` is a free mass.  ``hysteresis`` chooses the
storey law: ``linear`` (``V = k d``), ``bilinear`` (kinematic hardening, yield shear ``Fy[i]``,
post-yield ratio ``alpha``) or ``bouc_wen`` (``bw_n``, ``bw_beta``, ``bw_gamma``, A = 1).

Inputs: ``F[i]`` is held constant over the step (feed the contact FMU's impulse-preserving
mean).  The ground acceleration is either ``ag`` held constant over the step (``n_knots =
0``, the default: feed the ground FMU's ``ag_mean``) or, with ``n_knots >= 2``, the polyline
through ``(t_knot[k], ag_knot[k])`` which must cover the step ``[t, t+h]`` (feed the ground
FMU's knots of the same step; ``ag`` is then ignored).

Integration (``fmu_src/building_response.py``): exact for linear and bilinear storeys (the
linear zero-order-hold step is one matrix-vector product with a matrix from the building's modes
in closed form (``shear_building.ModalZohPropagator``, no matrix exponential), cached per step
length to round-off (``linear_response.canonical_length``); the first step of a length, which a run may take only once, from the modal solution instead of building that
matrix; otherwise the modal solution with yield and unloading events located inside the step,
a step over several record intervals of one length in one product, a step of one record
interval in one product with a matrix cached per length, like the zero-order hold's); Bouc-Wen
by an embedded Runge-Kutta 8(5,3) method with error control.  Outputs are at the end of the step; ``a[i]`` is the absolute acceleration
with the step's force.  Running peaks (``x_peak``, ``drift_peak``, ``a_peak``, and from them
``mu``, ``drift_ratio_peak``) are located inside every step; ``V_peak`` (storey shear) is ``k
drift_peak`` for linear storeys and located alike for yielding ones
(``ExactPiecewiseLinear._track_shear``, ``BoucWenRK.advance``).  Energies ``E_input``,
``E_external``, ``E_damping`` and ``E_hysteretic`` accumulate from the start; ``E_kinetic`` and
``E_strain`` (the elastic part) are instantaneous, so that ``E_input + E_external + E0 =
E_kinetic + E_strain + E_damping + E_hysteretic`` with ``E0`` the initial kinetic + strain energy.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from .building_response import StepCost, integrator_for, ramp_energy_rows
from .fmi_slave import SlaveBase as Fmi2Slave, SlaveError, Variable, array
from .hysteresis import BOUC_WEN_MAX_N, HYSTERESIS_MODELS, StoreyHysteresis
from .linear_response import canonical_length
from .record_knots import KNOT_CAPACITY
from .shear_building import DAMPING_MODELS, ModalZohPropagator, ShearBuilding, ZohPropagator

N_MAX = 20  # build-time storey capacity
_MAX_CACHED_STEPS = 64          # step matrices by canonical step length
_MAX_STEP_ALIASES = 256         # exact step lengths remembered to their canonical one
# Up to this many storeys a zero-order-hold step length gets its matrices at its first step (no
# step without matrices, _zoh_entry).  Measured (CPU, loaded, lengths near 10 ms): matrices M, a
# step without them U, a step with them s, us:  n = 1: 68 / 82 / 8;  4: 73 / 91 / 8;  5: 86 / 92 / 9;
# 8: 104 / 97 / 10;  10: 123 / 98 / 11;  15: 235 / 109 / 17.  Building at once loses M + s - U on
# a length stepped once (nothing up to 4 storeys, 17 us at 8, 36 at 10) and saves U - s on every
# length stepped again (75-87 us): up to 10 storeys the saving is over twice the loss, so it pays
# unless two lengths in three are stepped once (free_vibration: 7 lengths per building, each
# stepped 5 times or more; a record's tail: a few lengths once each).  Taller buildings keep the
# first step without matrices (15 storeys: the loss 144 us, the saving 92).
_EAGER_MATRIX_STOREYS = 10
# Parameter bounds: generous beyond any building (a storey of the tallest tower is ~1e7 kg and
# 1e10 N/m, periods stay below 10 s), and tight enough that the eigenproblem and the matrix
# exponential stay in double precision: m = 1e-300 kg made LAPACK fail, m = 1e300 kg and
# T1 = 1e300 s (stiffnesses scaled to 0) overflowed or underflowed the matrices.
M_MIN, M_MAX = 1e-6, 1e12       # kg
K_MAX = 1e15                    # N/m
T1_MAX = 100.0                  # s
X0_MAX, V0_MAX = 1e3, 1e3       # m, m/s
# Default storey stiffness: 1e5 kg * (2 pi / 0.5 s)^2, i.e. the default 1-storey building has T1 = 0.5 s.
_K_DEFAULT = 1e5 * (2.0 * math.pi / 0.5) ** 2
# Knots must start and end at the step's ends to this fraction of the step (hosts pass the same
# doubles to every FMU; the margin only absorbs a host that rounds times differently).
_KNOT_TIME_TOL = 1e-9
# Outputs computed from the state when read (none of them is needed to advance the state).
# (rows of one block, N_MAX wide, filled at the first read after a step: x_peak, drift_peak and
# a_peak are the state's running peaks in one copy).  Reading a peak row runs the deferred
# in-step peak searches; reading V does not (Building._shear_row: the master reads V at every
# step and the peaks once at the end, so most searches are superseded before anyone reads
# them: default_inelastic ran 239 searches with V read at every step, 32 without).
# drift_residual is published at every step instead: the master reads it at every step to prove
# a gap open for a yielding building (cosim/master/gap_bound.py).
_DERIVED = ("V", "x_peak", "drift_peak", "a_peak", "drift_ratio_peak", "mu", "V_peak")


class Building(Fmi2Slave):
    """Shear building, 1 to N_MAX storeys, linear or yielding storeys (see module docstring)."""

    DESCRIPTION = (f"Shear building (1..{N_MAX} storeys) with linear, bilinear or Bouc-Wen storeys; exact "
                   f"integration for linear and bilinear storeys, zero- or first-order-hold ground motion")
    DEFAULT_EXPERIMENT = (0.0, 10.0, 0.01)
    VARIABLES = (
        Variable("n_storeys", "Integer", start=1, low=1, high=N_MAX,
                 description=f"number of storeys used (capacity {N_MAX})"),
        *array("m", N_MAX, start=1e5, unit="kg", low=M_MIN, high=M_MAX, description="floor mass"),
        *array("k", N_MAX, start=_K_DEFAULT, unit="N/m", low=0.0, high=K_MAX,
               description="storey stiffness between floor i-1 and i (scaled if T1 > 0)"),
        Variable("T1", start=0.0, unit="s", low=0.0, high=T1_MAX,
                 description="fundamental period the stiffnesses are scaled to; 0 = use k as given"),
        Variable("zeta", start=0.05, low=0.0, high=1.0, high_open=True, description="viscous damping ratio"),
        Variable("damping", "String", start="rayleigh", choices=DAMPING_MODELS,
                 description="damping model: rayleigh (modes 1 and 2) or modal (every mode), "
                             "on the initial stiffness"),
        *array("x0", N_MAX, start=0.0, unit="m", low=-X0_MAX, high=X0_MAX,
               description="initial floor displacement relative to the ground"),
        *array("v0", N_MAX, start=0.0, unit="m/s", low=-V0_MAX, high=V0_MAX,
               description="initial floor velocity relative to the ground"),
        Variable("hysteresis", "String", start="linear", choices=HYSTERESIS_MODELS,
                 description="storey law: linear, bilinear (kinematic hardening) or bouc_wen"),
        *array("Fy", N_MAX, start=0.0, unit="N", low=0.0,
               description="storey yield shear (> 0 needed by bilinear and bouc_wen; linear: only for mu)"),
        Variable("alpha", start=0.05, unit="1", low=0.0, high=1.0, high_open=True,
                 description="post-yield stiffness / elastic stiffness"),
        Variable("bw_n", start=2.0, unit="1", low=1.0, high=BOUC_WEN_MAX_N,
                 description="Bouc-Wen exponent (sharpness of yielding)"),
        Variable("bw_beta", start=0.5, unit="1",
                 description="Bouc-Wen beta (A = 1); needs bw_beta + bw_gamma > 0 and bw_beta >= bw_gamma"),
        Variable("bw_gamma", start=0.5, unit="1",
                 description="Bouc-Wen gamma; bw_beta + bw_gamma = 1 makes Fy the strength"),
        *array("storey_height", N_MAX, start=3.0, unit="m", low=0.0, low_open=True,
               description="storey height (for drift_ratio_peak)"),
        Variable("ag", causality="input", start=0.0, unit="m/s2",
                 description="ground acceleration, held constant over the step (used when n_knots = 0)"),
        *array("F", N_MAX, causality="input", start=0.0, unit="N",
               description="external force on the floor, + along x, held constant over the step"),
        Variable("n_knots", "Integer", causality="input", start=0,
                 description=f"0: ag held over the step; 2..{KNOT_CAPACITY}: ground acceleration linear "
                             f"between the knots t_knot/ag_knot, which must cover the step"),
        *array("t_knot", KNOT_CAPACITY, causality="input", start=0.0, unit="s",
               description="time of a ground-motion knot (first = step start, last = step end)"),
        *array("ag_knot", KNOT_CAPACITY, causality="input", start=0.0, unit="m/s2",
               description="ground acceleration at the knot"),
        *array("x", N_MAX, causality="output", unit="m", description="floor displacement relative to the ground"),
        *array("v", N_MAX, causality="output", unit="m/s", description="floor velocity relative to the ground"),
        *array("a", N_MAX, causality="output", unit="m/s2", description="absolute floor acceleration"),
        *array("drift", N_MAX, causality="output", unit="m", description="inter-storey drift x[i] - x[i-1]"),
        *array("V", N_MAX, causality="output", unit="N", description="storey shear (restoring, without damping)"),
        Variable("base_shear", causality="output", unit="N", description="storey shear of storey 1, V[1]"),
        *array("x_peak", N_MAX, causality="output", unit="m",
               description="peak |x[i]| so far, located inside the steps"),
        *array("drift_peak", N_MAX, causality="output", unit="m",
               description="peak |drift[i]| so far, located inside the steps"),
        *array("a_peak", N_MAX, causality="output", unit="m/s2",
               description="peak |a[i]| so far (the building's own, with the held force), located inside the steps"),
        *array("drift_ratio_peak", N_MAX, causality="output", unit="1",
               description="drift_peak[i] / storey_height[i]"),
        *array("mu", N_MAX, causality="output", unit="1",
               description="ductility demand drift_peak[i] / (Fy[i] / k[i]); 0 if Fy[i] = 0"),
        *array("drift_residual", N_MAX, causality="output", unit="m",
               description="plastic part of the drift, drift[i] - V[i] / k[i] (the residual drift at rest)"),
        Variable("E_kinetic", causality="output", unit="J", description="kinetic energy of the relative motion"),
        Variable("E_strain", causality="output", unit="J",
                 description="strain energy of the storeys (elastic part)"),
        Variable("E_damping", causality="output", unit="J", description="energy dissipated by viscous damping"),
        Variable("E_hysteretic", causality="output", unit="J",
                 description="energy dissipated by yielding storeys"),
        Variable("E_input", causality="output", unit="J",
                 description="relative input energy of the ground motion, -int v' M 1 ag dt"),
        Variable("E_external", causality="output", unit="J", description="work of the external forces F"),
        # last: the value references of the variables before it stay those of earlier versions
        *array("V_peak", N_MAX, causality="output", unit="N",
               description="peak |V[i]| so far, located inside the steps (linear: k[i] drift_peak[i])"),
    )
    # _stepped_lengths: the canonical zero-order-hold step lengths this history has stepped (part
    # of the state: which path a step takes must replay after fmi2SetFMUstate, see _zoh_entry)
    PRIVATE_STATE = ("_state", "_stepped_lengths")

    def __init__(self, **kwargs):
        self._state = None
        self._stepped_lengths = frozenset()
        self._derived_cache = None
        self._shear_fresh = False
        self._ramps = False
        super().__init__(**kwargs)
        # Storey elements are checked only up to n_storeys (in validate): unused ones are ignored.
        self._element_checks = tuple(slot for slot in self._checked if slot[2] is not None)
        self._checked = [slot for slot in self._checked if slot[2] is None]
        # The finite-input check is done in step(), vectorised over the active storeys: the
        # per-variable loop of the base class costs more than the step itself.
        self._real_inputs = []
        self._building: ShearBuilding | None = None
        self._integrator = None
        # zero-order-hold step matrices by canonical step length (linear_response.canonical_length:
        # a host's t_next - t repeats a length only to round-off), and by every exact length seen
        self._steps: dict[float, tuple[np.ndarray, np.ndarray | None]] = {}
        self._step_aliases: dict[float, tuple[np.ndarray, np.ndarray | None]] = {}
        self.cost = StepCost()   # cost counters since initialisation (not part of the FMU state)

    # -- derived outputs, computed when read -------------------------------------------------------
    def _element_getter(self, attr, idx):
        if attr not in _DERIVED:
            return super()._element_getter(attr, idx)

        if attr == "V":
            def get():
                return 0.0 if self._state is None else float(self._shear_row()[idx])
            return get

        def get():
            if self._state is None:
                return 0.0
            return float(self._derived()[attr][idx])
        return get

    def _array_reader(self, attr):
        if attr not in _DERIVED:
            return functools.partial(getattr, self, attr)
        return functools.partial(self._derived_array, attr)

    def _derived_array(self, attr: str) -> np.ndarray:
        """A derived output whole (N_MAX elements, 0 above n_storeys), as its element getters read it."""
        if self._state is None:
            return np.zeros(N_MAX)
        if attr == "V":
            return self._shear_row()
        return self._derived()[attr]

    def _shear_row(self) -> np.ndarray:
        """``V`` (row 0 of the block of derived outputs) without the deferred peak searches: the
        master reads V at every step and the peaks only at the end, and a search run at every
        step cannot be superseded by a later, higher peak (:meth:`ExactPiecewiseLinear._peaks`).
        Filled by :meth:`_publish` where it computes V anyway."""
        if not self._shear_fresh:
            self._derived_block[0, :self._n] = self._integrator.storey_shear(self._state)
            self._shear_fresh = True
        return self._derived_block[0]

    def _derived(self) -> dict[str, np.ndarray]:
        """The derived outputs of the current state by name, rows of one block N_MAX wide (0 above
        n_storeys), filled at the first read after a step (readers copy what they read at once)."""
        if self._derived_cache is None:
            state, integ, n = self._state, self._integrator, self._n
            integ.resolve_peaks(state, self.cost)      # the in-step peak searches left to do
            self._shear_row()
            block = self._derived_block
            block[1:4, :n] = state.peaks.reshape(3, n)  # x_peak, drift_peak, a_peak
            np.divide(state.peak_drift, self.storey_height[:n], out=block[4, :n])
            np.multiply(state.peak_drift, self._inv_yield_drift, out=block[5, :n])
            shear = integ.peak_storey_shear(state)
            if shear is None:     # linear storeys: V = k drift, exactly
                np.multiply(state.peak_drift, self._building.stiffnesses, out=block[6, :n])
            else:
                block[6, :n] = shear
            self._derived_cache = self._derived_rows
        return self._derived_cache

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self._derived_cache = None
        self._shear_fresh = False

    # -- initialisation ------------------------------------------------------------------------
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
            hysteresis = StoreyHysteresis(str(self.hysteresis), self.Fy[:n].copy(), float(self.alpha),
                                          float(self.bw_n), float(self.bw_beta), float(self.bw_gamma))
            integrator = integrator_for(building, hysteresis)
            state = integrator.initial_state(self.x0[:n], self.v0[:n], self.F[:n])
        except ValueError as exc:
            raise SlaveError(f"invalid parameters: {exc}") from None
        self._building = building
        self._integrator = integrator
        self._legacy = hysteresis.model == "linear"   # the linear zero-order-hold step of old
        self._free_mass = building.is_free_mass
        # a one-interval knot step through one matrix (_ramp_step): linear storeys (a bilinear
        # building's steps measured no cheaper that way: they publish through the integrator, and
        # the steps that may yield paid for the product before taking the general path)
        self._ramps = self._legacy and not self._free_mass
        # small buildings build a length's matrices at its first step (_EAGER_MATRIX_STOREYS)
        self._eager_matrices = n <= _EAGER_MATRIX_STOREYS
        self._n = n
        self._state = state
        self._derived_cache = None
        self._shear_fresh = False
        self.cost = StepCost()
        fy = self.Fy[:n]
        with np.errstate(divide="ignore"):
            self._inv_yield_drift = np.where(fy > 0.0, building.stiffnesses / np.where(fy > 0.0, fy, 1.0), 0.0)
        self._y = np.zeros(3 * n + 1)  # work buffer [u; v; ag; f]
        self._k1 = float(building.stiffnesses[0])       # N/m, the base shear's stiffness
        # what _step_matrix needs that does not depend on h: diag(1 / m), the drift rows D, the
        # rows picking u0 out of y, sqrt(m) and sqrt(k) as columns
        self._zoh_parts = (np.diag(1.0 / building.masses), np.eye(n) - np.eye(n, k=-1), np.eye(n, 3 * n + 1),
                           np.sqrt(building.masses)[:, None], np.sqrt(building.stiffnesses)[:, None])
        # where _linear_step's energy product splits: y' Q y, f' du, |sqrt(m) v1|^2, |sqrt(k) d1|^2
        self._energy_sections = np.array([0, 3 * n + 1, 4 * n + 1, 5 * n + 1])
        self._derived_block = np.zeros((len(_DERIVED), N_MAX))
        self._derived_rows = dict(zip(_DERIVED, self._derived_block))
        # Absolute acceleration = R z + f / m with z = [u; v].
        self._R = -np.hstack([building.K, building.C]) / building.masses[:, None]
        # [drift; a; sqrt(m) v; sqrt(k) drift] = P [u; v; f] for the linear building's outputs (_publish)
        publish = np.zeros((4 * n, 3 * n))
        publish[:n, :n] = np.eye(n) - np.eye(n, k=-1)
        publish[n:2 * n, :2 * n] = self._R
        publish[n:2 * n, 2 * n:] = np.diag(1.0 / building.masses)
        publish[2 * n:3 * n, n:2 * n] = np.diag(np.sqrt(building.masses))
        publish[3 * n:, :n] = np.sqrt(building.stiffnesses)[:, None] * publish[:n, :n]
        self._publish_rows = publish
        self._energy_halves = np.array([0, n])
        self._steps = {}
        self._step_aliases = {}
        self._stepped_lengths = frozenset()
        for out in (self.x, self.v, self.a, self.drift, self.drift_residual):
            out[:] = 0.0
        self._publish(self.F[:n])

    def _publish(self, force) -> None:
        """Outputs from the state (the integrator path and initialisation)."""
        n, state = self._n, self._state
        if self._legacy:
            # the linear building: drift and acceleration in one product
            u, v = state.u, state.v
            w = self._publish_rows @ np.concatenate((u, v, force))
            self.x[:n] = u
            self.v[:n] = v
            self.drift[:n] = w[:n]
            self.a[:n] = w[n:2 * n]
            self.base_shear = self._k1 * float(u[0])          # the first storey's drift is u[0]
            # twice the kinetic and strain energies as sums of squares of the last rows
            roots = w[2 * n:]
            kinetic, strain = np.add.reduceat(roots * roots, self._energy_halves).tolist()
            self.E_kinetic = 0.5 * kinetic
            self.E_strain = 0.5 * strain
        else:
            drift, V, accel, strain = self._integrator.response(state, force)
            self.x[:n] = state.u
            self.v[:n] = state.v
            self.drift[:n] = drift
            self.drift_residual[:n] = drift - V / self._building.stiffnesses   # d - V / k (fmu_src/hysteresis.py)
            self.a[:n] = accel
            self.base_shear = float(V[0])
            self._derived_block[0, :n] = V      # the V output (_shear_row), computed here anyway
            self.E_kinetic = 0.5 * float(state.v @ (self._building.masses * state.v))
            self.E_strain = strain
        self.E_input = state.E_input
        self.E_external = state.E_external
        self.E_damping = state.E_damping
        self.E_hysteretic = state.E_hysteretic
        self._derived_cache = None
        self._shear_fresh = not self._legacy

    # -- stepping ----------------------------------------------------------------------------
    def _zoh_entry(self, step_size: float):
        """The matrices of a zero-order-hold step of ``step_size`` s (those of its canonical length,
        built once: bit for bit those of ``step_size`` when the host repeats a decimal length), or
        None at the first step of that length in this history: that step is taken from the modal
        solution without building matrices (``ExactPiecewiseLinear.advance_unmapped``).  A length a
        run steps once (the tail of a record: 0.02 to 0.16 s, one step each) would cost more to
        build (the closed-form step matrix with its damping form's quadrature, and the rows of the
        in-step peak search) than its step; from its second step on, the matrices pay.  Which
        lengths were stepped is part of the FMU state, so a restored state takes the same paths.
        A small building (up to _EAGER_MATRIX_STOREYS storeys, where the matrices cost little more
        than a step without them) builds them at the first step: never None."""
        entry = self._step_aliases.get(step_size)
        if entry is None:
            # a free mass (one storey, k = 0: its matrices cost nothing) keeps the matrix of the
            # exact length, bit for bit as before: its runs in tests/test_hard_cases.py decide
            # a first-order rebound by where the adaptive steps land, which round-off moves
            key = step_size if self._free_mass else canonical_length(step_size)
            if not self._eager_matrices and key not in self._stepped_lengths and self._unmapped_fits(key):
                self._stepped(key)
                return None
            entry = self._steps.get(key)
            if entry is None:
                entry = self._step_matrix(key, step_size)
            if len(self._step_aliases) >= _MAX_STEP_ALIASES:
                self._step_aliases.clear()
            self._step_aliases[step_size] = entry
        elif not self._eager_matrices and entry[2] not in self._stepped_lengths and self._unmapped_fits(entry[2]):
            self._stepped(entry[2])      # a state restored from before the first step of this length
            return None
        return entry

    def _unmapped_fits(self, h: float) -> bool:
        """True if a step of ``h`` s can be taken without matrices (not a free mass, whose modal
        basis is defective; a quadrature within its limit, ``ExactPiecewiseLinear.fits_unmapped``)."""
        return not self._free_mass and self._integrator.fits_unmapped(h)

    def _stepped(self, key: float) -> None:
        lengths = self._stepped_lengths if len(self._stepped_lengths) < _MAX_CACHED_STEPS else frozenset()
        self._stepped_lengths = lengths | {key}

    def _step_matrix(self, h: float, asked: float | None = None):
        """``G`` with ``G @ y`` = [u1; v1; a1; drift1; m' du; Q y; du; sqrt(m) v1; sqrt(k) drift1;
        start rows], and the matrices of the in-step peak search (``ExactPiecewiseLinear.legacy_rows``,
        whose ``start`` rows are the last rows of ``G``).

        ``y = [u0; v0; ag; f]``; ``Q`` is the exact damping-energy form (``E_damping = y' Q y``).
        Everything a step needs is one matrix-vector product and one elementwise product whose
        four partial sums are the energies (:meth:`_linear_step`).  The step
        matrix and ``Q`` from the building's modes in closed form (``ModalZohPropagator``: no
        matrix exponential per new step length); a free mass (no oscillating mode) keeps the
        block exponential (``ZohPropagator``), bit for bit as before.
        """
        b, n = self._building, self._n
        asked = h if asked is None else asked
        with np.errstate(over="ignore", invalid="ignore"):   # an overflow is refused below, in one message
            if self._free_mass:
                prop = ZohPropagator(b, h)
            else:
                try:
                    prop = ModalZohPropagator(b, h)
                except ValueError as exc:
                    raise SlaveError(f"a step of h = {asked!r} s is beyond what the building's arithmetic supports "
                                     f"({exc}); use a shorter step") from None
            S = prop.step_matrix                       # [u1; v1] = S y
            Su = S[:n]
            inv_m, D, u0_rows, sqrt_m, sqrt_k = self._zoh_parts
            accel = self._R @ S
            accel[:, 2 * n + 1:] += inv_m
            du = Su - u0_rows
            drift = D @ Su
            G = np.concatenate((S, accel, drift, (b.masses @ du)[None, :], prop.damping_form, du,
                                sqrt_m * S[n:], sqrt_k * drift))
        if not np.isfinite(G).all():
            # the block exponential (and Van Loan's damping integral, which grows like
            # exp(2 zeta w h)) overflows: no step of this length can be computed
            fastest = float(np.max(b.omegas))
            raise SlaveError(f"a step of h = {asked!r} s is beyond what the building's arithmetic supports (its step "
                             f"matrix overflows; fastest mode {fastest:.3g} rad/s, zeta = {b.damping_ratio:g}); "
                             f"use a shorter step")
        peaks = None
        if not self._free_mass:
            start, scan, reach = self._integrator.legacy_rows(h, S)
            G = np.vstack([G, start])            # the peak search's start values: rows of the same product
            peaks = (scan, reach)
        if len(self._steps) >= _MAX_CACHED_STEPS:
            self._steps.pop(next(iter(self._steps)))
        entry = self._steps[h] = (np.ascontiguousarray(G), peaks, h)
        return entry

    @staticmethod
    def _non_finite_input(ag: float, f: np.ndarray) -> str:
        if not math.isfinite(ag):
            return f"input ag = {ag!r} m/s2 is not finite"
        i = int(np.flatnonzero(~np.isfinite(f))[0])
        return f"input F[{i + 1}] = {float(f[i])!r} N is not finite"

    def step(self, current_time: float, step_size: float) -> None:
        knots = self._knots(current_time, step_size) if self.n_knots else None
        unmapped = False
        if knots is None and self._legacy:
            entry = self._zoh_entry(step_size)
            if entry is not None:
                self._linear_step(step_size, entry)
                return
            unmapped = True      # the first step of its length: no matrices built (_zoh_entry)
        n = self._n
        f = self.F[:n]
        # one sum (of Python floats: cheaper than numpy's for a few) instead of a per-element test;
        # a sum that is not finite is looked at closely
        finite = math.isfinite(sum(f.tolist())) or bool(np.isfinite(f).all())
        if knots is None:
            ag = float(self.ag)
            if not (math.isfinite(ag) and finite):
                raise SlaveError(self._non_finite_input(ag, f))
            times, values = (0.0, step_size), (ag, ag)
        else:
            if not finite:
                raise SlaveError(self._non_finite_input(0.0, f))
            if self._free_mass:
                raise SlaveError("n_knots > 0 needs a building with storeys: a free mass (k[1] = 0) takes "
                                 "ag held over the step (n_knots = 0)")
            times, values = knots
            if times.size == 2 and self._ramps:
                self._ramp_step(step_size, values, f)
                return
        state = self._state
        # what to restore if the step is refused: the integrators replace the state's fields,
        # never change them in place, except the list of deferred peak searches
        before = state.shallow()
        try:
            if unmapped:
                cost = self._integrator.advance_unmapped(state, step_size, values[0], f)
            else:
                cost = self._integrator.advance(state, times, values, f)
        except ValueError as exc:
            self._state = before
            raise SlaveError(f"{exc} (nothing was changed)") from None
        if not math.isfinite(sum(state.u.tolist()) + sum(state.v.tolist())):   # (Python floats: cheaper)
            self._state = before
            raise SlaveError(f"a step of h = {step_size!r} s would leave the building's state not finite: the "
                             f"inputs or the step are beyond what its arithmetic supports (nothing was changed)")
        self._count(cost)
        self._publish(f)

    def _ramp_step(self, step_size: float, values: np.ndarray, f: np.ndarray) -> None:
        """A step of one knot interval of a linear building (the ground acceleration linear over
        it, ``values`` at its ends) through one cached matrix (``ExactPiecewiseLinear.ramp_step``):
        the outputs are rows of the same product, as in :meth:`_linear_step`."""
        ag0 = float(values[0])
        ag1 = (values[1] - values[0]) / step_size      # advance's arithmetic (the same slope)
        state = self._state
        try:
            w = self._integrator.ramp_step(state, step_size, ag0, float(ag1), f, self.cost)
        except ValueError as exc:
            raise SlaveError(f"{exc} (nothing was changed)") from None
        n = self._n
        k = ramp_energy_rows(n)         # sqrt(m) v1, then sqrt(k) d1
        self._publish_product(w, 0.5 * float(w[k:k + n] @ w[k:k + n]),
                              0.5 * float(w[k + n:k + 2 * n] @ w[k + n:k + 2 * n]))

    def _count(self, cost: StepCost) -> None:
        total = self.cost
        total.segments += cost.segments
        total.cleared += cost.cleared
        total.events += cost.events
        total.root_searches += cost.root_searches
        total.peak_searches += cost.peak_searches
        total.peaks_deferred += cost.peaks_deferred
        total.rk_steps += cost.rk_steps
        total.rhs_evaluations += cost.rhs_evaluations

    def _linear_step(self, step_size: float, entry) -> None:
        """The linear zero-order-hold step: one product with a cached matrix (:meth:`_zoh_entry`)
        gives the end state, the outputs, the energies' factors and the peak search's start values."""
        G, peaks, _ = entry
        n = self._n
        ag = self.ag
        f = self.F[:n]
        # one sum of Python floats (cheaper than numpy's on a few) instead of a per-element test;
        # a sum that is not finite (an overflow too) is looked at closely
        if not math.isfinite(ag + sum(f.tolist())) and not (math.isfinite(ag) and np.isfinite(f).all()):
            raise SlaveError(self._non_finite_input(ag, f))
        state = self._state
        y = self._y
        y[:n] = state.u
        y[n:2 * n] = state.v
        y[2 * n] = ag
        y[2 * n + 1:] = f
        w = G @ y
        # rows (_step_matrix): [u1; v1; a1; drift1; m' du; Q y; du; sqrt(m) v1; sqrt(k) drift1; start]
        i = 4 * n
        j = i + 1
        k = j + 4 * n + 1
        # the energies as partial sums of one elementwise product: y' Q y, f' du and twice the
        # kinetic and strain energies (sums of squares)
        d_damping, d_external, kinetic, strain = np.add.reduceat(
            w[j:k + 2 * n] * np.concatenate((y, f, w[k:k + 2 * n])), self._energy_sections).tolist()
        d_input = -ag * float(w[i])
        kinetic *= 0.5
        strain *= 0.5
        # a non-finite displacement or velocity makes one of these non-finite (each is a sum of
        # squares or products of them): refuse before anything changes
        if not math.isfinite(kinetic + strain + d_damping + d_input + d_external):
            raise SlaveError(f"a step of h = {step_size!r} s with ag = {ag!r} m/s2 would leave the building's "
                             f"state not finite: the inputs or the step are beyond what its arithmetic supports "
                             f"(nothing was changed)")
        if peaks is None:
            self._free_mass_peaks(ag, f[0], step_size)
        else:
            scan, reach = peaks
            self._integrator.legacy_peaks(state, y, w[k + 2 * n:], scan, reach, step_size, self.cost)
        state.u = w[:n]           # views of the fresh product: nothing else writes to w
        state.v = w[n:2 * n]
        state.E_external += d_external
        state.E_input += d_input
        state.E_damping += d_damping
        self._publish_product(w, kinetic, strain)

    def _publish_product(self, w: np.ndarray, kinetic: float, strain: float) -> None:
        """Outputs of a linear building's step taken as one product ``w = [u1; v1; a1; drift1;
        ...]`` (:meth:`_linear_step`, :meth:`_ramp_step`), with its kinetic and strain energies
        (J) and the state's energy sums already advanced."""
        n, state = self._n, self._state
        self.x[:n] = w[:n]
        self.v[:n] = w[n:2 * n]
        self.a[:n] = w[2 * n:3 * n]
        self.drift[:n] = w[3 * n:4 * n]
        self.base_shear = self._k1 * float(w[0])
        self.E_external = state.E_external
        self.E_input = state.E_input
        self.E_damping = state.E_damping
        self.E_kinetic = kinetic
        self.E_strain = strain
        self._derived_cache = None
        self._shear_fresh = False

    def _step_outputs_problem(self) -> str | None:
        return None   # step() refuses a non-finite state before committing it (both paths)

    def _free_mass_peaks(self, ag: float, force: float, h: float) -> None:
        """In-step peaks of a free mass: u(s) = u0 + v0 s + acc s^2 / 2 with acc = F/m - ag."""
        state = self._state
        u0, v0 = float(state.u[0]), float(state.v[0])
        acc = force / float(self._building.masses[0]) - ag
        candidates = [abs(u0 + v0 * h + 0.5 * acc * h * h)]
        if acc != 0.0 and 0.0 < -v0 / acc < h:
            s = -v0 / acc
            candidates.append(abs(u0 + v0 * s + 0.5 * acc * s * s))
        peak = max(float(state.peaks[0]), *candidates)
        state.peaks = np.array([peak, peak, max(float(state.peaks[2]), abs(force / float(self._building.masses[0])))])

    def _knots(self, t: float, h: float):
        """Knot times relative to the step start and values, checked against the step."""
        count = int(self.n_knots)
        if not 2 <= count <= KNOT_CAPACITY:
            raise SlaveError(f"input n_knots = {count} is outside the allowed range: 0 (ag held) or "
                             f"2 <= n_knots <= {KNOT_CAPACITY}")
        times = self.t_knot[:count]
        values = self.ag_knot[:count].copy()
        listed = times.tolist()      # the checks on Python floats: the same IEEE comparisons, cheaper
        # (a sum that is not finite is looked at element by element)
        if not math.isfinite(sum(listed) + sum(values.tolist())) and not (
                np.isfinite(times).all() and np.isfinite(values).all()):
            for name, arr, unit in (("t_knot", times, "s"), ("ag_knot", values, "m/s2")):
                bad = np.flatnonzero(~np.isfinite(arr))
                if bad.size:
                    i = int(bad[0])
                    raise SlaveError(f"input {name}[{i + 1}] = {float(arr[i])!r} {unit} is not finite")
        tol = _KNOT_TIME_TOL * h
        first, last = listed[0], listed[-1]
        if abs(first - t) > tol or abs(last - (t + h)) > tol:
            raise SlaveError(
                f"the knots t_knot[1..{count}] cover [{first:.9g}, {last:.9g}] s but this step is "
                f"[{t:.9g}, {t + h:.9g}] s: feed the ground motion's knots of the same step (step the "
                f"ground motion first, as Gauss-Seidel does; a Jacobi master hands over the previous "
                f"step's) or set n_knots = 0")
        if count == 2:
            # the ends only (in order: within 1e-9 h of t and t + h), relative to the step start
            return np.array((0.0, h)), values
        if listed != sorted(listed):
            i = int(np.flatnonzero(np.diff(times) < 0.0)[0])
            raise SlaveError(f"input t_knot must not decrease: t_knot[{i + 1}] = {times[i]:.9g} s > "
                             f"t_knot[{i + 2}] = {times[i + 1]:.9g} s")
        rel = times - t
        rel[0] = 0.0
        rel[-1] = h
        # non-decreasing: only the inner ends can leave [0, h] (by the ends' tolerance)
        if listed[1] - t < 0.0 or listed[-2] - t > h:
            np.maximum(rel, 0.0, out=rel)    # np.clip's arithmetic without its Python overhead
            np.minimum(rel, h, out=rel)
        return rel, values
