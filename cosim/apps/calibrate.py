"""The seed paper's cyclic calibration (its Fig 4) as a tool, with the FMUs in the loop.

    pounding-cosim calibrate --model crvk --m1 200 --m2 200 --k 1.8974e11 --n 1.5 --v 10 --cr 0.4
    pounding-cosim calibrate --model jankowski --m1 300 --m2 300 --v 0.68 --cr 0.6 --peak-force 29.85e3
    pounding-cosim calibrate ... --out out/calibration --no-plots      (or: python cosim/calibrate.py ...)

Calibrating the damping constant: two free masses ``m1``, ``m2`` [kg] meet once at
relative speed ``v_imp`` [m/s] (the bundled ``single_impact`` scene, with typed overrides,
run by :func:`cosim.master.runner.run_scene`: two ``building.fmu``
free masses and one ``pounding.fmu``).  The FMU parameter ``zeta`` is found by brentq
so that the hysteresis-loop area ``int F d(delta)`` of that impact equals Goldsmith's
kinetic-energy loss ``0.5 m (1 - CR^2) v_imp^2`` (seed Eq 3.2), ``m = m1 m2 / (m1 + m2)``.
The physics-level root (:func:`fmu_src.single_impact.calibrate_zeta`, solve_ivp) gives the
starting bracket, so the FMU root costs a handful of co-simulations, and it is an
independent check: two integrators, one result.

The loop area through the FMUs is taken on the host side, ``sum_i F_i (delta_i -
delta_(i-1))`` with ``F_i`` the contact FMU's mean force over communication step ``i``
and ``delta = x1 - x2 - gap`` from the building FMUs: the work the contact force does on
the bodies, i.e. what the co-simulation really dissipates.

Calibrating the stiffness (``--peak-force``, how the paper matches its experiment): with
the damping constant calibrated for the assumed CR, the peak force of an impact is
``F_peak = f(model, zeta, n) k^(1/(n+1)) (m v_imp^2)^(n/(n+1))`` (scale invariance), so
``k`` follows in closed form and is confirmed (and polished once) through the FMUs.

Every target no setting can reach is refused with :class:`CalibrationError`, which names
the value, the reachable range and the place; nothing is written then.

Outputs (``--out``): ``calibration.json``, ``loop.png`` (force against penetration) and
``force_time.png``.
"""
from __future__ import annotations

import json
import math
import numbers
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from fmu_src.contact_laws import DAMPED_MODELS, MODELS, ContactLaw, effective_mass, law_spec, published_zeta
from fmu_src.single_impact import calibrate_zeta, goldsmith_loss, simulate_impact

from ..files import output_target, written_folder
from ..fmus import default_fmu_dir
from ..master.results import Cost
from ..master.runner import run_scene
from ..master.scene import Override
from ..master.system import Catalog

SCENE = "single_impact"
#: largest damping constant searched by default (CR(1e6) < 1e-4 for every model)
ZETA_MAX = 1.0e6
#: communication steps per contact duration: the FMU resolves the impact inside each
#: step, so this only sets how finely the recorded history (plots) samples the impact
STEPS_PER_CONTACT = 200
#: free-flight steps before contact: onset falls inside a step, never at t = 0
STEPS_BEFORE_CONTACT = 5.5


class CalibrationError(ValueError):
    """The requested calibration cannot be done; the message names value, range and place."""


