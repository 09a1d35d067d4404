"""Monolithic reference solution of a pounding scene: one ODE system, ``solve_ivp``, events.

The co-simulation splits a scene into FMUs (buildings, ground motion, one contact element per
pounding floor pair) that only talk at communication points.  This module solves the *same*
equations as one system, from the same physics functions (:mod:`fmu_src.shear_building`,
:mod:`fmu_src.contact_laws`, :mod:`fmu_src.ground_records`), with an adaptive high-order
integrator at tight tolerance, so that every coupling error of the master can be measured
against it.

Equations (relative coordinates, Chopra Sec. 9.4), for each building ``b``::

    M_b u_b'' + C_b u_b' + K_b u_b = -M_b 1 ag(t) + f_b(t)

and for each contact ``c`` between floor ``i`` of the left building and floor ``j`` of the
right one (left = body 1 on the negative side, as in ``pounding.fmu``)::

    delta = u_left[i] - u_right[j] - gap        (> 0: penetration)
    F = law.force(delta, delta', v_imp)          (>= 0, compressive; 0 when delta <= 0)
    f_left[i] -= F,  f_right[j] += F

Events.  Each contact is in one of three phases and the integration is restarted at every
phase change, located by ``solve_ivp``'s root finder on the dense output:

* ``open``:  onset when ``delta`` rises through 0; the impact velocity ``v_imp = delta'`` is
  latched there (the Hertzdamp-type laws need it);
* ``approach``: maximum penetration when ``delta'`` falls through 0 (the dashpot of the
  Jankowski-type laws switches off; the regularised proposed model has a force drop);
* ``restitution``: separation when ``delta`` falls through 0, or a new approach when
  ``delta'`` rises through 0 again (a building pushing back during a long contact);
* ``stick``: ``delta'`` held at 0 by the contact force that keeps it there, for a law whose
  force drops at ``delta' = 0`` (``LawSpec.sticks``; crvk: the approach branch's force is
  above the restitution branch's).  When the buildings push the bodies together with a force between the two
  branches at the same penetration, neither branch is consistent: on the approach branch the
  bodies would be pushed apart at once (``delta'' < 0``), on the restitution branch pushed
  together (``delta'' > 0``).  The solution is Filippov's sliding motion: the penetration
  stays, the force is the buildings' push.  It ends when that push exceeds the approach
  branch (loading again: ``approach``) or falls below the restitution branch (unloading:
  ``restitution``).  Entered from ``restitution`` at a re-approach and from ``approach`` at
  maximum penetration, whenever the branch the event points to is inconsistent at once.

Within a segment the right-hand side is smooth, so the integrator's order is not spoiled by
a kink hidden inside a step.  The ground acceleration of a :class:`~fmu_src.ground_records.Record`
is piecewise linear: its derivative jumps at every sample, so the integration is also
restarted at the sample times (``break_at_samples``), with the last step size carried over.

Integrator.  ``DOP853`` (explicit Runge-Kutta of order 8, Hairer, Norsett & Wanner,
*Solving ODEs I*, Sec. II.10) by default.  The contact is fast (1e9-1e11 N/m^1.5 gives
contacts of a few ms between floors of 1e4-1e6 kg) but it is not *stiff* in the sense that
matters: the reference must resolve each contact to report its force history and its
dissipation, so the step during a contact is set by accuracy, not by stability, and outside
contacts the buildings' own periods (>= 0.05 s) are slow.  An explicit 8th-order method is
then the cheapest way to 1e-10 relative accuracy.  ``Radau`` (implicit, order 5, analytic
Jacobian from ``law.force_and_derivatives``) is available for comparison and for scenes
with very stiff, very high storeys.

Energy.  The state carries three integrals, so the balance is an independent check of the
integration (Uang & Bertero 1990, relative formulation)::

    E_input = -int v' M 1 ag dt,   E_damping = int v' C v dt,   W_contact = int sum_c F delta' dt
    residual = E_input + E_kinetic(0) + E_strain(0) - (E_kinetic + E_strain + E_damping + W_contact)

``W_contact`` is the work done on the contact elements.  Over one complete impact (onset to
separation, no stored energy left) it is the energy the contact dissipated; summed over the
impacts it is ``dissipated_energy_J``.

Yielding storeys (``hystereses``: bilinear with kinematic hardening, Bouc-Wen) are the
storey part of the same system, :mod:`cosim.peers.storeys`: bilinear storeys switch between
elastic and yielding at located events (their own phases, as the contacts have), Bouc-Wen
storeys carry their hysteretic variable as states, and every yielding building carries its
hysteretic energy, so that the balance becomes::

    residual = E_input + E_kinetic(0) + E_strain(0)
               - (E_kinetic + E_strain + E_damping + E_hysteretic + W_contact)

with ``E_strain`` the elastic (stored) part.  A scene without yielding storeys is integrated
with exactly the arithmetic of the linear reference.

Indices: buildings are 0-based positions in the ``buildings`` sequence; floors are numbered
as in :class:`~fmu_src.shear_building.ShearBuilding` and the FMU variables ``F[i]``, ``x[i]``:
1 is the lowest floor.
"""
from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from fmu_src.hysteresis import StoreyHysteresis

from ..master.models import contact_law, ground_record, initial_state, shear_building
from ..master.names import element_name
from .storeys import EVENT_KINDS as STOREY_EVENTS, Storeys

OPEN, APPROACH, RESTITUTION, STICK = "open", "approach", "restitution", "stick"
METHODS = ("DOP853", "Radau", "RK45", "BDF", "LSODA")


# -- input ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Contact:
    """A contact element between two floors (the monolithic twin of one ``pounding.fmu``).

    Parameters
    ----------
    left, right : int
        Building indices (0-based) of body 1 (negative side) and body 2.
    left_floor, right_floor : int
        Floor numbers (1 = lowest floor) of the two bodies.
    law : ContactLaw
        Force law (``fmu_src.contact_laws.law_for(...)``): ``force(delta, delta_dot, v_imp)``.
    gap : float
        Initial clear distance (m), >= 0: ``delta = x_left - x_right - gap``.
    graze_depth : float
        A contact whose largest penetration stays below this (m) is a graze, not an impact
        (``pounding.fmu``'s parameter of that name); 0: every contact is an impact.
    """

    left: int
    left_floor: int
    right: int
    right_floor: int
    law: object
    gap: float = 0.0
    graze_depth: float = 0.0


