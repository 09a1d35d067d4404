"""Response of a shear building with hysteretic storeys over one communication step.

The step ``[0, h]`` (times relative to its start) is driven by

* the ground acceleration, piecewise linear through knots ``(times[j], ag[j])`` with
  ``times[0] = 0`` and ``times[-1] = h`` (first-order hold; two equal times encode a jump;
  a zero-order hold is the two knots ``(0, a), (h, a)``), and
* constant external floor forces ``force`` (N) (the contact FMU hands over the mean force).

Two integrators, one per kind of law, registered in ``INTEGRATORS``:

* :class:`ExactPiecewiseLinear` (``"linear"``, ``"bilinear"``): between yield and unloading
  events the building is linear (:mod:`fmu_src.linear_response`) and its exact solution is
  evaluated in modal form.  Events (an elastic storey reaching ``|d - s| = dy``; a yielding
  storey whose drift velocity changes sign) are located by bisection and bracketed Newton to
  ``EVENT_XTOL`` of the step.  The integration is exact up to round-off and that tolerance.
* :class:`BoucWenRK` (``"bouc_wen"``): the smooth Bouc-Wen law has no closed form; an embedded
  Runge-Kutta method of order 8(5,3) (Dormand-Prince, scipy's ``DOP853``) with error control
  (``rtol``, default ``1e-8``) integrates every knot interval, restarted at knots (where the
  forcing has a kink).

Both track the energy terms (``E_input``, ``E_external``, ``E_damping``, ``E_hysteretic``) and
the running peaks of ``|x[i]|``, ``|drift[i]|`` and the absolute floor acceleration ``|a[i]|``
inside the step, not only at its end, and for yielding storeys that of the storey shear
``|V[i]|`` (:meth:`ExactPiecewiseLinear._track_shear`; a linear storey's is ``k`` times its
peak drift).  The exact integrator works in three tiers, so that a
step where nothing happens costs a few vector operations:

1. a bound on how far every watched function can move in the segment (precomputed per
   configuration and segment length, :meth:`Configuration.change_bounds`, applied to
   ``|z'(0)|``) clears most segments at once: no storey can reach its limit, no function can
   pass its running peak; for the storeys it leaves, the same test to second order (the drift
   rates and accelerations with a bound of the next derivative,
   :meth:`ExactPiecewiseLinear._second_order_quiet`; in a batch of intervals, whose end states
   are all known, the chord through both ends with that bound,
   :meth:`ExactPiecewiseLinear._chord_quiet`);
2. for the functions it does not clear, cubic Hermite interpolation through the end values and
   slopes with a bound of the fourth derivative (:class:`~fmu_src.linear_response.Scan`);
3. for the few left, bisection and bracketed Newton on the exact solution
   (:func:`~fmu_src.linear_response.first_root`, :func:`~fmu_src.linear_response.max_abs`), on
   each function's Taylor polynomial (Python floats,
   :class:`~fmu_src.linear_response.TaylorSegment`; in modal form where a segment is too long
   for it).

A yielding building meets many stiffness configurations (yield patterns), most of them for a
few intervals: a pattern's segments are evaluated ad hoc (:class:`TaylorSegment`, their end
state and scan from its real Taylor coefficients, :class:`~fmu_src.linear_response.TaylorScan`)
until its ``MAP_AFTER_SEGMENTS + 1``-th, from which its cached segment map of that length
serves them.
A linear building's step of one knot interval takes one product with a matrix made from the
segment map of its length (:meth:`ExactPiecewiseLinear.ramp_step`, :class:`RampStep`): the end
state, the outputs, the energy increments and tier 1 at once, with the decisions of the general
path.

Bouc-Wen peaks are located on the dense output of every Runge-Kutta step where the
derivative changes sign.  The absolute acceleration is the building's own, ``M^-1 (f - C v -
D' V)`` with the held force.  Rayleigh or modal damping stays the initial (elastic) one in
every state.
"""
from __future__ import annotations

import copy
import math
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import DOP853
from scipy.optimize import brentq

from .hysteresis import (StoreyHysteresis, bilinear_offset, bilinear_plastic_force,
                                bilinear_strain_energy, bilinear_tangent)
from .linear_response import (CHUNK_RATE, MAX_CHUNKS, Configuration, ConfigurationConstants, ModalSegment, Scan,
                              SegmentMap, TaylorScan, TaylorSegment, canonical_length, first_root,
                              hermite_range_scalar, hermite_ranges, max_abs)
from .shear_building import ShearBuilding

EVENT_XTOL = 1e-12          # relative to the step: events located to 1e-12 h
PEAK_XTOL = 1e-7            # relative to the segment: a peak's time to 1e-7 L (its value to ~(w L 1e-7)^2)
# Peaks are established to PEAK_RTOL relative (linear_response) plus these absolute amounts,
# far below any engineering meaning: a response of 1e-15 m at the start of a record is not
# searched through (its bounds are dominated by cancelling modal terms).
PEAK_ATOL = (1e-12, 1e-12, 1e-9)   # |x| (m), |drift| (m), |a| (m/s^2)
MAX_PENDING = 256           # deferred peak searches kept before they are run anyway
MAX_EVENTS_PER_STEP = 10000  # a bound on yield/unloading events in one communication step
MAX_CONFIGURATIONS = 256    # cached stiffness configurations per building
MAX_PLANS = 16              # segment maps with a batch plan (ExactPiecewiseLinear._batch_plan) per building
MAX_CHAINS = 8              # interval counts with a chain (ExactPiecewiseLinear._chain) per plan
# ad hoc segments of a yield pattern before its segment map is built: about what the map costs
# (ten ad hoc segments, _worth_a_map), so a pattern never costs more than twice the cheaper of
# the two ways (rent-or-buy); kasai_maison_inelastic's building replay (loaded, best of 3):
# 2 -> 80 maps built, 657 ms; 8 -> 27 maps, 607 ms; 16 -> 10 maps, 604 ms
MAP_AFTER_SEGMENTS = 8
MAX_SPLIT_INTERVALS = 32    # intervals a step's long intervals are split into at most (_even_intervals)
# a knot interval shorter than this fraction of its step is a sliver left by the round-off of
# knot times (2e-12 of a 10 ms step measured), taken as a jump (_even_intervals)
SLIVER = 1e-11
MAX_RAMP_STEPS = 64         # one-interval step matrices (RampStep) by canonical length per building
# Bouc-Wen's work per communication step.  The span: the same bound as the exact integrator's
# quadrature (MAX_CHUNKS chunks of CHUNK_RATE / |lambda|), |lambda| h <= 8192, about 1300 periods
# of the fastest elastic mode; a longer step (h = 1e6 s ran for minutes) is refused before any
# work.  The Runge-Kutta steps: 1.6-15 per period of the fastest mode measured (1, 3 and 10
# storeys, bw_n 2 and 20, steps of 0.01-100 s), so the longest allowed span needs about 20,000;
# more means the integration is stuck on a stiff yield corner, not progressing.
BOUC_WEN_MAX_SPAN = CHUNK_RATE * MAX_CHUNKS     # |lambda|_max h, dimensionless
BOUC_WEN_MAX_RK_STEPS = 20_000                  # per communication step
_ROOT_BUDGET = 200          # evaluations per root search (bisection depth ~ 2^-100 of the segment)
_HERMITE_SLOPE_GAIN = 4.0 / 27.0   # max |h10|, |h11| on [0, 1] (cubic Hermite basis), see _peaks
_PREFILTER_FROM = 16        # candidate functions from which _peaks drops the clear ones at once
# round-off margin of the Hermite bounds (relative to the sum of the magnitudes of the end
# values and slopes): the floating-point Hermite test stays within 1e-12 of the exact range
# (test_the_peak_prefilter_bound_dominates_the_hermite_test measures < 1e-14), and the bound's
# own evaluation adds a few eps
_HERMITE_MARGIN = 2e-12


def _hermite_spread(g0: float, g1: float, d0: float, d1: float) -> float:
    """How far :func:`hermite_range_scalar` ``(g0, g1, d0, d1)`` can reach beyond the end values,
    round-off included: ``lo >= min(g0, g1) - spread`` and ``hi <= max(g0, g1) + spread``.

    On [0, 1] the cubic Hermite is ``h00 g0 + h01 g1 + h10 d0 + h11 d1`` with ``h00 + h01 = 1``,
    both in [0, 1], and ``|h10|, |h11| <= 4/27``; the floating-point range stays within 1e-12 of
    the magnitudes of the end values and slopes of that (``_HERMITE_MARGIN``,
    ``test_the_peak_prefilter_bound_dominates_the_hermite_test``).  Rounding being monotonic, a
    test that this wider range passes, the range itself passes: a prefilter that skips the roots."""
    a0, a1 = abs(d0), abs(d1)
    return _HERMITE_SLOPE_GAIN * (a0 + a1) + _HERMITE_MARGIN * (abs(g0) + abs(g1) + a0 + a1)


@dataclass
class BuildingState:
    """Everything a building carries from one step to the next (copied by FMU state, :meth:`snapshot`).

    ``u``, ``v`` floor displacements (m) and velocities (m/s) relative to the ground;
    ``slip`` (m) and ``mode`` (0, +1, -1) the bilinear storeys' state; ``z`` (-) the Bouc-Wen
    variable and ``rk_step`` (s) its integrator's step (part of the state, so that a restored
    state replays bit for bit); ``peaks`` the running peaks established so far and ``pending``
    the segments that may still raise them (searched when the peaks are read); ``peaks`` the running peaks ``[|x| (m), |drift| (m), |a| (m/s^2)]`` (3n, also
    as views ``peak_x``, ``peak_drift``, ``peak_accel``); energies (J) accumulated from the start.
    """

    u: np.ndarray
    v: np.ndarray
    slip: np.ndarray
    mode: np.ndarray
    z: np.ndarray
    peaks: np.ndarray
    E_input: float = 0.0
    E_external: float = 0.0
    E_damping: float = 0.0
    E_hysteretic: float = 0.0
    rk_step: float = 0.0      # Bouc-Wen: the last accepted Runge-Kutta step (s), the next first guess
    # bilinear: the floor forces of the storeys' constant parts D' r (N), a cache of (mode, slip)
    # cleared at every event (r does not depend on the slip of a yielding storey)
    offset: np.ndarray | None = None
    # yielding storeys (bilinear, Bouc-Wen): the running peak of |V[i]| (N) inside the steps
    # (:meth:`ExactPiecewiseLinear._track_shear`, :meth:`BoucWenRK.advance`); None for linear
    # storeys, whose peak shear is k times the peak drift
    peak_shear: np.ndarray | None = None
    # bilinear: which storeys have yielded so far (a storey that has not has V = k d, and its peak
    # shear is k times its peak drift, below Fy, the shear at its first yield)
    yielded: np.ndarray | None = None
    # segments in which a peak may exceed ``peaks``, searched when the peaks are read
    # (:meth:`ExactPiecewiseLinear.resolve_peaks`): (function, bound, configuration key, y, L, xtol)
    pending: list = field(default_factory=list)

    @property
    def peak_x(self) -> np.ndarray:
        return self.peaks[:self.u.size]

    @property
    def peak_drift(self) -> np.ndarray:
        n = self.u.size
        return self.peaks[n:2 * n]

    @property
    def peak_accel(self) -> np.ndarray:
        return self.peaks[2 * self.u.size:]

    def copy(self) -> "BuildingState":
        return copy.deepcopy(self)

    def shallow(self) -> "BuildingState":
        """A copy sharing the arrays (the integrators replace a state's arrays, never change them
        in place) with a list of deferred peak searches of its own: what a refused step restores."""
        new = object.__new__(BuildingState)
        new.__dict__.update(self.__dict__)
        new.pending = list(self.pending)
        return new

    def snapshot(self) -> "BuildingState":
        """A copy as independent as :meth:`copy`, for an FMU state (:func:`fmu_src.fmi_slave.snapshot`).

        The arrays are copied and the list of deferred peak searches is a new list of the same
        entries: an entry is a tuple of numbers, bytes and an array that nothing writes to after
        it was made (:meth:`ExactPiecewiseLinear._peaks` stores a copy of the segment's start),
        so sharing entries is safe, and copying them was most of the cost of a deep copy (up to
        ``MAX_PENDING`` entries, 0.4-0.7 ms per state).
        """
        new = object.__new__(BuildingState)
        fields = new.__dict__
        for name, value in self.__dict__.items():
            if type(value) is np.ndarray:
                value = value.copy()
            elif type(value) is list:
                value = list(value)
            fields[name] = value
        return new


@dataclass
class StepCost:
    """Cost counters of :meth:`advance` (summed by the caller if wanted)."""

    segments: int = 0
    cleared: int = 0          # segments cleared by the cheap bound (tier 1)
    events: int = 0
    root_searches: int = 0
    peak_searches: int = 0    # in-step peak searches run (max_abs)
    peaks_deferred: int = 0   # segments set aside for a search when the peaks are read
    rk_steps: int = 0
    rhs_evaluations: int = 0
    event_log: list = field(default_factory=list)   # (time in the step (s), storey index, kind)


@dataclass(frozen=True)
class RampStep:
    """A linear building's one-interval step of length ``length`` (s), the ground acceleration
    linear over it (first-order hold), as one matrix (:meth:`ExactPiecewiseLinear.ramp_step`).

    ``matrix @ y`` with ``y = [u0; v0; ag0; ag1; f]`` (``ag1`` the slope, m/s^3; ``f`` the floor
    forces, N) gives, in rows of this order: the end state ``[u1; v1]`` (2n), the absolute
    accelerations ``a1`` (n), the drifts ``d1`` (n), ``u1 - u0`` (n), the two input-energy rows
    ``r0, r1`` (``E_input`` increment ``= ag0 r0 y + ag1 r1 y``), ``Q y`` (the damping form,
    ``E_damping`` increment ``= y' Q y``; 3n + 2), ``sqrt(m) v1`` and ``sqrt(k) d1`` (n each,
    from row :func:`ramp_energy_rows`: twice the kinetic and the strain energy as sums of
    squares), then from row ``start`` what tier 1 needs: ``Re, Im W z'(0)`` (4n), the tracked
    functions at 0 (x, drift, a; 3n) and ``ag1``; ``reach @ |that|`` is tier 1's reach of every
    tracked function (its value at 0 plus the change bound, the ramp's term included).  Built
    from the segment map (``smap``, of the elastic configuration ``cfg``) that
    :meth:`ExactPiecewiseLinear._interval` uses: the same physics, one product instead of a
    dozen numpy calls.
    """

    length: float
    cfg: Configuration
    smap: SegmentMap
    matrix: np.ndarray
    reach: np.ndarray
    start: int