# ----------------------------------------------------------------------------------------------
# input
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ImpactCase:
    """One impact of two free masses: ``model``, masses [kg], stiffness [N/m^n], exponent,
    approach speed [m/s] and target restitution [-].  Validated on construction."""

    model: str
    m1: float
    m2: float
    k: float
    n: float
    v_imp: float
    CR: float

    def __post_init__(self):
        if self.model not in MODELS:
            raise CalibrationError(f"model = {self.model!r} is not allowed: one of {', '.join(MODELS)}")
        for name, unit in (("m1", "kg"), ("m2", "kg"), ("k", "N/m^n"), ("n", "-"), ("v_imp", "m/s")):
            value = getattr(self, name)
            if not (isinstance(value, numbers.Real) and math.isfinite(value) and value > 0.0):
                raise CalibrationError(f"{name} = {value!r} {unit} is outside the allowed range {name} > 0")
        if not (isinstance(self.CR, numbers.Real) and math.isfinite(self.CR) and 0.0 < self.CR <= 1.0):
            raise CalibrationError(f"CR = {self.CR!r} is outside the allowed range 0 < CR <= 1 (a passive "
                                   f"contact cannot rebound faster than it struck)")

    @property
    def m(self) -> float:
        """Effective mass ``m1 m2 / (m1 + m2)`` [kg]."""
        return effective_mass(self.m1, self.m2)

    @property
    def goldsmith_loss(self) -> float:
        """Kinetic energy the impact must dissipate [J] (seed Eq 3.2)."""
        return goldsmith_loss(self.m, self.CR, self.v_imp)

    @property
    def kinetic_energy(self) -> float:
        """Kinetic energy of the relative motion before impact, ``0.5 m v_imp^2`` [J]."""
        return 0.5 * self.m * self.v_imp ** 2

    def law(self, zeta: float) -> ContactLaw:
        return ContactLaw(self.model, float(self.k), float(self.n), self.m, float(zeta))

    def with_(self, **changes) -> "ImpactCase":
        return ImpactCase(**{**asdict(self), **changes})


# ----------------------------------------------------------------------------------------------
# one impact through the FMUs
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FMUImpact:
    """One impact of the ``single_impact`` scene run through the FMUs (SI units).

    ``achieved_CR`` from the building FMUs' velocities; ``loop_area`` the host-side
    ``sum F_i d(delta)`` [J]; ``kinetic_loss`` the bodies' kinetic-energy loss [J];
    ``fmu_dissipated`` the contact FMU's ``E_last`` [J]; ``peak_force`` its ``F_max`` [N]
    (instantaneous, located inside the steps); ``max_penetration`` [m];
    ``contact_duration`` [s]; ``step`` the communication step [s]; histories ``t`` [s],
    ``force`` (mean over each step) [N], ``delta`` (host, end of step) [m].
    """

    zeta: float
    zeta_used: float
    achieved_CR: float
    loop_area: float
    kinetic_loss: float
    fmu_dissipated: float
    peak_force: float
    max_penetration: float
    contact_duration: float
    impacts: int
    step: float
    wall_time: float
    t: np.ndarray = field(repr=False)
    force: np.ndarray = field(repr=False)
    delta: np.ndarray = field(repr=False)
    cost: Cost | None = field(default=None, repr=False)   # the co-simulation's cost counters


def scene_overrides(case: ImpactCase, zeta: float, contact_duration: float) -> tuple[list[Override], float, float]:
    """Overrides, communication step [s] and stop time [s] for one impact of ``case``.

    The bodies start ``gap`` apart with zero total momentum (each stays near the origin),
    contact begins after ``STEPS_BEFORE_CONTACT`` steps and the run stops a few steps after
    the expected separation.
    """
    h = contact_duration / STEPS_PER_CONTACT
    gap = case.v_imp * STEPS_BEFORE_CONTACT * h
    v1 = case.v_imp * case.m2 / (case.m1 + case.m2)
    v2 = v1 - case.v_imp
    stop = (STEPS_BEFORE_CONTACT + 1.5 * STEPS_PER_CONTACT + 10) * h
    values = {"left.m[1]": float(case.m1), "right.m[1]": float(case.m2), "left.k[1]": 0.0, "right.k[1]": 0.0,
              "left.zeta": 0.0, "right.zeta": 0.0, "left.x0[1]": 0.0, "right.x0[1]": 0.0,
              "left.v0[1]": float(v1), "right.v0[1]": float(v2),
              "pounding.model": case.model, "pounding.k": float(case.k), "pounding.n": float(case.n),
              "pounding.CR": float(case.CR), "pounding.m1": float(case.m1), "pounding.m2": float(case.m2),
              "pounding.gap": float(gap), "pounding.zeta": float(zeta), "pounding.resolve_impacts": True}
    return [Override.of(target, value) for target, value in values.items()], h, stop