@dataclass(frozen=True)
class Impact:
    """One impact, from onset to separation.

    Attributes
    ----------
    contact : int
        Index of the contact element.
    t_onset, t_separation : float
        Times (s) at which ``delta`` crossed 0 upward and downward (``nan`` if the contact
        was still closed at ``stop_time``).
    v_impact : float
        Relative approach velocity at onset (m/s), > 0.
    peak_force_N : float
        Maximum contact force during the impact (N).
    max_penetration : float
        Maximum ``delta`` (m).
    dissipated_energy_J : float
        Work done on the contact over the impact (J); for an impact still open at the end,
        that work minus the elastic energy ``k delta^(n+1) / (n+1)`` still stored.
    grazing : bool
        Its largest penetration stayed below the contact's ``graze_depth``: a graze, not an impact.
    """

    contact: int
    t_onset: float
    v_impact: float
    peak_force_N: float = 0.0
    max_penetration: float = 0.0
    t_separation: float = math.nan
    dissipated_energy_J: float = 0.0
    grazing: bool = False

    @property
    def duration(self) -> float:
        """Contact duration (s); ``nan`` if still in contact at the end."""
        return self.t_separation - self.t_onset


@dataclass(frozen=True)
class Energies:
    """Energy terms (J) on the output grid; ``residual`` closes the balance (module docstring)."""

    input: np.ndarray
    kinetic: np.ndarray
    strain: np.ndarray
    damping: np.ndarray
    contact_work: np.ndarray
    contact_stored: np.ndarray
    residual: np.ndarray
    hysteretic: np.ndarray | None = None     # dissipated by yielding storeys (None: none yield)

    @property
    def contact_dissipated(self) -> np.ndarray:
        """Energy dissipated by the contacts up to each time (J)."""
        return self.contact_work - self.contact_stored


@dataclass(frozen=True)
class ReferenceResult:
    """Outcome of :func:`solve_reference`.

    Histories are sampled on the output grid ``t`` (s); ``u`` and ``v`` are all floors of all
    buildings side by side (use :meth:`displacements` for one building).  ``t_steps`` are the
    integrator's own steps, event times included (event-refined).

    Cost counters follow ``scipy.integrate.OdeResult``: ``nfev``, ``njev``, ``nlu``; plus
    ``n_segments`` (restarts) and ``wall_time_s``.

    Storeys (every storey of every building side by side, storey 1 of the first building
    first; :meth:`drifts`, :meth:`shears` for one building): ``storey_drift`` (m) and
    ``storey_shear`` (N, restoring, without damping) on the output grid; per building
    ``peak_drifts`` (m, located on the dense output), ``ductility`` (peak drift / yield drift,
    0 without a yield shear, as the FMU's ``mu``), ``residual_drifts`` (m, ``d - V / k`` at the
    end, 0 for linear storeys, as the FMU's ``drift_residual``) and ``hysteretic_energy_J``
    (dissipated by yielding up to the end).
    """

    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    contact_force: np.ndarray        # (n_t, n_contacts), N
    penetration: np.ndarray          # (n_t, n_contacts), m
    energies: Energies
    impact_list: tuple[Impact, ...]
    peak_force_N: float
    dissipated_energy_J: float
    peak_displacements: tuple[np.ndarray, ...]   # per building, per floor: max |u| (m)
    peak_accelerations: tuple[np.ndarray, ...]   # per building, per floor: max |absolute acceleration| (m/s^2)
    t_steps: np.ndarray
    floor_offsets: tuple[int, ...]
    method: str
    rtol: float
    nfev: int
    njev: int
    nlu: int
    n_segments: int
    wall_time_s: float
    event_counts: dict = field(default_factory=dict)   # located events by kind
    storey_drift: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    storey_shear: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    storey_offsets: tuple[int, ...] = ()
    peak_drifts: tuple[np.ndarray, ...] = ()
    ductility: tuple[np.ndarray, ...] = ()
    residual_drifts: tuple[np.ndarray, ...] = ()
    hysteretic_energy_J: tuple[float, ...] = ()
    yielding_buildings: tuple[int, ...] = ()      # indices of the buildings with yielding storeys

    graze_list: tuple[Impact, ...] = ()                # contacts shallower than their graze_depth

    @property
    def impacts(self) -> int:
        """Number of impacts over all contacts (grazes not counted: ``graze_list``)."""
        return len(self.impact_list)

    @property
    def grazes(self) -> int:
        """Number of grazes: contacts whose penetration stayed below their contact's graze_depth."""
        return len(self.graze_list)

    @property
    def energy_residual(self) -> float:
        """Largest ``|residual|`` of the energy balance over the run (J)."""
        return float(np.max(np.abs(self.energies.residual)))

    def displacements(self, building: int) -> np.ndarray:
        """Floor displacements (m, relative to the ground) of one building, shape (n_t, n_floors)."""
        return self.u[:, self.floor_offsets[building]:self.floor_offsets[building + 1]]

    def velocities(self, building: int) -> np.ndarray:
        """Floor velocities (m/s, relative to the ground) of one building."""
        return self.v[:, self.floor_offsets[building]:self.floor_offsets[building + 1]]

    def drifts(self, building: int) -> np.ndarray:
        """Storey drifts (m) of one building on the output grid, shape (n_t, n_storeys)."""
        return self.storey_drift[:, self.storey_offsets[building]:self.storey_offsets[building + 1]]

    def shears(self, building: int) -> np.ndarray:
        """Storey shears (N) of one building on the output grid, shape (n_t, n_storeys)."""
        return self.storey_shear[:, self.storey_offsets[building]:self.storey_offsets[building + 1]]


# -- ground motion ------------------------------------------------------------------------------
def _ground(ground, stop_time: float):
    """``(ag(t), breakpoints)``: a callable in m/s^2 and the times where its slope jumps."""
    if ground is None:
        return (lambda t: 0.0), np.empty(0)
    if hasattr(ground, "at") and hasattr(ground, "times"):   # fmu_src.ground_records.Record
        times = np.asarray(ground.times, dtype=float)
        return ground.at, times[(times > 0.0) & (times < stop_time)]
    if callable(ground):
        return ground, np.asarray(getattr(ground, "breakpoints", ()), dtype=float)
    raise TypeError(f"ground = {ground!r}: expected None, a Record (with .at and .times) or a callable ag(t) in m/s^2")


