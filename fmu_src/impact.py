"""Single impacts of two free masses: reference integration, calibration, in-step resolver.

Pure physics (SI units, no FMI):

* :func:`goldsmith_loss` -- kinetic energy lost in an impact of restitution CR (seed Eq 3.2);
* :func:`simulate_impact` -- one impact integrated with scipy ``solve_ivp`` (DOP853, tight
  tolerances, events at maximum penetration and separation): the independent reference;
* :func:`calibrate_zeta` -- the seed paper's cyclic procedure (its Fig 4) done with a root
  finder: adjust a model's damping constant until the hysteresis-loop area equals
  Goldsmith's loss;
* :class:`ImpactResolver` -- the fast in-step impact integrator used by ``pounding.fmu``
  (pure Python Dormand-Prince 5(4) in the impact's own scales, with located events);
* :class:`PlainContact` -- the force law evaluated on the current inputs only (comparison);
* :func:`cr_table` -- achieved CR of every model with its published constant
  (``python -m fmu_src.impact --cr-table``).
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, minimize_scalar

from .contact_laws import (APPROACH_ONLY_MODELS, DAMPED_MODELS, MODELS, ContactLaw, crvk_printed_constant,
                           effective_mass, published_zeta)


def goldsmith_loss(m: float, CR: float, v_imp: float) -> float:
    """Kinetic energy lost in an impact, ``0.5 m (1 - CR^2) v_imp^2`` [J] (Goldsmith 1960, seed Eq 3.2).

    ``m`` effective mass [kg], ``CR`` restitution [-], ``v_imp`` approach speed [m/s].
    """
    return 0.5 * m * (1.0 - CR * CR) * v_imp * v_imp


# ----------------------------------------------------------------------------------------------
# reference: one impact with solve_ivp
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ImpactResult:
    """Outcome of one impact of two free masses (:func:`simulate_impact`).

    Attributes
    ----------
    v_impact, v_rebound : float
        Approach and rebound relative speeds [m/s].
    achieved_CR : float
        ``v_rebound / v_impact`` [-].
    peak_force : float
        Largest contact force [N].
    max_penetration : float
        Largest penetration [m].
    time_of_max_penetration, contact_duration : float
        From onset [s]; the contact ends when the force vanishes.
    dissipated_energy : float
        ``0.5 m (v_impact^2 - v_rebound^2)`` [J], from the velocities.
    loop_area : float
        Integral of ``F d(delta)`` around the hysteresis loop [J], integrated separately.
    impulse : float
        Integral of ``F dt`` [N s].
    nfev : int
        Right-hand-side evaluations spent.
    t, delta, delta_dot, force : ndarray or None
        Time history [s, m, m/s, N] when ``record=True``.
    """

    v_impact: float
    v_rebound: float
    achieved_CR: float
    peak_force: float
    max_penetration: float
    time_of_max_penetration: float
    contact_duration: float
    dissipated_energy: float
    loop_area: float
    impulse: float
    nfev: int
    t: np.ndarray | None = field(default=None, repr=False)
    delta: np.ndarray | None = field(default=None, repr=False)
    delta_dot: np.ndarray | None = field(default=None, repr=False)
    force: np.ndarray | None = field(default=None, repr=False)


def _check_speed(v_imp: float) -> float:
    v_imp = float(v_imp)
    if not (math.isfinite(v_imp) and v_imp > 0.0):
        raise ValueError(f"v_imp = {v_imp!r} m/s is outside the allowed range v_imp > 0")
    return v_imp


def simulate_impact(law: ContactLaw, v_imp: float, record: bool = False, rtol: float = 1e-10) -> ImpactResult:
    """Integrate one impact of two free masses (effective mass ``law.m``) to separation.

    Starts at ``delta = 0`` with approach speed ``v_imp`` [m/s].  scipy ``solve_ivp``
    (DOP853, ``rtol``; ``atol`` scaled by the impact's length, speed and energy scales) in
    two phases: approach up to the event ``delta_dot = 0`` (maximum penetration, where
    approach-only dashpots switch off) and restitution up to separation (``delta = 0``, or
    the force reaching zero for laws clipped at ``F >= 0``).  The state carries the loop
    integral ``int F d(delta)`` and the impulse, so the loop area is computed independently
    of the energy balance.
    """
    v = _check_speed(v_imp)
    m = law.m
    L = law.length_scale(v)
    T = L / v
    F0 = law.k * L ** law.n
    E0 = 0.5 * m * v * v
    atol = np.array([L, v, E0, m * v]) * rtol * 1e-2
    t_max = 100.0 * T * (1.0 + 2.0 * law.zeta)   # overdamped laws return on a time c/k ~ 2 zeta T

    def rhs(approaching):
        def f(t, y):
            F = law.force(y[0], y[1], v, approaching)
            return (y[1], -F / m, F * y[1], F)
        return f

    def max_penetration(t, y):
        return y[1]
    max_penetration.terminal = True
    max_penetration.direction = -1

    def separation(t, y):
        if y[0] <= 0.0 or not law.releases_before_unloading:
            return y[0] / L
        return min(y[0] / L, law.raw_force(y[0], y[1], v, False) / F0)
    separation.terminal = True
    separation.direction = -1

    approach = solve_ivp(rhs(True), (0.0, t_max), [0.0, v, 0.0, 0.0], method="DOP853", rtol=rtol,
                         atol=atol, events=max_penetration, dense_output=True)
    if approach.status != 1:
        raise RuntimeError(f"{law.model}: no maximum penetration within {t_max:.3g} s ({approach.message})")
    t1 = float(approach.t_events[0][0])
    y1 = approach.y_events[0][0].copy()
    y1[1] = 0.0
    rest = solve_ivp(rhs(False), (t1, t1 + t_max), y1, method="DOP853", rtol=rtol, atol=atol,
                     events=separation, dense_output=True)
    if rest.status != 1:
        raise RuntimeError(f"{law.model}: no separation within {t_max:.3g} s ({rest.message})")
    t2 = float(rest.t_events[0][0])
    y2 = rest.y_events[0][0]
    v_out = -float(y2[1])

    # Peak force: sample the dense output of each phase, then refine around the best sample.
    def peak(sol, ta, tb, approaching):
        ts = np.linspace(ta, tb, 2001)
        ys = sol.sol(ts)
        fs = np.array([law.force(d, dd, v, approaching) for d, dd in zip(ys[0], ys[1])])
        i = int(np.argmax(fs))
        lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, len(ts) - 1)]
        if hi > lo:
            res = minimize_scalar(lambda s: -law.force(*sol.sol(s)[:2], v, approaching), bounds=(lo, hi),
                                  method="bounded", options={"xatol": (tb - ta) * 1e-9})
            return max(fs[i], -res.fun)
        return fs[i]

    F_peak = max(peak(approach, 0.0, t1, True), peak(rest, t1, t2, False))
    result = ImpactResult(
        v_impact=v, v_rebound=v_out, achieved_CR=v_out / v, peak_force=float(F_peak),
        max_penetration=float(y1[0]), time_of_max_penetration=t1, contact_duration=t2,
        dissipated_energy=0.5 * m * (v * v - v_out * v_out), loop_area=float(y2[2]),
        impulse=float(y2[3]), nfev=int(approach.nfev + rest.nfev))
    if record:
        ta = np.linspace(0.0, t1, 400)
        tr = np.linspace(t1, t2, 400)[1:]
        ya, yr = approach.sol(ta), rest.sol(tr)
        t = np.concatenate([ta, tr])
        delta = np.concatenate([ya[0], yr[0]])
        delta_dot = np.concatenate([ya[1], yr[1]])
        force = np.array([law.force(d, dd, v, i < len(ta)) for i, (d, dd) in enumerate(zip(delta, delta_dot))])
        result = replace(result, t=t, delta=delta, delta_dot=delta_dot, force=force)
    return result


# ----------------------------------------------------------------------------------------------
# the cyclic procedure (seed Fig 4) as a root find
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Calibration:
    """Damping constant that makes a model's loop area equal Goldsmith's loss (:func:`calibrate_zeta`).

    ``zeta`` calibrated constant [-]; ``published_zeta`` the model's formula [-];
    ``achieved_CR`` [-]; ``loop_area`` and ``goldsmith_loss`` [J]; ``peak_force`` [N];
    ``max_penetration`` [m]; ``contact_duration`` [s]; ``n_impacts`` impact simulations spent;
    ``m`` [kg], ``k`` [N/m^n], ``v_imp`` [m/s] the inputs used.
    """

    model: str
    CR: float
    n: float
    zeta: float
    published_zeta: float
    achieved_CR: float
    loop_area: float
    goldsmith_loss: float
    peak_force: float
    max_penetration: float
    contact_duration: float
    n_impacts: int
    m: float
    k: float
    v_imp: float


def calibrate_zeta(model: str, CR: float, n: float = 1.5, *, k: float = 1.0, m1: float | None = None,
                   m2: float | None = None, v_imp: float = 1.0, zeta_max: float = 1e6,
                   rtol: float = 1e-9) -> Calibration:
    """Find the damping constant of ``model`` for which one impact dissipates Goldsmith's loss.

    The seed paper's cyclic procedure (Fig 4): simulate one impact of two free masses
    (:func:`simulate_impact`), compare the hysteresis-loop area with
    ``0.5 m (1 - CR^2) v_imp^2`` and adjust the constant -- here with brentq on a bracket
    ``[0, zeta_hi]`` (``zeta = 0`` is elastic; ``zeta_hi`` grows from the published value
    by factors of 4 up to ``zeta_max``).

    Dimensional inputs are optional: ``k`` [N/m^n], ``m1``, ``m2`` [kg] (default effective
    mass 1 kg), ``v_imp`` [m/s].  By scale invariance the constant depends only on
    (model, CR, n); the dimensional results (peak force etc.) are for the given inputs.

    Raises ``ValueError`` (with the reachable CR range) when the target cannot be reached.
    """
    if model not in MODELS:
        raise ValueError(f"model = {model!r} is not allowed: one of {', '.join(MODELS)}")
    CR = float(CR)
    if not (0.0 < CR <= 1.0):
        raise ValueError(f"CR = {CR!r} is outside the allowed range 0 < CR <= 1")
    if m1 is None and m2 is None:
        m = 1.0
    elif m1 is None or m2 is None:
        raise ValueError("give both m1 and m2 (kg), or neither (effective mass 1 kg)")
    else:
        m = effective_mass(m1, m2)
    v = _check_speed(v_imp)
    if not (math.isfinite(k) and k > 0.0):
        raise ValueError(f"k = {k!r} N/m^n is outside the allowed range k > 0")
    target = goldsmith_loss(m, CR, v)
    pub = published_zeta(model, CR, n)
    count = 0

    def impact(zeta: float) -> ImpactResult:
        nonlocal count
        count += 1
        return simulate_impact(ContactLaw(model, k, n, m, zeta), v, rtol=rtol)

    def result(zeta: float, res: ImpactResult) -> Calibration:
        return Calibration(model=model, CR=CR, n=n, zeta=zeta, published_zeta=pub,
                           achieved_CR=res.achieved_CR, loop_area=res.loop_area, goldsmith_loss=target,
                           peak_force=res.peak_force, max_penetration=res.max_penetration,
                           contact_duration=res.contact_duration, n_impacts=count, m=m, k=k, v_imp=v)

    if model not in DAMPED_MODELS:
        if CR == 1.0:
            return result(0.0, impact(0.0))
        raise ValueError(f"model {model!r} has no damping constant: it always gives CR = 1, "
                         f"so CR = {CR!r} is not reachable (reachable range: CR = 1)")
    if CR == 1.0:   # zeta = 0 is the elastic Hertz law, which dissipates nothing
        return result(0.0, impact(0.0))

    E0 = 0.5 * m * v * v
    cache: dict[float, ImpactResult] = {}

    def excess(zeta: float) -> float:   # loop area minus Goldsmith's loss, per initial kinetic energy
        cache[zeta] = impact(zeta)
        return (cache[zeta].loop_area - target) / E0

    hi = min(pub if pub > 0.0 else 1.0, zeta_max)
    while excess(hi) < 0.0:
        if hi >= zeta_max:
            cr_min = cache[hi].achieved_CR
            raise ValueError(f"{model}: CR = {CR!r} is not reachable with zeta <= {zeta_max:g}; "
                             f"reachable range {cr_min:.4g} <= CR <= 1")
        hi = min(4.0 * hi, zeta_max)
    lo = 0.0
    # Tighten the lower end to the last constant that dissipated too little (fewer iterations).
    for z in sorted(cache):
        if z < hi and (cache[z].loop_area - target) < 0.0:
            lo = max(lo, z)
    try:
        zeta = brentq(excess, lo, hi, xtol=1e-14, rtol=1e-10, maxiter=200)
    except ValueError as exc:   # no sign change on the bracket: non-monotone loop area
        raise ValueError(f"{model}: bracket [{lo:g}, {hi:g}] for CR = {CR!r} failed: {exc}") from exc
    res = cache.get(zeta) or impact(zeta)
    return result(zeta, res)


# ----------------------------------------------------------------------------------------------
# fast in-step resolver (pure Python, scaled variables)
# ----------------------------------------------------------------------------------------------
# Dormand-Prince 5(4) tableau (Dormand & Prince 1980; as in scipy's RK45).
_A21 = 1 / 5
_A31, _A32 = 3 / 40, 9 / 40
_A41, _A42, _A43 = 44 / 45, -56 / 15, 32 / 9
_A51, _A52, _A53, _A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
_A61, _A62, _A63, _A64, _A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
_B1, _B3, _B4, _B5, _B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
_E1, _E3, _E4, _E5, _E6, _E7 = 71 / 57600, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40


def _scaled_kernel(model: str, zeta: float, n: float, approaching: bool):
    """Return ``f(d, u)``: dimensionless force of one branch (see contact_laws.scaled_force)."""
    half = 0.5 * (n - 1.0)
    if model == "hertz" or zeta == 0.0 or (model in APPROACH_ONLY_MODELS and not approaching):
        def f(d, u):
            return d ** n if d > 0.0 else 0.0
    elif model in ("kelvin_voigt", "jankowski", "barros2013"):
        two_zeta = 2.0 * zeta
        def f(d, u):
            if d <= 0.0:
                return 0.0
            x = d ** n + two_zeta * d ** half * u
            return x if x > 0.0 else 0.0
    elif model == "crvk":
        four_a = 4.0 * zeta
        n1 = n - 1.0
        def f(d, u):
            if d <= 0.0:
                return 0.0
            s = d ** n
            return 0.5 * (s + math.sqrt(s * s + four_a * d ** n1))
    else:
        def f(d, u):
            if d <= 0.0:
                return 0.0
            x = d ** n * (1.0 + zeta * u)
            return x if x > 0.0 else 0.0
    return f


def _scaled_separation(law: ContactLaw):
    """Separation function of the restitution branch, > 0 in contact (ContactLaw.releases_before_unloading)."""
    n, zeta = law.n, law.zeta
    half = 0.5 * (n - 1.0)
    if law.releases_before_unloading:
        def g(d, u):
            if d <= 0.0:
                return d
            return min(d, d ** n + 2.0 * zeta * d ** half * u)
    else:
        def g(d, u):
            return d
    return g


@dataclass
class StepOutcome:
    """What one :meth:`ImpactResolver.step` hands back (SI units)."""

    impulse: float = 0.0          # N s over the step
    mean_force: float = 0.0       # N, impulse / h
    peak_force: float = 0.0       # N, largest instantaneous force in the step
    substeps: int = 0             # accepted internal integration steps
    nfev: int = 0                 # force evaluations
    impacts_started: int = 0
    impacts_completed: int = 0


class ImpactResolver:
    """Locate and integrate impacts inside a communication step, at the impact's own time scale.

    The relative motion during a step is that of two free masses under the contact force
    (``delta_ddot = -F / m``); the host supplies ``delta`` and ``delta_dot`` at the start of
    each step.  Rules (docs/contact_models.md):

    1. *Onset*: out of contact, a new impact starts where the free-flight prediction
       ``delta_eff + delta_dot s`` crosses zero while approaching, ``delta_eff = delta - offset``.
       If a step starts already overlapping while approaching (a crossing the prediction missed),
       the impact starts at once and the overlap is added to ``offset``.
    2. *During contact* the state is the internal one, not the host's smeared inputs; the
       impact is integrated (Dormand-Prince 5(4), scaled by ``L = (m v^2/k)^(1/(n+1))`` and
       ``T = L / v``) with located events at maximum penetration (``delta_dot = 0``) and
       separation (``delta = 0`` or the force reaching zero), and may straddle any number of steps.
    3. *After separation* the host bodies, moved by a constant mean force, may still overlap
       while separating.  The next step records that apparent overlap as ``offset`` (>= 0,
       cleared once the host's ``delta <= 0``); a residual overlap while separating never
       produces force.
    4. The impulse of the step is exact for free masses (``m`` times the change of the
       internal relative velocity), and ``mean_force = impulse / h``.

    The instance holds only plain numbers, so ``copy.deepcopy`` saves its state.
    """

    def __init__(self, law: ContactLaw, rtol: float = 1e-8):
        self.law = law
        self.rtol = rtol
        self._kernels = {True: _scaled_kernel(law.model, law.zeta, law.n, True),
                         False: _scaled_kernel(law.model, law.zeta, law.n, False)}
        self._separation = _scaled_separation(law)
        self.in_contact = False
        self.approaching = False
        self.v_imp = 0.0            # latched approach speed of the latest impact, m/s
        self.d = 0.0                # internal scaled penetration (in contact)
        self.u = 0.0                # internal scaled rate (in contact)
        self.offset = 0.0           # m, apparent overlap left by a resolved impact
        self.delta_end = 0.0        # m, internal penetration at the end of the last step
        self.delta_dot_end = 0.0    # m/s
        self.just_separated = False
        self.dtau = 1e-3            # next internal step, scaled
        self.impacts = 0
        self.E_completed = 0.0      # J, all completed impacts
        self.F_max = 0.0            # N
        self.impact_peak = 0.0      # N, current/latest impact
        self.impact_time = 0.0      # s, elapsed contact time of current/latest impact
        self.delta_max = 0.0        # m, current/latest impact
        self.last_CR = math.nan     # achieved CR of the latest completed impact
        self.last_E = 0.0           # J dissipated by the latest completed impact
        self._prev = ()             # last two (tau, f) samples for peak interpolation

    # -- derived outputs -------------------------------------------------------------------
    def _scales(self):
        v = self.v_imp
        L = self.law.length_scale(v)
        return v, L, L / v, self.law.m * v * v / L

    def dissipated_energy(self) -> float:
        """Energy dissipated by all impacts so far, the current one up to now [J]."""
        if not self.in_contact:
            return self.E_completed
        n = self.law.n
        E = 0.5 * self.law.m * self.v_imp ** 2
        return self.E_completed + E * (1.0 - self.u * self.u - 2.0 * self.d ** (n + 1.0) / (n + 1.0))

    # -- one communication step ------------------------------------------------------------
    def step(self, delta: float, delta_dot: float, h: float) -> StepOutcome:
        """Advance over ``h`` [s] from the host's ``delta`` [m], ``delta_dot`` [m/s] at the step start."""
        out = StepOutcome()
        s = 0.0                                  # s into the step where contact integration starts
        if not self.in_contact:
            if self.just_separated:
                self.offset = max(0.0, delta - self.delta_end)
                self.just_separated = False
            if delta <= 0.0:
                self.offset = 0.0
            d_eff = delta - self.offset
            if d_eff > 0.0:
                if delta_dot <= 0.0:             # residual overlap while separating: no force
                    self._free(delta - self.offset, delta_dot, h)
                    return out
                self.offset += d_eff             # missed onset: start now
                d_eff = 0.0
            elif not (delta_dot > 0.0 and d_eff + delta_dot * h > 0.0):
                self._free(d_eff, delta_dot, h)
                return out
            s = -d_eff / delta_dot
            self._start(delta_dot)
            out.impacts_started = 1
        self._integrate(s, h, out)
        out.mean_force = out.impulse / h
        return out

    def _free(self, delta: float, delta_dot: float, h: float) -> None:
        self.delta_end = delta + delta_dot * h
        self.delta_dot_end = delta_dot

    def _start(self, v: float) -> None:
        self.in_contact = True
        self.approaching = True
        self.v_imp = v
        self.d, self.u = 0.0, 1.0
        self.impacts += 1
        self.impact_peak = 0.0
        self.impact_time = 0.0
        self.delta_max = 0.0
        self._prev = ()
        self.dtau = 1e-3

    def _integrate(self, s: float, h: float, out: StepOutcome) -> None:
        v, L, T, F0 = self._scales()
        m = self.law.m
        tau = 0.0
        tau_end = (h - s) / T
        u_start = self.u
        f = self._kernels[self.approaching]
        d, u = self.d, self.u
        acc = -f(d, u)
        nfev = 1
        base = self.impact_time / T               # scaled contact time at the step start
        if not self._prev:
            nfev += self._sample(base, -acc, d, u, acc, self.approaching, out, F0)
        atol = rtol = self.rtol
        dtau = self.dtau
        separated = False
        while tau < tau_end * (1.0 - 1e-15):
            hs = min(dtau, tau_end - tau)
            last = hs >= tau_end - tau
            d1, u1, acc1, err = self._dp_step(f, d, u, acc, hs, atol, rtol)
            nfev += 6
            if err > 1.0:
                dtau = hs * max(0.2, 0.9 * err ** -0.2)
                continue
            out.substeps += 1
            # events on the accepted step
            if self.approaching and u1 <= 0.0:
                hs, d1, u1, n_ev = self._locate(f, d, u, acc, hs, lambda dd, uu: uu, atol, rtol)
                nfev += n_ev
                u1 = 0.0
                tau += hs
                d, u = d1, u1
                # force just before the switch (approach branch), then just after it
                f_end = f(d, 0.0)
                nfev += self._sample(base + tau, f_end, d, u, -f_end, True, out, F0, branch_end=True)
                self.approaching = False
                self.delta_max = d * L
                f = self._kernels[False]
                acc = -f(d, u)
                nfev += self._sample(base + tau, -acc, d, u, acc, False, out, F0)
                dtau = hs if hs > 0.0 else dtau
                continue
            if not self.approaching and self._separation(d1, u1) <= 0.0:
                hs, d1, u1, n_ev = self._locate(f, d, u, acc, hs, self._separation, atol, rtol)
                nfev += n_ev
                tau += hs
                d, u = d1, u1
                separated = True
                break
            tau += hs
            d, u, acc = d1, u1, acc1
            nfev += self._sample(base + tau, -acc, d, u, acc, self.approaching, out, F0)
            if not last:
                dtau = hs * min(5.0, 0.9 * max(err, 1e-10) ** -0.2)
        self.dtau = dtau
        t_used = tau * T
        self.impact_time += t_used
        out.impulse += m * v * (u_start - u)
        out.nfev += nfev
        if separated:
            self.in_contact = False
            self.just_separated = True
            self.last_CR = -u
            self.last_E = 0.5 * m * v * v * (1.0 - u * u)
            self.E_completed += self.last_E
            out.impacts_completed = 1
            rest = h - s - t_used
            self.delta_end = d * L + u * v * rest
            self.delta_dot_end = u * v
            self.d, self.u = d, u
        else:
            self.d, self.u = d, u
            self.delta_end = d * L
            self.delta_dot_end = u * v
            self.delta_max = max(self.delta_max, d * L)

    def _sample(self, tau, fs, d, u, acc, approaching, out, F0, branch_end=False) -> int:
        """Track the peak force at an accepted point; returns the force evaluations spent.

        A sampled local maximum (or a rise into the end of the approach branch) is refined
        by maximising the force along one Dormand-Prince step from the earlier sample
        (bounded Brent search), so the peak does not depend on where samples fall.
        """
        peak = fs
        nfev = 0
        prev = self._prev
        sample = (tau, fs, d, u, acc, approaching)
        same = [p for p in prev if p[5] == approaching]
        if len(same) == 2 and same[1][1] >= same[0][1] and same[1][1] >= fs:
            p, n_ev = self._refine_peak(same[0], tau - same[0][0])
            peak, nfev = max(peak, same[1][1], p), nfev + n_ev
        if branch_end and same and fs >= same[-1][1]:
            p, n_ev = self._refine_peak(same[-1], tau - same[-1][0])
            peak, nfev = max(peak, p), nfev + n_ev
        self._prev = (prev + (sample,))[-2:]
        F = peak * F0
        if F > out.peak_force:
            out.peak_force = F
        if F > self.impact_peak:
            self.impact_peak = F
        if F > self.F_max:
            self.F_max = F
        return nfev

    def _refine_peak(self, sample, span):
        """Largest scaled force along a DP step of length in (0, span] from ``sample``."""
        _, f0, d, u, acc, approaching = sample
        if not span > 0.0:
            return f0, 0
        f = self._kernels[approaching]
        rtol = self.rtol

        def minus_force(x):
            dx, ux, _, _ = self._dp_step(f, d, u, acc, x, rtol, rtol)
            return -f(dx, ux)

        res = minimize_scalar(minus_force, bounds=(0.0, span), method="bounded",
                              options={"xatol": 1e-7 * span})
        return -res.fun, 6 * res.nfev

    @staticmethod
    def _dp_step(f, d, u, a1, hs, atol, rtol):
        """One Dormand-Prince step of ``d' = u, u' = -f(d, u)``; returns (d, u, u', error norm)."""
        # stage states (d_i, u_i) and derivatives (u_i, a_i)
        d2 = d + hs * _A21 * u
        u2 = u + hs * _A21 * a1
        a2 = -f(d2, u2)
        d3 = d + hs * (_A31 * u + _A32 * u2)
        u3 = u + hs * (_A31 * a1 + _A32 * a2)
        a3 = -f(d3, u3)
        d4 = d + hs * (_A41 * u + _A42 * u2 + _A43 * u3)
        u4 = u + hs * (_A41 * a1 + _A42 * a2 + _A43 * a3)
        a4 = -f(d4, u4)
        d5 = d + hs * (_A51 * u + _A52 * u2 + _A53 * u3 + _A54 * u4)
        u5 = u + hs * (_A51 * a1 + _A52 * a2 + _A53 * a3 + _A54 * a4)
        a5 = -f(d5, u5)
        d6 = d + hs * (_A61 * u + _A62 * u2 + _A63 * u3 + _A64 * u4 + _A65 * u5)
        u6 = u + hs * (_A61 * a1 + _A62 * a2 + _A63 * a3 + _A64 * a4 + _A65 * a5)
        a6 = -f(d6, u6)
        dn = d + hs * (_B1 * u + _B3 * u3 + _B4 * u4 + _B5 * u5 + _B6 * u6)
        un = u + hs * (_B1 * a1 + _B3 * a3 + _B4 * a4 + _B5 * a5 + _B6 * a6)
        an = -f(dn, un)
        ed = hs * (_E1 * u + _E3 * u3 + _E4 * u4 + _E5 * u5 + _E6 * u6 + _E7 * un)
        eu = hs * (_E1 * a1 + _E3 * a3 + _E4 * a4 + _E5 * a5 + _E6 * a6 + _E7 * an)
        sd = atol + rtol * max(abs(d), abs(dn))
        su = atol + rtol * max(abs(u), abs(un))
        err = max(abs(ed) / sd, abs(eu) / su)
        return dn, un, an, err

    def _locate(self, f, d, u, acc, hs, g, atol, rtol):
        """Step length in (0, hs] where ``g`` of the DP step's end state reaches 0 (Illinois)."""
        a, ga = 0.0, g(d, u)
        b = hs
        db, ub, _, _ = self._dp_step(f, d, u, acc, b, atol, rtol)
        gb = g(db, ub)
        nfev = 6
        side = 0
        best = (b, db, ub)
        for _ in range(60):
            if gb == 0.0 or (b - a) <= 1e-14 * max(hs, 1e-300):
                break
            c = (a * gb - b * ga) / (gb - ga) if gb != ga else 0.5 * (a + b)
            if not (a < c < b):
                c = 0.5 * (a + b)
            dc, uc, _, _ = self._dp_step(f, d, u, acc, c, atol, rtol)
            nfev += 6
            gc = g(dc, uc)
            if gc > 0.0:
                a, ga = c, gc
                if side == -1:
                    gb *= 0.5
                side = -1
            else:
                b, gb = c, gc
                best = (b, dc, uc)
                if side == 1:
                    ga *= 0.5
                side = 1
            if abs(gc) < 1e-15:
                best = (c, dc, uc)
                break
        b, db, ub = best
        return b, db, ub, nfev


# ----------------------------------------------------------------------------------------------
# plain mode: the force law on the current inputs
# ----------------------------------------------------------------------------------------------
class PlainContact:
    """The force law evaluated on the host's current ``delta``, ``delta_dot`` only.

    ``v_imp`` is latched when a contact begins (``|delta_dot|`` at the first step found in
    contact).  The host applies the returned force over the whole step, so the work done on
    the contact in a step is ``F (delta_new - delta_old)``; the dissipated energy is that
    work minus the energy stored in the spring.
    """

    def __init__(self, law: ContactLaw):
        self.law = law
        self.in_contact = False
        self.v_imp = 0.0
        self.F = 0.0                # N, force applied over the current step
        self.delta_prev = 0.0
        self.work = 0.0             # J, work done on the contact so far
        self.impacts = 0
        self.F_max = 0.0
        self.delta_max = 0.0
        self.impact_time = 0.0
        self.started = False
        self.last_CR = math.nan     # -delta_dot / v_imp at the first inputs found out of contact
        self.last_E = 0.0           # J, dissipated by the latest completed contact
        self._E_at_onset = 0.0

    def step(self, delta: float, delta_dot: float, h: float) -> float:
        """Force [N] for the step of length ``h`` [s] starting at the given inputs."""
        if self.started:
            self.work += self.F * (delta - self.delta_prev)
        self.started = True
        self.delta_prev = delta
        if delta > 0.0:
            if not self.in_contact:
                self.in_contact = True
                self.impacts += 1
                self.v_imp = abs(delta_dot)
                self.delta_max = 0.0
                self.impact_time = 0.0
                self._E_at_onset = self.dissipated_energy()
            self.delta_max = max(self.delta_max, delta)
            self.impact_time += h
            self.F = self.law.force(delta, delta_dot, self.v_imp)
        else:
            if self.in_contact:
                self.in_contact = False
                self.last_CR = max(0.0, -delta_dot) / self.v_imp if self.v_imp > 0.0 else math.nan
                self.last_E = self.dissipated_energy() - self._E_at_onset
            self.F = 0.0
        self.F_max = max(self.F_max, self.F)
        return self.F

    def dissipated_energy(self) -> float:
        """Work done on the contact minus the elastic energy stored at the latest inputs [J]."""
        return self.work - self.law.elastic_energy(self.delta_prev)


# ----------------------------------------------------------------------------------------------
# CR table
# ----------------------------------------------------------------------------------------------
def cr_table(crs=(0.1, 0.2, 0.4, 0.65, 0.8, 0.9, 0.95), ns=(1.5,), rtol: float = 1e-10) -> str:
    """Markdown table of the CR each model achieves with its published constant.

    Rows: models (plus ``crvk (printed)`` with the seed's Eq 3.9 constant); columns: target CR.
    By scale invariance one impact per cell (m = k = v = 1) is enough.
    """
    lines = []
    for n in ns:
        lines.append(f"\nAchieved CR with the published constant, n = {n:g}\n")
        lines.append("| model | " + " | ".join(f"CR={c:g}" for c in crs) + " |")
        lines.append("|---|" + "---|" * len(crs))
        rows = [(mdl, lambda c, mdl=mdl: published_zeta(mdl, c, n)) for mdl in MODELS]
        rows.append(("crvk (printed Eq 3.9 constant)", lambda c: crvk_printed_constant(c)))
        for name, zeta_of in rows:
            model = name.split()[0]
            cells = []
            for c in crs:
                law = ContactLaw(model, 1.0, n, 1.0, zeta_of(c))
                cells.append(f"{simulate_impact(law, 1.0, rtol=rtol).achieved_CR:.4f}")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def benchmark(repeats: int = 20, CR: float = 0.65, ratios=(None, 0.1, 0.01)) -> str:
    """Wall time of :class:`ImpactResolver` per impact, per model (prints a markdown table).

    ``ratios``: communication step / contact duration (None: the whole impact in one step).
    Each cell is the best of ``repeats`` impacts; ``substeps`` is the accepted internal steps.
    """
    import time
    head = " | ".join("one step" if r is None else f"h = t_c x {r:g}" for r in ratios)
    lines = [f"| model | {head} | substeps (one step) |", "|---|" + "---|" * (len(ratios) + 1)]
    for model in MODELS:
        law = ContactLaw(model, 1.8974e11, 1.5, 100.0, published_zeta(model, CR, 1.5))
        t_c = simulate_impact(law, 10.0, rtol=1e-8).contact_duration
        cells, subs = [], 0
        for ratio in ratios:
            h = 3.0 * t_c if ratio is None else ratio * t_c
            best = math.inf
            for _ in range(repeats):
                r = ImpactResolver(law)
                delta, count = -0.3 * 10.0 * h, 0
                t0 = time.perf_counter()
                out = r.step(delta, 10.0, h)
                count += out.substeps
                while r.in_contact:
                    out = r.step(r.delta_end, r.delta_dot_end, h)
                    count += out.substeps
                best = min(best, time.perf_counter() - t0)
            cells.append(f"{best * 1e3:.2f} ms")
            if ratio is None:
                subs = count
        lines.append(f"| {model} | " + " | ".join(cells) + f" | {subs} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Single-impact tools of the contact models")
    parser.add_argument("--cr-table", action="store_true", help="print achieved CR vs target CR per model")
    parser.add_argument("--n", type=float, nargs="*", default=[1.5], help="stiffness exponents for the table")
    parser.add_argument("--bench", action="store_true", help="print the in-step resolver's cost per impact")
    args = parser.parse_args(argv)
    if args.cr_table:
        print(cr_table(ns=tuple(args.n)))
        return 0
    if args.bench:
        print(benchmark())
        return 0
    parser.print_help()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