class FMURunner:
    """Runs single impacts through the FMUs, loading them once (context manager).

    ``fmu_dir``: folder with ``pounding.fmu`` and ``building.fmu`` (default: ``build/fmus``,
    built from the sources when missing or out of date); ``catalog``: an already loaded
    :class:`cosim.master.Catalog` to reuse.  ``runs`` counts the co-simulations.
    """

    def __init__(self, fmu_dir: str | Path | None = None, catalog=None):
        self._own = catalog is None
        self.catalog = catalog if catalog is not None else Catalog(
            fmu_dir if fmu_dir is not None else default_fmu_dir())
        self.runs = 0

    def close(self) -> None:
        if self._own:
            self.catalog.close()

    def __enter__(self) -> "FMURunner":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def impact(self, case: ImpactCase, zeta: float, contact_duration: float | None = None) -> FMUImpact:
        """Run one impact of ``case`` with damping constant ``zeta`` (< 0: published formula).

        ``contact_duration`` [s] sets the communication step; default: from the physics
        reference (:func:`fmu_src.single_impact.simulate_impact`).
        """
        if contact_duration is None:
            z = zeta if zeta >= 0.0 else published_zeta(case.model, case.CR, case.n)
            contact_duration = simulate_impact(case.law(z if law_spec(case.model).damped else 0.0), case.v_imp,
                                               rtol=1e-8).contact_duration
        sets, h, stop = scene_overrides(case, zeta, contact_duration)
        t0 = time.perf_counter()
        run = run_scene(SCENE, sets, step=h, stop_time=stop, catalog=self.catalog, write=False, plots=False,
                        progress=False)
        wall = time.perf_counter() - t0
        self.runs += 1
        res = run.result
        contact = run.scene.contacts[0].name
        gap = float(run.scene.contacts[0].parameters["gap"])
        x1, x2 = res["left.x[1]"], res["right.x[1]"]
        v1, v2 = res["left.v[1]"], res["right.v[1]"]
        F = res[f"{contact}.F"]                     # row i: mean force over (t_(i-1), t_i]
        delta = x1 - x2 - gap
        impacts = int(res[f"{contact}.impacts"][-1])
        # CR_achieved is 0 until the first impact completes (a released Kelvin-Voigt contact
        # may still overlap geometrically while separating, so delta is no test)
        if impacts != 1 or not res[f"{contact}.CR_achieved"][-1] > 0.0 or F[-1] != 0.0:
            raise RuntimeError(f"single impact of {case} with zeta = {zeta!r}: expected one completed impact, "
                               f"got {impacts} (contact still closed at t = {stop:g} s?)")
        v_in = float(v1[0] - v2[0])
        v_out = float(v2[-1] - v1[-1])
        m = case.m
        return FMUImpact(
            zeta=float(zeta), zeta_used=float(res[f"{contact}.zeta_used"][-1]), achieved_CR=v_out / v_in,
            loop_area=float(np.dot(F[1:], np.diff(delta))), kinetic_loss=0.5 * m * (v_in ** 2 - v_out ** 2),
            fmu_dissipated=float(res[f"{contact}.E_last"][-1]), peak_force=float(res[f"{contact}.F_max"][-1]),
            max_penetration=float(res[f"{contact}.delta_max"][-1]),
            contact_duration=float(res[f"{contact}.contact_time"][-1]), impacts=impacts, step=h, wall_time=wall,
            cost=run.cost,
            t=res.time.copy(), force=F.copy(), delta=delta)