# -- the assembled system ---------------------------------------------------------------------
class _System:
    """Global matrices, contact topology and the right-hand side for one phase assignment."""

    def __init__(self, buildings, contacts, ag, hystereses=None):
        self.buildings = list(buildings)
        sizes = [len(b.masses) for b in self.buildings]
        self.offsets = tuple(int(x) for x in np.concatenate(([0], np.cumsum(sizes))))
        n = self.n = self.offsets[-1]
        self.masses = np.concatenate([np.asarray(b.masses, dtype=float) for b in self.buildings])
        self.K = np.zeros((n, n))
        self.C = np.zeros((n, n))
        for b, o0, o1 in zip(self.buildings, self.offsets[:-1], self.offsets[1:]):
            self.K[o0:o1, o0:o1] = b.K
            self.C[o0:o1, o0:o1] = b.C
        self.minv = 1.0 / self.masses
        self.contacts = list(contacts)
        self.dof_left = np.array([self.offsets[c.left] + c.left_floor - 1 for c in self.contacts], dtype=np.intp)
        self.dof_right = np.array([self.offsets[c.right] + c.right_floor - 1 for c in self.contacts], dtype=np.intp)
        self.gaps = np.array([c.gap for c in self.contacts], dtype=float)
        self.ag = ag
        # state layout: [u (n), v (n), E_input, E_damping, W_contact (one per contact), then the
        # storeys' states (z of Bouc-Wen storeys, E_hysteretic per yielding building)]; the
        # work is kept per contact so that impacts overlapping in time are charged separately
        self.storeys = Storeys(self.buildings, hystereses, self.offsets, 2 * n + 2 + len(self.contacts))
        self.size = 2 * n + 2 + len(self.contacts) + self.storeys.size
        # the linear buildings' stiffness (the yielding storeys' forces come from self.storeys)
        self.K_linear = self.K * np.outer(self.storeys.linear_floor, self.storeys.linear_floor)
        self.storey_state = None   # the yielding storeys' law of the segment being integrated (rhs)

    def kinematics(self, y):
        """Penetrations ``delta`` (m) and rates ``delta'`` (m/s) of every contact."""
        n = self.n
        delta = y[self.dof_left] - y[self.dof_right] - self.gaps
        rate = y[n + self.dof_left] - y[n + self.dof_right]
        return delta, rate

    def contact_forces(self, y, phases, v_imp):
        delta, rate = self.kinematics(y)
        forces = np.zeros(len(self.contacts))
        for c, contact in enumerate(self.contacts):
            if phases[c] not in (OPEN, STICK) and delta[c] > 0.0:
                forces[c] = contact.law.force(delta[c], rate[c], v_imp[c], approaching=phases[c] == APPROACH)
        stuck = [c for c, p in enumerate(phases) if p == STICK]
        if stuck:
            forces[stuck] = self.holding_forces(y, forces, stuck)
        return forces, rate

    def restoring_force(self, y):
        """Storey and damping forces on the floors [N] at state ``y``, with the yielding storeys'
        law of the current segment (the one :meth:`rhs` was last built for)."""
        n = self.n
        u, v = y[:n], y[n:2 * n]
        storeys = self.storeys
        if not storeys.inelastic:
            return -(self.K @ u) - self.C @ v
        K_storeys, p_storeys = storeys.segment_terms(self.storey_state)
        f = -((self.K_linear + K_storeys) @ u) - self.C @ v - p_storeys
        z = y[storeys.i_z:storeys.i_h]
        if z.size:
            f += storeys.Z @ z
        return f

    def free_rates(self, y, forces):
        """``delta''`` of every contact with the given contact forces [N] (the ground cancels)."""
        f = self.restoring_force(y)
        np.subtract.at(f, self.dof_left, forces)
        np.add.at(f, self.dof_right, forces)
        a = self.minv * f
        return a[self.dof_left] - a[self.dof_right]

    def holding_forces(self, y, forces, stuck):
        """Forces [N] of the contacts ``stuck`` that keep their ``delta'' = 0`` (``forces``: the
        others'): ``delta''_S = delta''_S(0) - G_SS F_S`` with ``G = B M^-1 B'``, ``B`` the
        contacts' +1/-1 incidence on the floors."""
        trial = forces.copy()
        trial[stuck] = 0.0
        free = self.free_rates(y, trial)[stuck]
        G = np.empty((len(stuck), len(stuck)))
        for i, c in enumerate(stuck):
            for j, d in enumerate(stuck):
                G[i, j] = sum(self.minv[p] * s * t for p, s in ((self.dof_left[c], 1.0), (self.dof_right[c], -1.0))
                              for q, t in ((self.dof_left[d], 1.0), (self.dof_right[d], -1.0)) if p == q)
        return np.linalg.solve(G, free)

    def branch_rates(self, y, phases, v_imp, c):
        """``delta''`` of contact ``c`` at ``delta' = 0`` on its approach and on its
        restitution branch, the other contacts in their phases."""
        out = []
        for branch in (APPROACH, RESTITUTION):
            trial = list(phases)
            trial[c] = branch
            forces, _ = self.contact_forces(y, trial, v_imp)
            delta = self.kinematics(y)[0][c]
            forces[c] = self.contacts[c].law.force(delta, 0.0, v_imp[c], approaching=branch == APPROACH) \
                if delta > 0.0 else 0.0
            out.append(float(self.free_rates(y, forces)[c]))
        return out

    def rhs(self, phases, v_imp, storey_state=None):
        self.storey_state = storey_state   # the segment's storey law, for restoring_force
        n = self.n
        K, C, minv, masses, ag = self.K, self.C, self.minv, self.masses, self.ag
        left, right = self.dof_left, self.dof_right
        any_closed = any(p != OPEN for p in phases)
        nc = len(self.contacts)
        storeys = self.storeys
        yielding = storeys.inelastic
        if yielding:
            K_storeys, p_storeys = storeys.segment_terms(storey_state)
            K = self.K_linear + K_storeys
            Z, iz, ih = storeys.Z, storeys.i_z, storeys.i_h

        def fun(t, y):
            u, v = y[:n], y[n:2 * n]
            f = -(K @ u) - C @ v
            if yielding:
                z = y[iz:ih]
                f -= p_storeys
                if z.size:
                    f += Z @ z
            work = 0.0
            if any_closed:
                forces, rate = self.contact_forces(y, phases, v_imp)
                np.subtract.at(f, left, forces)
                np.add.at(f, right, forces)
                work = forces * rate
            a_g = float(ag(t))
            dy = np.empty_like(y)
            dy[:n] = v
            dy[n:2 * n] = minv * f - a_g
            dy[2 * n] = -a_g * float(masses @ v)
            dy[2 * n + 1] = float(v @ (C @ v))
            dy[2 * n + 2:2 * n + 2 + nc] = work
            if yielding:
                dy[iz:ih], dy[ih:] = storeys.rates(u, v, z, storey_state)
            return dy
        return fun

    def jacobian(self, phases, v_imp):
        """Analytic Jacobian for the implicit methods (``law.force_and_derivatives``)."""
        n = self.n
        left, right = self.dof_left, self.dof_right

        def jac(t, y):
            J = np.zeros((self.size, self.size))
            u, v = y[:n], y[n:2 * n]
            J[:n, n:2 * n] = np.eye(n)
            J[n:2 * n, :n] = -self.minv[:, None] * self.K
            J[n:2 * n, n:2 * n] = -self.minv[:, None] * self.C
            J[2 * n, n:2 * n] = -float(self.ag(t)) * self.masses
            J[2 * n + 1, n:2 * n] = 2.0 * (self.C @ v)
            delta, rate = self.kinematics(y)
            for c, contact in enumerate(self.contacts):
                if phases[c] == OPEN or delta[c] <= 0.0:
                    continue
                F, dF_dd, dF_dr = contact.law.force_and_derivatives(
                    delta[c], _phase_rate(phases[c], rate[c]), v_imp[c])[:3]
                i, j = left[c], right[c]
                # d delta/d(u_i, u_j) = (+1, -1); d rate/d(v_i, v_j) = (+1, -1)
                for dof, sign_f in ((i, -1.0), (j, +1.0)):
                    row = n + dof
                    J[row, i] += sign_f * self.minv[dof] * dF_dd
                    J[row, j] -= sign_f * self.minv[dof] * dF_dd
                    J[row, n + i] += sign_f * self.minv[dof] * dF_dr
                    J[row, n + j] -= sign_f * self.minv[dof] * dF_dr
                w = 2 * n + 2 + c
                J[w, i] += dF_dd * rate[c]
                J[w, j] -= dF_dd * rate[c]
                J[w, n + i] += dF_dr * rate[c] + F
                J[w, n + j] -= dF_dr * rate[c] + F
            return J
        return jac

    def events(self, phases, v_imp, overlap):
        """Terminal events of the current phase assignment: list of (function, contact, kind)."""
        out = []
        n = self.n
        for c, contact in enumerate(self.contacts):
            i, j, gap = self.dof_left[c], self.dof_right[c], self.gaps[c]

            def delta(t, y, i=i, j=j, gap=gap):
                return y[i] - y[j] - gap

            def rate(t, y, i=i, j=j):
                return y[n + i] - y[n + j]

            if phases[c] == OPEN and overlap[c]:
                # left by a clipped law with the floors still overlapping: they part when delta
                # falls through 0; a new approach before that is a new impact (rare; v_imp = 0
                # then switches the Hertz-damp dashpot off)
                out.append((_event(delta, -1), c, "parted"))
                out.append((_event(rate, +1), c, "onset"))
            elif phases[c] == OPEN:
                out.append((_event(delta, +1), c, "onset"))
            elif phases[c] == APPROACH:
                out.append((_event(rate, -1), c, "max_penetration"))
            elif phases[c] == STICK:
                law, v = contact.law, float(v_imp[c])

                def held(t, y, c=c):
                    return self.contact_forces(y, phases, v_imp)[0][c]

                def loading(t, y, c=c, law=law, v=v, i=i, j=j, gap=gap):
                    return held(t, y) - law.force(y[i] - y[j] - gap, 0.0, v, approaching=True)

                def unloading(t, y, c=c, law=law, v=v, i=i, j=j, gap=gap):
                    return held(t, y) - law.force(y[i] - y[j] - gap, 0.0, v, approaching=False)
                out.append((_event(loading, +1), c, "loading"))
                out.append((_event(unloading, -1), c, "unloading"))
            else:
                out.append((_event(delta, -1), c, "separation"))
                out.append((_event(rate, +1), c, "reapproach"))
                if contact.law.spec.clipped and contact.law.zeta > 0.0:   # the contact law table's rule
                    # the force reaches 0 (and is clipped) before delta does: separation
                    def raw(t, y, law=contact.law, i=i, j=j, gap=gap, v=float(v_imp[c])):
                        return law.raw_force(y[i] - y[j] - gap, y[n + i] - y[n + j], v, approaching=False)
                    out.append((_event(raw, -1), c, "force_separation"))
        return out

    def next_branch(self, y, phases, v_imp, c, kind) -> str:
        """Phase of contact ``c`` after a branch event at ``delta' = 0`` (module docstring).

        ``max_penetration``/``unloading`` point to restitution, ``reapproach``/``loading`` to
        approach; either is taken if consistent (restitution: ``delta'' <= 0``; approach:
        ``delta'' >= 0``), else the contact sticks if sticking is consistent (the holding force
        between the two branches), else the other branch.  A law that cannot stick
        (``LawSpec.sticks``: the two branches' forces are equal at ``delta' = 0``) takes the
        branch the event points to."""
        wants = RESTITUTION if kind in ("max_penetration", "unloading") else APPROACH
        law = self.contacts[c].law
        if not (law.spec.sticks and law.zeta > 0.0):
            return wants
        on_approach, on_restitution = self.branch_rates(y, phases, v_imp, c)
        # an event leaves the state on a boundary: a rate within round-off of 0 (1e-9 of the
        # branches' difference) counts as 0, or the contact would stick and leave again at once
        tol = 1e-9 * (abs(on_approach) + abs(on_restitution))
        if wants == RESTITUTION and on_restitution <= tol:
            return RESTITUTION
        if wants == APPROACH and on_approach >= -tol:
            return APPROACH
        if on_approach < -tol and on_restitution > tol:
            return STICK
        return APPROACH if wants == RESTITUTION else RESTITUTION

    def stored_energy(self, delta):
        """Elastic energy ``k delta^(n+1) / (n+1)`` held by each contact (J)."""
        return np.array([contact.law.elastic_energy(d) for contact, d in zip(self.contacts, delta)])