def _drift(u: np.ndarray) -> np.ndarray:
    d = u.copy()
    d[1:] -= u[:-1]
    return d


def _drift_rows(u: np.ndarray) -> np.ndarray:
    """:func:`_drift` of every row of ``u`` (states by rows)."""
    d = u.copy()
    d[:, 1:] -= u[:, :-1]
    return d


def _state_and_scan(segment, poly, z0: np.ndarray, w: np.ndarray, s: float, ag_slope: float) -> tuple[np.ndarray, Scan]:
    """A segment's state at ``s`` and its :class:`~fmu_src.linear_response.Scan` over ``[0, s]``
    (``ag_slope``: the ground acceleration's slope, m/s^3): from its Taylor coefficients
    (``poly``, a :class:`TaylorScan`) where it has them, else from its exact solution
    (``segment.state``, :meth:`Configuration.scan_vector`)."""
    cfg = segment.cfg
    if poly is not None:
        z1, G = poly.state_and_values(s)
        return z1, Scan.of_parts(cfg, G, poly.rate0, ag_slope, s)
    z1 = segment.state(s)
    return z1, Scan(cfg, cfg.scan_vector(z0, z1, w, s), ag_slope, s)


def _floor_forces(V: np.ndarray) -> np.ndarray:
    """``D' V``: storey shears to floor forces (storey i acts on floors i-1 and i)."""
    out = V.copy()
    out[:-1] -= V[1:]
    return out


def ramp_energy_rows(n: int) -> int:
    """The first row of ``sqrt(m) v1`` in :class:`RampStep`'s product (``sqrt(k) d1`` follows)."""
    return 8 * n + 4