# ----------------------------------------------------------------------------------------------
# calibration of the damping constant
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CalibrationResult:
    """Damping constant for which one impact dissipates Goldsmith's loss (:func:`calibrate`).

    Inputs: ``model``, ``m1``, ``m2``, ``m`` [kg], ``k`` [N/m^n], ``n``, ``v_imp`` [m/s],
    ``target_CR``.  ``zeta`` the calibrated constant (through the FMUs when ``fmu``);
    ``zeta_physics`` the solve_ivp root; ``zeta_published`` the model's published formula
    (crvk: the printed Eq 3.9 constant ``0.0159 (1 - CR) CR^0.2805``) and ``published_CR`` what
    it achieves.  Achieved ``achieved_CR``, ``loop_area_J``,
    ``goldsmith_loss_J``, ``peak_force_N``, ``max_penetration_m``, ``contact_duration_s``
    at ``zeta``.  Cost: ``fmu_runs`` co-simulations, ``physics_impacts`` solve_ivp impacts,
    ``wall_time_s``.
    """

    model: str
    m1: float
    m2: float
    m: float
    k: float
    n: float
    v_imp: float
    target_CR: float
    zeta: float
    zeta_physics: float
    zeta_published: float
    published_CR: float
    achieved_CR: float
    loop_area_J: float
    goldsmith_loss_J: float
    peak_force_N: float
    max_penetration_m: float
    contact_duration_s: float
    fmu: bool
    fmu_runs: int
    physics_impacts: int
    wall_time_s: float
    impact: FMUImpact | None = field(default=None, repr=False, compare=False)

    @property
    def CR_error(self) -> float:
        """Achieved minus target CR [-]."""
        return self.achieved_CR - self.target_CR

    @property
    def energy_error(self) -> float:
        """Loop area / Goldsmith's loss - 1 [-] (0 when both vanish, CR = 1)."""
        if self.goldsmith_loss_J == 0.0:
            return self.loop_area_J / (0.5 * self.m * self.v_imp ** 2)
        return self.loop_area_J / self.goldsmith_loss_J - 1.0

    def to_dict(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "impact"}
        d["CR_error"] = self.CR_error
        d["energy_error_relative"] = self.energy_error
        return d

    def summary(self) -> str:
        via = "through the FMUs" if self.fmu else "physics level (solve_ivp)"
        return "\n".join([
            f"model {self.model}: m1 = {self.m1:g} kg, m2 = {self.m2:g} kg (m = {self.m:g} kg), k = {self.k:.6g} "
            f"N/m^{self.n:g}, v_imp = {self.v_imp:g} m/s, target CR = {self.target_CR:g}",
            f"  calibrated zeta     {self.zeta:.8g}   ({via}; solve_ivp root {self.zeta_physics:.8g})",
            f"  published zeta      {self.zeta_published:.8g}   (achieves CR = {self.published_CR:.4f})",
            f"  achieved CR         {self.achieved_CR:.6f}   (error {self.CR_error:+.2e})",
            f"  loop area           {self.loop_area_J:.6g} J",
            f"  Goldsmith loss      {self.goldsmith_loss_J:.6g} J   (loop / Goldsmith - 1 = {self.energy_error:+.2e})",
            f"  peak force          {self.peak_force_N:.6g} N",
            f"  max penetration     {self.max_penetration_m:.6g} m",
            f"  contact duration    {self.contact_duration_s:.6g} s",
            f"  cost                {self.fmu_runs} co-simulations, {self.physics_impacts} solve_ivp impacts, "
            f"{self.wall_time_s:.2f} s"])


def _physics_cr(case: ImpactCase, zeta: float) -> float:
    return simulate_impact(case.law(zeta), case.v_imp, rtol=1e-9).achieved_CR


def _check_bounds(zeta_bounds) -> tuple[float, float]:
    lo, hi = (float(z) for z in zeta_bounds)
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise CalibrationError(f"zeta_bounds = ({lo!r}, {hi!r}) is not a bracket: need 0 <= low < high, finite")
    return lo, hi