def _phase_rate(phase: str, rate: float) -> float:
    """``delta'`` clamped to the sign of the phase, so that ``force_and_derivatives`` (which
    picks its branch from the sign of ``delta'``) differentiates the branch of the phase."""
    if phase == APPROACH:
        return rate if rate > 0.0 else 0.0
    if phase == RESTITUTION:
        return rate if rate < 0.0 else -0.0
    return rate


def _event(fun, direction):
    fun.terminal = True
    fun.direction = direction
    return fun


# -- the solver -----------------------------------------------------------------------------------
def solve_reference(buildings: Sequence, ground, contacts: Sequence[Contact], stop_time: float,
                    x0: Sequence | None = None, v0: Sequence | None = None, *,
                    hystereses: Sequence | None = None, t_output: np.ndarray | None = None, output_dt: float = 1e-3,
                    method: str = "DOP853", rtol: float = 1e-10, atol: float | None = None,
                    break_at_samples: bool = True, max_step: float = math.inf) -> ReferenceResult:
    """Solve a pounding scene as one ODE system (see module docstring).

    Parameters
    ----------
    buildings : sequence of ShearBuilding
        Anything with ``masses`` (kg), ``K`` (N/m) and ``C`` (N s/m).
    ground : Record, callable or None
        Ground acceleration (m/s^2): a ``Record`` (linear between samples, restarts at the
        samples), a callable ``ag(t)`` (an attribute ``breakpoints`` lists its kinks), or
        ``None`` for free vibration.
    contacts : sequence of Contact
    stop_time : float
        End time (s).
    x0, v0 : sequence of arrays, optional
        Initial floor displacements (m) and velocities (m/s) relative to the ground, one
        array per building; zero by default.  No contact may be closed at ``t = 0``.
    hystereses : sequence of StoreyHysteresis or None, optional
        The storey law of each building (:class:`fmu_src.hysteresis.StoreyHysteresis`; None or
        a missing list: linear), checked as ``building.fmu`` checks it (ValueError naming the
        parameter).  Yielding storeys start elastic (an initial drift beyond yield is refused).
    t_output : array, optional
        Output grid (s); default ``0, output_dt, ..., stop_time``.
    method : str
        ``solve_ivp`` method; ``DOP853`` (default) or ``Radau`` (analytic Jacobian; with
        yielding storeys a finite-difference one).
    rtol, atol : float
        Tolerances; ``atol`` defaults to ``rtol`` times 1e-2 m, 1e-1 m/s and 1 kJ for
        displacements, velocities and energies (scales below any quantity that matters:
        penetrations are 1e-5-1e-3 m).
    break_at_samples : bool
        Restart at the record's sample times, where ``ag`` has a kink.
    max_step : float
        Largest step (s).
    """
    t_start = time.perf_counter()
    buildings = list(buildings)
    contacts = list(contacts)
    stop_time = float(stop_time)
    if not (math.isfinite(stop_time) and stop_time > 0.0):
        raise ValueError(f"stop_time = {stop_time!r} s must be finite and > 0")
    if method not in METHODS:
        raise ValueError(f"method = {method!r} is not allowed: one of {', '.join(METHODS)}")
    if not (0.0 < rtol < 1e-2):
        raise ValueError(f"rtol = {rtol!r} is outside 0 < rtol < 1e-2")
    _check_contacts(buildings, contacts)
    ag, breakpoints = _ground(ground, stop_time)
    system = _System(buildings, contacts, ag, hystereses)
    y0 = _initial_state(system, x0, v0)
    storey_state = system.storeys.initial(y0)
    t_output = _output_grid(stop_time, output_dt, t_output)
    breaks = np.unique(np.append(breakpoints[(breakpoints > 0) & (breakpoints < stop_time)]
                                 if break_at_samples else np.empty(0), stop_time))
    run = _Integration(system, method, rtol, _tolerances(system, rtol, atol), max_step, t_output, y0,
                       storey_state)
    run.march(breaks, stop_time)
    return run.result(t_start)


