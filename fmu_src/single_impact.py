"""One impact of two free masses: the independent reference and the seed paper's calibration.

Pure physics (SI units, no FMI):

* :func:`goldsmith_loss` -- kinetic energy lost in an impact of restitution CR (seed Eq 3.2);
* :func:`simulate_impact` -- one impact integrated with scipy ``solve_ivp`` (DOP853, tight
  tolerances, events at maximum penetration and separation): the independent reference;
* :func:`calibrate_zeta` -- the seed paper's cyclic procedure (its Fig 4) done with a root
  finder: adjust a model's damping constant until the hysteresis-loop area equals
  Goldsmith's loss.

Not shipped inside an FMU (the FMUs integrate impacts with :mod:`.resolver`); the reference
solver, the calibration tool and the report use it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, minimize_scalar

from .contact_laws import DAMPED_MODELS, ContactLaw, effective_mass, law_spec, published_zeta

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
    law_spec(model)   # an unknown name is refused with the allowed ones
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