def calibrate(model: str, CR: float, *, m1: float, m2: float, k: float, v_imp: float, n: float = 1.5,
              fmu: bool = True, zeta_bounds: tuple[float, float] = (0.0, ZETA_MAX), runner: FMURunner | None = None,
              fmu_dir: str | Path | None = None, xtol: float = 1e-9) -> CalibrationResult:
    """Find the damping constant ``zeta`` of ``model`` that makes one impact dissipate Goldsmith's loss.

    Parameters
    ----------
    model : str
        One of :data:`fmu_src.contact_laws.MODELS`.
    CR : float
        Target restitution, 0 < CR <= 1.
    m1, m2 : float
        Colliding masses [kg].
    k : float
        Contact stiffness [N/m^n], > 0.
    v_imp : float
        Approach speed [m/s], > 0.
    n : float
        Stiffness exponent [-].
    fmu : bool
        True: the root is found through ``pounding.fmu`` and two free-mass ``building.fmu``
        (the physics root only brackets it); False: physics level only.
    zeta_bounds : (float, float)
        Search interval ``[low, high]`` of the constant; the achieved CR falls as ``zeta``
        rises, so the reachable range is ``CR(high) <= CR <= CR(low)``.
    runner, fmu_dir :
        FMUs to use (:class:`FMURunner` to reuse across calls, or a folder).
    xtol : float
        Relative tolerance on ``zeta`` of the FMU root.

    Raises
    ------
    CalibrationError
        Invalid input, or a target outside the reachable range (the message gives it).
    """
    t_start = time.perf_counter()
    case = ImpactCase(model, m1, m2, k, n, v_imp, CR)
    lo, hi = _check_bounds(zeta_bounds)
    if model not in DAMPED_MODELS:
        if CR != 1.0:
            raise CalibrationError(f"model {model!r} has no damping constant and always gives CR = 1: target "
                                   f"CR = {CR!r} is not reachable (reachable range: CR = 1; choose one of "
                                   f"{', '.join(DAMPED_MODELS)})")
        lo = hi = 0.0
    # the paper's own formula for crvk is the printed Eq 3.9 constant (contact_laws' "published"
    # crvk value is already the exact calibration, which would compare the root with itself)
    spec = law_spec(model)
    pub = spec.printed_constant(CR, n)
    pub_law_zeta = pub if spec.damped else 0.0
    published_CR = _physics_cr(case, pub_law_zeta)
    impacts = 1

    # reachable range of the bracket (physics level: the CR falls monotonically with zeta)
    if model in DAMPED_MODELS:
        cr_hi, cr_lo = _physics_cr(case, lo), _physics_cr(case, hi)
        impacts += 2
        tol = 1e-9   # solve_ivp rtol: a target on the bracket's edge is reachable
        if not (cr_lo - tol <= CR <= cr_hi + tol):
            why = ("the model always dissipates with zeta >= %g" % lo) if CR > cr_hi else \
                  ("more damping than zeta = %g would be needed" % hi)
            raise CalibrationError(
                f"{model}: target CR = {CR!r} is not reachable with {lo:g} <= zeta <= {hi:g} ({why}); "
                f"reachable range {cr_lo:.6g} <= CR <= {cr_hi:.6g}")
        if CR == 1.0 or CR >= cr_hi:
            z_phys = lo
        elif CR <= cr_lo:
            z_phys = hi
        else:
            cal = calibrate_zeta(model, CR, n, k=k, m1=m1, m2=m2, v_imp=v_imp, zeta_max=max(hi, 1e-12))
            z_phys = cal.zeta
            impacts += cal.n_impacts
            if not (lo <= z_phys <= hi):   # monotone CR(zeta): cannot happen unless the law changed
                raise CalibrationError(f"{model}: physics root zeta = {z_phys:g} outside the bracket "
                                       f"[{lo:g}, {hi:g}] although CR = {CR!r} is within its range")
    else:
        z_phys = 0.0

    ref = simulate_impact(case.law(z_phys), v_imp, rtol=1e-10)
    impacts += 1
    if not fmu:
        return CalibrationResult(
            model=model, m1=m1, m2=m2, m=case.m, k=k, n=n, v_imp=v_imp, target_CR=CR, zeta=z_phys,
            zeta_physics=z_phys, zeta_published=pub, published_CR=published_CR, achieved_CR=ref.achieved_CR,
            loop_area_J=ref.loop_area, goldsmith_loss_J=case.goldsmith_loss, peak_force_N=ref.peak_force,
            max_penetration_m=ref.max_penetration, contact_duration_s=ref.contact_duration, fmu=False,
            fmu_runs=0, physics_impacts=impacts, wall_time_s=time.perf_counter() - t_start)

    own = runner is None
    runner = runner if runner is not None else FMURunner(fmu_dir)
    runs0 = runner.runs
    try:
        z_fmu, imp = _fmu_root(runner, case, z_phys, lo, hi, ref.contact_duration, xtol)
    finally:
        if own:
            runner.close()
    return CalibrationResult(
        model=model, m1=m1, m2=m2, m=case.m, k=k, n=n, v_imp=v_imp, target_CR=CR, zeta=z_fmu, zeta_physics=z_phys,
        zeta_published=pub, published_CR=published_CR, achieved_CR=imp.achieved_CR, loop_area_J=imp.loop_area,
        goldsmith_loss_J=case.goldsmith_loss, peak_force_N=imp.peak_force, max_penetration_m=imp.max_penetration,
        contact_duration_s=imp.contact_duration, fmu=True, fmu_runs=runner.runs - runs0, physics_impacts=impacts,
        wall_time_s=time.perf_counter() - t_start, impact=imp)