def _initial_state(system: "_System", x0, v0) -> np.ndarray:
    """The state at t = 0 from the floors' initial displacements and velocities (m, m/s)."""
    n = system.n
    y0 = np.zeros(system.size)
    for name, values, start in (("x0", x0, 0), ("v0", v0, n)):
        if values is None:
            continue
        if len(values) != len(system.buildings):
            raise ValueError(f"{name}: {len(values)} arrays for {len(system.buildings)} buildings")
        for b, arr in enumerate(values):
            arr = np.zeros(0) if arr is None else np.asarray(arr, dtype=float).reshape(-1)
            size = system.offsets[b + 1] - system.offsets[b]
            if arr.size == 0:
                continue
            if arr.size != size:
                raise ValueError(f"{name}[{b}] has {arr.size} values; building {b} has {size} floors")
            y0[start + system.offsets[b]:start + system.offsets[b + 1]] = arr
    delta0, _ = system.kinematics(y0)
    for c, d in enumerate(delta0):
        if d > 0.0:
            raise ValueError(f"contact {c} is closed at t = 0 (penetration {d:.3e} m): start the scene "
                             f"with the floors apart (x_left - x_right < gap)")
    return y0


def _tolerances(system: "_System", rtol: float, atol: float | None):
    """``atol`` of each state component (m, m/s, J), or the one given."""
    if atol is not None:
        return float(atol)
    n = system.n
    # The energy accumulators start at 0 J and only feed the balance check.  At rtol J
    # (1e-9 J) Radau's Newton iteration on the contact work cannot converge at an onset
    # whose dashpot grows like delta^((n-1)/2) (Jankowski: the step collapses to nothing);
    # 1e3 rtol J is still 1e-6 of a 1 kJ impact.
    # The storeys' states: the Bouc-Wen variable z is of order 1; hysteretic energies as above.
    storeys = system.storeys
    return np.concatenate((np.full(n, 1e-2 * rtol), np.full(n, 1e-1 * rtol),
                           np.full(2 + len(system.contacts), 1e3 * rtol),
                           np.full(storeys.bw.size, rtol), np.full(storeys.size - storeys.bw.size, 1e3 * rtol)))


def _output_grid(stop_time: float, output_dt: float, t_output) -> np.ndarray:
    if t_output is None:
        count = int(math.floor(stop_time / output_dt + 1e-9))
        t_output = np.append(np.arange(count + 1) * output_dt, stop_time)
        t_output = np.unique(t_output)
    t_output = np.asarray(t_output, dtype=float)
    if t_output.size and (t_output[0] < 0.0 or t_output[-1] > stop_time or np.any(np.diff(t_output) < 0)):
        raise ValueError("t_output must be sorted and within [0, stop_time]")
    return t_output


