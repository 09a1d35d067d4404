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
import copy
import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, minimize_scalar

from .contact_laws import (APPROACH_ONLY_MODELS, DAMPED_MODELS, HERTZDAMP_MODELS, MIN_IMPACT_SPEED, MODELS,
                           ContactLaw, crvk_printed_constant, effective_mass, published_zeta)


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
_C2, _C3, _C4, _C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9
_A21 = 1 / 5
_A31, _A32 = 3 / 40, 9 / 40
_A41, _A42, _A43 = 44 / 45, -56 / 15, 32 / 9
_A51, _A52, _A53, _A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
_A61, _A62, _A63, _A64, _A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
_B1, _B3, _B4, _B5, _B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
_E1, _E3, _E4, _E5, _E6, _E7 = 71 / 57600, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40

#: scaled rate above which a restitution branch turns back into approach (the structure pushes the
#: bodies together again before they separate); a small positive threshold so that the event
#: cannot fire at the very point where the approach branch ended.
_REAPPROACH_RATE = 1e-9
#: guard against an endless impact/flight alternation inside one step (never reached in tests)
_MAX_IMPACTS_PER_STEP = 1000
#: branch switches (maximum penetration / re-approach) per step after which re-approach is no
#: longer detected in that step: a guard against chatter at delta_dot = 0 (a crvk contact held
#: between its branches sticks instead, ImpactResolver._stick; never reached in the tests)
_MAX_SWITCHES_PER_STEP = 200


def _scaled_kernel(model: str, zeta: float, n: float, approaching: bool):
    """Return ``f(d, u) -> (force, power)`` of one branch in the impact's scales.

    ``force`` is the dimensionless contact force (see contact_laws.scaled_force); ``power`` the
    dimensionless power of its dissipative part, ``(force - d^n) u`` >= 0 (the dashpot acts with
    the sign of ``u``; a force clipped at 0 in restitution, ``u < 0``, gives ``-d^n u`` >= 0).
    """
    half = 0.5 * (n - 1.0)
    if model == "hertz" or zeta == 0.0 or (model in APPROACH_ONLY_MODELS and not approaching):
        def f(d, u):
            return (d ** n, 0.0) if d > 0.0 else (0.0, 0.0)
    elif model in ("kelvin_voigt", "jankowski", "barros2013"):
        two_zeta = 2.0 * zeta
        def f(d, u):
            if d <= 0.0:
                return 0.0, 0.0
            s = d ** n
            x = s + two_zeta * d ** half * u
            x = x if x > 0.0 else 0.0
            return x, (x - s) * u
    elif model == "crvk":
        four_a = 4.0 * zeta
        n1 = n - 1.0
        def f(d, u):
            if d <= 0.0:
                return 0.0, 0.0
            s = d ** n
            x = 0.5 * (s + math.sqrt(s * s + four_a * d ** n1))
            return x, (x - s) * u
    else:
        def f(d, u):
            if d <= 0.0:
                return 0.0, 0.0
            s = d ** n
            x = s * (1.0 + zeta * u)
            x = x if x > 0.0 else 0.0
            return x, (x - s) * u
    return f


def _scaled_separation(law: ContactLaw):
    """Separation function of the restitution branch, > 0 in contact.

    The contact ends where ``d`` reaches 0 or, for Kelvin-Voigt, where the raw force reaches 0
    first (ContactLaw.releases_before_unloading); see also :func:`_scaled_separation_pulled`.
    """
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


def _scaled_separation_pulled(law: ContactLaw):
    """Separation function of the Hertz-damp family while an external force pulls the bodies apart.

    ``w = 1 + zeta u`` obeys ``w' = zeta (alpha - d^n w)``: it can change sign (the raw force
    turns negative and is clipped) only if the scaled external acceleration ``alpha < 0``.  For
    free masses ``w`` decays towards 0 without reaching it (the creeping end of an overdamped
    impact), where round-off alone would flip its sign: so this function is used only while
    ``alpha`` is clearly negative.
    """
    if not (law.model in HERTZDAMP_MODELS and law.zeta > 0.0):
        return _scaled_separation(law)
    zeta = law.zeta

    def g(d, u):
        if d <= 0.0:
            return d
        return min(d, 1.0 + zeta * u)
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


#: taps of a host's delivery kernel the observer identifies: a one-step-late (Jacobi) HHT-alpha
#: host spreads one step's impulse over four steps (0, w0, w1, w2)
_KERNEL_TAPS = 4
#: identification rows after which an unclear edge is given up (the extrapolated structural
#: motion it is measured against drifts away with the horizon)
_MAX_EDGE_ROWS = 12
#: standard error every identified weight must have at most: a weight off by e leaves
#: e F h / m of our own force in the learnt structural increment of each step
_WEIGHT_STANDARD_ERROR = 0.01
#: |sum of the weights - 1| above which the host is inconsistent: it delivers more or less than
#: the impulse we hand over (wiring, masses m1/m2 not those the host integrates)
_MOMENTUM_TOLERANCE = 0.05
#: weights below this are taken as zero (shortens the settling window); above the standard error
_NEGLIGIBLE_WEIGHT = 0.02


#: chi-square per row below which the rows fit a kernel (the row errors are estimated
#: generously, so a consistent fit gives well under 1)
_CHI2_CONSISTENT = 4.0
#: weight of the latest clean step in the running mean square of the prediction errors
_SCATTER_WEIGHT = 0.3
#: part of a row's impulse taken as the error of its structural baseline from the structures'
#: reaction to the force itself, which the clean stretch before the edge cannot show
_REACTION = 0.01
#: energy the hand-over's timing may have given the host before it is taken back, as a part of
#: the impact's kinetic energy m v_imp^2 (rule 7 of ImpactResolver)
_DEBT_TOLERANCE = 1e-4


def _padded(w) -> tuple[float, ...]:
    return (tuple(w) + (0.0,) * _KERNEL_TAPS)[:_KERNEL_TAPS]
#: mean delivery delay [steps] assumed before the first impact has shown the host's: that of a
#: zero-order hold in Gauss-Seidel order.  Any other guess costs more than it saves: handing the
#: first impulse over a step early to a Gauss-Seidel host stops its bodies before they touch
_ASSUMED_LEAD = 0.0


def _hht_kernel(alpha: float, late: bool) -> tuple[float, ...]:
    """Delivery kernel of an HHT-alpha host (alpha = 0: Newmark average acceleration) that takes
    our F as its load at the step end: ``v += h ((1 - g) a_n + g a_(n+1))`` with
    ``M a_(n+1) = (1 + alpha) p_(n+1) - alpha p_n``, ``g = 1/2 - alpha``; ``late``: one step late."""
    g = 0.5 - alpha
    w = (g * (1.0 + alpha), (1.0 - g) * (1.0 + alpha) - g * alpha, -(1.0 - g) * alpha)
    w = w[:2] if alpha == 0.0 else w
    return ((0.0,) + w) if late else w


def _mean_delay(w) -> float:
    """Mean delay of a kernel, in steps (0: the impulse reaches the host in its own step)."""
    return sum(j * x for j, x in enumerate(w))


#: kernels of the structural integrators in use: zero-order hold, symplectic Euler and velocity
#: Verlet (1); Newmark average acceleration (1/2, 1/2); HHT-alpha; each also one step late
_STANDARD_KERNELS = tuple(
    kernel for late in (False, True)
    for kernel in ((((0.0, 1.0) if late else (1.0,)),)
                   + tuple(_hht_kernel(a, late) for a in (0.0, -0.05, -0.1, -0.15, -0.2, -0.25, -0.3, -1.0 / 3.0))))