def _fmu_root(runner: FMURunner, case: ImpactCase, z0: float, lo: float, hi: float, duration: float,
              xtol: float) -> tuple[float, FMUImpact]:
    """brentq on ``(loop area - Goldsmith) / E0`` through the FMUs, bracket grown around ``z0``."""
    target, E0 = case.goldsmith_loss, case.kinetic_energy
    cache: dict[float, FMUImpact] = {}

    def run(z: float) -> FMUImpact:
        if z not in cache:
            cache[z] = runner.impact(case, z, duration)
        return cache[z]

    def excess(z: float) -> float:
        return (run(z).loop_area - target) / E0

    if lo == hi or case.CR == 1.0 or z0 in (lo, hi):   # the root is a bracket end (CR = 1: zeta = 0)
        return z0, run(z0)
    # The FMU resolver (rtol 1e-8) and solve_ivp (1e-10) agree to ~1e-7 in zeta: start narrow.
    width = 1e-4
    a, b = max(lo, z0 * (1.0 - width)), min(hi, z0 * (1.0 + width))
    fa, fb = excess(a), excess(b)
    while (fa > 0.0 and a > lo) or (fb < 0.0 and b < hi):   # loop area grows with zeta
        width *= 8.0
        if fa > 0.0 and a > lo:
            a = max(lo, z0 * (1.0 - width)) if width < 1.0 else lo
            fa = excess(a)
        if fb < 0.0 and b < hi:
            b = min(hi, z0 * (1.0 + width))
            fb = excess(b)
    if fa > 0.0 or fb < 0.0:
        cr_a, cr_b = run(a).achieved_CR, run(b).achieved_CR
        cr_top, cr_bottom = run(lo).achieved_CR, run(hi).achieved_CR   # the bounds' ends, measured
        raise CalibrationError(
            f"{case.model}: the FMU root finder does not bracket the target CR = {case.CR!r}: zeta in "
            f"[{a:g}, {b:g}] gives CR from {cr_b:.6g} to {cr_a:.6g} through the FMUs (loop area - Goldsmith "
            f"= {fa * E0:.4g} J .. {fb * E0:.4g} J); reachable range with {lo:g} <= zeta <= {hi:g} is about "
            f"{cr_bottom:.6g} <= CR <= {cr_top:.6g}")
    if fa == 0.0:
        return a, run(a)
    if fb == 0.0:
        return b, run(b)
    z = brentq(excess, a, b, xtol=xtol * z0, rtol=4 * np.finfo(float).eps, maxiter=60)
    return z, run(z)


# ----------------------------------------------------------------------------------------------
# calibration of the stiffness to a measured peak force
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StiffnessCalibration:
    """Contact stiffness for which one impact reaches a measured peak force (:func:`calibrate_stiffness`).

    ``k`` [N/m^n], ``target_peak_N`` and achieved ``peak_force_N`` [N], ``zeta`` the damping
    constant used (calibrated for ``CR`` unless given), and the impact it predicts:
    ``achieved_CR``, ``loop_area_J``, ``goldsmith_loss_J``, ``max_penetration_m``,
    ``contact_duration_s``; ``fmu_runs`` co-simulations.
    """

    model: str
    m1: float
    m2: float
    n: float
    v_imp: float
    CR: float
    target_peak_N: float
    k: float
    zeta: float
    peak_force_N: float
    achieved_CR: float
    loop_area_J: float
    goldsmith_loss_J: float
    max_penetration_m: float
    contact_duration_s: float
    fmu: bool
    fmu_runs: int
    impact: FMUImpact | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "impact"}
        d["peak_error_relative"] = self.peak_force_N / self.target_peak_N - 1.0
        return d

    def summary(self) -> str:
        via = "through the FMUs" if self.fmu else "physics level (solve_ivp)"
        m = effective_mass(self.m1, self.m2)
        return "\n".join([
            f"model {self.model}: m1 = {self.m1:g} kg, m2 = {self.m2:g} kg (m = {m:g} kg), n = {self.n:g}, "
            f"v_imp = {self.v_imp:g} m/s, CR = {self.CR:g}, target peak force = {self.target_peak_N:.6g} N",
            f"  calibrated k        {self.k:.8g} N/m^{self.n:g}   ({via})",
            f"  zeta                {self.zeta:.8g}",
            f"  peak force          {self.peak_force_N:.6g} N   (error {self.peak_force_N / self.target_peak_N - 1.0:+.2e})",
            f"  achieved CR         {self.achieved_CR:.6f}",
            f"  loop area           {self.loop_area_J:.6g} J",
            f"  Goldsmith loss      {self.goldsmith_loss_J:.6g} J",
            f"  max penetration     {self.max_penetration_m:.6g} m",
            f"  contact duration    {self.contact_duration_s:.6g} s",
            f"  cost                {self.fmu_runs} co-simulation(s)"])