class _Integration:
    """One reference run: the segments between events and breakpoints, and their bookkeeping.

    Holds the contacts' phases, latched impact speeds and open impacts, the output grid being
    filled, the integrator's steps and the cost counters (module docstring: events).
    """

    def __init__(self, system: "_System", method: str, rtol: float, atol, max_step: float,
                 t_output: np.ndarray, y0: np.ndarray, storey_state=None):
        self.system = system
        self.storey_state = storey_state if storey_state is not None else system.storeys.initial(y0)
        self.method, self.rtol, self.atol, self.max_step = method, rtol, atol, max_step
        nc = len(system.contacts)
        self.phases = [OPEN] * nc
        self.v_imp = np.zeros(nc)
        self.event_counts: dict[str, int] = {}
        self.overlap = [False] * nc   # open after a force separation, floors still overlapping
        self.open_impacts: dict[int, dict] = {}
        self.impacts: list[Impact] = []
        self.t_output, self.y0 = t_output, y0
        self.y_out = np.empty((t_output.size, system.size))
        self.V_out = np.empty((t_output.size, system.storeys.count))
        self.step_t: list[np.ndarray] = [np.array([0.0])]
        self.nfev = self.njev = self.nlu = self.segments = 0
        self.first_step = None
        self.out_index = 0
        if t_output.size and t_output[0] == 0.0:
            self.y_out[0] = y0
            self.V_out[0] = system.storeys.shears(y0[None, :], self.storey_state)[0]
            self.out_index = 1
        self.peaks = _PeakTracker(np.abs(y0[:system.n]))
        D = system.storeys.D
        self.drift_peaks = _PeakTracker(np.abs(D @ y0[:system.n]), D)
        self.acceleration_peaks = _AccelerationTracker(system, y0)

    def march(self, breaks: np.ndarray, stop_time: float) -> None:
        """Integrate from 0 to ``stop_time``: one segment to the next event or breakpoint at a time."""
        t, y = 0.0, self.y0
        break_index = 0
        while t < stop_time:
            while breaks[break_index] <= t:
                break_index += 1
            t_end = breaks[break_index]
            if t_end - t <= 8.0 * np.finfo(float).eps * max(1.0, abs(t)):
                t = t_end          # an event a few ulp before a sample time: nothing to integrate
                continue
            t, y = self._segment(t, t_end, y)
        self.y_end = y

    def _segment(self, t: float, t_end: float, y: np.ndarray) -> tuple[float, np.ndarray]:
        """One ``solve_ivp`` run with the current phases, up to ``t_end`` or the first event."""
        system, phases, v_imp = self.system, self.phases, self.v_imp
        storeys, storey_state = system.storeys, self.storey_state
        probe = storey_state.probe
        if probe:
            t_end = min(t_end, t + probe)       # a short segment to find which side a kink function is on
        if self.first_step is not None:
            self.first_step = min(self.first_step, t_end - t)
        event_list = system.events(phases, v_imp, self.overlap)
        if storeys.inelastic:
            event_list += storeys.events(storey_state)
        kwargs = {}
        if self.method in ("Radau", "BDF", "LSODA") and not storeys.inelastic and STICK not in phases:
            # (finite differences while a contact sticks or storeys yield)
            kwargs["jac"] = system.jacobian(phases, v_imp)
        fun = system.rhs(phases, v_imp, storey_state)
        sol = solve_ivp(fun, (t, t_end), y, method=self.method, rtol=self.rtol,
                        atol=self.atol, events=[e[0] for e in event_list], dense_output=True,
                        first_step=self.first_step, max_step=self.max_step, **kwargs)
        if sol.status < 0:
            raise RuntimeError(f"reference solver failed at t = {t:.6g} s: {sol.message}")
        self.segments += 1
        self.nfev += sol.nfev
        self.njev += sol.njev
        self.nlu += sol.nlu
        t_new = float(sol.t[-1])
        y_new = sol.y[:, -1]
        if sol.t.size >= 2:
            self.first_step = min(float(sol.t[-1] - sol.t[-2]), self.max_step) or None
            if sol.status == 1 and sol.t.size >= 3:   # the event step is truncated: use the one before
                self.first_step = float(sol.t[-2] - sol.t[-3])
        self.step_t.append(sol.t[1:])
        self.peaks.update(sol)
        self.drift_peaks.update(sol)
        # the segment's right-hand side with its phases, impact speeds and storey state frozen: the
        # tracker may evaluate it after later events have changed them (self.phases is mutated)
        self.acceleration_peaks.update(sol, fun, any(p != OPEN for p in phases), lambda: system.rhs(
            list(phases), v_imp.copy(), copy.deepcopy(storey_state)))

        # output grid points inside (t, t_new]
        stop = np.searchsorted(self.t_output, t_new, side="right")
        if stop > self.out_index:
            self.y_out[self.out_index:stop] = sol.sol(self.t_output[self.out_index:stop]).T
            self.V_out[self.out_index:stop] = storeys.shears(self.y_out[self.out_index:stop], storey_state)
            self.out_index = stop

        # contact bookkeeping on this segment
        closed = [c for c in range(len(system.contacts)) if phases[c] != OPEN]
        for c in closed:
            F_peak, d_peak = _segment_peaks(system, sol, c, phases, v_imp)
            rec = self.open_impacts[c]
            rec["peak_force_N"] = max(rec["peak_force_N"], F_peak)
            rec["max_penetration"] = max(rec["max_penetration"], d_peak)

        if sol.status == 1:
            fired = [(len(te) and te[0], k) for k, te in enumerate(sol.t_events) if len(te)]
            _, k = min(fired)
            _, c, kind = event_list[k]
            if kind in STOREY_EVENTS:
                self.event_counts[kind] = self.event_counts.get(kind, 0) + 1
                storeys.apply(kind, c, y_new, fun(t_new, y_new), storey_state)
            else:
                self._event(kind, c, t_new, y_new)
        elif probe:
            storeys.after_probe(y_new, storey_state)
        return t_new, y_new

    def _event(self, kind: str, c: int, t: float, y: np.ndarray) -> None:
        """The phase change of contact ``c`` at an event of ``kind`` (module docstring)."""
        system, phases, n = self.system, self.phases, self.system.n
        self.event_counts[kind] = self.event_counts.get(kind, 0) + 1
        delta, rate = system.kinematics(y)
        if kind == "onset":
            self.overlap[c] = False
            phases[c] = APPROACH
            self.v_imp[c] = rate[c]
            self.open_impacts[c] = dict(contact=c, t_onset=t, v_impact=float(rate[c]), peak_force_N=0.0,
                                        max_penetration=0.0, work0=float(y[2 * n + 2 + c]))
            if rate[c] <= 0.0:   # grazing contact: no approach phase
                phases[c] = RESTITUTION
        elif kind in ("max_penetration", "reapproach", "loading", "unloading"):
            phases[c] = system.next_branch(y, phases, self.v_imp, c, kind)
        elif kind == "parted":
            self.overlap[c] = False
        elif kind in ("separation", "force_separation"):
            phases[c] = OPEN
            self.overlap[c] = kind == "force_separation" and delta[c] > 0.0
            rec = self.open_impacts.pop(c)
            self.impacts.append(_close_impact(rec, t, float(y[2 * n + 2 + c]) - rec.pop("work0")))

    def result(self, t_start: float) -> "ReferenceResult":
        """The histories on the output grid, the impacts and the energy balance."""
        system, n, y_out, y0, t_output = self.system, self.system.n, self.y_out, self.y0, self.t_output
        impacts = list(self.impacts)
        # impacts still closed at the end: dissipated = work - stored elastic energy
        delta_end, _ = system.kinematics(self.y_end)
        stored_end = system.stored_energy(np.where(np.array([p != OPEN for p in self.phases]), delta_end, 0.0))
        for c, rec in sorted(self.open_impacts.items()):
            work = float(self.y_end[2 * n + 2 + c]) - rec.pop("work0")
            impacts.append(_close_impact(rec, math.nan, work - stored_end[c]))
        impacts.sort(key=lambda imp: imp.t_onset)
        impacts = [replace(imp, grazing=imp.max_penetration < system.contacts[imp.contact].graze_depth)
                   for imp in impacts]

        # histories on the output grid (phases re-derived from the impact list)
        u_out, v_out = y_out[:, :n], y_out[:, n:2 * n]
        forces, deltas, stored = _force_history(system, t_output, y_out, impacts)
        storeys = system.storeys
        nc = len(system.contacts)
        contact_work = y_out[:, 2 * n + 2:2 * n + 2 + nc].sum(axis=1)
        kinetic = 0.5 * np.einsum("ij,j,ij->i", v_out, system.masses, v_out)
        strain = 0.5 * np.einsum("ij,jk,ik->i", u_out, system.K_linear, u_out)
        drift_out = u_out @ storeys.D.T
        hysteretic = None
        if storeys.inelastic:
            strain = strain + storeys.yielding_strain_energy(drift_out, self.V_out)
            hysteretic = y_out[:, storeys.i_h:].sum(axis=1)
        # the initial state is elastic: every storey holds k d^2 / 2
        e0 = 0.5 * float(y0[n:2 * n] @ (system.masses * y0[n:2 * n])) + 0.5 * float(y0[:n] @ system.K @ y0[:n])
        dissipated = kinetic + strain + y_out[:, 2 * n + 1] + contact_work
        if hysteretic is not None:
            dissipated = dissipated + hysteretic
        energies = Energies(input=y_out[:, 2 * n], kinetic=kinetic, strain=strain, damping=y_out[:, 2 * n + 1],
                            contact_work=contact_work, contact_stored=stored.sum(axis=1),
                            residual=y_out[:, 2 * n] + e0 - dissipated, hysteretic=hysteretic)
        # the storeys at the end of the run, in the final storey state
        y_end = self.y_end
        V_end = storeys.shears(y_end[None, :], self.storey_state)[0]
        residual_end = storeys.residual_drift(storeys.D @ y_end[:n], V_end)
        peak_d = self.drift_peaks.refined()
        mu = storeys.ductility(peak_d)
        e_h = np.zeros(len(system.buildings))
        for row, b in enumerate(storeys.yielding_buildings):
            e_h[b] = float(y_end[storeys.i_h + row])
        nb = len(system.buildings)
        peak_u = self.peaks.refined()
        peak_a = self.acceleration_peaks.refined()
        per_building = list(zip(system.offsets[:-1], system.offsets[1:]))
        return ReferenceResult(
            t=t_output, u=u_out, v=v_out, contact_force=forces, penetration=deltas, energies=energies,
            impact_list=tuple(imp for imp in impacts if not imp.grazing),
            graze_list=tuple(imp for imp in impacts if imp.grazing),
            peak_force_N=max((imp.peak_force_N for imp in impacts), default=0.0),
            dissipated_energy_J=float(sum(imp.dissipated_energy_J for imp in impacts)),
            peak_displacements=tuple(peak_u[o0:o1] for o0, o1 in per_building),
            peak_accelerations=tuple(peak_a[o0:o1] for o0, o1 in per_building),
            t_steps=np.concatenate(self.step_t), floor_offsets=system.offsets, method=self.method, rtol=self.rtol,
            nfev=self.nfev, njev=self.njev, nlu=self.nlu, n_segments=self.segments,
            wall_time_s=time.perf_counter() - t_start, event_counts=self.event_counts,
            storey_drift=drift_out, storey_shear=self.V_out, storey_offsets=storeys.storey_offsets,
            peak_drifts=tuple(storeys.of_building(peak_d, b) for b in range(nb)),
            ductility=tuple(storeys.of_building(mu, b) for b in range(nb)),
            residual_drifts=tuple(storeys.of_building(residual_end, b) for b in range(nb)),
            hysteretic_energy_J=tuple(float(e) for e in e_h),
            yielding_buildings=tuple(storeys.yielding_buildings),
        )