#: what a host may declare about itself (``pounding.fmu`` parameter ``host``): its delivery
#: kernel, and whether its positions are exact for a force held over the step (then they are
#: learnt from too, as the structures' displacement over the step).  ``any``: nothing declared,
#: the kernel is identified from the host's response to the first impact.
HOSTS = {
    "any": None,
    "zoh": ((1.0,), True),              # exact for a held force, Gauss-Seidel order (building.fmu)
    "zoh_late": ((0.0, 1.0), True),     # the same one step late: Jacobi order (libcosim)
    "trapezoidal": ((0.5, 0.5), False),           # Newmark average acceleration, F as load at the step end
    "trapezoidal_late": ((0.0, 0.5, 0.5), False),  # the same, Jacobi order
}


class HostObserver:
    """What the host does with our force, and the structures' own relative acceleration.

    Over its step ``k`` every consistent host changes the relative velocity by

        ``dV_k = A_k - h_k sum_j w_j F_(k-j) / m``

    ``A_k``: the structures' contribution (storey springs, dampers, other contacts, as the host
    integrates them); ``w``: the host's *delivery kernel* of our mean forces ``F``, with
    ``sum w = 1`` (momentum).  Exact zero-order hold, symplectic Euler, velocity Verlet in
    Gauss-Seidel order: ``w = (1)``; the same in Jacobi order: ``(0, 1)``; Newmark average
    acceleration holding ``F`` as its load at the step end: ``(1/2, 1/2)``; HHT-alpha: three
    taps (:func:`_hht_kernel`).  Position increments depend on the host's integrator and are
    never used.

    * ``A_k`` is *clean* -- free of our force -- when no force of ours can reach the observed
      step (the last ``support`` forces are zero) or when ``w`` is known.  The structural
      acceleration over the next step is the linear extrapolation of the last two clean
      means; the difference between a clean increment and the one assumed is returned as
      the correction of the resolver's own state.
    * ``w`` is identified once, at the first contact *edge* that says it clearly.  After a
      clean stretch the structural increments are extrapolated; the host's departures from
      that extrapolation over the steps that follow our first force are the impulses it
      delivered, ``h_k sum_j w_j F_(k-j)``: weighted least squares, each row weighted by the
      scatter of the clean one-step predictions grown with the horizon.  Accepted as any
      kernel when every weight is known to 0.01 (fine steps, free masses), or as one of the
      standard hosts' kernels when it fits and excludes, by 5 sigma, every standard kernel
      that times the impulse differently.  A sum of weights off 1 by more than 5 % marks the
      host inconsistent (logged once): safe mode.
    * While the kernel is unknown (and in safe mode) a step whose increment may hold our force
      is not learnt from: the structural acceleration is held at the value it had reached.
      Bodies that showed no structural motion before are then exactly right (free masses);
      others drift from the host by what the structures do that the hold misses, without
      feedback, until the edge is decided.  The hand-over is timed meanwhile for the latest
      standard host the rows do not exclude (:meth:`_identify`).

    Plain numbers and tuples only: ``copy.deepcopy`` saves it with the FMU state.
    """

    def __init__(self, m: float, extrapolate: bool = True, host: str = "any"):
        if host not in HOSTS:
            raise ValueError(f"host = {host!r} is not allowed: one of {', '.join(HOSTS)}")
        self.m = m
        self.extrapolate = extrapolate
        declared = HOSTS[host]
        self.exact_positions = bool(declared and declared[1])   # positions learnt from too
        self.last = None            # (delta [m], delta_dot [m/s], h [s]) of the host at the last step start
        self.forces = ()            # our mean forces [N] of the latest steps, latest first
        self.means = ()             # clean structural mean accelerations [m/s^2], latest first
        self.spans = ()             # their step sizes [s]
        self.scatter = 0.0          # (m/s)^2, mean square error of the one-step prediction of clean increments
        self.kernel = None          # delivery weights w_0, w_1, ... (declared or identified)
        self.support = _KERNEL_TAPS # steps over which one step's force reaches the host (the kernel's length)
        self.lead = _ASSUMED_LEAD   # steps, mean delay of the host's delivery: the kernel's, or assumed
        self.quiet_steps = _KERNEL_TAPS  # steps since our last nonzero force
        self.inconsistent = False   # clear evidence that the host does not conserve momentum
        self.provisional = _STANDARD_KERNELS[0]  # the standard kernel the edges so far fit best
        self.provisional_lead = None  # steps, its mean delay (None: nothing measured yet)
        if declared:
            self._set_kernel(declared[0])
        self.a0 = 0.0               # m/s^2, structural relative acceleration at the step start
        self.a1 = 0.0               # m/s^3, its rate over the step
        self.predicted = 0.0        # m/s, structural rate change assumed over the last step
        self.predicted_position = 0.0  # m, and the displacement, from rest
        self.rows = ()              # rows of the current edge: (x, r, sigma, dV, used, t_mid, h)
        self.edge_given_up = False  # the current edge gave no clear answer
        self.clock = 0.0            # s, start of the observed step from the start of the edge
        self.baseline = (0.0, 0.0)  # (m/s^2, m/s^3) structural acceleration extrapolated over the edge
        self.internal = 0.0         # N s, impulse the resolver's own bodies received in the last step
        self.timing = 0.0           # N s, impulse delivered to the host minus received internally, this episode
        self.debt = 0.0             # J, energy the hand-over's timing gave the host this episode (_book_timing)
        self.notices = []           # messages for the FMU log (drained by the adapter)

    def _set_kernel(self, kernel) -> None:
        self.kernel = kernel
        self.support = len(kernel) if kernel is not None else _KERNEL_TAPS
        self.lead = _mean_delay(kernel) if kernel is not None else \
            (self.provisional_lead if self.provisional_lead is not None else _ASSUMED_LEAD)

    def pending(self) -> bool:
        """True if part of an impulse we handed over may not have reached the host yet."""
        return self.quiet_steps < self.support - 1

    def structural_rate(self, r: float) -> float:
        """Rate change [m/s] the structures give over the first ``r`` s of the current step."""
        return self.a0 * r + 0.5 * self.a1 * r * r

    def observe(self, delta: float, delta_dot: float, h: float) -> tuple[float, float]:
        """Take the host's state at a step start; returns the correction (m, m/s) of the
        structural motion assumed over the last step, and predicts the next step."""
        cx = cu = 0.0
        held = False
        if self.last is not None:
            D, V, hp = self.last
            dV = delta_dot - V
            quiet = self.quiet_steps >= self.support
            hits = self.forces[:self.support]
            delivered = 0.0
            if quiet:
                clean = dV
                self.rows, self.edge_given_up = (), False
                if self.internal == 0.0:        # the episode is over
                    self.timing = self.debt = 0.0
            elif self.kernel is not None:
                delivered = self._delivered(self.kernel, hits, hp)
                clean = dV + delivered
                self._book_timing(delivered * self.m, self.internal, clean)
            else:
                clean = None
                verdict = None if self.inconsistent else self._edge(dV, hp, hits)
                if verdict is not None:
                    cx, cu = verdict
            if clean is not None:
                du = clean - self.predicted
                if self.exact_positions:
                    # the host's displacement over the step, minus what the delivered impulse
                    # held over it does from rest: the structures' own
                    moved = delta - D - V * hp + 0.5 * delivered * hp
                    cx, cu = cx + moved - self.predicted_position, cu + du
                    self._learn_step(clean, moved, hp)
                else:
                    cx, cu = cx + 0.5 * du * hp, cu + du
                    self._learn(clean / hp, hp)
                if quiet and self.means:
                    self.scatter += _SCATTER_WEIGHT * (du * du - self.scatter)
            held = clean is None
        if not (self.exact_positions and not held and self.last is not None):
            self._predict(held)
        self.last = (delta, delta_dot, h)
        return cx, cu

    def record(self, F: float, h: float, internal: float) -> None:
        """Book our mean force [N] of the step just taken, the impulse [N s] the resolver's own
        bodies received in it, and what the structures were assumed to do."""
        self.forces = (F,) + self.forces[:_KERNEL_TAPS - 1]
        self.quiet_steps = self.quiet_steps + 1 if F == 0.0 else 0
        self.internal = internal
        self.predicted = self.structural_rate(h)
        self.predicted_position = 0.5 * self.a0 * h * h + self.a1 * h * h * h / 6.0

    def _book_timing(self, delivered: float, internal: float, clean: float) -> None:
        """Energy the hand-over's timing gave the host over one observed step (rule 7).

        With ``C`` the impulse delivered to the host minus the impulse the resolver's own bodies
        received, cumulated, the host's relative velocity is the resolver's minus ``C / m``, so
        the contact's work on the host exceeds its work on the resolver's bodies by
        ``int C A dt`` over an episode (``A`` the structures' acceleration): zero for free
        masses, zero for a hand-over on time, positive (energy created) for a late one while the
        structures pull the bodies apart.  ``clean`` is ``A`` integrated over the step."""
        C = self.timing + delivered - internal
        self.debt += 0.5 * (self.timing + C) * clean
        self.timing = C

    # -- learning ---------------------------------------------------------------------------------
    def _delivered(self, kernel, hits, hp: float) -> float:
        """Rate change [m/s] the host gave our forces ``hits`` (latest first) over a step ``hp``."""
        return hp * sum(w * F for w, F in zip(kernel, hits)) / self.m

    def _learn(self, a: float, h: float) -> None:
        self.means = ((a,) + self.means)[:2]
        self.spans = ((h,) + self.spans)[:2]

    def _learn_step(self, rate: float, moved: float, h: float) -> None:
        """Exact positions: the linear acceleration that reproduces both structural increments
        of the last step (rate [m/s], displacement [m]), continued over the next one."""
        self._learn(rate / h, h)
        if self.extrapolate:
            b1 = 12.0 * (0.5 * rate * h - moved) / (h * h * h)
            self.a0, self.a1 = rate / h + 0.5 * b1 * h, b1
        else:
            self.a0, self.a1 = rate / h, 0.0

    def _predict(self, held: bool) -> None:
        if held:                    # nothing learnt: hold the acceleration reached
            self.a0 += self.a1 * self.last[2]
            self.a1 = 0.0
        elif not self.means:
            self.a0 = self.a1 = 0.0
        elif len(self.means) == 1 or not self.extrapolate:
            self.a0, self.a1 = self.means[0], 0.0
        else:
            slope = (self.means[0] - self.means[1]) / (0.5 * (self.spans[0] + self.spans[1]))
            self.a0 = self.means[0] + 0.5 * slope * self.spans[0]
            self.a1 = slope

    def _edge(self, dV: float, hp: float, hits):
        """One step of an edge while the kernel is unknown: a row of its least-squares problem.

        Returns the kernel's verdict, the correction (cx, cu) of the edge's steps, or None."""
        if self.edge_given_up:
            return None
        if not self.rows:
            # the edge starts with the observed step: its structural motion is measured
            # against the extrapolation of the clean increments before it, a line in time
            self.clock = 0.0
            self.baseline = (self.a0, self.a1)
        b0, b1 = self.baseline
        P = b0 * hp + b1 * (self.clock * hp + 0.5 * hp * hp)
        x = tuple(hp * F for F in (hits + (0.0,) * _KERNEL_TAPS)[:_KERNEL_TAPS])
        r = (P - dV) * self.m                   # N s: the impulse the host delivered, if A = P
        # error of the extrapolated structural increment: the RMS of the one-step
        # predictions of the clean increments before the edge, grown with the horizon as
        # a linear extrapolation's error does, (j + 1)(j + 2) / 2 after j steps;
        # plus the structures' reaction to the force itself, taken as 1 % of the row's
        # impulses; plus the round-off of the increments
        j = self.clock / hp
        scale = max(abs(v) for v in x)
        sigma = self.m * math.sqrt(self.scatter) * 0.5 * (j + 1.0) * (j + 2.0) \
            + _REACTION * scale + 1e-12 * (scale + (abs(dV) + abs(P)) * self.m)
        self.rows = self.rows + ((x, r, sigma, dV, self.predicted, self.clock + 0.5 * hp, hp, self.internal),)
        self.clock += hp
        verdict = self._identify()
        if verdict is None and self.rows:
            self._book_edge(_padded(self.provisional))
        return verdict

    def _book_edge(self, kernel) -> None:
        """Book the hand-over's timing over the edge's rows as ``kernel`` delivers them."""
        self.timing = self.debt = 0.0
        for x, _, _, dV, _, _, _, internal in self.rows:
            delivered = sum(wj * xj for wj, xj in zip(kernel, x))
            self._book_timing(delivered, internal, dV + delivered / self.m)

    def _identify(self):
        """Decide the kernel from the edge's rows if they say it clearly (class docstring);
        returns the correction (cx, cu) of the edge's steps when decided, else None."""
        rows = self.rows
        X = np.array([row[0] for row in rows])
        s = np.array([row[2] for row in rows])
        Xw = X / s[:, None]
        rw = np.array([row[1] for row in rows]) / s
        # 1. any kernel, if the rows pin every weight down to 0.01
        if len(rows) > _KERNEL_TAPS:
            normal = Xw.T @ Xw
            if np.linalg.cond(normal) < 1e14:
                w = np.linalg.solve(normal, Xw.T @ rw)
                cov = np.linalg.inv(normal)
                se = np.sqrt(np.abs(np.diag(cov)))
                chi2 = float(np.sum((Xw @ w - rw) ** 2)) / (len(rows) - _KERNEL_TAPS)
                if se.max() < _WEIGHT_STANDARD_ERROR and chi2 < _CHI2_CONSISTENT:
                    return self._accept(w)
                # the delivered total alone can be clear before every weight is: a host that
                # delivers a wrong impulse is named as soon as its sum is off by 5 sigma
                off = abs(float(w.sum()) - 1.0)
                if chi2 < _CHI2_CONSISTENT and off > max(_MOMENTUM_TOLERANCE, 5.0 * math.sqrt(abs(cov.sum()))):
                    return self._accept(w)
        # 2. one of the standard hosts, if it fits and every host that times the impulse
        #    differently (mean delay off by more than 0.1 step) is excluded by 5 sigma
        chi2 = {w: float(np.sum((Xw @ np.array(_padded(w)) - rw) ** 2)) for w in _STANDARD_KERNELS}
        best = min(chi2, key=chi2.get)
        fits = chi2[best] < _CHI2_CONSISTENT * len(rows)
        # ... once every tap of it has been seen (one row fits (1/2, 1/2) and a host that
        # delivers half the impulse alike)
        if fits and len(best) <= len(rows) and all(chi2[w] - chi2[best] > 25.0 for w in _STANDARD_KERNELS
                                                    if abs(_mean_delay(w) - _mean_delay(best)) > 0.1):
            return self._accept(np.array(_padded(best)))
        if fits:
            # meanwhile, time the hand-over for the earliest standard host the rows do not
            # exclude: a hand-over a step early to a Gauss-Seidel host stops its bodies before
            # they touch, which costs far more than a late one to a Jacobi host
            self.provisional, self.provisional_lead = best, _mean_delay(best)
            self._set_kernel(None)
        if len(rows) >= _MAX_EDGE_ROWS or not any(F != 0.0 for F in self.forces[:_KERNEL_TAPS - 1]):
            self.edge_given_up = True
            self.rows = ()
        return None

    def _accept(self, w):
        """Book a kernel; returns the correction (cx, cu) of what the edge's steps assumed."""
        rows, self.rows = self.rows, ()
        total = float(w.sum())
        if abs(total - 1.0) > _MOMENTUM_TOLERANCE:
            self.inconsistent = True
            self.notices.append(
                f"the host delivers {total:.3g} times the impulse of F (delivery weights "
                f"{', '.join(f'{x:.3g}' for x in w)}); a consistent host delivers it once "
                f"(allowed: |sum - 1| <= {_MOMENTUM_TOLERANCE:g}). Check that F acts on body 2 along +x "
                f"and on body 1 along -x, and that m1, m2 are the masses the host moves. Safe mode: the "
                f"structures' motion is no longer learnt while an impulse is on its way")
            return 0.0, 0.0
        w = np.where(np.abs(w) < _NEGLIGIBLE_WEIGHT, 0.0, w)
        w = w / w.sum()
        self._set_kernel(tuple(float(x) for x in w[:int(np.flatnonzero(w)[-1]) + 1]))
        # the edge's structural increments, now clean: learn them, correct what was assumed
        self.timing = self.debt = 0.0
        cx = cu = 0.0
        for x, _, _, dV, used, t_mid, hp, internal in rows:
            delivered = sum(wj * xj for wj, xj in zip(self.kernel, x))
            clean = dV + delivered / self.m
            self._book_timing(delivered, internal, clean)
            cu += clean - used
            cx += (clean - used) * (self.clock - t_mid)
            self._learn(clean / hp, hp)
        return cx, cu