def calibrate_stiffness(model: str, peak_force: float, CR: float, *, m1: float, m2: float, v_imp: float,
                        n: float = 1.5, zeta: float | None = None, k_bounds: tuple[float, float] | None = None,
                        fmu: bool = True, runner: FMURunner | None = None, fmu_dir: str | Path | None = None,
                        rtol: float = 1e-6) -> StiffnessCalibration:
    """Contact stiffness ``k`` [N/m^n] for which one impact at ``v_imp`` peaks at ``peak_force`` [N].

    ``zeta``: damping constant; default calibrated so that the impact has restitution ``CR``
    (a measured peak force alone cannot fix both ``k`` and ``zeta``: CR must be assumed).
    The peak force grows like ``k^(1/(n+1))``, so every positive peak is reachable with
    some ``k > 0``; ``k_bounds = (k_low, k_high)`` restricts the search and any peak outside
    ``[F(k_low), F(k_high)]`` is refused with that range.  With ``fmu`` the closed-form
    ``k`` is confirmed through the FMUs and corrected once if their peak differs by more
    than ``rtol``.
    """
    if not (isinstance(peak_force, numbers.Real) and math.isfinite(peak_force) and peak_force > 0.0):
        raise CalibrationError(f"peak_force = {peak_force!r} N is outside the allowed range peak_force > 0")
    probe = ImpactCase(model, m1, m2, 1.0, n, v_imp, CR)
    if zeta is None:
        z = calibrate(model, CR, m1=m1, m2=m2, k=1.0, v_imp=v_imp, n=n, fmu=False).zeta
    else:
        if not (math.isfinite(zeta) and zeta >= 0.0):
            raise CalibrationError(f"zeta = {zeta!r} is outside the allowed range zeta >= 0")
        z = float(zeta)
    if not law_spec(model).damped:
        z = 0.0
    # F_peak = f1 * k^(1/(n+1)): one impact at k = 1 gives f1 (scale invariance).
    f1 = simulate_impact(probe.law(z), v_imp, rtol=1e-10).peak_force
    p = n + 1.0

    def k_for(F):
        return (F / f1) ** p

    if k_bounds is not None:
        k_lo, k_hi = (float(x) for x in k_bounds)
        if not (0.0 < k_lo < k_hi and math.isfinite(k_hi)):
            raise CalibrationError(f"k_bounds = ({k_lo!r}, {k_hi!r}) N/m^n is not a bracket: need "
                                   f"0 < k_low < k_high, finite")
        F_lo, F_hi = f1 * k_lo ** (1.0 / p), f1 * k_hi ** (1.0 / p)
        if not (F_lo <= peak_force <= F_hi):
            raise CalibrationError(
                f"{model}: peak_force = {peak_force:.6g} N is not reachable with {k_lo:g} <= k <= {k_hi:g} N/m^{n:g} "
                f"(CR = {CR:g}, v_imp = {v_imp:g} m/s): reachable range {F_lo:.6g} N <= peak force <= {F_hi:.6g} N")
    k = k_for(peak_force)
    case = probe.with_(k=k)
    ref = simulate_impact(case.law(z), v_imp, rtol=1e-10)
    if not fmu:
        return StiffnessCalibration(model, m1, m2, n, v_imp, CR, peak_force, k, z, ref.peak_force, ref.achieved_CR,
                                    ref.loop_area, case.goldsmith_loss, ref.max_penetration, ref.contact_duration,
                                    False, 0)
    own = runner is None
    runner = runner if runner is not None else FMURunner(fmu_dir)
    runs0 = runner.runs
    try:
        imp = runner.impact(case, z, ref.contact_duration)
        if abs(imp.peak_force / peak_force - 1.0) > rtol:   # the FMU's own peak: one power-law correction
            k *= (peak_force / imp.peak_force) ** p
            case = case.with_(k=k)
            imp = runner.impact(case, z, ref.contact_duration * (imp.peak_force / peak_force) ** (p / 2.0))
    finally:
        if own:
            runner.close()
    return StiffnessCalibration(model, m1, m2, n, v_imp, CR, peak_force, k, z, imp.peak_force, imp.achieved_CR,
                                imp.loop_area, case.goldsmith_loss, imp.max_penetration, imp.contact_duration,
                                True, runner.runs - runs0, impact=imp)