def _check_contacts(buildings, contacts):
    for c, contact in enumerate(contacts):
        for side in ("left", "right"):
            b = getattr(contact, side)
            floor = getattr(contact, f"{side}_floor")
            if not (0 <= b < len(buildings)):
                raise ValueError(f"contact {c}: {side} = {b!r} is not a building index (0..{len(buildings) - 1})")
            nf = len(buildings[b].masses)
            if not (1 <= floor <= nf):
                raise ValueError(f"contact {c}: {side}_floor = {floor!r} is outside 1..{nf} (building {b})")
        if contact.left == contact.right:
            raise ValueError(f"contact {c}: left and right are the same building ({contact.left})")
        if not (math.isfinite(contact.gap) and contact.gap >= 0.0):
            raise ValueError(f"contact {c}: gap = {contact.gap!r} m must be finite and >= 0")


def _close_impact(rec: dict, t_sep: float, dissipated: float) -> Impact:
    rec = dict(rec)
    rec.pop("work0", None)
    return Impact(t_separation=t_sep, dissipated_energy_J=dissipated, **rec)


def _segment_peaks(system: _System, sol, c: int, phases, v_imp) -> tuple[float, float]:
    """Largest force and penetration of contact ``c`` over one segment, from the dense output.

    The force is sampled at the integrator's steps and 8 points inside each step, and the best
    sample is refined by a bounded scalar search on the interpolant (7th order for DOP853).
    """
    ts = sol.t
    if ts.size < 2:
        return 0.0, 0.0
    frac = np.linspace(0.0, 1.0, 9)[:-1]
    grid = np.append((ts[:-1, None] + np.diff(ts)[:, None] * frac).ravel(), ts[-1])
    ys = sol.sol(grid)

    def force_at(tt):
        y = sol.sol(tt)
        if phases[c] == STICK:
            return float(system.contact_forces(y, phases, v_imp)[0][c])
        delta, rate = system.kinematics(y)
        return system.contacts[c].law.force(delta[c], rate[c], v_imp[c], approaching=phases[c] == APPROACH)

    deltas = ys[system.dof_left[c]] - ys[system.dof_right[c]] - system.gaps[c]
    values = np.array([force_at(tt) for tt in grid])
    k = int(np.argmax(values))
    best_F = float(values[k])
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    if hi > lo:
        res = minimize_scalar(lambda tt: -force_at(tt), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-12 * max(1.0, hi)})
        best_F = max(best_F, -float(res.fun))
    k = int(np.argmax(deltas))
    best_d = float(deltas[k])
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    if hi > lo:
        def neg_delta(tt):
            y = sol.sol(tt)
            return -(y[system.dof_left[c]] - y[system.dof_right[c]] - system.gaps[c])
        res = minimize_scalar(neg_delta, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12 * max(1.0, hi)})
        best_d = max(best_d, -float(res.fun))
    return best_F, best_d