class ImpactResolver:
    """Locate and integrate impacts inside a communication step, at the impact's own time scale.

    The host supplies ``delta`` [m] and ``delta_dot`` [m/s] at the start of each step and applies
    the returned mean force over the step.  Inside the step the relative motion obeys
    ``delta_ddot = a_ext(s) - F / m``: the contact force on the effective mass plus the
    *external* relative acceleration ``a_ext`` of the structures the bodies belong to (storey
    springs and dampers; zero for free masses).  Rules (docs/contact_models.md, "in-step rules"):

    1. *Following the host* (:class:`HostObserver`).  ``a_ext`` is learnt from the host's
       velocity increments only, once our own force is taken out of them with the host's
       identified delivery kernel (or when none of our force can be in them), and extrapolated
       linearly over the next step.  Position increments, which depend on the host's
       integrator, are never learnt from.
    2. *Whose state.*  Out of contact, once every impulse handed over has reached the host, the
       host's state is the truth (rule 4 for a residual overlap).  Through a contact and until
       its impulse has reached the host, the resolver's own state is: it is corrected only by
       the difference between the clean structural increment and the one assumed.  For free
       masses that difference is zero whatever the host integrator, so an impact of free
       masses is exact at any step.
    3. *Onset*: out of contact, a new impact starts where the prediction
       ``delta_eff + delta_dot s + int int a_ext`` crosses zero while approaching.
       A step that starts overlapping (a crossing the prediction missed) moves the overlap
       into ``offset``; the impact starts at once if the bodies approach.
    4. *During contact* the impact is integrated (Dormand-Prince 5(4), scaled by
       ``L = (m v^2/k)^(1/(n+1))`` and ``T = L / v``) with located events at maximum
       penetration (``delta_dot = 0``), re-approach (``delta_dot`` rising again while loaded,
       the structure pushing back: same impact), stick (a push between the two branches of a
       law whose force drops at ``delta_dot = 0``: held, :meth:`_stick`) and separation (``delta = 0``, or the raw
       force reaching zero for laws with a dashpot in restitution); it may straddle any number
       of steps, and several impacts may occur in one step.
    5. *After separation* the host, moved by a held mean force, may still overlap while
       separating.  Such an apparent overlap is kept as ``offset`` (>= 0, cleared once the
       host's ``delta <= 0``); a force separation with ``delta > 0`` moves the remaining
       overlap into the offset as well.
    6. *Impulse and energy*: the impulse is ``int F dt`` of the internal force history,
       ``mean_force = impulse / h``.  ``E_dissipated`` is the work of the dissipative part of the
       force, ``int (F - k delta^n) delta_dot dt`` >= 0, integrated along the internal trajectory
       (plus, at a force separation, the elastic energy left in the overlap): it never decreases,
       and it does not depend on how the host holds the force, so the host's energy balance
       shows the coupling error instead of hiding it.

    ``follow_host=False`` restores the free-mass model (``a_ext = 0``, no corrections).
    The instance holds only plain numbers, so ``copy.deepcopy`` saves its state.
    """

    def __init__(self, law: ContactLaw, rtol: float = 1e-8, follow_host: bool = True,
                 extrapolate: bool = True, host: str = "any"):
        self.law = law
        self.rtol = rtol
        self.follow_host = follow_host
        self.observer = HostObserver(law.m, extrapolate, host)
        self._kernels = {True: _scaled_kernel(law.model, law.zeta, law.n, True),
                         False: _scaled_kernel(law.model, law.zeta, law.n, False)}
        self._separations = (_scaled_separation(law), _scaled_separation_pulled(law))
        self._separation = self._separations[0]
        self.in_contact = False
        self.approaching = False
        self.sticking = False       # held at delta_dot = 0 between the law's two branches (rule 4)
        self.v_imp = 0.0            # latched approach speed of the latest impact, m/s
        self.d = 0.0                # internal scaled penetration (in contact)
        self.u = 0.0                # internal scaled rate (in contact)
        self.e = 0.0                # scaled energy dissipated by the current impact (unit m v_imp^2)
        self.e_top = 0.0            # largest e - margin so far (reported while in contact: never decreases)
        self.offset = 0.0           # m, apparent overlap left by a resolved impact
        self.delta_end = 0.0        # m, internal penetration at the end of the last step
        self.delta_dot_end = 0.0    # m/s
        self.started = False        # a step has been taken
        self.ahead = 0.0            # N s, impulse handed over ahead of the internal trajectory (rule 7)
        self.just_separated = False
        self.dtau = 1e-3            # next internal step, scaled
        self.a0 = 0.0               # m/s^2, external relative acceleration at the step start
        self.a1 = 0.0               # m/s^3, its rate over the step
        self.correction = (0.0, 0.0)  # (m, m/s) last correction applied to the internal state
        self.impacts = 0
        self.E_completed = 0.0      # J, all completed impacts
        self.F_max = 0.0            # N
        self.impact_peak = 0.0      # N, current/latest impact
        self.impact_time = 0.0      # s, elapsed contact time of current/latest impact
        self.delta_max = 0.0        # m, current/latest impact
        self.last_CR = math.nan     # achieved CR of the latest completed impact
        self.last_E = 0.0           # J dissipated by the latest completed impact
        self._prev = ()             # last two force samples for peak interpolation
        self._sep = (0.0, 0.0)      # (m, m/s) state at the latest separation, shifted to delta <= 0

    # -- derived outputs -------------------------------------------------------------------
    def _scales(self):
        v = self.v_imp
        L = self.law.length_scale(v)
        return v, L, L / v, self.law.m * v * v / L

    def dissipated_energy(self) -> float:
        """Energy dissipated by all impacts so far, the current one up to now [J]; never decreases."""
        if not self.in_contact:
            return self.E_completed
        # same floating-point expression as in _finish: the total cannot drop by a rounding
        return self.E_completed + self.law.m * self.v_imp * self.v_imp * self.e_top

    # -- external acceleration -------------------------------------------------------------
    def _ext_rate(self, t: float, r: float) -> float:
        """Rate change [m/s] from the external acceleration over [t, t + r] of the step."""
        return self.a0 * r + self.a1 * (t * r + 0.5 * r * r)

    def _ext_position(self, t: float, r: float) -> float:
        """Position change [m] from the external acceleration over [t, t + r], from rest."""
        return 0.5 * self.a0 * r * r + self.a1 * (0.5 * t * r * r + r * r * r / 6.0)

    def _follow(self, delta: float, delta_dot: float, h: float) -> None:
        """Rule 1-2: learn the structures' motion, correct the resolver's own state by the
        difference between the clean structural increment and the one assumed."""
        if not self.follow_host:
            self.a0 = self.a1 = 0.0
            return
        cx, cu = (float(c) for c in self.observer.observe(delta, delta_dot, h))
        self.a0, self.a1 = float(self.observer.a0), float(self.observer.a1)
        self.correction = (cx, cu)
        if cx == 0.0 and cu == 0.0:
            return
        if self.in_contact:
            v, L = self.v_imp, self.law.length_scale(self.v_imp)
            self.d += cx / L
            self.u += cu / v
        self.delta_end += cx
        self.delta_dot_end += cu

    # -- one communication step ------------------------------------------------------------
    def step(self, delta: float, delta_dot: float, h: float) -> StepOutcome:
        """Advance over ``h`` [s] from the host's ``delta`` [m], ``delta_dot`` [m/s] at the step start."""
        if not (h > 0.0 and math.isfinite(h)):
            raise ValueError(f"communication step h = {h!r} s is outside the allowed range h > 0")
        out = StepOutcome()
        delta, delta_dot = float(delta), float(delta_dot)
        self._follow(delta, delta_dot, h)
        d0, v0 = (0.0, 0.0) if self.in_contact else self._flight_start(delta, delta_dot)
        self._advance(0.0, h, d0, v0, out)
        # the force law is compressive; a quadrature of a force that fades to zero at
        # separation can sum to -1e-29 N s, which must not reach the host as tension
        internal = max(out.impulse, 0.0)
        lead = self.observer.lead if self.follow_host else 0.0
        if lead > 0.0 or self.ahead != 0.0 or (self.follow_host and self.observer.debt > 0.0):
            out.impulse, internal = self._hand_over(internal, lead, h)
        else:
            out.impulse = internal
        out.mean_force = out.impulse / h
        if self.follow_host:
            self.observer.record(out.mean_force, h, internal)
        self.started = True
        return out

    def _probe(self, h: float, span: float) -> float:
        """Impulse [N s] the resolver's own bodies will receive over ``span`` s after this step."""
        probe = copy.copy(self)
        out = StepOutcome()
        probe._advance(h, h + span, probe.delta_end, probe.delta_dot_end, out)
        return max(out.impulse, 0.0)

    def _hand_over(self, internal: float, lead: float, h: float) -> tuple[float, float]:
        """Rule 7: the impulse [N s] to hand over this step, and the internal one to book.

        The host delivers our force ``lead`` steps late on average: hand it over that much
        early, so that it reaches the host's structures when it acts on the resolver's own
        bodies (``ahead`` keeps the difference; momentum is exact over an episode).  While the
        timing has given the host energy (the host's kernel was not yet known), hand over
        early or late by the step that takes it back: ``int C A dt`` (HostObserver._book_timing)
        changes by ``dJ A h`` when ``dJ`` is handed over one step early.
        """
        target = self._probe(h, lead * h) if lead > 0.0 else 0.0
        debt = self.observer.debt
        a_next = self.a0 + self.a1 * h
        if debt > _DEBT_TOLERANCE * self.law.m * self.v_imp * self.v_imp and a_next != 0.0 \
                and (self.in_contact or target > 0.0):
            shift = -debt / (a_next * h)
            if shift > 0.0:                       # early: at most the next step's impulse
                shift = min(shift, self._probe(h, (lead + 1.0) * h) - target)
            target += shift
        emitted = max(internal + target - self.ahead, 0.0)
        self.ahead += emitted - internal
        if not self.in_contact and target <= 0.0 and self.ahead > 0.0:
            # handed over for an impact the resolver's own motion did not make after all:
            # the host has it, so the bodies have it (momentum)
            self.delta_dot_end -= self.ahead / self.law.m
            internal += self.ahead
            self.ahead = 0.0
        return emitted, internal

    def _advance(self, t: float, t_end: float, d0: float, v0: float, out: StepOutcome) -> None:
        """Flight and impacts from ``t`` to ``t_end`` [s] into the step (d0, v0: flight state at t)."""
        for _ in range(_MAX_IMPACTS_PER_STEP):
            if self.in_contact:
                t = self._integrate(t, t_end, out)
                if self.in_contact:
                    return
                d0, v0 = self._sep
            s = self._onset(d0, v0, t, t_end - t)
            if s is None:
                r = t_end - t
                self.delta_end = d0 + v0 * r + self._ext_position(t, r)
                self.delta_dot_end = v0 + self._ext_rate(t, r)
                return
            v_on = v0 + self._ext_rate(t, s)
            t += s
            self._start(v_on)
            out.impacts_started += 1

    def _flight_start(self, delta: float, delta_dot: float):
        """Internal (penetration, rate) out of contact at the step start; sets ``offset`` (rule 5)."""
        if self.follow_host and self.started and self.observer.pending():
            # part of an impulse is still on its way to the host: the resolver's own flight
            d0, v0 = self.delta_end, self.delta_dot_end
            self.offset = max(0.0, delta - d0) if delta > 0.0 else 0.0
            if d0 > 0.0:
                self.offset, d0 = self.offset + d0, 0.0
            return d0, v0
        if self.follow_host and self.started:
            inner = self.delta_end               # internal flight, predicted over the last step
        else:
            inner = self.delta_end if self.just_separated else delta - self.offset
        self.just_separated = False
        v0 = delta_dot
        offset = delta - inner
        if delta <= 0.0 or offset < 0.0:         # host open, or the host is behind the internal state
            offset = 0.0
        d0 = delta - offset
        if d0 > 0.0:                             # overlap the prediction missed: into the offset
            offset += d0
            d0 = 0.0
        self.offset = offset
        return d0, v0

    def _onset(self, d0: float, v0: float, t: float, r: float):
        """First time in (0, r] [s] at which the flight ``d0 + v0 s + ext`` crosses 0 upward, or None."""
        if not r > 0.0:
            return None
        a0, a1 = self.a0 + self.a1 * t, self.a1

        def g(s):
            return d0 + v0 * s + 0.5 * a0 * s * s + a1 * s * s * s / 6.0

        # monotone pieces between the zeros of g' = v0 + a0 s + a1 s^2 / 2
        cuts = [0.0, r]
        if a1 != 0.0:
            disc = a0 * a0 - 2.0 * a1 * v0
            if disc >= 0.0:
                q = math.sqrt(disc)
                cuts += [(-a0 + q) / a1, (-a0 - q) / a1]
        elif a0 != 0.0:
            cuts.append(-v0 / a0)
        cuts = sorted(c for c in cuts if 0.0 <= c <= r)
        g_lo = d0
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            g_hi = g(hi)
            if g_lo <= 0.0 < g_hi:
                if g_lo == 0.0:
                    return lo
                return brentq(g, lo, hi, xtol=1e-15 * r, rtol=1e-15)
            g_lo = g_hi
        return None

    def _start(self, v: float) -> None:
        self.in_contact = True
        self.approaching = True
        self.sticking = False
        self.v_imp = max(v, MIN_IMPACT_SPEED)
        self.d, self.u, self.e, self.e_top = 0.0, 1.0, 0.0, 0.0
        self.impacts += 1
        self.impact_peak = 0.0
        self.impact_time = 0.0
        self.delta_max = 0.0
        self._prev = ()
        self.dtau = 1e-3

    def _finish(self, d: float, u: float, L: float, v: float) -> None:
        """Book a completed impact that separated at scaled (d, u)."""
        n, m = self.law.n, self.law.m
        # a force separation with d > 0 leaves the spring energy of the overlap behind: lost
        e = max(self.e_top, self.e) + (d ** (n + 1.0) / (n + 1.0) if d > 0.0 else 0.0)
        self.in_contact = False
        self.just_separated = True
        self.last_CR = max(0.0, -u)
        self.last_E = m * self.v_imp * self.v_imp * e
        self.E_completed += self.last_E
        self._sep = (min(d, 0.0) * L, u * v)   # the overlap at a force separation goes to the offset

    def _integrate(self, t: float, h: float, out: StepOutcome) -> float:
        """Integrate the current impact from ``t`` [s] into the step; returns the time reached."""
        v, L, T, F0 = self._scales()
        m = self.law.m
        # external acceleration in scaled units: alpha(tau) = al0 + al1 tau from time t
        al0 = (self.a0 + self.a1 * t) * T / v
        al1 = self.a1 * T * T / v
        tau = 0.0
        tau_end = (h - t) / T
        # 1e-10: a pull below 1e-10 of the impact's force scale cannot clip the force before
        # round-off in 1 + zeta u does (see _scaled_separation_pulled)
        self._separation = self._separations[1 if min(al0, al0 + al1 * tau_end) < -1e-10 else 0]
        u_ref = self.u                            # impulse = m (ext rate change - internal rate change)
        d, u = self.d, self.u
        # branch consistent with the (possibly corrected) state
        if self.sticking:
            u = 0.0                               # held: a correction of the rate goes into the force
        elif self.approaching and u <= 0.0:
            self._switch_to_restitution(d, u, L)
        elif not self.approaching and u > _REAPPROACH_RATE:
            self.approaching = True
        f = self._kernels[self.approaching]
        if not self.approaching and self._separation(d, u) <= 0.0:
            self._finish(d, u, L, v)
            out.impacts_completed += 1
            return t
        fs, p = f(d, u)
        acc = al0 - fs
        nfev = 1
        base = self.impact_time / T               # scaled contact time at the step start
        if not self._prev:
            nfev += self._sample(base, fs, d, u, acc, al0, al1, self.approaching, out, F0)
        atol = rtol = self.rtol
        dtau = self.dtau
        e, e_top = self.e, self.e_top
        # the identity drifts by the integration error (~rtol) where the true power is 0: the
        # reported value trails it by this margin, so that booking the completed impact's own
        # value (exact for free masses) never lowers the total
        margin = 10.0 * self.rtol
        separated = False
        switches = 0
        while tau < tau_end * (1.0 - 1e-15):
            if self.sticking:
                tau = self._stick(d, al0, al1, tau, tau_end, base, out, F0)
                if self.sticking:
                    break
                f = self._kernels[self.approaching]
                fs, p = f(d, 0.0)
                acc = al0 + al1 * tau - fs
                continue
            hs = min(dtau, tau_end - tau)
            last = hs >= tau_end - tau
            al_t = al0 + al1 * tau
            d1, u1, acc1, f1, p1, de, err = self._dp_step(f, al_t, al1, d, u, acc, p, hs, atol, rtol)
            nfev += 6
            if err > 1.0:
                dtau = hs * max(0.2, 0.9 * err ** -0.2)
                continue
            out.substeps += 1
            event = None
            if self.approaching:
                if u1 <= 0.0:
                    event = "max_penetration"
            else:
                if self._separation(d1, u1) <= 0.0:
                    event = "separation"
                if u1 > _REAPPROACH_RATE and switches < _MAX_SWITCHES_PER_STEP:
                    event = "reapproach" if event is None else self._first_event(
                        f, al_t, al1, d, u, acc, p, hs, atol, rtol)
            if event is not None:
                switches += 1
                g = self._event_function(event)
                hs, d1, u1, _, _, _, _, n_ev = self._locate(f, al_t, al1, d, u, acc, p, hs, g, atol, rtol)
                nfev += n_ev
                tau += hs
                e += self._dissipated(d, u, d1, u1, al_t, al1, hs)
                e_top = e - margin if e - margin > e_top else e_top
                d, u = d1, u1
                if event == "separation":
                    separated = True
                    break
                self.e, self.e_top = e, e_top
                if event == "max_penetration":
                    u = 0.0
                    f_end = f(d, 0.0)[0]
                    nfev += self._sample(base + tau, f_end, d, u, al0 + al1 * tau - f_end, al0 + al1 * tau, al1,
                                         True, out, F0, branch_end=True)
                    self._switch_to_restitution(d, u, L)
                    self.sticking = self._holds(d, al0 + al1 * tau)
                else:                                     # re-approach: the dashpot acts again ...
                    self.approaching = True
                    if self._holds(d, al0 + al1 * tau):   # ... unless its force would push back at once
                        self.approaching, self.sticking, u = False, True, 0.0
                if self.sticking:
                    continue
                f = self._kernels[self.approaching]
                fs, p = f(d, u)
                acc = al0 + al1 * tau - fs
                nfev += 1 + self._sample(base + tau, fs, d, u, acc, al0 + al1 * tau, al1, self.approaching,
                                         out, F0)
                dtau = hs if hs > 0.0 else dtau
                continue
            tau += hs
            e += self._dissipated(d, u, d1, u1, al_t, al1, hs)
            e_top = e - margin if e - margin > e_top else e_top
            d, u, acc, p = d1, u1, acc1, p1
            nfev += self._sample(base + tau, f1, d, u, acc, al0 + al1 * tau, al1, self.approaching, out, F0)
            if not last:
                dtau = hs * min(5.0, 0.9 * max(err, 1e-10) ** -0.2)
        self.dtau = dtau
        t_used = tau * T
        self.impact_time += t_used
        # impulse = m * (change of rate due to the external acceleration - change of the rate)
        out.impulse += m * (v * (u_ref - u) + self._ext_rate(t, t_used))
        out.nfev += nfev
        self.d, self.u, self.e, self.e_top = d, u, e, e_top
        if separated:
            self._finish(d, u, L, v)
            out.impacts_completed += 1
            return t + t_used
        self.delta_end = d * L
        self.delta_dot_end = u * v
        self.delta_max = max(self.delta_max, d * L)
        return h

    def _holds(self, d: float, alpha: float) -> bool:
        """True if the contact sticks at scaled penetration ``d`` under the scaled external
        acceleration ``alpha``: pushed together harder than the restitution branch holds at zero
        rate, less than the approach branch does (crvk's force drop).  Neither branch is then
        consistent; the solution is Filippov's sliding motion, as in cosim/reference.py."""
        f_approach = self._kernels[True](d, 0.0)[0]
        f_restitution = self._kernels[False](d, 0.0)[0]
        return f_restitution < alpha < f_approach

    def _stick(self, d, al0, al1, tau, tau_end, base, out, F0) -> float:
        """Hold the penetration from ``tau`` while ``alpha(s) = al0 + al1 s`` stays between the
        branches' forces at ``d``; returns where it leaves (into approach above the upper one,
        restitution below the lower one) or ``tau_end``.  The force is ``alpha``: no work, no
        dissipation; the impulse is the external rate change (_integrate's bookkeeping)."""
        upper = self._kernels[True](d, 0.0)[0]
        lower = self._kernels[False](d, 0.0)[0]
        end = tau_end
        if al1 > 0.0:
            end = min(end, (upper - al0) / al1)
        elif al1 < 0.0:
            end = min(end, (lower - al0) / al1)
        end = max(end, tau)
        for s in (tau, end):                      # the force is linear in time: peaks at the ends
            F = (al0 + al1 * s) * F0
            out.peak_force = max(out.peak_force, F)
            self.impact_peak = max(self.impact_peak, F)
            self.F_max = max(self.F_max, F)
        if end < tau_end:
            self.sticking = False
            self.approaching = al1 > 0.0
        self._prev = ()
        return end

    def _dissipated(self, d, u, d1, u1, al, al1, hs) -> float:
        """Scaled energy dissipated over one internal step from (d, u) to (d1, u1), length ``hs``.

        Energy identity of ``u' = alpha - f``: ``int f u = int alpha u - [u^2 / 2]``, minus the
        energy stored in the spring, ``[d^(n+1) / (n+1)]``.  With ``alpha = al + al1 s``,
        ``int alpha u = [alpha d] - al1 int d`` (``int d`` by the Hermite rule, exact to h^5).
        For free masses (alpha = 0) the sum over an impact telescopes to
        ``(1 - u_out^2) / 2``: the kinetic energy the host loses, to round-off.
        """
        n1 = self.law.n + 1.0
        s0 = d ** n1 / n1 if d > 0.0 else 0.0
        s1 = d1 ** n1 / n1 if d1 > 0.0 else 0.0
        work = 0.0
        if al != 0.0 or al1 != 0.0:
            work = (al + al1 * hs) * d1 - al * d - al1 * hs * (0.5 * (d + d1) + hs * (u - u1) / 12.0)
        return 0.5 * (u * u - u1 * u1) + (s0 - s1) + work

    def _switch_to_restitution(self, d: float, u: float, L: float) -> None:
        self.approaching = False
        self.delta_max = max(self.delta_max, d * L)

    def _event_function(self, event: str):
        if event == "max_penetration":
            return lambda dd, uu: uu
        if event == "reapproach":
            return lambda dd, uu: _REAPPROACH_RATE - uu
        return self._separation

    def _first_event(self, f, al_t, al1, d, u, acc, p, hs, atol, rtol) -> str:
        """Separation and re-approach both inside one step: the one located first."""
        t_sep = self._locate(f, al_t, al1, d, u, acc, p, hs, self._separation, atol, rtol)[0]
        t_re = self._locate(f, al_t, al1, d, u, acc, p, hs, self._event_function("reapproach"), atol, rtol)[0]
        return "separation" if t_sep <= t_re else "reapproach"

    def _sample(self, tau, fs, d, u, acc, al, al1, approaching, out, F0, branch_end=False) -> int:
        """Track the peak force at an accepted point; returns the force evaluations spent.

        A sampled local maximum (or a rise into the end of the approach branch) is refined
        by maximising the force along one Dormand-Prince step from the earlier sample
        (bounded Brent search), so the peak does not depend on where samples fall.
        """
        peak = fs
        nfev = 0
        prev = self._prev
        sample = (tau, fs, d, u, acc, approaching, al, al1)
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
        _, f0, d, u, acc, approaching, al, al1 = sample
        if not span > 0.0:
            return f0, 0
        f = self._kernels[approaching]
        rtol = self.rtol

        def minus_force(x):
            dx, ux = self._dp_step(f, al, al1, d, u, acc, 0.0, x, rtol, rtol)[:2]
            return -f(dx, ux)[0]

        res = minimize_scalar(minus_force, bounds=(0.0, span), method="bounded",
                              options={"xatol": 1e-7 * span})
        return -res.fun, 6 * res.nfev

    @staticmethod
    def _dp_step(f, al, al1, d, u, a1, p1, hs, atol, rtol):
        """One Dormand-Prince step of ``d' = u, u' = al + al1 s - f(d, u)`` with the dissipated
        energy ``e' = power``; returns (d, u, u', force, power, e increment, error norm)."""
        # stage states (d_i, u_i) and derivatives (u_i, a_i); p_i dissipative power
        d2 = d + hs * _A21 * u
        u2 = u + hs * _A21 * a1
        f2, _ = f(d2, u2)
        a2 = al + al1 * _C2 * hs - f2
        d3 = d + hs * (_A31 * u + _A32 * u2)
        u3 = u + hs * (_A31 * a1 + _A32 * a2)
        f3, p3 = f(d3, u3)
        a3 = al + al1 * _C3 * hs - f3
        d4 = d + hs * (_A41 * u + _A42 * u2 + _A43 * u3)
        u4 = u + hs * (_A41 * a1 + _A42 * a2 + _A43 * a3)
        f4, p4 = f(d4, u4)
        a4 = al + al1 * _C4 * hs - f4
        d5 = d + hs * (_A51 * u + _A52 * u2 + _A53 * u3 + _A54 * u4)
        u5 = u + hs * (_A51 * a1 + _A52 * a2 + _A53 * a3 + _A54 * a4)
        f5, p5 = f(d5, u5)
        a5 = al + al1 * _C5 * hs - f5
        d6 = d + hs * (_A61 * u + _A62 * u2 + _A63 * u3 + _A64 * u4 + _A65 * u5)
        u6 = u + hs * (_A61 * a1 + _A62 * a2 + _A63 * a3 + _A64 * a4 + _A65 * a5)
        f6, p6 = f(d6, u6)
        a6 = al + al1 * hs - f6
        dn = d + hs * (_B1 * u + _B3 * u3 + _B4 * u4 + _B5 * u5 + _B6 * u6)
        un = u + hs * (_B1 * a1 + _B3 * a3 + _B4 * a4 + _B5 * a5 + _B6 * a6)
        fn, pn = f(dn, un)
        an = al + al1 * hs - fn
        de = hs * (_B1 * p1 + _B3 * p3 + _B4 * p4 + _B5 * p5 + _B6 * p6)
        ed = hs * (_E1 * u + _E3 * u3 + _E4 * u4 + _E5 * u5 + _E6 * u6 + _E7 * un)
        eu = hs * (_E1 * a1 + _E3 * a3 + _E4 * a4 + _E5 * a5 + _E6 * a6 + _E7 * an)
        sd = atol + rtol * max(abs(d), abs(dn))
        su = atol + rtol * max(abs(u), abs(un))
        err = max(abs(ed) / sd, abs(eu) / su)
        return dn, un, an, fn, pn, de, err

    def _locate(self, f, al, al1, d, u, acc, p, hs, g, atol, rtol):
        """Step length in (0, hs] where ``g`` of the DP step's end state reaches 0 (Illinois).

        Returns (length, d, u, u', force, power, e increment, force evaluations).
        """
        a, ga = 0.0, g(d, u)
        b = hs
        best = self._dp_step(f, al, al1, d, u, acc, p, b, atol, rtol)
        gb = g(best[0], best[1])
        best = (b,) + best[:6]
        nfev = 6
        side = 0
        for _ in range(60):
            if gb == 0.0 or (b - a) <= 1e-14 * max(hs, 1e-300):
                break
            c = (a * gb - b * ga) / (gb - ga) if gb != ga else 0.5 * (a + b)
            if not (a < c < b):
                c = 0.5 * (a + b)
            step = self._dp_step(f, al, al1, d, u, acc, p, c, atol, rtol)
            nfev += 6
            gc = g(step[0], step[1])
            if gc > 0.0:
                a, ga = c, gc
                if side == -1:
                    gb *= 0.5
                side = -1
            else:
                b, gb = c, gc
                best = (c,) + step[:6]
                if side == 1:
                    ga *= 0.5
                side = 1
            if abs(gc) < 1e-15:
                best = (c,) + step[:6]
                break
        return best + (nfev,)


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
# plausibility watch: what a host should hear about (the FMU's self-protection)
# ----------------------------------------------------------------------------------------------
#: energy the hand-over's timing may give the host before it is reported, as a part of the
#: impact's kinetic energy m v_imp^2 / 2 (HostObserver._book_timing)
TIMING_ENERGY_LIMIT = 0.01
#: a plain-law step longer than this part of the impact time scale T = L / v_imp: the
#: dissipated energy is off by about h / T (the master's stability guard uses the same limit)
PLAIN_STEP_LIMIT = 0.25
#: rebound / approach speed above which a damped plain-law impact created energy
REBOUND_LIMIT = 1.0 + 1e-3
#: impacts begun within this many steps of the previous separation, at least this part of the
#: previous approach speed, count as multiplying (the host bounces the bodies, they do not)
MULTIPLYING_STEPS = 2
MULTIPLYING_SPEED = 0.5
#: multiplying impacts in a row that are reported
MULTIPLYING_COUNT = 2


