"""The storeys of the monolithic reference: linear, bilinear and Bouc-Wen storey laws in one ODE system.

:mod:`cosim.peers.reference` integrates every building of a scene as one system with
``solve_ivp``.  This module is its storey part: the restoring forces of yielding storeys, the
states and events they add, and what a run reports about them.  The laws are those of
:mod:`fmu_src.hysteresis` (the same equations as ``building.fmu``); the integration is the
reference's own (an adaptive Runge-Kutta method with located events), independent of the
FMU's exact modal solution and of its Runge-Kutta stepping.

Storey ``j`` (numbered over every building, storey 1 of the first building first) has the drift
``d_j = u[top_j] - u[bottom_j]`` (``u = 0`` for the ground).  Linear buildings keep their
stiffness matrix in the reference's right-hand side, so that a scene without yielding storeys
is integrated with exactly the arithmetic of earlier versions.  A yielding building's storeys
add ``-D' V`` to the floor forces:

* ``bilinear`` (kinematic hardening): a discrete state ``(mode, slip)`` per storey, constant
  between events, and ``V = alpha k d + (1 - alpha) k (d - slip)`` (``mode = 0``, elastic) or
  ``V = alpha k d + mode (1 - alpha) Fy`` (``mode = +-1``, yielding), linear in ``u`` within a
  segment.  Events (terminal, located by ``solve_ivp`` on its dense output):

  - elastic: ``d - slip - dy`` rising through 0 (yield, ``mode = +1``) or ``d - slip + dy``
    falling through 0 (``mode = -1``); a storey that only touches its limit with its drift
    already turning back stays elastic;
  - yielding: ``mode d'`` falling through 0 (unloading): ``mode = 0``, ``slip = d - mode dy``,
    so that ``V`` is continuous.

  The dissipation rate is ``(1 - alpha) Fy mode d'`` on yielding storeys (>= 0 up to the
  unloading event), integrated as one more state per building.
* ``bouc_wen``: ``z`` is a state per storey with the rate of :func:`fmu_src.hysteresis.bouc_wen_rate`,
  ``V = alpha k d + (1 - alpha) Fy z``, and the dissipation rate of
  :func:`fmu_src.hysteresis.bouc_wen_dissipation_rate`.  The rate has kinks where ``d'`` or ``z``
  changes sign (``|d'|``, ``|z|^n``): the integration is restarted there (events, no change of
  state), so that no Runge-Kutta step straddles a kink.  Each kink event watches for the
  crossing away from the side the function is on (its sign, a discrete state set from the
  function's derivative at the last crossing); a function found exactly at 0 with a zero
  derivative (a building at rest) is watched again after a short probe segment.

Energy: the elastic (stored) part of a yielding storey is ``alpha k d^2 / 2 + q^2 / (2 (1 -
alpha) k)`` with ``q = V - alpha k d`` (bilinear: the elastic-perfectly-plastic element's force;
Bouc-Wen: ``(1 - alpha) Fy z``, whose energy ``(1 - alpha) Fy dy z^2 / 2`` is the same
expression), as :mod:`fmu_src.hysteresis` defines it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from fmu_src.hysteresis import StoreyHysteresis, bouc_wen_dissipation_rate, bouc_wen_rate

#: the event kinds of the storeys (the reference dispatches on them)
YIELD_UP, YIELD_DOWN, UNLOAD, RATE_KINK, Z_KINK = "yield+", "yield-", "unload", "bw_rate", "bw_z"
EVENT_KINDS = (YIELD_UP, YIELD_DOWN, UNLOAD, RATE_KINK, Z_KINK)
#: first probe (s) after a kink function found at exactly 0 with a zero derivative; doubled
#: while the function stays 0 (a building at rest)
PROBE = 1e-6


@dataclass
class StoreyState:
    """The discrete storey state of a reference run (changes only at events).

    ``mode`` (0, +1, -1) and ``slip`` (m) per bilinear storey; ``rate_side`` and ``z_side``
    (-1, 0, +1) per Bouc-Wen storey: the side of 0 on which ``d'`` and ``z`` are (0: unknown,
    probe); ``probe`` (s): the length of the next probe segment (0: none needed).
    """

    mode: np.ndarray
    slip: np.ndarray
    rate_side: np.ndarray
    z_side: np.ndarray
    probe: float = 0.0
    counts: dict = field(default_factory=dict)    # events by kind


class Storeys:
    """Every storey of a reference system (see module docstring).

    Parameters
    ----------
    buildings : sequence of ShearBuilding
    hystereses : sequence of StoreyHysteresis or None
        One per building (None: linear).
    offsets : sequence of int
        First global floor index of each building (and the total at the end).
    first_state : int
        Index in the reference's state vector where the storeys' states begin
        (``z`` of every Bouc-Wen storey, then the hysteretic energy of every yielding building).
    """

    def __init__(self, buildings: Sequence, hystereses: Sequence | None, offsets: Sequence[int], first_state: int):
        buildings = list(buildings)
        hystereses = [None] * len(buildings) if hystereses is None else list(hystereses)
        if len(hystereses) != len(buildings):
            raise ValueError(f"hystereses: {len(hystereses)} for {len(buildings)} buildings")
        self.hystereses = [h if h is not None else StoreyHysteresis() for h in hystereses]
        n = int(offsets[-1])
        self.n = n
        tops, bottoms, storey_offsets = [], [], [0]
        stiff, fy, alpha, law, building_of = [], [], [], [], []
        bw_n, bw_beta, bw_gamma = [], [], []
        self.damping_ratios = [float(building.damping_ratio) for building in buildings]
        for b, (building, h) in enumerate(zip(buildings, self.hystereses)):
            k = np.asarray(building.stiffnesses, dtype=float)
            if h.inelastic:
                h.check(k, building.damping_ratio)
            fy_b = h.yield_shear if h.yield_shear.size == k.size else np.zeros(k.size)
            for i in range(k.size):
                tops.append(offsets[b] + i)
                bottoms.append(offsets[b] + i - 1 if i else -1)
                stiff.append(k[i])
                fy.append(fy_b[i])
                alpha.append(h.alpha)
                law.append(h.model)
                building_of.append(b)
                bw_n.append(h.bw_n)
                bw_beta.append(h.bw_beta)
                bw_gamma.append(h.bw_gamma)
            storey_offsets.append(len(tops))
        self.count = len(tops)
        self.storey_offsets = tuple(storey_offsets)
        self.top = np.array(tops, dtype=np.intp)
        self.bottom = np.array(bottoms, dtype=np.intp)
        self.k = np.array(stiff)
        self.fy = np.array(fy)
        self.alpha = np.array(alpha)
        self.law = np.array(law)
        D = np.zeros((self.count, n))             # d = D u for every storey
        D[np.arange(self.count), self.top] = 1.0
        below = self.bottom >= 0
        D[np.flatnonzero(below), self.bottom[below]] = -1.0
        self.D = D
        self.yielding_buildings = [b for b, h in enumerate(self.hystereses) if h.inelastic]
        self.inelastic = bool(self.yielding_buildings)
        # the yielding storeys: bilinear, then Bouc-Wen
        self.bil = np.flatnonzero(self.law == "bilinear")
        self.bw = np.flatnonzero(self.law == "bouc_wen")
        self.dy = np.where(self.fy > 0.0, self.fy / np.where(self.k > 0.0, self.k, 1.0), np.inf)
        self.bw_n = np.array(bw_n)[self.bw]
        self.bw_beta = np.array(bw_beta)[self.bw]
        self.bw_gamma = np.array(bw_gamma)[self.bw]
        # states: z of every Bouc-Wen storey, then E_hysteretic of every yielding building
        self.i_z = int(first_state)
        self.i_h = self.i_z + self.bw.size
        self.size = self.bw.size + len(self.yielding_buildings)
        # H @ (per-storey dissipation rate) = per-building rate
        self.H = np.zeros((len(self.yielding_buildings), self.count))
        for row, b in enumerate(self.yielding_buildings):
            self.H[row, storey_offsets[b]:storey_offsets[b + 1]] = 1.0
        self.linear_floor = np.ones(n, dtype=bool)   # floors of linear buildings
        for b in self.yielding_buildings:
            self.linear_floor[offsets[b]:offsets[b + 1]] = False
        # Bouc-Wen: V = alpha k d + (1 - alpha) Fy z  ->  floor forces -D' V
        self.Z = -(self.D[self.bw].T * ((1.0 - self.alpha) * self.fy)[self.bw])     # (n, n_bw)

    # -- initial state -------------------------------------------------------------------------
    def initial(self, y0: np.ndarray) -> StoreyState:
        """The elastic initial state (``slip = 0``, ``z = d0 / dy``), written into ``y0``;
        refuses an initial drift beyond yield as the FMU does."""
        d0 = self.D @ y0[:self.n]
        for b in self.yielding_buildings:
            s0, s1 = self.storey_offsets[b], self.storey_offsets[b + 1]
            self.hystereses[b].check(self.k[s0:s1], self.damping_ratios[b], d0[s0:s1])
        y0[self.i_z:self.i_h] = d0[self.bw] / self.dy[self.bw]
        v0 = self.D @ y0[self.n:2 * self.n]
        state = StoreyState(mode=np.zeros(self.bil.size, dtype=np.int64), slip=np.zeros(self.bil.size),
                            rate_side=np.sign(v0[self.bw]).astype(np.int64),
                            z_side=np.sign(y0[self.i_z:self.i_h]).astype(np.int64))
        if self.bw.size and (not state.rate_side.all() or not state.z_side.all()):
            state.probe = PROBE
        return state

    # -- right-hand side -----------------------------------------------------------------------
    def segment_terms(self, state: StoreyState):
        """``(K, p)``: the yielding storeys' floor forces in this state are ``-(K u + p) + Z z``
        (``Z`` fixed; ``K`` (N/m) and ``p`` (N) change at bilinear events)."""
        n = self.n
        kt = self.alpha * self.k
        offset = np.zeros(self.count)
        bil = self.bil
        if bil.size:
            mode = state.mode
            kb, fb, ab = self.k[bil], self.fy[bil], self.alpha[bil]
            kt = kt.copy()
            kt[bil] = np.where(mode == 0, kb, ab * kb)
            offset[bil] = np.where(mode == 0, -(1.0 - ab) * kb * state.slip, mode * (1.0 - ab) * fb)
        rows = np.zeros(self.count, dtype=bool)
        rows[bil] = True
        rows[self.bw] = True
        D = self.D[rows]
        K = D.T @ (kt[rows][:, None] * D) if rows.any() else np.zeros((n, n))
        p = D.T @ offset[rows] if rows.any() else np.zeros(n)
        return K, p

    def rates(self, u: np.ndarray, v: np.ndarray, z: np.ndarray, state: StoreyState):
        """``(z', per-building dissipation rate)`` (1/s, W) at one point."""
        dz = np.empty(0)
        per_storey = np.zeros(self.count)
        if self.bil.size:
            yielding = state.mode != 0
            if yielding.any():
                rate = self.D[self.bil] @ v
                per_storey[self.bil] = np.where(yielding, (1.0 - self.alpha[self.bil]) * self.fy[self.bil]
                                                * state.mode * rate, 0.0)
        if self.bw.size:
            rate = self.D[self.bw] @ v
            dz = bouc_wen_rate(z, rate, self.dy[self.bw], self.bw_n, self.bw_beta, self.bw_gamma)
            per_storey[self.bw] = bouc_wen_dissipation_rate(z, rate, self.fy[self.bw], self.alpha[self.bw],
                                                            self.bw_n, self.bw_beta, self.bw_gamma)
        return dz, self.H @ per_storey

    # -- events --------------------------------------------------------------------------------
    def _drift_fun(self, j: int, rate: bool, shift: float = 0.0, sign: float = 1.0):
        n = self.n
        top, bottom = int(self.top[j]) + (n if rate else 0), int(self.bottom[j]) + (n if rate else 0)
        if self.bottom[j] < 0:
            return lambda t, y: sign * y[top] - shift
        return lambda t, y: sign * (y[top] - y[bottom]) - shift

    def events(self, state: StoreyState) -> list:
        """Terminal events of the current storey state: ``(function, storey, kind)``."""
        out = []
        for a, j in enumerate(self.bil):
            mode = int(state.mode[a])
            if mode == 0:
                out.append((_event(self._drift_fun(j, False, state.slip[a] + self.dy[j]), +1), a, YIELD_UP))
                out.append((_event(self._drift_fun(j, False, state.slip[a] - self.dy[j]), -1), a, YIELD_DOWN))
            else:
                out.append((_event(self._drift_fun(j, True, 0.0, float(mode)), -1), a, UNLOAD))
        if state.probe:
            return out      # the kinks are watched again after the probe segment
        for a, j in enumerate(self.bw):
            out.append((_event(self._drift_fun(j, True), -int(state.rate_side[a])), a, RATE_KINK))
            out.append((_event(lambda t, y, i=self.i_z + a: y[i], -int(state.z_side[a])), a, Z_KINK))
        return out

    def apply(self, kind: str, a: int, y: np.ndarray, dydt: np.ndarray, state: StoreyState) -> None:
        """The state change of an event of ``kind`` on (bilinear or Bouc-Wen) storey ``a``,
        located at state ``y`` with derivative ``dydt``."""
        state.counts[kind] = state.counts.get(kind, 0) + 1
        n = self.n
        if kind in (YIELD_UP, YIELD_DOWN):
            j = self.bil[a]
            direction = 1 if kind == YIELD_UP else -1
            if direction * float(self.D[j] @ y[n:2 * n]) > 0.0:    # else it only touches the limit
                state.mode = state.mode.copy()
                state.mode[a] = direction
        elif kind == UNLOAD:
            j = self.bil[a]
            mode = state.mode.copy()
            slip = state.slip.copy()
            slip[a] = float(self.D[j] @ y[:n]) - mode[a] * self.dy[j]
            mode[a] = 0
            state.mode, state.slip = mode, slip
        elif kind == RATE_KINK:
            j = self.bw[a]
            state.rate_side = state.rate_side.copy()
            state.rate_side[a] = int(np.sign(float(self.D[j] @ dydt[n:2 * n])))
        elif kind == Z_KINK:
            state.z_side = state.z_side.copy()
            state.z_side[a] = int(np.sign(dydt[self.i_z + a]))
        else:
            raise ValueError(f"unknown storey event {kind!r}")
        if self.bw.size and (not state.rate_side.all() or not state.z_side.all()):
            state.probe = state.probe or PROBE

    def after_probe(self, y: np.ndarray, state: StoreyState) -> None:
        """At the end of a probe segment: the sides from the functions' values (m/s, -)."""
        n = self.n
        rate = self.D[self.bw] @ y[n:2 * n]
        z = y[self.i_z:self.i_h]
        state.rate_side = np.where(state.rate_side == 0, np.sign(rate), state.rate_side).astype(np.int64)
        state.z_side = np.where(state.z_side == 0, np.sign(z), state.z_side).astype(np.int64)
        if state.rate_side.all() and state.z_side.all():
            state.probe = 0.0
        else:
            state.probe *= 2.0

    # -- what a run reports --------------------------------------------------------------------
    def shears(self, Y: np.ndarray, state: StoreyState) -> np.ndarray:
        """Storey shears ``V`` (N), shape (points, storeys), for states ``Y`` (rows) in ``state``."""
        n = self.n
        d = Y[:, :n] @ self.D.T
        V = self.k * d
        if self.bil.size:
            b = self.bil
            kb, ab = self.k[b], self.alpha[b]
            elastic = ab * kb * d[:, b] + (1.0 - ab) * kb * (d[:, b] - state.slip)
            yielding = ab * kb * d[:, b] + state.mode * (1.0 - ab) * self.fy[b]
            V[:, b] = np.where(state.mode == 0, elastic, yielding)
        if self.bw.size:
            w = self.bw
            V[:, w] = self.alpha[w] * self.k[w] * d[:, w] + (1.0 - self.alpha[w]) * self.fy[w] * Y[:, self.i_z:self.i_h]
        return V

    def yielding_strain_energy(self, d: np.ndarray, V: np.ndarray) -> np.ndarray:
        """Elastic energy (J) held by the yielding storeys, per point (module docstring)."""
        out = np.zeros(d.shape[0])
        for idx in (self.bil, self.bw):
            if idx.size:
                k, a = self.k[idx], self.alpha[idx]
                q = V[:, idx] - a * k * d[:, idx]
                out += np.sum(0.5 * a * k * d[:, idx] ** 2 + q * q / (2.0 * (1.0 - a) * k), axis=1)
        return out

    def residual_drift(self, d: np.ndarray, V: np.ndarray) -> np.ndarray:
        """``d - V / k`` of every storey (m) at one point; 0 for linear storeys (as the FMU)."""
        out = d - V / np.where(self.k > 0.0, self.k, 1.0)
        return np.where(self.law == "linear", 0.0, out)

    def ductility(self, peak_drift: np.ndarray) -> np.ndarray:
        """Peak drift / yield drift per storey (-); 0 without a yield shear (as the FMU's ``mu``)."""
        return np.where(self.fy > 0.0, peak_drift * self.k / np.where(self.fy > 0.0, self.fy, 1.0), 0.0)

    def of_building(self, values: np.ndarray, b: int) -> np.ndarray:
        """The entries of building ``b`` of a per-storey array (last axis)."""
        return values[..., self.storey_offsets[b]:self.storey_offsets[b + 1]]


def _event(fun, direction):
    fun.terminal = True
    fun.direction = direction
    return fun