# ----------------------------------------------------------------------------------------------
# outputs
# ----------------------------------------------------------------------------------------------
def reference_history(model: str, m: float, k: float, n: float, v_imp: float, zeta: float):
    """Recorded solve_ivp impact (:class:`fmu_src.single_impact.ImpactResult` with histories)."""
    return simulate_impact(ContactLaw(model, k, n, m, zeta if law_spec(model).damped else 0.0), v_imp, record=True,
                           rtol=1e-10)


def plot_calibration(res: CalibrationResult | StiffnessCalibration, out: Path) -> list[Path]:
    """``loop.png`` (force vs penetration) and ``force_time.png`` into ``out``; returns the paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = effective_mass(res.m1, res.m2)
    ref = reference_history(res.model, m, res.k, res.n, res.v_imp, res.zeta)
    cr = res.target_CR if isinstance(res, CalibrationResult) else res.CR
    title = f"{res.model}, m = {m:g} kg, k = {res.k:.4g} N/m^{res.n:g}, v = {res.v_imp:g} m/s, CR = {cr:g}"
    paths = []
    imp = res.impact
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.plot(ref.delta * 1e3, ref.force / 1e3, "-", color="C0", label="solve_ivp reference (instantaneous force)")
    if imp is not None:
        ax.step(imp.delta * 1e3, imp.force / 1e3, where="pre", color="C1", lw=0.9, alpha=0.8,
                label="through the FMUs (mean force per step, host penetration)")
    ax.set_xlabel("penetration delta [mm]")
    ax.set_ylabel("contact force F [kN]")
    ax.set_title(title, fontsize=9)
    ax.text(0.02, 0.97, f"zeta = {res.zeta:.6g}\nloop area = {res.loop_area_J:.6g} J\n"
            f"Goldsmith loss = {res.goldsmith_loss_J:.6g} J\nachieved CR = {res.achieved_CR:.5f}",
            transform=ax.transAxes, va="top", fontsize=8)
    dmax = float(np.max(ref.delta)) * 1e3
    ax.set_xlim(-0.05 * dmax, 1.1 * dmax)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    paths.append(out / "loop.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.plot(ref.t * 1e3, ref.force / 1e3, "-", color="C0", label="solve_ivp reference (instantaneous force)")
    if imp is not None:
        onset = imp.t[np.argmax(imp.force > 0.0) - 1]
        ax.step((imp.t - onset) * 1e3, imp.force / 1e3, where="pre", color="C1", lw=0.9, alpha=0.8,
                label="through the FMUs (mean force per step)")
        ax.set_xlim(-0.05 * ref.t[-1] * 1e3, 1.2 * ref.t[-1] * 1e3)
    ax.set_xlabel("time from contact onset [ms]")
    ax.set_ylabel("contact force F [kN]")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out / "force_time.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths


def write_into(res: CalibrationResult | StiffnessCalibration, folder: Path, plots: bool = True) -> None:
    """Write ``calibration.json`` (and the plots) into the claimed, empty ``folder``."""
    (folder / "calibration.json").write_text(json.dumps(res.to_dict(), indent=2) + "\n")
    if plots:
        plot_calibration(res, folder)


def write_outputs(res: CalibrationResult | StiffnessCalibration, out: str | Path, plots: bool = True, *,
                  overwrite: bool = False) -> Path:
    """Write ``calibration.json`` (and the plots) into ``out`` by the output rule
    (:mod:`cosim.files`: an earlier calibration's folder is replaced only with ``overwrite``),
    complete or not at all.  Returns the folder."""
    target = output_target(out, overwrite=overwrite)
    with written_folder(target, "calibration", overwrite=overwrite) as pending:
        write_into(res, pending.path, plots)
    return pending.target