class PlausibilityWatch:
    """Findings about one contact's impacts that mean the host's numbers are wrong.

    Checked after each step (:meth:`check`), each kind reported once per impact:

    * ``timing_energy`` (resolved): the hand-over's timing has given the host more than
      ``TIMING_ENERGY_LIMIT`` of the impact's kinetic energy (HostObserver._book_timing):
      a host that delivers the force later than the contact could know, at a step coarse for
      the impact;
    * ``rebound`` (plain): a damped law's impact ended faster than it began, or dissipated
      negative energy;
    * ``coarse_plain_step`` (plain): a step longer than ``PLAIN_STEP_LIMIT`` impact time scales;
    * ``multiplying`` (either): ``MULTIPLYING_COUNT`` impacts in a row that began within
      ``MULTIPLYING_STEPS`` steps of the previous separation at more than
      ``MULTIPLYING_SPEED`` of its approach speed.

    Each finding names the numbers and the remedy.  Plain numbers only (saved with the FMU state).
    """

    def __init__(self, law: ContactLaw):
        self.law = law
        self.reported = ()          # kinds reported during the current impact
        self.impacts = 0            # impacts seen so far
        self.steps_open = 0         # steps since the last separation
        self.last_speed = 0.0       # m/s, approach speed of the previous impact
        self.in_a_row = 0           # multiplying impacts in a row

    def check(self, contact, h: float) -> list[tuple[str, str]]:
        """(kind, message) of what is new after a step of ``h`` [s] of ``contact``."""
        found = []
        law, v = self.law, contact.v_imp
        energy = 0.5 * law.m * v * v
        if contact.impacts > self.impacts:                      # new impact(s) this step
            quick = self.impacts > 0 and self.steps_open <= MULTIPLYING_STEPS \
                and v >= MULTIPLYING_SPEED * self.last_speed
            self.in_a_row = self.in_a_row + 1 if quick else 0
            self.impacts, self.last_speed, self.reported = contact.impacts, v, ()
            if self.in_a_row >= MULTIPLYING_COUNT:
                found.append(("multiplying", (
                    f"impacts multiplying: {self.in_a_row + 1} impacts in a row, each within {MULTIPLYING_STEPS} "
                    f"steps of the previous separation at {v:.3g} m/s (at least {MULTIPLYING_SPEED:g} of the "
                    f"previous approach speed): the host bounces the bodies back; use a smaller step "
                    f"(h = {h:.3g} s)")))
        self.steps_open = 0 if contact.in_contact else self.steps_open + 1
        if v > 0.0:
            T = law.length_scale(v) / v
            debt = getattr(getattr(contact, "observer", None), "debt", 0.0)
            if debt > TIMING_ENERGY_LIMIT * energy:
                found.append(("timing_energy", (
                    f"the host received {debt:.4g} J more from the contact than the impact returns "
                    f"({debt / energy:.1%} of its kinetic energy {energy:.4g} J, limit {TIMING_ENERGY_LIMIT:.0%}): "
                    f"it applies the force later than the contact could hand it over (before the first "
                    f"impact has shown how the host applies it, or at a step of {h / T:.2g} impact time scales); "
                    f"use a smaller step (below {0.1 * T:.3g} s), or declare the host (parameter host)")))
            if isinstance(contact, PlainContact):
                if contact.in_contact and h > PLAIN_STEP_LIMIT * T:
                    found.append(("coarse_plain_step", (
                        f"plain force law (resolve_impacts = false) stepped at h = {h:.3g} s = {h / T:.2g} impact "
                        f"time scales T = L / v_imp = {T:.3g} s (limit {PLAIN_STEP_LIMIT:g}): the dissipated energy is "
                        f"off by about {min(h / T, 1.0):.0%}; use resolve_impacts = true, or a step below "
                        f"{PLAIN_STEP_LIMIT * T:.3g} s")))
                ended = not contact.in_contact and contact.impacts and contact.last_CR == contact.last_CR
                if ended and law.zeta > 0.0 and (contact.last_CR > REBOUND_LIMIT or contact.last_E < -1e-3 * energy):
                    found.append(("rebound", (
                        f"the impact ended faster than it began (rebound / approach {contact.last_CR:.4g} with a "
                        f"damped law, dissipated {contact.last_E:.4g} J): the plain force law at h = {h:.3g} s "
                        f"({h / T:.2g} impact time scales) created energy; use resolve_impacts = true, or a step "
                        f"below {0.1 * T:.3g} s")))
        new = [(k, m) for k, m in found if k not in self.reported]
        self.reported = self.reported + tuple(k for k, _ in new)
        return new


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
                delta, rate, count = -0.3 * 10.0 * h, 10.0, 0
                t0 = time.perf_counter()
                while True:   # host: free masses moved exactly under the held mean force
                    out = r.step(delta, rate, h)
                    count += out.substeps
                    delta += rate * h - 0.5 * out.mean_force / law.m * h * h
                    rate -= out.mean_force / law.m * h
                    if r.impacts and not r.in_contact:
                        break
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