def _even_intervals(times: np.ndarray, ag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The knots of a step with every interval that is an integer multiple (to round-off) of the
    shortest one split into intervals of that length, the ground acceleration interpolated
    linearly at the new knots (the same polyline: the same exact response); the knots as given
    if none is, or if the split would give more than ``MAX_SPLIT_INTERVALS``.  First, an
    interval shorter than ``SLIVER`` of the step becomes a jump (see below).

    A record's last samples leave one long interval to the end of the run (El Centro: 0.19 and
    0.31 s after 10 ms ones); its segment map, made for that one step, cost 7 and 13 ms for 15
    storeys (the energy forms' quadrature grows with the length), where the record's own
    interval has its map already: split, the step is uniform and takes the cached chain.
    """
    lengths = times[1:] - times[:-1]
    short, longest = float(lengths.min()), float(lengths.max())
    if not longest > 1.5 * short:
        return times, ag                             # one length (to round-off), no jump: most steps
    slivers = (lengths > 0.0) & (lengths <= SLIVER * (times[-1] - times[0]))
    if slivers.any():
        # a record sample within round-off of a step end (28.79000000000002 s in a step from
        # 28.79 s): its interval of 2e-14 s would get a segment map of its own (1.9 ms for 15
        # storeys); the knot moves onto its neighbour and the sliver becomes a jump (the velocity
        # changes by the ground acceleration's change across the sliver times its length less)
        times = times.copy()
        last = times.size - 1
        for j in slivers.nonzero()[0].tolist():
            if j + 1 < last:
                times[j + 1] = times[j]
            else:
                times[j] = times[j + 1]
        lengths = times[1:] - times[:-1]
    positive = lengths[lengths > 0.0]
    if positive.size < 2:
        return times, ag
    short = float(positive.min())
    if not longest > 1.5 * short:
        return times, ag
    pieces = np.rint(lengths / short)
    # integer multiples only (to the round-off of a host's knot times, far below 1e-9)
    pieces = np.where(np.abs(lengths - pieces * short) <= 1e-9 * lengths, pieces, 1.0).astype(np.int64)
    pieces[lengths <= 0.0] = 1                       # a jump stays a jump (and passes no time)
    if pieces.max() == 1 or int(pieces[lengths > 0.0].sum()) > MAX_SPLIT_INTERVALS:
        return times, ag
    fractions = [np.arange(k) / k for k in pieces.tolist()]
    new_times = np.concatenate([t + f * L for t, L, f in zip(times[:-1], lengths, fractions)] + [times[-1:]])
    new_ag = np.concatenate([a + f * (b - a) for a, b, f in zip(ag[:-1], ag[1:], fractions)] + [ag[-1:]])
    return new_times, new_ag


class BuildingIntegrator:
    """Common part of the integrators: parameters, derived outputs, initial state."""

    name = ""

    def __init__(self, building: ShearBuilding, hysteresis: StoreyHysteresis):
        hysteresis.check(building.stiffnesses, building.damping_ratio)
        self.building = building
        self.hysteresis = hysteresis
        self._inelastic = hysteresis.inelastic     # asked at every segment: the property once
        n = building.n
        self.n = n
        self.k = building.stiffnesses
        self.alpha = hysteresis.alpha
        self.fy = hysteresis.yield_shear if hysteresis.inelastic else np.full(n, np.inf)
        self.dy = hysteresis.yield_drift(self.k)
        self.masses = building.masses
        self.C = building.C

    # -- storey quantities (overridden per law) ------------------------------------------------
    def storey_shear(self, state: BuildingState) -> np.ndarray:
        return self.k * _drift(state.u)

    def strain_energy(self, state: BuildingState) -> float:
        d = _drift(state.u)
        return 0.5 * float(self.k @ (d * d))

    def residual_drift(self, state: BuildingState) -> np.ndarray:
        """``d - V / k`` per storey (m): see :mod:`fmu_src.hysteresis`."""
        if not self._inelastic:
            return np.zeros(self.n)
        return _drift(state.u) - self.storey_shear(state) / self.k

    def absolute_acceleration(self, state: BuildingState, force) -> np.ndarray:
        """``M^-1 (f - C v - D' V)`` (m/s^2)."""
        return (np.asarray(force, float) - self.C @ state.v - _floor_forces(self.storey_shear(state))) / self.masses

    def response(self, state: BuildingState, force):
        """``(drift, V, a, E_strain)`` of a state, each computed once (what an FMU publishes)."""
        d = self._drift_of(state.u)
        V, strain = self._shear_and_strain(state, d)
        a = (force - self.C @ state.v - _floor_forces(V)) / self.masses
        return d, V, a, strain

    def _shear_and_strain(self, state, d):
        # the strain energy as ShearBuilding.strain_energy writes it (the linear model, bit for bit)
        return self.k * d, 0.5 * float(self.k @ (d * d))

    def _drift_of(self, u: np.ndarray) -> np.ndarray:
        """The storey drifts of floor displacements ``u`` (an array nobody writes to)."""
        return _drift(u)

    def initial_state(self, u0, v0, force=None) -> BuildingState:
        """The elastic initial state at ``(u0, v0)``; peaks start from its values."""
        n = self.n
        u0 = np.array(u0, dtype=float)
        v0 = np.array(v0, dtype=float)
        self.hysteresis.check(self.k, self.building.damping_ratio, _drift(u0))
        d0 = _drift(u0)
        z0 = d0 / self.dy if self.hysteresis.model == "bouc_wen" else np.zeros(n)
        state = BuildingState(u=u0, v=v0, slip=np.zeros(n), mode=np.zeros(n, dtype=np.int64), z=z0,
                              peaks=np.zeros(3 * n))
        f = np.zeros(n) if force is None else np.asarray(force, float)
        state.peaks = np.concatenate([np.abs(u0), np.abs(d0), np.abs(self.absolute_acceleration(state, f))])
        if self._inelastic:
            state.peak_shear = np.abs(self.storey_shear(state))
            if self.hysteresis.model == "bilinear":
                state.yielded = np.zeros(n, dtype=bool)
        return state

    def peak_storey_shear(self, state: BuildingState) -> np.ndarray | None:
        """The running peak of every storey's ``|V|`` (N), the deferred peak searches run first
        (:meth:`resolve_peaks`); None for linear storeys (``k`` times the peak drift)."""
        if state.peak_shear is None:
            return None
        if state.yielded is None:
            return state.peak_shear
        self.resolve_peaks(state)
        return np.where(state.yielded, state.peak_shear, self.k * state.peak_drift)

    def advance(self, state: BuildingState, times, ag, force) -> StepCost:
        raise NotImplementedError

    def resolve_peaks(self, state: BuildingState, cost: StepCost | None = None) -> None:
        """Run the deferred peak searches (none for integrators that search at once)."""


class ExactPiecewiseLinear(BuildingIntegrator):
    """Linear and bilinear storeys, exact between located events (see module docstring)."""

    name = "exact"

    def __init__(self, building: ShearBuilding, hysteresis: StoreyHysteresis):
        super().__init__(building, hysteresis)
        self._configs: OrderedDict[bytes, Configuration] = OrderedDict()
        # what every configuration shares (made once: a yield pattern builds only its own part)
        self._cfg_constants = ConfigurationConstants(self.masses, self.C)
        self.configurations_built = 0   # cost counter
        # what a mode array implies, remembered for the array object last seen (a state's mode
        # is replaced, never changed in place): (mode, configuration, elastic mask, any yielding)
        self._mode_memo = None
        n = self.n
        self._drift_rows = np.eye(n) - np.eye(n, k=-1)   # d = D u
        self._peak_atol = np.repeat(np.array(PEAK_ATOL), n)
        self._peak_atol_list = self._peak_atol.tolist()
        self._all_functions = list(range(3 * n))        # _peaks' candidates when tier 1 flagged none
        self._inv_m = 1.0 / self.masses
        self._plans: dict[int, tuple] = {}
        # the bilinear law's constants, as hysteresis.py's functions compute them (bit for bit)
        self._elastic_k = (1.0 - self.alpha) * self.k       # stiffness of the plastic element
        self._hard_k = self.alpha * self.k                  # the hardening spring
        self._law_memo = None
        self._shear_memo = None
        self._drift_memo = None     # (u, its drifts) of the last displacement array asked (_drift_of)
        self._cover_memo = None
        self._covered_memo = None
        self._yield_q = (1.0 - self.alpha) * self.fy       # the plastic element's strength (N)
        # the same as Python floats (_track_shear)
        self._k_list, self._hard_list = self.k.tolist(), self._hard_k.tolist()
        self._soft_list, self._qy_list = self._elastic_k.tolist(), self._yield_q.tolist()
        limit = self.dy * (1.0 - 1e-12)       # _second_order_quiet's yield limits, made once
        self._second_order_limits = (limit, -limit)
        self._second_order_limit_lists = (limit.tolist(), (-limit).tolist())
        self._dy_list = self.dy.tolist()
        # a linear building's one-interval step matrices by canonical length, and by every
        # exact length asked (ramp_step)
        self._ramps: dict[float, RampStep] = {}
        self._ramp_aliases: dict[float, RampStep] = {}
        self._ramp_y = np.zeros(3 * n + 2)     # work buffer [u0; v0; ag0; ag1; p]
        self._legacy_parts = None              # legacy_rows' constant rows, made at its first call

    # -- bilinear storey state -----------------------------------------------------------------
    def _drift_of(self, u: np.ndarray) -> np.ndarray:
        """:func:`_drift` of ``u``, remembered for the array object last asked (a state's arrays
        are replaced, never changed in place, and nobody writes to the drifts returned): a
        segment's end drifts (:meth:`_yield_along`) are the next segment's start drifts and the
        published ones."""
        memo = self._drift_memo
        if memo is not None and memo[0] is u:
            return memo[1]
        d = _drift(u)
        self._drift_memo = (u, d)
        return d

    def _law_facts(self, mode: np.ndarray):
        """``(mode, yielding mask, any yielding, q of the yielding storeys, (1 - alpha) Fy mode,
        mode dy)`` of a mode array, remembered for the array object last seen (a state's mode is
        replaced, never changed in place).  ``q`` as :func:`bilinear_plastic_force` computes it."""
        memo = self._law_memo
        if memo is None or memo[0] is not mode:
            yielding = mode != 0
            memo = self._law_memo = (mode, yielding, bool(yielding.any()), mode * (1.0 - self.alpha) * self.fy,
                                     (1.0 - self.alpha) * self.fy * mode, mode * self.dy)
        return memo

    def _plastic_force(self, state, d):
        """:func:`bilinear_plastic_force` of a state, bit for bit, with the constants made once."""
        _, yielding, any_yielding, q_yield, _, _ = self._law_facts(state.mode)
        elastic_part = self._elastic_k * (d - state.slip)
        # every storey elastic: np.where would select every element of elastic_part
        return np.where(yielding, q_yield, elastic_part) if any_yielding else elastic_part

    def _shear_of(self, state, d):
        """``(V, q, alpha k d)`` of a state with drifts ``d``, remembered for the last state's
        arrays (a step publishes V, and the reading of the derived outputs asks for it again)."""
        memo = self._shear_memo
        if memo is not None and memo[0] is state.u and memo[1] is state.mode and memo[2] is state.slip:
            return memo[3], memo[4], memo[5]
        q = self._plastic_force(state, d)
        hard = self._hard_k * d
        V = hard + q
        self._shear_memo = (state.u, state.mode, state.slip, V, q, hard)
        return V, q, hard

    def storey_shear(self, state):
        d = _drift(state.u)
        if not self._inelastic:
            return self.k * d
        return self._shear_of(state, d)[0].copy()

    def strain_energy(self, state):
        if not self._inelastic:
            return super().strain_energy(state)
        return bilinear_strain_energy(self.k, self.alpha, _drift(state.u), state.slip, state.mode, self.fy)

    def _shear_and_strain(self, state, d):
        if not self._inelastic:
            return super()._shear_and_strain(state, d)
        V, q, hard = self._shear_of(state, d)
        strain = 0.5 * float(hard @ d) + 0.5 * float(q @ (q / self._elastic_k))
        return V.copy(), strain

    def configuration(self, mode: np.ndarray) -> Configuration:
        """The linear system of a yield pattern (cached; Rayleigh/modal C stays the initial one)."""
        if not self._inelastic and self._configs:
            return next(iter(self._configs.values()))     # a linear building has one
        key = (mode != 0).tobytes()
        cfg = self._configs.get(key)
        if cfg is None:
            tangent = bilinear_tangent(self.k, self.alpha, mode) if self._inelastic else self.k
            cfg = Configuration(self.masses, self.C, tangent, elastic=not mode.any(), constants=self._cfg_constants)
            if len(self._configs) >= MAX_CONFIGURATIONS:
                self._configs.popitem(last=False)
            self._configs[key] = cfg
            self.configurations_built += 1
        else:
            self._configs.move_to_end(key)
        return cfg

    def _net_force(self, state, force):
        """``p = f - D' r``: external force minus the storeys' constant offsets (N)."""
        if not self._inelastic:
            return np.asarray(force, float)
        if state.offset is None:
            state.offset = _floor_forces(bilinear_offset(self.k, self.fy, self.alpha, state.slip, state.mode))
        return force - state.offset

    def _mode_facts(self, mode: np.ndarray):
        """``(mode, configuration, elastic mask, any storey yielding)`` of a mode array."""
        memo = self._mode_memo
        if memo is None or memo[0] is not mode:
            elastic = mode == 0
            memo = self._mode_memo = (mode, self.configuration(mode), elastic, not bool(elastic.all()))
        return memo

    # -- stepping -----------------------------------------------------------------------------
    def advance(self, state, times, ag, force) -> StepCost:
        times = np.asarray(times, dtype=float)
        ag = np.asarray(ag, dtype=float)
        force = np.asarray(force, dtype=float)
        first = 0
        cost = None
        if times.size > 3 or (times.size == 3 and not self._inelastic):
            # worth batching: the intervals before the first one where an event may occur at once,
            # the rest (if any) interval by interval from there
            batch = self._advance_batch(state, times, ag, force)
            if batch is not None:
                cost, times, ag, first = batch
                if first == times.size - 1:
                    return cost
        if first == 0 and times.size > 2:
            # interval by interval: no segment map made for one step either (_advance_batch
            # splits its steps itself, from the lengths it computes anyway)
            times, ag = _even_intervals(times, ag)
        if cost is None:
            cost = StepCost()
        events = 0
        h = float(times[-1] - times[0])
        for j in range(first, times.size - 1):
            length = float(times[j + 1] - times[j])
            if length <= 0.0:
                continue                      # a jump of the record: no time passes
            slope = (ag[j + 1] - ag[j]) / length
            events += self._interval(state, length, float(ag[j]), float(slope), force, cost, h,
                                     float(times[j] - times[0]))
            if events > MAX_EVENTS_PER_STEP:
                raise ValueError(f"more than {MAX_EVENTS_PER_STEP} yield/unloading events in one step of "
                                 f"{h:.6g} s: the storeys chatter at their yield limits; use shorter steps")
        cost.events = events
        return cost

    def _advance_batch(self, state, times, ag, force):
        """The knot intervals of a step at once, in the current configuration, up to the first
        interval in which a yield or unloading event may occur: ``(cost, times, ag, first)``
        with the knots the step was split into (:func:`_even_intervals`) and the index of the
        knot from which the rest of the step is left to :meth:`_interval` (``times.size - 1``:
        none left), or None (the state untouched) if an event may occur in the first interval.

        Without events the intervals only chain through the state.  Intervals of one length
        (a record's samples: every step of a run measured) are chained by one product with a
        cached block matrix (:meth:`_chain`); intervals of different lengths by one
        matrix-vector product each (with the cached map of its length).  Then one matrix
        product per distinct length gives every interval's energies and tier-1 test quantities
        (:meth:`_interval` explains them): an elastic storey must stay inside its elastic range
        and a yielding storey keep its drift rate's sign in every interval taken here, by tier 1
        or, for the intervals it leaves, by the chord through both ends (:meth:`_chord_quiet`;
        the first interval that neither clears ends the batch: a step whose later intervals
        yield keeps the batch's work on the quiet ones before, instead of redoing them one by
        one); only the intervals where a peak may grow are looked at one by one, and in them
        only the functions that tier 1 did not clear.  Same arithmetic as :meth:`_interval` per
        interval up to round-off, without its per-interval overhead (a step of 30 record
        intervals costs little more than one).  A yielding storey's drift is monotonic over the
        intervals taken, so its slip and dissipation follow from the end drift as in
        :meth:`_commit`.
        """
        n = self.n
        two_n = 2 * n
        cost = StepCost()
        lengths = times[1:] - times[:-1]             # np.diff's arithmetic
        _, cfg, elastic, yielding = self._mode_facts(state.mode)
        inelastic = self._inelastic
        size = 3 * n + 2
        positive = lengths.tolist()
        if min(positive) > 0.0:                      # no jump: slices, the same arithmetic
            knots = None                             # interval j starts at knot j
            ag0 = ag[:-1]
            slope = (ag[1:] - ag[:-1]) / lengths
        else:                                        # equal times: a jump, no time passes
            idx = (lengths > 0.0).nonzero()[0]
            knots = idx.tolist()                     # the knot each positive interval starts at
            ag0 = ag[idx]
            slope = (ag[idx + 1] - ag[idx]) / lengths[idx]
            positive = lengths[idx].tolist()
            if not positive:
                return None                          # jumps only: nothing to batch
        shortest, longest = min(positive), max(positive)
        if longest > 1.5 * shortest:
            # a long interval or a sliver, split or merged before any map is made for it
            even_times, even_ag = _even_intervals(times, ag)
            if even_times is not times:
                return self._advance_batch(state, even_times, even_ag, force)
        count = len(positive)
        if inelastic and yielding and not cfg.has_map(positive[0]) and cfg.segments_without_map < MAP_AFTER_SEGMENTS:
            # a yield pattern met briefly so far: most last a few intervals (_worth_a_map), and a
            # map costs about ten ad hoc segments; _interval takes it ad hoc until it has lasted
            return None
        p = self._net_force(state, force)
        first = cfg.segment_map(positive[0])
        # one length (to round-off) for every interval: canonical_length is monotonic, so the
        # shortest and the longest sharing a map means all do (every step of a run, measured)
        uniform = ((shortest == positive[0] or cfg.segment_map(shortest) is first)
                   and (longest == positive[0] or cfg.segment_map(longest) is first))
        if uniform and not inelastic and knots is None:
            return self._uniform_elastic_batch(state, times, ag, p, force, cfg, first, count)
        maps = [first] * count if uniform else [cfg.segment_map(L) for L in positive]
        if uniform:
            # z_1 .. z_count in one product, x = [z0; p; ag_0 .. ag_count-1; slope_0 .. slope_count-1];
            # Y's rows [z_j; ag_j; slope_j; p] gathered from [x; z_1 .. z_count] by one index
            # (the same numbers as assigning its blocks, in a third of the numpy calls)
            x = np.concatenate((state.u, state.v, p, ag0, slope))
            chain = self._batch_plan(first)[4].get(count)
            if chain is None:
                chain = self._chain(first, count)
            chain, gather = chain
            known = np.concatenate((x, chain @ x))
            Y = known[gather]
            z = known[-two_n:]
            groups = {id(first): range(count)}
        else:
            Y = np.empty((count, size))
            Y[:, two_n] = ag0
            Y[:, two_n + 1] = slope
            Y[:, two_n + 2:] = p
            Y[0, :n] = state.u
            Y[0, n:two_n] = state.v
            groups = {}                              # intervals by map (lengths equal to round-off share one)
            for j, smap in enumerate(maps):
                groups.setdefault(id(smap), []).append(j)
            # the state across the intervals: each product written straight into the next row
            for j in range(count - 1):
                np.matmul(maps[j].state, Y[j], out=Y[j + 1, :two_n])
            z = maps[-1].state @ Y[-1]
        tested = []                      # (intervals, map, their rows, tier-1 values, bounds) of each group
        taken = count                    # intervals before the first one not cleared of events (tier 1, chords)
        for js in groups.values():
            smap = maps[js[0]]
            tier1, change = self._batch_plan(smap)[1:3]
            # the rows of the group, as a slice where they are consecutive (a view, not a copy)
            Yg = Y[js[0]:js[-1] + 1] if js[-1] - js[0] == len(js) - 1 else Y[js]
            # per interval only what tier 1 needs (a product small enough for one BLAS thread:
            # the whole stacked map of 32 intervals of 15 storeys went multithreaded, 10 ms a
            # step on a loaded machine): the watched functions and drift rates at the start,
            # and the modal amplitudes of z'(0)
            out = Yg @ tier1.T
            bound = np.abs(out[:, 4 * n:]) @ change   # |Re|, |Im| of W z'(0) and |ag slope|
            if inelastic:
                # elastic storeys stay inside |d - s| < dy, yielding ones keep mode d' > 0
                if yielding:
                    margin = np.where(elastic, self.dy - np.abs(out[:, n:two_n] - state.slip) - bound[:, n:two_n],
                                      state.mode * out[:, 3 * n:4 * n] - bound[:, 3 * n:])
                else:     # every storey elastic: np.where's first branch, fewer operations
                    margin = self.dy - np.abs(out[:, n:two_n] - state.slip) - bound[:, n:two_n]
                if not margin.min() > 0.0:
                    # the intervals tier 1 leaves go to the chord test (both ends are known here);
                    # the group's first interval that neither clears may hold an event (the
                    # groups' intervals ascend)
                    left = (~(margin.min(axis=1) > 0.0)).nonzero()[0]
                    if js[int(left[0])] < taken:
                        unclear = left[~self._chord_quiet(cfg, state, elastic, yielding, out[left], Y, z, js, left,
                                                          positive)]
                        if unclear.size:
                            taken = min(taken, js[int(unclear[0])])
                            if taken == 0:
                                return None
            tested.append((js, smap, Yg, out, bound))
        if taken < count:
            # the step goes on from the start of interval `taken` (its start state is Y's row)
            count = taken
            z = Y[count, :two_n]
            positive = positive[:count]
            Y = Y[:count]
            kept = []
            for js, smap, Yg, out, bound in tested:
                k = sum(1 for j in js if j < count)          # the groups' intervals ascend
                if k:
                    kept.append((js[:k], smap, Yg[:k], out[:k], bound[:k]))
            tested = kept
        e_damp = e_in = 0.0
        flagged = []
        peaks = state.peaks
        drift_bounds = []                # (intervals, tier-1 bounds, flags) of each group
        drift_flagged = False
        for js, smap, Yg, out, bound in tested:
            forms = self._batch_plan(smap)[3]
            # both energy forms summed over the group's intervals: sum_j y_j' Q y_j = <Q, Y'Y>
            e_damp_g, e_in_g = (forms @ (Yg.T @ Yg).ravel()).tolist()
            e_damp += e_damp_g
            e_in += e_in_g
            # against the peaks at the step start: a superset of what later intervals need; a
            # function cleared here cannot pass the peaks anywhere in the interval (tier 1 is
            # rigorous), so only the others are tested in _peaks
            need = np.abs(out[:, :3 * n]) + bound[:, :3 * n] > peaks
            if inelastic:
                # for the storey shears' peaks (_track_shear_rows): any drift tier 1 left here?
                drift_bounds.append((js, bound, need))
                if not drift_flagged and need.any():
                    drift_flagged = bool(need[:, n:two_n].any())
            if need.any():
                rows = need.any(axis=1).nonzero()[0].tolist()
                scans = Yg[rows] @ smap.scan.T           # the Scan vectors of those intervals only
                flagged.append((js, rows, scans, need[rows], smap.length))
        cost.segments = count
        cost.cleared = count - sum(len(rows) for _, rows, _, _, _ in flagged)
        if flagged:
            xtol = EVENT_XTOL * float(times[-1] - times[0])
            if len(flagged) == 1:            # one length: the intervals in order, tested together
                js, rows, scans, need, L = flagged[0]
                self._interval_peaks(cfg, state, Y[[js[i] for i in rows]], scans, need, p, L, xtol, cost)
            else:
                each = sorted((js[i], scan, flags, L) for js, rows, scans, need, L in flagged
                              for i, scan, flags in zip(rows, scans, need))
                for j, scan_vector, flags, L in each:
                    y = Y[j].copy()
                    scan = Scan(cfg, scan_vector, float(y[two_n + 1]), L)
                    self._peaks(cfg, scan, None, state, y, p, L, xtol, cost, flags.tolist())
        state.E_damping += e_damp
        state.E_input += e_in
        # a covered storey whose |drift| tier 1 kept under its peak in an interval cannot pass its
        # own peak shear there
        if inelastic:
            covered, mask = self._shear_covered(state)
            if not covered or drift_flagged:
                drift_reach = np.empty((count, n))
                wanted = np.empty((count, n), dtype=bool)
                for js, bound, need in drift_bounds:
                    drift_reach[js] = bound[:, n:two_n]
                    wanted[js] = need[:, n:two_n]
                wanted[:, ~mask] = True
                self._track_shear_rows(state, cfg, Y, z, positive, drift_reach, wanted)
        u1 = z[:n]                  # views of a fresh product: nothing else writes to it
        state.E_external += float(force @ (u1 - state.u))
        if yielding:
            self._yield_along(state, u1)
        state.u = u1
        state.v = z[n:]
        last = times.size - 1
        return cost, times, ag, (last if count == len(maps) else count if knots is None else knots[count])

    def _chord_quiet(self, cfg, state, elastic, yielding, out, Y, z_end, js, rows, lengths) -> np.ndarray:
        """For the intervals ``js[rows]`` of a batch (:meth:`_advance_batch`; ``out`` their tier-1
        rows, ``Y`` every interval's ``y`` row, ``z_end`` the last one's end state, ``lengths``
        (s) every interval's): True where no storey can change state in the interval, proven
        from its exact solution at both ends (the batch knows them) and a bound of the next
        derivative: tighter than tier 1 and than :meth:`_second_order_quiet`, which start from
        one end.

        On ``[0, L]`` a function whose second derivative is at most ``B`` in size stays within
        ``B t (L - t) / 2 <= B L^2 / 8`` of its chord: an elastic storey's ``e = d - s`` within
        ``[min(e0, e1) - B2 L^2 / 8, max(e0, e1) + B2 L^2 / 8]``, a yielding storey's ``mode d'``
        above ``min(g0, g1) - B3 L^2 / 8``, with ``B2`` and ``B3`` the bounds of the drifts' second
        and third derivatives (:meth:`Configuration.drift_curvature_rows` with the growth
        factor, as :meth:`_second_order_quiet`).  Margins: that test's yield limits (``1e-12``
        of ``dy``) and ``1e-12`` of the drift rates' end values (the chained end states carry
        round-off of ~1e-16 of the floors' velocities)."""
        n = self.n
        M, Ra, Rb = cfg.drift_curvature_rows()
        which = np.asarray(js)[rows]
        L = np.asarray(lengths, dtype=float)[which]
        bound = np.abs(out[:, 4 * n:8 * n]) @ M.T
        bound += np.abs(out[:, 8 * n])[:, None] * (L[:, None] * Ra + Rb)
        bound *= (0.125 * L * L * np.exp(cfg.growth_rate * L))[:, None]
        # the states at both ends: interval j starts at Y[j] and ends at Y[j + 1] (z_end for the last)
        ends = np.empty((rows.size, 2 * n))
        last = Y.shape[0] - 1
        for k, j in enumerate(which.tolist()):
            ends[k] = Y[j + 1, :2 * n] if j < last else z_end[:2 * n]
        limit, low = self._second_order_limits
        e0 = out[:, n:2 * n] - state.slip
        e1 = _drift_rows(ends[:, :n]) - state.slip
        quiet = (np.maximum(e0, e1) + bound[:, :n] < limit) & (np.minimum(e0, e1) - bound[:, :n] > low)
        if yielding:
            g0 = state.mode * out[:, 3 * n:4 * n]
            g1 = state.mode * _drift_rows(ends[:, n:])
            moving = np.minimum(g0, g1) - bound[:, n:] > 1e-12 * (np.abs(g0) + np.abs(g1))
            quiet = np.where(elastic, quiet, moving)
        return quiet.all(axis=1)

    def _uniform_elastic_batch(self, state, times, ag, p, force, cfg, smap, count):
        """:meth:`_advance_batch` of a linear building's step of intervals of one length and no
        jump (every knot step of a run measured): no event can occur, so every interval is taken;
        the same physics with the least numpy calls: the states and the ground acceleration's
        slopes by one product with the cached chain of the knot values (:meth:`_knot_chain`),
        tier 1's reach of every watched function by one product with the plan's reach matrix
        (``|g(0)|`` plus the change bound, as in :meth:`legacy_rows`), both energy forms by one
        product over the intervals' ``Y' Y``."""
        n = self.n
        _, tier1, _, forms, chains, reach = self._batch_plan(smap)
        chain = chains.get(("knots", count))
        if chain is None:
            chain = self._knot_chain(smap, count)
        chain, gather = chain
        x = np.concatenate((state.u, state.v, p, ag))
        known = np.concatenate((x, chain @ x))
        Y = known[gather]
        # against the peaks at the step start (a superset of what later intervals need, see
        # _advance_batch): strict, a function tier 1 keeps at or under them cannot pass them
        need = np.abs(Y @ tier1.T) @ reach > state.peaks
        e_damp, e_in = (forms @ (Y.T @ Y).ravel()).tolist()
        cost = StepCost()
        cost.segments = count
        if np.count_nonzero(need):
            rows = need.any(axis=1).nonzero()[0].tolist()
            cost.cleared = count - len(rows)
            Yr = Y[rows]
            xtol = EVENT_XTOL * float(times[-1] - times[0])
            self._interval_peaks(cfg, state, Yr, Yr @ smap.scan.T, need[rows], p, smap.length, xtol, cost)
        else:
            cost.cleared = count
        state.E_damping += e_damp
        state.E_input += e_in
        z = known[-(2 * n + count):-count]      # z_count, of a fresh product: nothing else writes to it
        u1 = z[:n]
        state.E_external += float(force @ (u1 - state.u))
        state.u = u1
        state.v = z[n:]
        return cost, times, ag, times.size - 1

    def _interval_peaks(self, cfg, state, Y, scans, flags, p, length, xtol, cost) -> None:
        """:meth:`_peaks` of consecutive intervals of one length, in order: ``Y`` their ``y``
        rows, ``scans`` their Scan vectors, ``flags`` the functions tier 1 did not clear.

        The Scan bounds of all of them in one product, and the prefilter of :meth:`_peaks` (a
        function whose Hermite bound stays under its limit, or whose slope provably keeps its
        sign) over all of them at once, each interval against the peaks as :meth:`_peaks` would
        see them (the peaks at the start raised by the end values of the intervals before it):
        only intervals with a function left go through :meth:`_peaks`, with the same decisions.
        """
        n = self.n
        m = 3 * n
        two_n = 2 * n
        count = Y.shape[0]
        G = scans[:, :6 * m].reshape(count, 6, m)            # rows: g(0), g(L), g'(0), g'(L), g''(0), g''(L)
        re = scans[:, 6 * m:6 * m + two_n]
        im = scans[:, 6 * m + two_n:]
        # Scan's bounds (linear_response._scan_bounds), every interval at once: the same elements
        # (the same operations on each; x + 0 and x * 1 are x, where that skips them)
        a = np.abs(Y[:, two_n + 1])[:, None]
        amp = np.hypot(re, im) + (length * a) * cfg.ramp_abs
        if cfg.growth_rate:
            amp = amp * math.exp(cfg.growth_rate * length)
        ramp23 = cfg.scan_parts[3]
        bound4 = (cfg.lam3 * amp + a * ramp23[:, 0]) @ cfg.peak_modal_abs.T
        bound5 = (cfg.lam4 * amp + a * ramp23[:, 1]) @ cfg.peak_modal_abs.T
        accel_offset = p * self._inv_m
        offset = np.zeros(m)
        offset[two_n:] = accel_offset
        g0 = np.abs(G[:, 0] + offset)
        g1 = np.abs(G[:, 1] + offset)
        # the peaks each interval's _peaks starts from: the end values of those before it folded in
        running = np.maximum.accumulate(np.vstack([state.peaks[None, :], g1]), axis=0)
        limits = running[1:] + self._peak_atol
        w4 = length ** 4 / 384.0
        s0, s1 = np.abs(G[:, 2]), np.abs(G[:, 3])
        slopes = (s0 + s1) * length
        reach = np.maximum(g0, g1) + _HERMITE_SLOPE_GAIN * slopes + 1e-12 * (g0 + g1 + slopes) + bound4 * w4
        curvatures = (np.abs(G[:, 4]) + np.abs(G[:, 5])) * length
        monotonic = np.minimum(s0, s1) - _HERMITE_SLOPE_GAIN * curvatures - _HERMITE_MARGIN * (
            s0 + s1 + curvatures) - bound5 * w4 > 0.0
        monotonic &= G[:, 2] * G[:, 3] > 0.0
        keep = flags & ~(reach <= limits) & ~monotonic
        rows, cols = keep.nonzero()                           # interval by interval, functions ascending
        if rows.size:
            # the tests _peaks runs on each candidate, on all of them at once: the same IEEE
            # operations (hermite_ranges is hermite_range_scalar element by element), so the same
            # decisions and the same deferred bounds.  A candidate with a slope of one sign whose
            # slope's Hermite range keeps that sign (within its bound) has its extremes at the ends
            # (the cheaper bound of that test failed for every candidate: `monotonic` above)
            # (each Hermite range only where _peaks would take it: the slope's where the slope
            # has one sign at both ends, the function's where that test did not decide)
            s0c, s1c = G[rows, 2, cols], G[rows, 3, cols]
            same = (s0c * s1c > 0.0).nonzero()[0]
            if same.size:
                r, c = rows[same], cols[same]
                err = bound5[r, c] * w4
                slo, shi = hermite_ranges(s0c[same], s1c[same], length * G[r, 4, c], length * G[r, 5, c])
                sign_kept = np.zeros(rows.size, dtype=bool)
                sign_kept[same] = (slo - err > 0.0) | (shi + err < 0.0)
                left = (~sign_kept).nonzero()[0]
                rows, cols, s0c, s1c = rows[left], cols[left], s0c[left], s1c[left]
            ends = G[rows, 1, cols]
            accel = cols >= two_n
            ends[accel] += accel_offset[cols[accel] - two_n]           # as _peaks' g1 (no 0.0 added elsewhere)
            lo, hi = hermite_ranges(G[rows, 0, cols] + offset[cols], ends, length * s0c, length * s1c)
            bound = np.maximum(-lo, hi) + bound4[rows, cols] * w4
            deferred = ~(bound <= limits[rows, cols])
            rows, cols, bound = rows[deferred].tolist(), cols[deferred].tolist(), bound[deferred].tolist()
        else:
            rows = cols = bound = []
        # the deferred searches, interval by interval as _peaks would add them (the same list
        # and, past MAX_PENDING, the same pruning at the same interval with the same peaks)
        key = (state.mode != 0).tobytes()
        pending = state.pending
        k, total = 0, len(rows)
        while k < total:
            i = rows[k]
            stop = k + 1
            while stop < total and rows[stop] == i:
                stop += 1
            y_copy = Y[i].copy()
            pending.extend((j, U, key, y_copy, length, xtol) for j, U in zip(cols[k:stop], bound[k:stop]))
            cost.peaks_deferred += stop - k
            k = stop
            if len(pending) > MAX_PENDING:
                new = running[i + 1]                          # _peaks' running peaks after interval i
                atol = self._peak_atol
                state.pending = pending = [e for e in pending if e[1] > new[e[0]] + atol[e[0]]]
                if len(pending) > MAX_PENDING // 2:
                    # the searches raise the running peaks: the intervals after this one go
                    # through _peaks one by one, against those (as before)
                    state.peaks = np.maximum(state.peaks, new)
                    self.resolve_peaks(state, cost)
                    self._peaks_one_by_one(cfg, state, Y, G, bound4, bound5, keep, running, i + 1, p, length,
                                           xtol, cost)
                    return
        state.peaks = np.maximum(state.peaks, running[-1])

    def _peaks_one_by_one(self, cfg, state, Y, G, bound4, bound5, keep, running, first, p, length, xtol, cost):
        """:meth:`_peaks` of the intervals from ``first`` on (of :meth:`_interval_peaks`), one by one."""
        B = np.stack([bound4, bound5], axis=2)               # (count, m, 2) as Scan.B
        for i in keep[first:].any(axis=1).nonzero()[0].tolist():
            i += first
            state.peaks = np.maximum(state.peaks, running[i])  # the end values before it
            scan = object.__new__(Scan)
            scan.G = G[i].T
            scan.B = B[i]
            self._peaks(cfg, scan, None, state, Y[i].copy(), p, length, xtol, cost, keep[i].tolist())
        state.peaks = np.maximum(state.peaks, running[-1])

    def _batch_plan(self, smap):
        """``(smap, tier1, change, forms, chains, reach)`` of a segment map for :meth:`_advance_batch`:
        ``tier1 @ y`` gives what tier 1 needs of an interval: the watched functions at its start
        (the accelerations with their constant part ``p / m``), the drift rates, ``Re, Im W
        z'(0)`` and the ground acceleration's slope; ``|that[4n:]| @ change`` the tier-1 bound
        (:meth:`Configuration.change_bounds`, the ramp term as one more row); ``forms`` the
        damping and input forms as two rows (for ``<Q, Y'Y>``); ``chains`` the chains by
        interval count (:meth:`_chain`); ``|tier1 @ y| @ reach`` tier 1's reach of every watched
        function (:meth:`_uniform_elastic_batch`).  Cached per map (at most ``MAX_PLANS``, the map itself
        kept so that its id is not reused)."""
        plan = self._plans.get(id(smap))
        if plan is not None and plan[0] is smap:
            return plan
        n = self.n
        slope_row = np.zeros((1, 3 * n + 2))
        slope_row[0, 2 * n + 1] = 1.0
        tier1 = np.vstack([smap.stacked[2 * n:6 * n], smap.scan[-4 * n:], slope_row])
        tier1[2 * n:3 * n, 2 * n + 2:] = np.diag(self._inv_m)
        change = np.ascontiguousarray(np.vstack([smap.change.T, smap.ramp_change[None, :]]))
        forms = np.ascontiguousarray(np.vstack([smap.damping.ravel(), smap.input.ravel()]))
        # |tier1 @ y| @ reach: each watched function's value at the start plus its change bound
        # (tier 1's reach over the interval, the drift rates' columns unused)
        reach = np.zeros((tier1.shape[0], 3 * n))
        reach[:3 * n] = np.eye(3 * n)
        reach[4 * n:] = change[:, :3 * n]
        if len(self._plans) >= MAX_PLANS:
            self._plans.pop(next(iter(self._plans)))
        plan = self._plans[id(smap)] = (smap, np.ascontiguousarray(tier1), change, forms, {}, reach)
        return plan

    def _chain(self, smap, count: int) -> np.ndarray:
        """The block matrix giving the states ``z_1 .. z_count`` (rows of ``2n``) after ``count``
        intervals of ``smap``'s length from ``x = [z0; p; ag_0 .. ag_count-1; slope_0 ..
        slope_count-1]``: ``z_j = S^j z0 + sum_{i<j} S^i S_p p + sum_{i<j} S^(j-1-i) S_a [ag_i;
        slope_i]`` with ``smap.state = [S, S_a, S_p]``, with the index that gathers the intervals'
        ``y`` rows from ``[x; z_1 .. z_count]``: ``(chain, gather)``.  Kept in the map's plan, at
        most ``MAX_CHAINS`` counts per map (a step of 32 intervals of a 20-storey building: 1.3 MB)."""
        n = self.n
        two_n = 2 * n
        state = smap.state
        S, Sa, Sp = state[:, :two_n], state[:, two_n:two_n + 2], state[:, two_n + 2:]
        chain = np.zeros((count * two_n, 3 * n + 2 * count))
        power = np.eye(two_n)                    # S^j
        forced = np.zeros((two_n, n))            # sum_{i<j} S^i S_p
        ramps = np.empty((count, two_n, 2))      # S^k S_a
        for j in range(1, count + 1):
            ramps[j - 1] = power @ Sa
            forced = forced + power @ Sp
            power = S @ power
            block = chain[(j - 1) * two_n:j * two_n]
            block[:, :two_n] = power
            block[:, two_n:3 * n] = forced
            # interval i's ramp columns: S^(j-1-i) S_a, i = 0 .. j-1 (copies, one per column kind)
            block[:, 3 * n:3 * n + j] = ramps[j - 1::-1, :, 0].T
            block[:, 3 * n + count:3 * n + count + j] = ramps[j - 1::-1, :, 1].T
        # Y's rows (_advance_batch) from [x; z_1 .. z_count]: z_j at 3n + 2 count + 2n (j - 1) (x's z0
        # for j = 0), then ag_j, slope_j and p from x
        width = 3 * n + 2 * count
        gather = np.empty((count, 3 * n + 2), dtype=np.intp)
        gather[0, :two_n] = np.arange(two_n)
        gather[1:, :two_n] = width + np.arange((count - 1) * two_n).reshape(count - 1, two_n)
        gather[:, two_n] = 3 * n + np.arange(count)
        gather[:, two_n + 1] = 3 * n + count + np.arange(count)
        gather[:, two_n + 2:] = two_n + np.arange(n)
        return self._keep_chain(smap, count, chain, gather)

    def _knot_chain(self, smap, count: int):
        """:meth:`_chain` for :meth:`_uniform_elastic_batch`: from ``x = [z0; p; ag_0 .. ag_count]``
        (the knot values: fewer columns than values and slopes) the states ``z_1 .. z_count``
        (rows of ``2n``) and then the slopes ``(ag_j+1 - ag_j) / L`` (``count`` rows), with the
        index gathering the intervals' ``y = [z_j; ag_j; slope_j; p]`` rows from ``[x; chain @
        x]``: ``(chain, gather)``.  With ``smap.state = [S, S_a, S_p]`` and ``S_a = [a0, a1]``
        (the responses to ``ag`` and to its slope), interval i adds ``S^(j-1-i) (a0 ag_i + a1
        (ag_i+1 - ag_i) / L)`` to ``z_j``: knot k enters ``z_j`` through ``S^(j-1-k) (a0 - a1 /
        L)`` (k < j) and ``S^(j-k) a1 / L`` (1 <= k <= j).  Kept in the map's plan."""
        n = self.n
        two_n = 2 * n
        state = smap.state
        S, Sa, Sp = state[:, :two_n], state[:, two_n:two_n + 2], state[:, two_n + 2:]
        inv_length = 1.0 / smap.length
        own = Sa[:, 0] - Sa[:, 1] * inv_length       # knot k's weight through interval k
        ahead = Sa[:, 1] * inv_length                # knot k's weight through interval k - 1
        width = 3 * n + count + 1
        chain = np.zeros((count * two_n + count, width))
        power = np.eye(two_n)                        # S^j
        forced = np.zeros((two_n, n))                # sum_{i<j} S^i S_p
        own_powers = np.empty((count, two_n))        # S^m own
        ahead_powers = np.empty((count, two_n))      # S^m ahead
        for j in range(1, count + 1):
            own_powers[j - 1] = power @ own
            ahead_powers[j - 1] = power @ ahead
            forced = forced + power @ Sp
            power = S @ power
            block = chain[(j - 1) * two_n:j * two_n]
            block[:, :two_n] = power
            block[:, two_n:3 * n] = forced
            block[:, 3 * n:3 * n + j] = own_powers[j - 1::-1].T           # knots 0 .. j-1
            block[:, 3 * n + 1:3 * n + j + 1] += ahead_powers[j - 1::-1].T  # knots 1 .. j
        intervals = np.arange(count)
        chain[count * two_n + intervals, 3 * n + intervals] = -inv_length
        chain[count * two_n + intervals, 3 * n + 1 + intervals] = inv_length
        gather = np.empty((count, 3 * n + 2), dtype=np.intp)
        gather[0, :two_n] = np.arange(two_n)
        gather[1:, :two_n] = width + np.arange((count - 1) * two_n).reshape(count - 1, two_n)
        gather[:, two_n] = 3 * n + intervals
        gather[:, two_n + 1] = width + count * two_n + intervals
        gather[:, two_n + 2:] = two_n + np.arange(n)
        return self._keep_chain(smap, ("knots", count), chain, gather)

    def _keep_chain(self, smap, key, chain: np.ndarray, gather: np.ndarray) -> tuple:
        """``(chain, gather)`` kept in ``smap``'s plan under ``key`` (at most ``MAX_CHAINS``, the
        oldest goes) and returned."""
        chains = self._batch_plan(smap)[4]
        if len(chains) >= MAX_CHAINS:
            chains.pop(next(iter(chains)))
        chains[key] = (chain, gather)
        return chains[key]

    def fits_unmapped(self, h: float) -> bool:
        """True if :meth:`advance_unmapped` can take a step of ``h`` s (its quadrature stays within
        ``MAX_CHUNKS`` chunks of the fastest mode; a longer zero-order-hold step takes the matrices,
        which have no such limit)."""
        return math.ceil(self.configuration(np.zeros(self.n, dtype=np.int64)).rate * h / CHUNK_RATE) <= MAX_CHUNKS

    def advance_unmapped(self, state, h: float, ag: float, force) -> StepCost:
        """One zero-order-hold step (``ag`` held, m/s^2) of the elastic building from its modal
        solution at ``h``, without the matrices of its length (:meth:`Configuration.segment_map`,
        whose energy forms cost a quadrature over a tensor of every mode, node and input: 1 to
        40 ms for 15 storeys): the state, the energies by the quadrature of the solution itself,
        the peaks as in :meth:`_interval`.  For a length stepped once."""
        n = self.n
        cost = StepCost(segments=1)
        cfg = self.configuration(state.mode)
        p = np.asarray(force, float)
        y = np.concatenate((state.u, state.v, (ag, 0.0), p))
        z0, w = y[:2 * n], y[2 * n:]
        segment = ModalSegment(cfg, z0, w)
        z1 = cfg.state_at(segment.q0, segment.beta0, segment.beta1, h)
        e_damp, e_in = cfg.energies(segment.q0, segment.beta0, segment.beta1, w, h)
        scan = Scan(cfg, cfg.scan_vector(z0, z1, w, h), 0.0, h)
        self._peaks(cfg, scan, segment, state, y, p, h, EVENT_XTOL * h, cost)
        self._commit(state, z1, p, e_damp, e_in, yielding=False)
        return cost

    def _interval(self, state, length, ag0, ag1, force, cost, h, start) -> int:
        """One knot interval (linear ground acceleration), split at events."""
        n = self.n
        s = 0.0
        events = 0
        xtol = EVENT_XTOL * max(h, length)
        inelastic = self._inelastic
        while length - s > xtol:
            rem = length - s
            _, cfg, elastic, yielding = self._mode_facts(state.mode)
            p = self._net_force(state, force)
            y = np.concatenate((state.u, state.v, (ag0 + ag1 * s, ag1), p))
            w = y[2 * n:]
            z0 = y[:2 * n]
            segment = poly = scan = None
            e_damp = e_in = None
            change = None
            if s == 0.0 and (not inelastic or self._worth_a_map(cfg, rem, not yielding)):
                # a whole knot interval or step (a repeated length): one product with the
                # cached map gives the end state, z'(0), the watched values, the test
                # quantities and the energy forms
                smap = cfg.segment_map(rem)
                out = smap.stacked @ y
                size = y.size
                rows = 6 * n + smap.scan.shape[0]
                z1 = out[:2 * n]
                watched = out[2 * n:6 * n]
                scan_vector = out[6 * n:rows]
                e_damp = float(y @ out[rows:rows + size])
                e_in = float(y @ out[rows + size:])
                change = smap.change
            else:
                # after an event, the rest of the interval, or a yield pattern met only briefly
                # so far (only a yielding building has either)
                segment = TaylorSegment(cfg, z0, w, rem)
                if TaylorScan.fits(cfg, rem):     # the end state and the scan from the Taylor coefficients
                    poly = TaylorScan(segment)
                z1, scan = _state_and_scan(segment, poly, z0, w, rem, ag1)
            cost.segments += 1
            # tier 1: how far can every watched function move in this segment?
            peak_flags = unload_flags = up_flags = down_flags = None
            quiet = False      # True: tier 1 proved that no storey changes state in this segment
            if change is not None:
                # on Python floats and bools, function by function: the same IEEE operations as
                # numpy's elementwise ones (so the same decisions), without a numpy call per
                # operation on the few storeys' 4n watched functions
                bound = (change @ np.abs(scan_vector[-4 * n:])).tolist()
                if ag1 != 0.0:
                    slope = abs(ag1)
                    bound = [b + slope * r for b, r in zip(bound, smap.ramp_change.tolist())]
                watched = watched.tolist()
                for i, offset in enumerate((p * self._inv_m).tolist()):
                    watched[2 * n + i] += offset          # the accelerations' constant part p / m
                # strict (no tolerance): a segment cleared here records no end value
                peak_flags = [abs(g) + b > peak for g, b, peak in zip(watched[:3 * n], bound, state.peaks.tolist())]
                if inelastic:
                    # elastic storeys stay inside |d - s| < dy, yielding ones keep mode d' > 0
                    e0 = [d - s for d, s in zip(watched[n:2 * n], state.slip.tolist())]
                    reach = bound[n:2 * n]
                    dy = self._dy_list
                    el = elastic.tolist()
                    if yielding:
                        modes, rate = state.mode.tolist(), watched[3 * n:]
                        quiet = all((dy[i] - abs(e0[i]) - reach[i] if el[i] else modes[i] * rate[i] - bound[3 * n + i])
                                    > 0.0 for i in range(n))
                    else:      # every storey elastic
                        quiet = all(dy[i] - abs(e0[i]) - reach[i] > 0.0 for i in range(n))
                    if not quiet:
                        # the storeys left, as lists of bools, which _second_order_quiet narrows
                        # and _first_event reads
                        up_flags = [el[i] and e0[i] + reach[i] >= dy[i] for i in range(n)]
                        down_flags = [el[i] and e0[i] - reach[i] <= -dy[i] for i in range(n)]
                        if yielding:
                            unload_flags = [not el[i] and modes[i] * rate[i] - bound[3 * n + i] <= 0.0
                                            for i in range(n)]
                        else:      # no yielding storey to unload
                            unload_flags = [False] * n
                        quiet = self._second_order_quiet(cfg, state, elastic, e0, watched[3 * n:], scan_vector,
                                                         ag1, rem, up_flags, down_flags, unload_flags)
                else:
                    quiet = True
                if quiet and not any(peak_flags):
                    cost.cleared += 1
                    # tier 1 kept every |drift| under its peak: a covered storey's shear cannot pass its own
                    if inelastic:
                        covered, mask = self._shear_covered(state)
                        if not covered:
                            self._track_shear(state, cfg, y, z1, rem, drift_reach=bound[n:2 * n],
                                              storeys=[not m for m in mask.tolist()])
                    self._commit(state, z1, force, e_damp, e_in, yielding)
                    return events
            if scan is None:        # (the ad hoc path made it with the end state)
                scan = Scan(cfg, scan_vector, ag1, rem)
            event = None
            if inelastic and not quiet:     # a quiet segment only raises peaks: no event to look for
                segment, event = self._first_event(cfg, scan, state, y, rem, xtol, cost, up_flags, down_flags,
                                                   unload_flags, segment)
            stop = rem
            if event is not None:
                stop = event[0]
                if stop > 0.0:
                    if poly is None and TaylorScan.fits(cfg, rem):
                        poly = TaylorScan(segment)
                    z1, scan = _state_and_scan(segment, poly, z0, w, stop, ag1)
                e_damp = None
            if stop > 0.0:
                if e_damp is None:
                    e_damp, e_in = (poly or segment).energies(w, stop)
                self._peaks(cfg, scan, segment, state, y, p, stop, xtol, cost, peak_flags)
                # (a storey whose |drift| tier 1 kept under its peak is covered as above)
                if inelastic:
                    covered, mask = self._shear_covered(state)
                    if peak_flags is None:
                        storeys = None
                    else:
                        storeys = [f or not m for f, m in zip(peak_flags[n:2 * n], mask.tolist())]
                    if storeys is None or any(storeys):
                        self._track_shear(state, cfg, y, z1, stop, scan=scan, segment=segment,
                                          drift_reach=None if change is None else bound[n:2 * n], storeys=storeys)
                self._commit(state, z1, force, e_damp, e_in, yielding)
            s += stop
            if event is not None:
                self._switch(state, event[1], event[2])
                cost.event_log.append((start + s, event[1], event[2]))
                events += 1
                if events > MAX_EVENTS_PER_STEP:
                    break
        return events

    @staticmethod
    def _worth_a_map(cfg, length, all_elastic: bool) -> bool:
        """Whether an interval of a yielding building's configuration goes through the cached
        segment map of its length (built now if missing) rather than ad hoc.  A map costs about
        as much as ten ad hoc segments (15 storeys: 1.4 ms against 0.1-0.2 ms, loaded), and in a
        tall building most yield patterns last a few intervals (kasai_maison_inelastic: 227
        patterns, 85 of them met in one or two intervals, 27 met more than 8 times): a pattern
        gets its map from its
        ``MAP_AFTER_SEGMENTS + 1``-th segment on; the elastic one at once."""
        if all_elastic or cfg.has_map(length):
            return True
        cfg.segments_without_map += 1
        return cfg.segments_without_map > MAP_AFTER_SEGMENTS

    def _second_order_quiet(self, cfg, state, elastic, e0, rate0, scan_vector, ag1, length,
                            up_flags, down_flags, unload_flags) -> bool:
        """The event test of tier 1 to second order, for a segment the first-order bound could
        not clear: True if no storey can change state in ``[0, length]``; otherwise the flags
        (changed in place) keep only the storeys this test cannot clear either.

        An elastic storey's elastic deformation ``e = d - s`` stays within ``e0 + e'0 t`` (its
        extremes at the ends) plus ``max|d''| t^2 / 2``; a yielding storey's ``mode d'`` stays
        above ``mode (d'0 + d''0 t) - max|d'''| t^2 / 2``, a concave bound whose minimum is at an
        end (:meth:`Configuration.drift_curvature_rows` bounds ``d''`` and ``d'''``).  The margins
        (``1e-12`` of ``dy`` and of ``|d'0|``) cover the round-off of these few operations.
        """
        n = self.n
        M, Ra, Rb = cfg.drift_curvature_rows()
        bound = (M @ np.abs(scan_vector[-4 * n:])).tolist()
        # on Python floats, storey by storey: the same IEEE operations as numpy's elementwise
        # ones (so the same decisions) without a numpy call per operation on a few storeys; the
        # flags are lists of bools, narrowed in place
        if ag1 != 0.0:
            slope = abs(ag1)
            bound = [b + slope * (length * ra + rb) for b, ra, rb in zip(bound, *cfg.drift_curvature_lists())]
        half = 0.5 * length * length * math.exp(cfg.growth_rate * length)
        limit, low = self._second_order_limit_lists
        for i in range(n):
            if up_flags[i] or down_flags[i]:
                rem2 = bound[i] * half
                a = e0[i]
                b = a + rate0[i] * length
                hi, lo = (a, b) if a >= b else (b, a)
                up_flags[i] = up_flags[i] and hi + rem2 >= limit[i]
                down_flags[i] = down_flags[i] and lo - rem2 <= low[i]
        if not any(unload_flags):       # no yielding storey left to test (all elastic: most segments)
            return not (any(up_flags) or any(down_flags))
        m = 3 * n                                # rows of each block of the scan vector; block 4: g''(0)
        mode = state.mode.tolist()
        curvature = scan_vector[4 * m + n:4 * m + 2 * n].tolist()
        for i in range(n):
            if unload_flags[i]:
                g0 = mode[i] * rate0[i]
                g1 = g0 + mode[i] * curvature[i] * length - bound[n + i] * half
                unload_flags[i] = (g0 if g0 <= g1 else g1) <= 1e-12 * abs(g0)
        return not (any(up_flags) or any(down_flags) or any(unload_flags))

    def _storey_shear_at(self, state, d):
        """``V`` of drifts ``d`` (any shape ending in n) in the state's yield pattern: a yielding
        storey ``alpha k d + (1 - alpha) Fy mode``, an elastic one ``k d - (1 - alpha) k s``."""
        _, yielding, any_yielding, q_yield, _, _ = self._law_facts(state.mode)
        elastic_part = self._elastic_k * (d - state.slip)
        q = np.where(yielding, q_yield, elastic_part) if any_yielding else elastic_part
        return self._hard_k * d + q

    def _shear_covered(self, state) -> tuple[bool, np.ndarray]:
        """``(all, mask)``: which storeys' ``|V|`` cannot pass its running peak while their
        ``|drift|`` stays within its running peak ``P`` (a storey whose drift tier 1 cleared in
        a segment then needs no shear test there), and whether all.

        ``|V| = |alpha k d + q|`` with ``|q| <= (1 - alpha) Fy`` in every state, so ``|V| <=
        alpha k P + (1 - alpha) Fy``; once a storey has yielded, its drift peak is reached while
        yielding (elastic, it stays within ``2 dy`` of the last yield drift, inside the peak), where
        ``|V|`` is that bound, so the bound meets its peak shear.  A storey that has not yielded
        counts as covered: its shear is ``k d`` and its peak ``k P`` (:meth:`peak_storey_shear`).
        Compared with the peak to ``1e-12`` (the two sides are computed differently; the peaks
        themselves are established to ``PEAK_RTOL``).  Remembered for the arrays it was computed
        from (a state's arrays are replaced, never changed in place)."""
        memo = self._cover_memo
        if memo is None or memo[0] is not state.peak_shear or memo[1] is not state.yielded:
            # the largest P for which that bound stays at the peak, per storey: changes only when
            # a peak shear grows or a storey first yields (the drift peaks change far more often)
            # (on Python floats, storey by storey: the same operations as elementwise numpy, without
            # an errstate context and a dozen calls; a storey not yielded is not tracked,
            # peak_storey_shear: k times the peak drift)
            V = (state.peak_shear * (1.0 + 1e-12)).tolist()
            level = np.array([((v - q) / h if h > 0.0 else (math.inf if v >= q else -math.inf)) if y else math.inf
                              for v, q, h, y in zip(V, self._qy_list, self._hard_list, state.yielded.tolist())])
            memo = self._cover_memo = (state.peak_shear, state.yielded, level)
            self._covered_memo = None
        known = self._covered_memo
        if known is not None and known[0] is state.peaks:
            return known[1]
        n = self.n
        mask = state.peaks[n:2 * n] <= memo[2]       # the drift peaks
        result = (all(mask.tolist()), mask)
        self._covered_memo = (state.peaks, result)
        return result

    def _track_shear(self, state, cfg, y, z1, length, scan=None, drift_reach=None, segment=None, storeys=None):
        """Raise ``state.peak_shear`` over a segment of ``length`` s from ``y`` (``[u0; v0; ag;
        ag'; p]``) to ``z1`` (``[u; v]``) in the state's yield pattern (before its events apply).

        Between events a storey's shear is linear in its drift: yielding, ``alpha k d + const``
        with the drift monotonic (unloading is an event); elastic, ``k d - (1 - alpha) k s``
        with the slip fixed.  So a yielding storey's peak is at a segment end, and an elastic
        storey's at an end or at an interior extremum of its drift: where a rigorous bound of
        ``|V|`` over the segment (``drift_reach``, tier 1's bound of the drift's change, or the
        cubic Hermite bound of ``scan``'s drift rows) exceeds the peak, the exact solution is
        searched (:func:`max_abs` on ``c' z + offset``); only in ``storeys`` (a list of bools; all
        if None: the others are covered, :meth:`_shear_covered`).  ``drift_reach``: a list of
        floats per storey.  The start was counted by the segment before (or the initial state)."""
        n = self.n
        # on Python floats: the storeys asked are few (those whose drift tier 1 did not clear)
        # (a storey that has not yielded is not tracked: peak_storey_shear)
        if storeys is None:
            which = state.yielded.nonzero()[0].tolist()
        else:
            which = [i for i, (a, b) in enumerate(zip(storeys, state.yielded.tolist())) if a and b]
        if not which:
            return
        u1, u0 = z1[:n].tolist(), y[:n].tolist()
        mode, slip = state.mode.tolist(), state.slip.tolist()
        k, hard, soft, qy = self._k_list, self._hard_list, self._soft_list, self._qy_list
        peak = state.peak_shear.tolist()
        if scan is not None:
            G, B = scan.G[n:2 * n].tolist(), scan.B[n:2 * n, 0].tolist()      # the drift rows
        w4 = length ** 4 / 384.0
        raised = False
        for i in which:
            d1 = u1[i] - u1[i - 1] if i else u1[0]
            if mode[i]:
                V1 = hard[i] * d1 + mode[i] * qy[i]
            else:
                V1 = hard[i] * d1 + soft[i] * (d1 - slip[i])
            if abs(V1) > peak[i]:
                peak[i] = abs(V1)
                raised = True
            if mode[i]:
                continue       # yielding: monotonic drift, the peak at an end
            shift = soft[i] * slip[i]                     # V = k d - shift
            if drift_reach is not None:
                d0 = u0[i] - u0[i - 1] if i else u0[0]
                if abs(k[i] * d0 - shift) + k[i] * drift_reach[i] <= peak[i]:
                    continue
            if scan is not None:
                # the Hermite test (as in _peaks): the drift's range and its error bound
                g = G[i]
                g0, g1, s0, s1 = g[0], g[1], length * g[2], length * g[3]
                err = B[i] * w4 + 1e-12 * (abs(g0) + abs(g1) + length * (abs(g[2]) + abs(g[3])))
                # first the cheaper bound of that range (_hermite_spread): where it decides, the
                # test decides the same (|k x - shift| is convex in x and rounding is monotonic),
                # without the roots (most storeys of most segments, 9600 of 9700 tests measured)
                spread = _hermite_spread(g0, g1, s0, s1)
                low, high = (g0, g1) if g0 < g1 else (g1, g0)
                if max(abs(k[i] * (low - spread - err) - shift), abs(k[i] * (high + spread + err) - shift)) <= peak[i]:
                    continue
                lo, hi = hermite_range_scalar(g0, g1, s0, s1)
                if max(abs(k[i] * (lo - err) - shift), abs(k[i] * (hi + err) - shift)) <= peak[i]:
                    continue
            if segment is None:
                segment = TaylorSegment(cfg, y[:2 * n], y[2 * n:], length)
            value, _ = max_abs(segment, k[i] * cfg.peak_modal[n + i], -shift, length, peak[i], PEAK_XTOL * length,
                               min_width=EVENT_XTOL * length, budget=_ROOT_BUDGET, atol=k[i] * PEAK_ATOL[1])
            if value > peak[i]:
                peak[i] = value
                raised = True
        if raised:
            state.peak_shear = np.array(peak)

    def _track_shear_rows(self, state, cfg, Y, z_end, lengths, drift_reach, wanted):
        """:meth:`_track_shear` over consecutive intervals in one yield pattern (the batch path):
        ``Y`` their ``y`` rows, ``z_end`` the last one's end, ``lengths`` (s) and
        ``drift_reach`` (tier 1's bound of each drift's change, rows) theirs, ``wanted`` (rows)
        the storeys not covered in each (:meth:`_shear_covered`).  An interval whose bound
        stays under the step's largest end value cannot hold the step's peak."""
        n = self.n
        count = Y.shape[0]
        U = np.empty((count + 1, n))
        U[:count] = Y[:, :n]
        U[count] = z_end[:n]
        d = U.copy()
        d[:, 1:] -= U[:, :n - 1]
        V = np.abs(self._storey_shear_at(state, d))
        peak = np.maximum(state.peak_shear, V[1:].max(axis=0))
        elastic = state.mode == 0
        if elastic.any():
            shift = self._elastic_k * state.slip
            reach = np.abs(self.k * d[:count] - shift) + self.k * drift_reach
            flagged = (reach > peak) & (elastic & state.yielded) & wanted
            if flagged.any():
                # the intervals tier 1 leaves, one by one in order: _track_shear's tests on the
                # interval's scan (its Hermite bounds, then the search), against the peak so far
                state.peak_shear = peak
                for j in flagged.any(axis=1).nonzero()[0].tolist():
                    storeys = flagged[j] & (reach[j] > state.peak_shear)   # an earlier peak may cover it
                    if not storeys.any():
                        continue
                    y = Y[j]
                    L = float(lengths[j])
                    scan = Scan(cfg, cfg.segment_map(L).scan @ y, float(y[2 * n + 1]), L)
                    end = Y[j + 1] if j + 1 < count else z_end
                    self._track_shear(state, cfg, y, end, L, scan=scan, storeys=storeys.tolist())
                return
        state.peak_shear = peak

    def _commit(self, state, z1, force, e_damp, e_in, yielding=True):
        """End a segment at ``z1`` (a fresh array: the state keeps views of it).  ``yielding``
        False: no storey yields in this segment (its hysteretic state stays)."""
        n = self.n
        u1 = z1[:n]
        state.E_external += float(force @ (u1 - state.u))
        state.E_damping += e_damp
        state.E_input += e_in
        if yielding and self._inelastic:
            self._yield_along(state, u1)
        state.u = u1
        state.v = z1[n:]

    def _yield_along(self, state, u1):
        """The yielding storeys from ``state.u`` to ``u1``: a yielding storey dissipates
        ``(1 - alpha) Fy`` per unit of slip; its drift is monotonic in the direction of mode over
        the segment (unloading is an event), its slip follows the drift."""
        _, yielding, any_yielding, _, work, offset = self._law_facts(state.mode)
        if any_yielding:
            d0 = self._drift_of(state.u)
            d1 = self._drift_of(u1)
            state.E_hysteretic += float(work @ (d1 - d0))      # elastic storeys: mode 0
            state.slip = np.where(yielding, d1 - offset, state.slip)

    def _switch(self, state, storey: int, kind: int):
        """Apply an event: ``kind`` = +1/-1 yield in that direction, 0 unloading."""
        d = _drift(state.u)[storey]
        if kind != 0:
            # the shear where the storey yields (the segment that ended here may have been
            # covered, :meth:`_shear_covered`, and a storey's first yield starts its tracking)
            shear = abs(float(self._storey_shear_at(state, _drift(state.u))[storey]))
            if shear > state.peak_shear[storey]:
                peak = state.peak_shear.copy()
                peak[storey] = shear
                state.peak_shear = peak
        mode = state.mode.copy()
        slip = state.slip.copy()
        if kind == 0:
            slip[storey] = d - mode[storey] * self.dy[storey]   # elastic again, at the limit
        mode[storey] = kind
        state.mode = mode
        if kind != 0 and not state.yielded[storey]:
            yielded = state.yielded.copy()      # replaced, never changed in place (shallow copies)
            yielded[storey] = True
            state.yielded = yielded
        state.slip = slip
        state.offset = None

    # -- events -------------------------------------------------------------------------------
    def _first_event(self, cfg, scan, state, y, rem, xtol, cost, up_flags=None, down_flags=None,
                     unload_flags=None, segment=None):
        """``(segment, event)``: the segment's :class:`TaylorSegment` (``segment``, made if None and
        needed) and ``(time, storey, kind)`` of the first event in [0, rem], or None.

        Events: an elastic storey whose plastic element reaches its strength (``|d - s| = dy``;
        kind = the direction) and a yielding storey whose drift velocity changes sign (kind 0).
        Tier 2 (cubic Hermite through the drift rows of the scan, with the bound of the fourth
        or fifth derivative) narrows the candidates of tier 1; the rest are searched one by one
        (:func:`first_root`) up to the earliest event found so far.
        """
        n = self.n
        mode = state.mode
        modes = mode.tolist()
        if up_flags is None:
            ups = downs = [m == 0 for m in modes]
            unloads = [m != 0 for m in modes]
            storeys = list(range(n))
        else:       # lists of bools (_interval, _second_order_quiet)
            ups, downs, unloads = up_flags, down_flags, unload_flags
            storeys = [i for i in range(n) if ups[i] or downs[i] or unloads[i]]
        w4 = rem ** 4 / 384.0
        if not storeys:
            return segment, None
        # The tests on Python floats: the same IEEE double operations as on numpy scalars (so
        # the same bits and decisions), at a fraction of their cost per operation.
        G = scan.G[n:2 * n].tolist()                    # the drift rows
        B = scan.B[n:2 * n].tolist()
        slips, dys = state.slip.tolist(), self._dy_list
        candidates = []
        # (each Hermite range only where its cheaper bound, _hermite_spread, leaves the test
        # open: where that bound decides, the range decides the same, rounding being monotonic)
        for i in storeys:
            g = G[i]
            if modes[i] == 0:
                s = slips[i]
                g0, g1, s0, s1 = g[0] - s, g[1] - s, rem * g[2], rem * g[3]
                err = B[i][0] * w4
                dy = dys[i]
                spread = _hermite_spread(g0, g1, s0, s1)
                low, high = (g0, g1) if g0 < g1 else (g1, g0)
                up = ups[i] and high + spread + err >= dy
                down = downs[i] and low - spread - err <= -dy
                if not (up or down):
                    continue
                lo, hi = hermite_range_scalar(g0, g1, s0, s1)
                if up and hi + err >= dy:
                    candidates.append((i, +1))
                if down and lo - err <= -dy:
                    candidates.append((i, -1))
            elif unloads[i]:
                sg = float(modes[i])
                g0, g1, s0, s1 = sg * g[2], sg * g[3], rem * sg * g[4], rem * sg * g[5]
                err = B[i][1] * w4
                if (g0 if g0 < g1 else g1) - _hermite_spread(g0, g1, s0, s1) - err > 0.0:
                    continue
                lo, _ = hermite_range_scalar(g0, g1, s0, s1)
                if lo - err <= 0.0:
                    candidates.append((i, 0))
        if not candidates:
            return segment, None
        if segment is None:
            segment = TaylorSegment(cfg, y[:2 * n], y[2 * n:], rem)
        best = None
        D = self._drift_rows
        event_rows = cfg.event_rows
        for i, kind in candidates:
            # the modal row of the event function, kept by the configuration (the same product)
            key = (i, kind, modes[i])
            rows = event_rows.get(key)
            if rows is None:
                row = np.zeros(2 * n)
                if kind == 0:
                    row[n:] = mode[i] * D[i]         # g = mode d' >= 0 until unloading
                else:
                    row[:n] = -kind * D[i]           # g = dy - kind (d - s) >= 0 until yield
                c_modal = row @ cfg.V
                rows = event_rows[key] = (c_modal, np.abs(c_modal))
            c_modal, c_abs = rows
            offset = 0.0 if kind == 0 else self.dy[i] + kind * state.slip[i]
            horizon = rem if best is None else best[0]
            if horizon <= 0.0:
                return segment, best
            cost.root_searches += 1
            t = first_root(segment, c_modal, 0, offset, horizon, xtol, min_width=xtol, budget=_ROOT_BUDGET,
                           c_modal_abs=c_abs)
            if t is not None and (best is None or t < best[0]):
                best = (t, int(i), kind)
        return segment, best

    # -- peaks --------------------------------------------------------------------------------
    def _peaks(self, cfg, scan, segment, state, y, p, length, xtol, cost, flags=None):
        """Update the running peaks of |x|, |drift|, |a| over a segment of the exact solution.

        The end values are recorded; the functions that tier 1 (``flags``, a list of 3n bools;
        all if None) could not clear are tested by the cubic Hermite bound and, where a new peak
        remains possible, the segment is kept in ``state.pending`` for a search when the peaks
        are read (:meth:`resolve_peaks`): a peak that a later step exceeds is never searched.
        """
        n = self.n
        G, B = scan.G, scan.B
        w4 = length ** 4 / 384.0
        accel_offset = p * self._inv_m
        prefilter = 3 * n >= _PREFILTER_FROM and (flags is None or flags.count(True) >= _PREFILTER_FROM)
        if prefilter:
            g1 = G[:, 1].copy()
            g1[2 * n:] += accel_offset
            new = np.maximum(state.peaks, np.abs(g1))
            limits = new + self._peak_atol
        else:
            # the few functions of a low building on Python floats: the same IEEE operations as
            # the arrays' (np.maximum's NaN included), without a numpy call for each
            g1 = G[:, 1].tolist()
            for i, offset in enumerate(accel_offset.tolist()):
                g1[2 * n + i] += offset
            raised = [b if b > a or b != b else a for a, b in zip(state.peaks.tolist(), map(abs, g1))]
            new = np.array(raised)
            limits = None       # raised + PEAK_ATOL, added below for the few functions that need it
        # Drop at once the functions that the Hermite test below provably drops: on [0, 1] a
        # cubic Hermite through end values g0, g1 and slopes d0, d1 stays within max(|g0|, |g1|)
        # + 4/27 (|d0| + |d1|) (its basis: h00 + h01 = 1, both in [0, 1]; |h10|, |h11| <= 4/27),
        # and the test's floating-point evaluation of it stays within 1e-12 (|g0| + |g1| + |d0|
        # + |d1|) of that (its round-off is ~20 eps of those magnitudes); floating-point addition
        # being monotonic, a function this bound keeps under its limit fails the test too.
        # (a dozen numpy calls: worth it from about 16 candidates, measured; fewer are tested
        # one by one at once)
        if prefilter:
            keep = np.ones(3 * n, dtype=bool) if flags is None else np.array(flags)
            g0v = np.abs(G[:, 0] + self._watch_offset(accel_offset))
            g1v = np.abs(g1)
            s0v, s1v = np.abs(G[:, 2]), np.abs(G[:, 3])
            slopes = s0v + s1v
            slopes *= length
            magnitude = g0v + g1v + slopes
            reach = np.maximum(g0v, g1v) + _HERMITE_SLOPE_GAIN * slopes + 1e-12 * magnitude + B[:, 0] * w4
            # and those whose slope provably keeps its sign, by the same bound on the slope's
            # Hermite (the test below, _monotonic)
            curvatures = np.abs(G[:, 4]) + np.abs(G[:, 5])
            curvatures *= length
            monotonic = np.minimum(s0v, s1v) - _HERMITE_SLOPE_GAIN * curvatures - _HERMITE_MARGIN * (
                s0v + s1v + curvatures) - B[:, 1] * w4 > 0.0
            monotonic &= G[:, 2] * G[:, 3] > 0.0
            keep &= ~(reach <= limits) & ~monotonic
            candidates = keep.nonzero()[0].tolist()
        elif flags is None:
            candidates = None
        else:
            candidates = [j for j, f in enumerate(flags) if f]
        if candidates is None:
            # every function a candidate (no prefilter for a few storeys): all rows, in order
            candidates = self._all_functions
            rows, bounds = G.tolist(), B.tolist()
        else:
            if not candidates:            # every function cleared: only the end values count
                state.peaks = new
                return
            rows, bounds = G[candidates].tolist(), B[candidates].tolist()
        # The tests run on Python floats: the same IEEE double operations as on numpy scalars
        # (so the same bits), at a fraction of their cost per operation.
        # (only the candidates' rows: most segments leave a few of the 3n functions)
        # (rows gathered apart: np.column_stack cost more than the tests of a few candidates)
        if prefilter:
            ends, limit_list = g1.tolist(), limits.tolist()
        else:
            ends, limit_list = g1, None
        offsets = accel_offset.tolist()
        atol = self._peak_atol_list
        gain, margin = _HERMITE_SLOPE_GAIN, _HERMITE_MARGIN
        deferred = []
        for j, (g0, _, s0, s1, c0, c1), (bound0, bound1) in zip(candidates, rows, bounds):
            if s0 * s1 > 0.0:
                # a slope that provably keeps its sign puts the extremes at the ends: first the
                # bound of the slope's Hermite (as the prefilter's above, with its round-off
                # margin: where it decides, the exact test decides the same), then the test
                # (min(a0, a1) written out: the same float, without a call)
                err = bound1 * w4
                a0, a1 = abs(s0), abs(s1)
                e = length * (abs(c0) + abs(c1))
                if (a0 if a0 <= a1 else a1) - gain * e - margin * (a0 + a1 + e) - err > 0.0:
                    continue
                lo, hi = hermite_range_scalar(s0, s1, length * c0, length * c1)
                if lo - err > 0.0 or hi + err < 0.0:
                    continue
            # (the start value as the array path forms it: the acceleration's constant part added,
            # 0.0 added to the others)
            g0 = g0 + offsets[j - 2 * n] if j >= 2 * n else g0 + 0.0
            lo, hi = hermite_range_scalar(g0, ends[j], length * s0, length * s1)
            reach = max(-lo, hi) + bound0 * w4
            if reach <= (raised[j] + atol[j] if limit_list is None else limit_list[j]):
                continue
            # a new peak is possible in this segment: keep it for a search when the peaks are
            # read (most are superseded by a later, higher peak before anyone reads them)
            deferred.append((j, reach))
        state.peaks = new
        if deferred:
            y_copy = y.copy()
            key = (state.mode != 0).tobytes()
            state.pending.extend((j, U, key, y_copy, length, xtol) for j, U in deferred)
            cost.peaks_deferred += len(deferred)
            if len(state.pending) > MAX_PENDING:
                # drop what the established peaks already exceed; search if still too many
                atol = self._peak_atol
                state.pending = [e for e in state.pending if e[1] > new[e[0]] + atol[e[0]]]
                if len(state.pending) > MAX_PENDING // 2:
                    self.resolve_peaks(state, cost)

    def _watch_offset(self, accel_offset: np.ndarray) -> np.ndarray:
        """``[0 (2n); accel_offset]``: what the watched functions (x, drift, a) add to ``F z``."""
        out = np.zeros(3 * self.n)
        out[2 * self.n:] = accel_offset
        return out

    def resolve_peaks(self, state, cost=None) -> None:
        """Run the deferred peak searches, highest bound first (:func:`max_abs`)."""
        if not state.pending:
            return
        n = self.n
        cost = cost or StepCost()
        new = state.peaks.copy()
        atol = self._peak_atol
        segments = {}
        inelastic = self._inelastic
        for j, bound, key, y, length, xtol in sorted(state.pending, key=lambda e: -e[1]):
            if bound <= new[j] + atol[j]:
                continue
            cfg = self._configuration_of(key)
            segment = segments.get(id(y))
            if segment is None:
                # the searches run on Taylor polynomials (Python floats, no exponential per point;
                # the modal form for a segment too long for them, TaylorSegment.taylor): the
                # same sums in another order, so a peak moves by round-off from the modal
                # evaluation's (kasai_maison: 4e-16 relative at most) at a third of the cost
                # (its final read of the peaks: 64 searches, 14 -> 5 ms)
                segment = segments[id(y)] = TaylorSegment(cfg, y[:2 * n], y[2 * n:], length)
            offset = y[2 * n + 2 + j - 2 * n] * self._inv_m[j - 2 * n] if j >= 2 * n else 0.0
            cost.peak_searches += 1
            new[j], _ = max_abs(segment, cfg.peak_modal[j], offset, length, new[j], PEAK_XTOL * length,
                                min_width=xtol, budget=_ROOT_BUDGET, atol=atol[j])
        state.peaks = new
        state.pending = []

    def _configuration_of(self, key: bytes) -> Configuration:
        return self.configuration(np.frombuffer(key, dtype=bool).astype(np.int64))

    # -- the linear zero-order-hold step computed elsewhere (building_slave) -------------------
    def legacy_rows(self, h: float, step_matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For a zero-order-hold step ``h`` of the elastic building acting on ``y = [u0; v0; ag; f]``
        whose end state is ``step_matrix @ y`` (``[u1; v1]``, the building's step matrix of
        ``h``): ``(start, scan, reach)``: ``start @ y = [Re W z'(0); Im W z'(0); watched functions
        at 0 (accel with f/m)]``, ``scan @ y`` the :class:`Scan` vector, and ``reach @ |start @
        y|`` the tier-1 bound of every watched function over the step (its value at 0 plus the
        change bound acting on ``|Re| + |Im|``, an upper bound of the modal amplitude).  No
        segment map (its energy forms are the step matrix's business): the scan rows from the
        step matrix, the change bound in closed form."""
        cfg = self.configuration(np.zeros(self.n, dtype=np.int64))
        n = self.n
        if self._legacy_parts is None:
            # what does not depend on h, made once: the watched functions' rows at the start (the
            # accelerations with f / m) and the identity of reach's value-at-start columns
            watch = np.hstack([cfg.watch_rows, np.zeros((4 * n, n + 1))])
            watch[2 * n:3 * n, 2 * n + 1:] = np.diag(1.0 / self.masses)
            self._legacy_parts = (np.ascontiguousarray(watch[:3 * n]), np.eye(3 * n))
        watch, identity = self._legacy_parts
        drop = 2 * n + 1     # the ag1 column: a zero-order hold has no ramp (any value there is dropped)
        # np.insert / np.delete of that column, as plain copies (a fifth of the cost of a new length)
        state_map = np.zeros((step_matrix.shape[0], step_matrix.shape[1] + 1))
        state_map[:, :drop] = step_matrix[:, :drop]
        state_map[:, drop + 1:] = step_matrix[:, drop:]
        full = cfg.scan_rows(state_map, h)
        scan = np.empty((full.shape[0], full.shape[1] - 1))
        scan[:, :drop] = full[:, :drop]
        scan[:, drop:] = full[:, drop + 1:]
        change, _ = cfg.change_bounds(h)
        start = np.concatenate((scan[-4 * n:], watch))
        reach = np.concatenate((change[:3 * n], identity), axis=1)
        return start, scan, reach

    def legacy_peaks(self, state, y_zoh: np.ndarray, start_values: np.ndarray, scan_rows: np.ndarray,
                     reach: np.ndarray, h: float, cost: StepCost) -> None:
        """Running peaks over a zero-order-hold step of the elastic building (``y_zoh`` =
        ``[u0; v0; ag; f]``, ``start_values = start @ y_zoh`` of :meth:`legacy_rows`);
        ``state`` still holds the start of the step."""
        flags = reach @ np.abs(start_values) > state.peaks    # strict, see _interval
        if not np.count_nonzero(flags):      # (cheaper than flags.any() on a few elements)
            cost.cleared += 1
            return
        n = self.n
        cfg = self.configuration(state.mode)
        y = np.empty(3 * n + 2)
        y[:2 * n + 1] = y_zoh[:2 * n + 1]
        y[2 * n + 1] = 0.0
        y[2 * n + 2:] = y_zoh[2 * n + 1:]
        scan = Scan(cfg, scan_rows @ y_zoh, 0.0, h)
        self._peaks(cfg, scan, None, state, y, y[2 * n + 2:], h, EVENT_XTOL * h, cost, flags.tolist())


    # -- a linear building's one-interval step through one matrix (building_slave) ------------
    def ramp_step(self, state, h: float, ag0: float, ag1: float, force, cost: StepCost) -> np.ndarray:
        """One knot interval of ``h`` s (ground acceleration ``ag0 + ag1 s``, m/s^2) of a linear
        building through one cached matrix (:class:`RampStep`): what :meth:`advance` does for
        these two knots (:meth:`_interval` with the segment map of this length: the same end
        state, energies and tier-1 decisions, the same in-step peak tests where tier 1 leaves a
        function), with one product instead of a dozen numpy calls.  Returns the product
        (the building's outputs are rows of it); ``cost`` counts the step.  Raises ValueError,
        the state untouched, if the step would leave the state not finite or the segment map
        cannot be made (:meth:`Configuration.chunk_nodes`)."""
        n = self.n
        two_n = 2 * n
        m = 3 * n
        plan = self._ramp_aliases.get(h)
        if plan is None:
            plan = self._ramp_plan(h)
        y = self._ramp_y
        y[:n] = state.u
        y[n:two_n] = state.v
        y[two_n] = ag0
        y[two_n + 1] = ag1
        y[two_n + 2:] = force
        w = plan.matrix @ y
        i = 4 * n                            # u1 - u0, then the input rows, then Q y
        j = i + n + 2
        e_damp = float(y @ w[j:j + m + 2])
        e_in = ag0 * float(w[i + n]) + ag1 * float(w[i + n + 1])
        d_ext = float(force @ w[i:i + n])
        if not math.isfinite(e_damp + e_in + d_ext + float(w[:two_n].sum())):
            raise ValueError(f"a step of h = {h!r} s would leave the building's state not finite: the inputs "
                             f"or the step are beyond what its arithmetic supports")
        cost.segments += 1
        flags = plan.reach @ np.abs(w[plan.start:]) > state.peaks        # strict, as _interval
        if flags.any():
            scan = Scan(plan.cfg, plan.smap.scan @ y, ag1, h)
            self._peaks(plan.cfg, scan, None, state, y, force, h, EVENT_XTOL * h, cost, flags.tolist())
        else:
            cost.cleared += 1
        state.E_external += d_ext
        state.E_damping += e_damp
        state.E_input += e_in
        state.u = w[:n]                     # views of the fresh product: nothing else writes to w
        state.v = w[n:two_n]
        return w

    def _ramp_plan(self, h: float) -> RampStep:
        """The :class:`RampStep` of ``h`` s, built once per canonical length (from the segment
        map :meth:`_interval` would use) and remembered by every exact length asked."""
        key = canonical_length(h)
        plan = self._ramps.get(key)
        if plan is None:
            if len(self._ramps) >= MAX_RAMP_STEPS:
                self._ramps.pop(next(iter(self._ramps)))
            plan = self._ramps[key] = self._make_ramp_plan(key)
        if len(self._ramp_aliases) >= 4 * MAX_RAMP_STEPS:
            self._ramp_aliases.clear()
        self._ramp_aliases[h] = plan
        return plan

    def _make_ramp_plan(self, h: float) -> RampStep:
        n = self.n
        two_n, m, size = 2 * n, 3 * n, 3 * n + 2
        cfg = self.configuration(np.zeros(n, dtype=np.int64))
        smap = cfg.segment_map(h)
        S = smap.state
        net = np.zeros((n, size))                 # f / m
        net[:, two_n + 2:] = np.diag(self._inv_m)
        accel = cfg.peak_rows[two_n:] @ S + net
        drift = self._drift_rows @ S[:n]
        du = S[:n] - np.eye(n, size)
        # y' I y with the input form I, which is zero outside the rows and columns of ag0 and ag1
        # (-int (1'M v)(ag0 + ag1 s) ds is linear in ag0 and ag1): ag0 r0 y + ag1 r1 y
        form = smap.input
        r0 = 2.0 * form[two_n]
        r0[two_n] = form[two_n, two_n]
        r1 = 2.0 * form[two_n + 1]
        r1[two_n] = 0.0
        r1[two_n + 1] = form[two_n + 1, two_n + 1]
        watched = np.zeros((m, size))
        watched[:, :two_n] = cfg.watch_rows[:m]
        watched[two_n:] += net
        slope = np.zeros((1, size))
        slope[0, two_n + 1] = 1.0
        matrix = np.vstack([S, accel, drift, du, r0, r1, smap.damping, np.sqrt(self.masses)[:, None] * S[n:],
                            np.sqrt(self.k)[:, None] * drift, smap.scan[-4 * n:], watched, slope])
        # reach @ [|Re|, |Im| W z'(0) (4n); |watched| (3n); |ag1|]: _interval's tier-1 bound plus |g(0)|
        reach = np.zeros((m, 7 * n + 1))
        reach[:, :4 * n] = smap.change[:m]
        reach[:, 4 * n:7 * n] = np.eye(m)
        reach[:, 7 * n] = smap.ramp_change[:m]
        return RampStep(h, cfg, smap, np.ascontiguousarray(matrix), reach, matrix.shape[0] - (7 * n + 1))

class BoucWenRK(BuildingIntegrator):
    """Bouc-Wen storeys, embedded Runge-Kutta 8(5,3) with error control (see module docstring)."""

    name = "bouc_wen_rk"

    def __init__(self, building: ShearBuilding, hysteresis: StoreyHysteresis, rtol: float = 1e-8):
        super().__init__(building, hysteresis)
        n = self.n
        self.rtol = float(rtol)
        h = hysteresis
        self.bw = (h.bw_n, h.bw_beta, h.bw_gamma)
        dy = self.dy
        w1 = float(building.omegas[0])
        # Absolute tolerances from the building's own scales: yield drift, its velocity at the
        # fundamental frequency, z ~ 1, energy Fy dy.
        scale_u = float(np.min(dy))
        energy = float(np.sum(self.fy * dy))
        self.atol = np.concatenate([np.full(n, scale_u), np.full(n, scale_u * w1), np.ones(n),
                                    np.full(3, energy)]) * self.rtol
        # q = P y: drifts, drift rates, C v and 1'M v in one product
        D = np.eye(n) - np.eye(n, k=-1)
        P = np.zeros((3 * n + 1, 3 * n + 3))
        P[:n, :n] = D
        P[n:2 * n, n:2 * n] = D
        P[2 * n:3 * n, n:2 * n] = self.C
        P[3 * n, n:2 * n] = self.masses
        self._P = P
        self._DT = np.ascontiguousarray(D.T)
        self._inv_m = 1.0 / self.masses
        self._inv_dy = 1.0 / dy

    def _shear(self, d, z):
        return self.alpha * self.k * d + (1.0 - self.alpha) * self.fy * z

    def storey_shear(self, state):
        return self._shear(_drift(state.u), state.z)

    def strain_energy(self, state):
        d = _drift(state.u)
        return float(np.sum(0.5 * self.alpha * self.k * d * d
                            + 0.5 * (1.0 - self.alpha) * self.fy * self.dy * state.z * state.z))

    def _shear_and_strain(self, state, d):
        return self._shear(d, state.z), self.strain_energy(state)

    def _rhs(self, ag0, ag1, force):
        """``y' = fun(s, y)`` with ``y = [u, v, z, E_damping, E_input, E_hysteretic]``."""
        n = self.n
        P, DT, inv_m, inv_dy = self._P, self._DT, self._inv_m, self._inv_dy
        ak = self.alpha * self.k
        hf = (1.0 - self.alpha) * self.fy
        bw_n, beta, gamma = self.bw

        def fun(s, y):
            q = P @ y
            d, dd, cv = q[:n], q[n:2 * n], q[2 * n:3 * n]
            v = y[n:2 * n]
            z = y[2 * n:3 * n]
            ag = ag0 + ag1 * s
            az = np.abs(z)
            zn = az ** bw_n
            sg = np.sign(dd * z)
            out = np.empty_like(y)
            out[:n] = v
            out[n:2 * n] = (force - cv - DT @ (ak * d + hf * z)) * inv_m - ag
            # Bouc-Wen rate and dissipation, see fmu_src.hysteresis
            out[2 * n:3 * n] = dd * (1.0 - zn * (gamma + beta * sg)) * inv_dy
            out[3 * n] = v @ cv
            out[3 * n + 1] = -q[3 * n] * ag
            out[3 * n + 2] = hf @ (az * zn * np.abs(dd) * (beta + gamma * sg))
            return out
        return fun

    def _peak_values(self, y, dy_dt, force):
        """Values and time derivatives of the tracked functions (x, drift, a, V) at one point."""
        n = self.n
        u, v, z = y[:n], y[n:2 * n], y[2 * n:3 * n]
        acc_rel, zdot = dy_dt[n:2 * n], dy_dt[2 * n:3 * n]
        d, dd = _drift(u), _drift(v)
        V = self._shear(d, z)
        Vdot = self.alpha * self.k * dd + (1.0 - self.alpha) * self.fy * zdot
        a = (force - self.C @ v - _floor_forces(V)) / self.masses
        adot = (-self.C @ acc_rel - _floor_forces(Vdot)) / self.masses
        return np.concatenate([u, d, a, V]), np.concatenate([v, dd, adot, Vdot])

    def advance(self, state, times, ag, force) -> StepCost:
        times = np.asarray(times, dtype=float)
        ag = np.asarray(ag, dtype=float)
        force = np.asarray(force, dtype=float)
        cost = StepCost()
        n = self.n
        h = float(times[-1] - times[0])
        rate = float(np.max(self.building.omegas))   # the elastic modes are the fastest: yielding softens
        if rate * h > BOUC_WEN_MAX_SPAN:
            raise ValueError(f"a step of {h:.6g} s spans {rate * h:.6g} radians of the fastest mode "
                             f"({rate:.6g} rad/s); the limit is {BOUC_WEN_MAX_SPAN:g} (about "
                             f"{BOUC_WEN_MAX_SPAN / (2.0 * math.pi):.0f} periods): use shorter steps")
        u_start = state.u.copy()
        y = np.concatenate([state.u, state.v, state.z, [0.0, 0.0, 0.0]])
        # the running peaks of x, drift, a and the storey shear V, located alike
        peaks = np.concatenate((state.peaks, state.peak_shear))
        for j in range(times.size - 1):
            length = float(times[j + 1] - times[j])
            if length <= 0.0:
                continue
            slope = (ag[j + 1] - ag[j]) / length
            fun = self._rhs(float(ag[j]), float(slope), force)
            solver = DOP853(fun, 0.0, y, length, rtol=self.rtol, atol=self.atol,
                            first_step=min(state.rk_step, length) if state.rk_step > 0.0 else None)
            f_old = solver.f
            vals_old, rates_old = self._peak_values(y, f_old, force)
            while solver.status == "running":
                solver.step()
                cost.rk_steps += 1
                if cost.rk_steps > BOUC_WEN_MAX_RK_STEPS:
                    raise ValueError(f"more than {BOUC_WEN_MAX_RK_STEPS} Runge-Kutta steps in one step of {h:.6g} s "
                                     f"(the last {solver.step_size:.3g} s long): the Bouc-Wen storeys are too "
                                     f"stiff at their yield corners (bw_n = {self.bw[0]:g}); use shorter steps "
                                     f"or a smaller bw_n")
                if solver.status == "failed":
                    raise ValueError(f"Bouc-Wen integration failed: {solver.message}")
                y_new, f_new = solver.y, solver.f
                vals_new, rates_new = self._peak_values(y_new, f_new, force)
                peaks = np.maximum(peaks, np.abs(vals_new))
                turning = np.flatnonzero(rates_old * rates_new < 0.0)
                if turning.size:
                    dense = solver.dense_output()
                    for i in turning:
                        cost.peak_searches += 1

                        def rate(s, i=i):
                            yy = dense(s)
                            return self._peak_values(yy, fun(s, yy), force)[1][i]
                        s_star = brentq(rate, solver.t_old, solver.t, xtol=1e-12 * length)
                        yy = dense(s_star)
                        value = abs(self._peak_values(yy, fun(s_star, yy), force)[0][i])
                        peaks[i] = max(peaks[i], value)
                vals_old, rates_old = vals_new, rates_new
                if solver.step_size is not None and solver.status == "running":
                    state.rk_step = float(solver.step_size)
            cost.rhs_evaluations += solver.nfev
            y = solver.y.copy()
        state.u = y[:n].copy()
        state.v = y[n:2 * n].copy()
        state.z = y[2 * n:3 * n].copy()
        state.E_damping += float(y[3 * n])
        state.E_input += float(y[3 * n + 1])
        state.E_hysteretic += float(y[3 * n + 2])
        state.E_external += float(force @ (y[:n] - u_start))
        state.peaks = peaks[:3 * n]
        state.peak_shear = peaks[3 * n:]
        return cost


INTEGRATORS = {"linear": ExactPiecewiseLinear, "bilinear": ExactPiecewiseLinear, "bouc_wen": BoucWenRK}


def integrator_for(building: ShearBuilding, hysteresis: StoreyHysteresis) -> BuildingIntegrator:
    """The integrator of a hysteresis law (raises ValueError naming bad parameters)."""
    return INTEGRATORS[hysteresis.model](building, hysteresis)