class _PeakTracker:
    """Largest ``|u|`` of every floor over the run (or of ``|P u|``, e.g. the storey drifts,
    with a matrix ``transform = P``), from the dense output.

    Each segment is sampled at its steps and 8 points inside each step; the segment holding
    a floor's best sample is kept, and :meth:`refined` polishes each maximum with a bounded
    scalar search on that segment's interpolant (the grid alone is off by ~(w h)^2 / 8).
    """

    def __init__(self, initial: np.ndarray, transform: np.ndarray | None = None):
        self.value = initial.copy()
        self.where: list = [None] * initial.size
        self.transform = transform

    def _rows(self, states: np.ndarray) -> np.ndarray:
        """The tracked functions of states (columns of the full state vector)."""
        if self.transform is None:
            return states[:self.value.size]
        return self.transform @ states[:self.transform.shape[1]]

    def update(self, sol) -> None:
        ts = sol.t
        if ts.size < 2:
            return
        frac = np.linspace(0.0, 1.0, 9)[:-1]
        grid = np.append((ts[:-1, None] + np.diff(ts)[:, None] * frac).ravel(), ts[-1])
        u = np.abs(self._rows(sol.sol(grid)))
        best = np.argmax(u, axis=1)
        for dof in np.flatnonzero(u[np.arange(u.shape[0]), best] > self.value):
            k = best[dof]
            self.value[dof] = u[dof, k]
            self.where[dof] = (sol.sol, grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)])

    def refined(self) -> np.ndarray:
        out = self.value.copy()
        for dof, where in enumerate(self.where):
            if where is None or where[2] <= where[1]:
                continue
            interp, lo, hi = where
            if self.transform is None:
                def value(tt, interp=interp, dof=dof):
                    return -abs(interp(tt)[dof])
            else:
                def value(tt, interp=interp, row=self.transform[dof]):
                    return -abs(float(row @ interp(tt)[:row.size]))
            res = minimize_scalar(value, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12 * max(1.0, hi)})
            out[dof] = max(out[dof], -float(res.fun))
        return out


class _AccelerationTracker:
    """Largest absolute floor acceleration ``|u'' + ag|`` of every floor over the run, from the
    dense output and the segment's own right-hand side (contact forces of its phases, yielding
    storeys, stick: the impact spikes included).

    As :class:`_PeakTracker`: 8 samples per solver step, the best segment kept with its
    right-hand side, each maximum polished by a bounded scalar search.  A segment without a
    closed contact or yielding storeys is evaluated for all samples at once (linear in the state).
    """

    def __init__(self, system: "_System", y0: np.ndarray):
        self.system = system
        n = system.n
        self.value = np.abs(system.minv * (-(system.K @ y0[:n]) - system.C @ y0[n:2 * n]))
        self.where: list = [None] * n

    def _values(self, fun, ts: np.ndarray, ys: np.ndarray, linear: bool) -> np.ndarray:
        """|absolute acceleration| (n, points) at times ``ts`` of states ``ys`` (size, points)."""
        system, n = self.system, self.system.n
        if linear:
            return np.abs(system.minv[:, None] * (-(system.K @ ys[:n]) - system.C @ ys[n:2 * n]))
        return np.abs(np.column_stack([fun(t, ys[:, k])[n:2 * n] + float(system.ag(t))
                                       for k, t in enumerate(ts)]))

    def update(self, sol, fun, closed: bool, freeze) -> None:
        """Sample segment ``sol`` (right-hand side ``fun``); ``freeze()``: ``fun`` with its
        arguments copied, kept for :meth:`refined` when the segment holds a new maximum."""
        ts = sol.t
        if ts.size < 2:
            return
        linear = not closed and not self.system.storeys.inelastic
        frac = np.linspace(0.0, 1.0, 9)[:-1]
        grid = np.append((ts[:-1, None] + np.diff(ts)[:, None] * frac).ravel(), ts[-1])
        a = self._values(fun, grid, sol.sol(grid), linear)
        best = np.argmax(a, axis=1)
        frozen = None
        for dof in np.flatnonzero(a[np.arange(a.shape[0]), best] > self.value):
            k = best[dof]
            self.value[dof] = a[dof, k]
            frozen = frozen or (fun if linear else freeze())
            self.where[dof] = (sol.sol, grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)], frozen, linear)

    def refined(self) -> np.ndarray:
        out = self.value.copy()
        for dof, where in enumerate(self.where):
            if where is None or where[2] <= where[1]:
                continue
            interp, lo, hi, fun, linear = where

            def minus(tt, interp=interp, fun=fun, linear=linear, dof=dof):
                return -float(self._values(fun, np.array([tt]), interp(tt)[:, None], linear)[dof, 0])

            res = minimize_scalar(minus, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12 * max(1.0, hi)})
            out[dof] = max(out[dof], -float(res.fun))
        return out


def _force_history(system: _System, t_out, y_out, impacts):
    """Contact forces, penetrations and stored energies on the output grid.

    The phase at each output time follows from the impact list (onset, separation) and the
    sign of ``delta'``, exactly as during the integration.
    """
    nc = len(system.contacts)
    forces = np.zeros((t_out.size, nc))
    deltas = np.zeros((t_out.size, nc))
    stored = np.zeros((t_out.size, nc))
    for k in range(t_out.size):
        delta, rate = system.kinematics(y_out[k])
        deltas[k] = delta
        for imp in impacts:
            c = imp.contact
            end = imp.t_separation if math.isfinite(imp.t_separation) else math.inf
            if imp.t_onset <= t_out[k] <= end and delta[c] > 0.0:
                law = system.contacts[c].law
                forces[k, c] = law.force(delta[c], rate[c], imp.v_impact)
                stored[k, c] = law.elastic_energy(delta[c])
    return forces, deltas, stored


# -- scenes ----------------------------------------------------------------------------------------
def reference_for_scene(scene, overrides: dict | None = None) -> ReferenceResult:
    """Reference solution of a :class:`cosim.master.scene.Scene`.

    ``overrides`` are keyword arguments of :func:`solve_reference` that replace those derived
    from the scene (e.g. ``{"rtol": 1e-8, "stop_time": 5.0, "output_dt": 0.01}``).
    """
    inputs = scene_inputs(scene)
    inputs.update(overrides or {})
    return solve_reference(**inputs)


def scene_inputs(scene) -> dict:
    """Plain arguments of :func:`solve_reference` for a scene, with the FMUs' physics.

    Builds the same objects the slaves build in ``initialize()`` from the same parameter
    values (:mod:`cosim.master.models`; the storey laws as ``StoreyHysteresis``).  Contacts keep
    the scene's order.
    """
    buildings, x0, v0, hystereses = [], [], [], []
    for spec in scene.buildings:
        buildings.append(shear_building(spec))
        floors = range(1, int(spec.value("n_storeys")) + 1)
        hystereses.append(StoreyHysteresis(
            str(spec.value("hysteresis")), [float(spec.value(element_name("Fy", i))) for i in floors],
            float(spec.value("alpha")), float(spec.value("bw_n")), float(spec.value("bw_beta")),
            float(spec.value("bw_gamma"))))
        x, v = initial_state(spec)
        x0.append(x)
        v0.append(v)
    ground = ground_record(scene.ground) if scene.ground is not None else None
    contacts = []
    index = {spec.name: b for b, spec in enumerate(scene.buildings)}
    for level, spec in zip(scene.levels, scene.contacts):
        contacts.append(Contact(index[level.left], int(level.floor_left), index[level.right],
                                int(level.floor_right), contact_law(spec), float(spec.value("gap")),
                                float(spec.value("graze_depth"))))
    return dict(buildings=buildings, ground=ground, contacts=contacts, stop_time=float(scene.stop_time),
                x0=x0, v0=v0, hystereses=hystereses)
