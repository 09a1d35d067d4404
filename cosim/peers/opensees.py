"""OpenSees as an independent peer: the same pounding scene, solved the way practice solves it.

Benchmark only (``openseespy`` is an optional dependency, extra ``bench``).  The scene's
buildings, ground motion and contacts (:class:`cosim.reference.Contact`) become an OpenSees
model:

* one 1-D node per floor with its lumped mass, ``ndm = ndf = 1``, displacements relative to
  the ground (``UniformExcitation``, as our buildings);
* per storey a ``zeroLength`` element with an ``Elastic`` material ``E = k_i`` whose damping
  tangent ``eta = a1 k_i`` gives the stiffness-proportional part of Rayleigh damping
  exactly, and per floor a ``zeroLength`` dashpot to the fixed ground node with
  ``eta = a0 m_i`` for the mass-proportional part: ``C = a0 M + a1 K`` as in
  :class:`~fmu_src.shear_building.ShearBuilding`, and no Rayleigh damping on the contact
  (``zeroLength`` elements take none unless ``-doRayleigh`` is given);
* yielding storeys (:class:`fmu_src.hysteresis.StoreyHysteresis`) in the same ``zeroLength``
  springs, with the stiffness-proportional dashpot ``a1 k_i`` (Rayleigh on the *initial*
  stiffness, as ``building.fmu``) moved to a parallel ``zeroLength`` element of an ``Elastic``
  material with ``E = 0``:

  - ``bilinear``: ``Steel01(Fy, E0 = k, b = alpha, a1 = 0, a2 = 1, a3 = 0, a4 = 1)``.  Its stress
    is ``max(b E0 eps - (1 - b) Fy, min(b E0 eps + (1 - b) Fy, sigma_n + E0 d eps))``
    (``Steel01::determineTrialState``): kinematic hardening, our law exactly; ``a1 = a3 = 0``
    switch its isotropic hardening off (``a2 = a4 = 1`` only keep its formula finite);
  - ``bouc_wen``: ``BoucWen(alpha, ko = k, n, gamma / dy^n, beta / dy^n, Ao = 1, 0, 0, 0, tol,
    maxIter)`` (Haukaas, ``BoucWenMaterial.cpp``): stress ``alpha ko eps + (1 - alpha) ko z``
    with a *displacement-valued* ``z`` and ``dz/deps = Ao - |z|^n (gamma + beta sgn(deps z))``.
    With ``z = dy zeta`` this is our dimensionless law (``(1 - alpha) k dy zeta = (1 - alpha)
    Fy zeta``) when its ``gamma`` and ``beta`` are ours divided by ``dy^n``; ``deltaA =
    deltaNu = deltaEta = 0`` (no degradation).  The material integrates ``z`` by backward
    Euler over each strain increment (a Newton iteration to ``tol`` in m), first order in
    ``dt``;
* the ground acceleration as a ``Path`` time series on the record's samples (OpenSees
  interpolates linearly between them, as :meth:`Record.at` does);
* per contact a ``zeroLength`` element between the two floors with

  - ``JankowskiImpact(Kh, xi, mEff, gap, n)`` (P. J. Hughes, UCSD 2019): in approach
    ``F = Kh d^n + 2 xi sqrt(Kh d^(n-1) mEff) d'``, in restitution ``Kh d^n``: our
    ``jankowski`` law exactly with ``Kh = k``, ``xi = zeta``, ``mEff = m``;
  - or ``Hertzdamp(Kh, xiNorm, gap, n)``: ``F = (Kh + xi d') d^n`` with
    ``xi = xiNorm Kh / v_imp`` and ``v_imp`` latched from the strain rate of the *first
    step that closes the gap* (not the onset): our Hertz-damp family with
    ``xiNorm = zeta``, up to that latching error, which shrinks only linearly with ``dt``;
    it is also not clipped at ``F >= 0``.

  Both take a *negative* gap (a positive one is flipped with a warning): here ``-gap``.
  The element deformation is ``u_right - u_left = -(delta + gap)``.

Time integration: Newmark average acceleration (``gamma = 1/2, beta = 1/4``) at a fixed
``dt``, Newton iterations on ``NormDispIncr``.  Contact energy is measured with the rule this
integrator conserves: the trapezoid ``0.5 (F_n + F_n+1) (delta_n+1 - delta_n)`` over each
contact element's own, unclipped deformation (:func:`contact_work`; why, in
:class:`PeerResult`).  The contact materials return no damping
tangent for their ``d'``-dependent term, so Newton is not quadratic during the approach and
plain Newton fails at ``dt >= 5e-4 s`` on several records; each step therefore falls back
through ``KrylovNewton``, ``NewtonLineSearch`` and ``ModifiedNewton`` and then halves the
step (up to ``max_subdivisions`` times).  :attr:`PeerResult.algorithms` records what each
step needed.

OpenSees runs in a subprocess: the wheel's ``opensees.so`` needs ``libblas.so.3`` from the
wheel's own ``openseespylinux/lib`` folder, which is not on the loader path (we set
``LD_LIBRARY_PATH`` for the child and also preload the libraries with ``RTLD_GLOBAL``);
OpenSees keeps one global domain per process; and the child's timing excludes Python start-up
and model transfer.
"""
from __future__ import annotations

import functools
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from fmu_src.contact_laws import LAWS, law_spec

from .opensees_worker import opensees_library_dir
from .reference import reference_for_scene, scene_inputs

#: the child process's script (numpy and openseespy only)
WORKER = Path(__file__).resolve().with_name("opensees_worker.py")

MATERIALS = ("JankowskiImpact", "Hertzdamp")
#: our contact models each OpenSees material reproduces (see module docstring): the contact law
#: table's ``opensees`` entries
MATERIAL_MODELS = {material: tuple(name for name, spec in LAWS.items() if spec.opensees == material)
                   for material in MATERIALS}


def material_for(model: str) -> str:
    """The OpenSees material that reproduces contact law ``model`` (the table's ``opensees``);
    ValueError for an unknown name or a law OpenSees has no equivalent of."""
    material = law_spec(model).opensees
    if material is None:
        have = [name for name, spec in LAWS.items() if spec.opensees]
        raise ValueError(f"model = {model!r} has no OpenSees equivalent; laws that have one: {', '.join(have)}")
    return material


# -- locating and loading openseespy ------------------------------------------------------------
def _child_env() -> dict:
    env = dict(os.environ)
    lib = opensees_library_dir()
    if lib is not None:
        env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (str(lib), env.get("LD_LIBRARY_PATH", "")) if p)
    return env


@functools.lru_cache(maxsize=1)
def opensees_available() -> bool:
    """True if ``openseespy`` imports in a child process (checked once per process)."""
    if importlib.util.find_spec("openseespy") is None:
        return False
    try:
        proc = subprocess.run([sys.executable, "-P", str(WORKER), "--check"], env=_child_env(),
                              capture_output=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return proc.returncode == 0


# -- result --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PeerResult:
    """Outcome of :func:`run_opensees` (SI units).

    ``t`` holds every step (s); ``u`` the floor displacements of all buildings side by side
    (m); ``v`` their velocities (m/s) when the run was asked to record them
    (``record_velocity``; else an empty array); ``contact_force`` (N, >= 0 compressive) and
    ``penetration`` (m, the element's own deformation as ``delta = x_left - x_right - gap``,
    negative while open, never clipped) per contact.

    ``dissipated_energy_J`` is what the contact elements took out of the *discrete* solution:
    :func:`contact_work` (the trapezoid ``0.5 (F_n + F_n+1) (delta_n+1 - delta_n)`` summed over
    the steps, on the element's unclipped deformation) minus the elastic energy still stored
    at the end.  That trapezoid is the rule Newmark's average acceleration conserves: with
    ``gamma = 1/2, beta = 1/4`` the kinetic energy changes over a step by exactly the trapezoid
    of every force over its own displacement increment, so the energy balance of the OpenSees
    solution closes with it (``tests/test_opensees_peer.py`` checks the balance to round-off).
    Clipping the penetration at zero, as this peer once did, drops the part of the closing and
    opening steps spent on the open side of the gap and over-states the dissipation (default
    scene at dt = 5 ms: +6.9 % clipped, -0.2 % consistent, against the reference).

    ``wall_time_s`` (``cpu_time_s``: its CPU time) times the analysis loop in the child
    process; ``build_time_s`` the model definition.  ``algorithms`` counts the steps each fallback algorithm settled;
    ``subdivided_steps`` the steps that had to be halved (the balance then holds per
    sub-step, not over the recorded step).
    """

    material: str
    dt: float
    converged: bool
    t: np.ndarray
    u: np.ndarray
    contact_force: np.ndarray
    penetration: np.ndarray
    peak_force_N: float
    impacts: int
    dissipated_energy_J: float
    peak_displacements: tuple[np.ndarray, ...]
    floor_offsets: tuple[int, ...]
    wall_time_s: float
    build_time_s: float
    algorithms: dict = field(default_factory=dict)
    subdivided_steps: int = 0
    message: str = ""
    v: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    cpu_time_s: float = float("nan")
    #: per building (as :class:`cosim.peers.reference.ReferenceResult`): peak storey drifts
    #: (m, sampled at the steps), ductility (peak drift / yield drift, 0 without a yield
    #: shear), residual drifts ``d - V / k`` at the end (m, 0 for linear storeys) and the
    #: hysteretic energy (J, trapezoid of ``V`` over ``d`` minus the elastic energy at the end;
    #: NaN unless the storey shears were recorded, ``record_storeys``)
    peak_drifts: tuple[np.ndarray, ...] = ()
    ductility: tuple[np.ndarray, ...] = ()
    residual_drifts: tuple[np.ndarray, ...] = ()
    hysteretic_energy_J: tuple[float, ...] = ()
    #: storey shears (N): every step with ``record_storeys``, else the last step only
    storey_shear: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def displacements(self, building: int) -> np.ndarray:
        return self.u[:, self.floor_offsets[building]:self.floor_offsets[building + 1]]


# -- model description (plain numbers, JSON) -------------------------------------------------------
def _rayleigh(building) -> tuple[float, float]:
    """``(a0, a1)`` with ``C = a0 M + a1 K``; refuses damping that is not of that form."""
    M, K, C = (np.asarray(x, dtype=float) for x in (building.M, building.K, building.C))
    if hasattr(building, "damping") and building.damping == "rayleigh":
        a0, a1 = building.rayleigh_coefficients
    else:   # fit and check: only Rayleigh damping maps onto element dashpots
        A = np.column_stack((M.ravel(), K.ravel()))
        (a0, a1), *_ = np.linalg.lstsq(A, C.ravel(), rcond=None)
    scale = max(np.max(np.abs(C)), 1e-300)
    if np.max(np.abs(a0 * M + a1 * K - C)) > 1e-9 * scale:
        raise ValueError("OpenSees peer: building damping is not Rayleigh (C != a0 M + a1 K); "
                         "use damping = 'rayleigh'")
    return float(a0), float(a1)


def _storey_stiffnesses(building) -> np.ndarray:
    if hasattr(building, "stiffnesses"):
        return np.asarray(building.stiffnesses, dtype=float)
    K = np.asarray(building.K, dtype=float)
    n = K.shape[0]
    above = np.array([-K[i, i + 1] for i in range(n - 1)])
    return np.append(K[0, 0] - (above[0] if n > 1 else 0.0), above) if n > 1 else np.array([K[0, 0]])


#: absolute tolerance (m) of BoucWen's Newton iteration on its displacement-valued z, and its
#: iteration limit: far below every drift of interest (dy ~ 1e-2 m), so that the material's
#: own time discretisation is what the comparison measures
BOUC_WEN_TOL = 1e-14
BOUC_WEN_MAX_ITER = 50


def storey_spec(hysteresis, k: float, fy: float) -> dict | None:
    """The OpenSees material of one storey (module docstring): None for a linear storey, else
    ``{"material": "Steel01" | "BoucWen", "args": [...]}`` (the arguments after the tag)."""
    if hysteresis is None or not hysteresis.inelastic:
        return None
    alpha = float(hysteresis.alpha)
    if hysteresis.model == "bilinear":
        return dict(material="Steel01", args=[float(fy), float(k), alpha, 0.0, 1.0, 0.0, 1.0])
    if hysteresis.model == "bouc_wen":
        dy = fy / k
        scale = dy ** hysteresis.bw_n
        return dict(material="BoucWen", args=[alpha, float(k), float(hysteresis.bw_n), hysteresis.bw_gamma / scale,
                                               hysteresis.bw_beta / scale, 1.0, 0.0, 0.0, 0.0, BOUC_WEN_TOL,
                                               BOUC_WEN_MAX_ITER])
    raise ValueError(f"OpenSees peer: hysteresis = {hysteresis.model!r} has no OpenSees material here")


def model_description(buildings: Sequence, ground, contacts: Sequence, stop_time: float, dt: float,
                      x0=None, v0=None, material: str = "JankowskiImpact", *, tol: float = 1e-12,
                      max_iter: int = 25, max_subdivisions: int = 4, hystereses: Sequence | None = None,
                      record_storeys: bool = False, record_velocity: bool = False) -> dict:
    """The OpenSees model as plain numbers (what the child process receives)."""
    if material not in MATERIALS:
        raise ValueError(f"material = {material!r} is not allowed: one of {', '.join(MATERIALS)}")
    dt, stop_time = float(dt), float(stop_time)
    if not (math.isfinite(dt) and 0.0 < dt <= stop_time):
        raise ValueError(f"dt = {dt!r} s must be > 0 and <= stop_time = {stop_time!r} s")
    spec_buildings = []
    hystereses = list(hystereses) if hystereses is not None else [None] * len(buildings)
    if len(hystereses) != len(buildings):
        raise ValueError(f"hystereses: {len(hystereses)} for {len(buildings)} buildings")
    for b, building in enumerate(buildings):
        a0, a1 = _rayleigh(building)
        n = len(building.masses)
        hysteresis = hystereses[b]
        k_storeys = _storey_stiffnesses(building)
        storeys = None
        if hysteresis is not None and hysteresis.inelastic:
            hysteresis.check(k_storeys, float(getattr(building, "damping_ratio", 0.05)))
            storeys = [storey_spec(hysteresis, k_storeys[i], hysteresis.yield_shear[i]) for i in range(n)]
        init = []
        for name, values in (("x0", x0), ("v0", v0)):
            arr = np.zeros(n) if values is None or values[b] is None else np.asarray(values[b], dtype=float)
            if arr.size != n:
                raise ValueError(f"{name}[{b}] has {arr.size} values; building {b} has {n} floors")
            init.append(arr.tolist())
        fy = (np.asarray(hysteresis.yield_shear, dtype=float) if hysteresis is not None
              and np.size(hysteresis.yield_shear) == n else np.zeros(n))
        spec_buildings.append(dict(mass=np.asarray(building.masses, dtype=float).tolist(),
                                   k=k_storeys.tolist(), a0=a0, a1=a1, x0=init[0], v0=init[1],
                                   storeys=storeys, Fy=fy.tolist(),
                                   alpha=float(hysteresis.alpha) if hysteresis is not None else 0.0))
    spec_ground = None
    if ground is not None:
        if not (hasattr(ground, "times") and hasattr(ground, "acceleration")):
            raise TypeError("OpenSees peer: the ground motion must be a sampled Record (times, acceleration)")
        spec_ground = dict(times=np.asarray(ground.times, dtype=float).tolist(),
                           values=np.asarray(ground.acceleration, dtype=float).tolist())
    spec_contacts = []
    for c, contact in enumerate(contacts):
        law = contact.law
        if law.spec.opensees != material:
            raise ValueError(f"contact {c}: OpenSees {material} reproduces the models "
                             f"{', '.join(MATERIAL_MODELS[material])}, not {law.model!r}")
        spec_contacts.append(dict(left=int(contact.left), left_floor=int(contact.left_floor),
                                  right=int(contact.right), right_floor=int(contact.right_floor),
                                  k=float(law.k), n=float(law.n), zeta=float(law.zeta), m=float(law.m),
                                  gap=float(contact.gap), graze_depth=float(getattr(contact, "graze_depth", 0.0))))
    return dict(buildings=spec_buildings, ground=spec_ground, contacts=spec_contacts, stop_time=stop_time,
                dt=dt, material=material, tol=float(tol), max_iter=int(max_iter),
                max_subdivisions=int(max_subdivisions), record_storeys=bool(record_storeys),
                record_velocity=bool(record_velocity))


# -- the parent side -----------------------------------------------------------------------------------
def run_opensees(buildings: Sequence, ground, contacts: Sequence, stop_time: float, dt: float,
                 x0=None, v0=None, material: str = "JankowskiImpact", *, tol: float = 1e-12,
                 max_iter: int = 25, max_subdivisions: int = 4, timeout: float | None = None,
                 hystereses: Sequence | None = None, record_storeys: bool = False,
                 record_velocity: bool = False) -> PeerResult:
    """Solve the scene with OpenSees (Newmark average acceleration, fixed ``dt`` in s).

    Same plain inputs as :func:`cosim.peers.reference.solve_reference`.  ``tol`` (m) is the
    ``NormDispIncr`` tolerance: far below the penetrations (1e-5-1e-3 m) so that the
    iteration error does not mask the time-step error.  ``hystereses``: the storey law of
    each building (as :func:`cosim.peers.reference.solve_reference`); ``record_storeys`` also
    returns every step's storey shears (``PeerResult.storey_shear``, the hysteretic energy;
    off by default: reading them costs analysis time); ``record_velocity`` also returns the
    floor velocities (``PeerResult.v``, off by default likewise).  Raises ``RuntimeError`` if
    openseespy is not usable; a step that fails every fallback ends the run with
    ``converged = False`` and the history up to there.
    """
    spec = model_description(buildings, ground, contacts, stop_time, dt, x0, v0, material, tol=tol,
                             max_iter=max_iter, max_subdivisions=max_subdivisions, hystereses=hystereses,
                             record_storeys=record_storeys, record_velocity=record_velocity)
    if opensees_library_dir() is None and importlib.util.find_spec("openseespy") is None:
        raise RuntimeError("openseespy is not installed (pip install openseespy, extra 'bench')")
    with tempfile.TemporaryDirectory(prefix="opensees_peer_") as tmp:
        inp, out = Path(tmp) / "model.json", Path(tmp) / "result.npz"
        inp.write_text(json.dumps(spec), encoding="utf-8")
        # the worker as a script (-P: without its folder on sys.path): the child needs numpy and
        # openseespy, not the cosim package and its fmpy imports
        proc = subprocess.run([sys.executable, "-P", str(WORKER), "--worker", str(inp), str(out)],
                              env=_child_env(), capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0 or not out.exists():
            tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-8:])
            raise RuntimeError(f"OpenSees child process failed (exit {proc.returncode}):\n{tail}")
        with np.load(out, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    summary = json.loads(str(arrays.pop("summary")))
    offsets = tuple(int(x) for x in np.concatenate(([0], np.cumsum([len(b["mass"]) for b in spec["buildings"]]))))
    return _summarise(spec, arrays, summary, offsets)


def contact_work(force: np.ndarray, penetration: np.ndarray) -> float:
    """Work (J) a contact element took over a Newmark average-acceleration history: the
    trapezoid ``sum 0.5 (F_n + F_n+1) (delta_n+1 - delta_n)`` of its compressive force ``F``
    (N) over its own, unclipped penetration ``delta`` (m), step by step (the identity the
    integrator conserves: see :class:`PeerResult`)."""
    force, penetration = np.asarray(force, dtype=float), np.asarray(penetration, dtype=float)
    return float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(penetration)))


def count_impacts(force: np.ndarray, penetration: np.ndarray, graze_depth: float = 0.0) -> int:
    """Impacts in one contact element's history: runs of compressive ``force`` (N) whose largest
    ``penetration`` (m) reaches ``graze_depth`` (m), as pounding.fmu and the reference count them
    (a shallower contact is a graze)."""
    on = np.asarray(force) > 0.0
    edges = np.flatnonzero(np.diff(np.concatenate(([0], on.astype(np.int8), [0]))))
    return sum(1 for a, b in zip(edges[::2], edges[1::2]) if float(np.max(penetration[a:b])) >= graze_depth)


def _summarise(spec: dict, arrays: dict, summary: dict, offsets) -> PeerResult:
    t, u, F, delta = arrays["t"], arrays["u"], arrays["force"], arrays["delta"]
    impacts = 0
    dissipated = 0.0
    for c, contact in enumerate(spec["contacts"]):
        on = F[:, c] > 0.0
        impacts += count_impacts(F[:, c], delta[:, c], float(contact.get("graze_depth", 0.0)))
        d_end = max(float(delta[-1, c]), 0.0) if delta.size else 0.0
        stored = contact["k"] * d_end ** (contact["n"] + 1.0) / (contact["n"] + 1.0) if on.size and on[-1] else 0.0
        dissipated += contact_work(F[:, c], delta[:, c]) - stored
    peak_u = np.max(np.abs(u), axis=0) if u.size else np.zeros(offsets[-1])
    storeys = _storey_results(spec, u, arrays["storey_shear"], offsets)
    return PeerResult(
        material=spec["material"], dt=spec["dt"], converged=bool(summary["converged"]), t=t, u=u,
        contact_force=F, penetration=delta, peak_force_N=float(np.max(F)) if F.size else 0.0,
        impacts=impacts, dissipated_energy_J=dissipated,
        peak_displacements=tuple(peak_u[o0:o1] for o0, o1 in zip(offsets[:-1], offsets[1:])),
        floor_offsets=offsets, wall_time_s=float(summary["wall_time_s"]),
        build_time_s=float(summary["build_time_s"]), algorithms=summary["algorithms"],
        subdivided_steps=int(summary["subdivided_steps"]), message=summary["message"],
        v=arrays.get("v", np.zeros((0, u.shape[1] if u.ndim == 2 else 0))),
        cpu_time_s=float(summary.get("cpu_time_s", float("nan"))), **storeys)


def _storey_results(spec: dict, u: np.ndarray, shear: np.ndarray, offsets) -> dict:
    """Per building: peak drifts, ductility, residual drifts, hysteretic energy (PeerResult)."""
    peaks, mus, residuals, energies = [], [], [], []
    s0 = 0
    for b, building in enumerate(spec["buildings"]):
        o0, o1 = offsets[b], offsets[b + 1]
        n = o1 - o0
        drift = np.diff(u[:, o0:o1], axis=1, prepend=0.0) if u.size else np.zeros((1, n))
        k, fy = np.asarray(building["k"]), np.asarray(building["Fy"])
        V = shear[:, s0:s0 + n]
        s0 += n
        peak = np.max(np.abs(drift), axis=0)
        peaks.append(peak)
        mus.append(np.where(fy > 0.0, peak * k / np.where(fy > 0.0, fy, 1.0), 0.0))
        yielding = building["storeys"] is not None
        residuals.append(drift[-1] - V[-1] / k if yielding else np.zeros(n))
        energy = 0.0 if not yielding else math.nan
        if yielding and V.shape[0] == drift.shape[0]:
            # the trapezoid of V over d (Newmark average acceleration conserves it) minus the
            # elastic energy the storeys still hold
            work = float(np.sum(0.5 * (V[1:] + V[:-1]) * np.diff(drift, axis=0)))
            alpha = building["alpha"]
            q = V[-1] - alpha * k * drift[-1]
            stored = float(np.sum(0.5 * alpha * k * drift[-1] ** 2 + q * q / (2.0 * (1.0 - alpha) * k)))
            energy = work - stored
        energies.append(energy)
    return dict(peak_drifts=tuple(peaks), ductility=tuple(mus), residual_drifts=tuple(residuals),
                hysteretic_energy_J=tuple(energies), storey_shear=shear)


def opensees_for_scene(scene, dt: float, material: str | None = None, overrides: dict | None = None,
                       **options) -> PeerResult:
    """:func:`run_opensees` on a :class:`cosim.master.scene.Scene` (inputs as the reference builds them);
    ``material`` default: the one of the scene's contact law (:func:`material_for`)."""
    inputs = scene_inputs(scene)
    inputs.update(overrides or {})
    if material is None:
        materials = {material_for(c.law.model) for c in inputs["contacts"]} or {MATERIALS[0]}
        if len(materials) > 1:
            raise ValueError(f"the scene's contacts need several OpenSees materials {sorted(materials)}: give one")
        material = materials.pop()
    options.setdefault("hystereses", inputs.get("hystereses"))
    return run_opensees(inputs["buildings"], inputs["ground"], inputs["contacts"], inputs["stop_time"], dt,
                        inputs.get("x0"), inputs.get("v0"), material, **options)


# -- the child side ----------------------------------------------------------------------------------


def compare(scene, dts: Sequence[float] = (1e-3, 5e-4, 2e-4, 1e-4), material: str = "JankowskiImpact",
            overrides: dict | None = None) -> str:
    """Table of OpenSees at several ``dt`` against the reference solver on one scene (benchmark;
    ``pounding-cosim opensees SCENE --dt ...``)."""
    ref = reference_for_scene(scene, {"output_dt": 0.01, **(overrides or {})})
    lines = [f"scene {scene.name}: reference ({ref.method}, rtol {ref.rtol:g}) impacts {ref.impacts}, "
             f"peak force {ref.peak_force_N:.5e} N, dissipated {ref.dissipated_energy_J:.6g} J, "
             f"wall {ref.wall_time_s:.2f} s, nfev {ref.nfev}",
             f"{'dt (s)':>8} {'impacts':>7} {'d peak F':>9} {'d E_diss':>9} {'d peak u':>9} {'wall (s)':>8}  algorithms"]
    for dt in dts:
        peer = opensees_for_scene(scene, dt, material, overrides)
        du = max(float(np.max(np.abs(p / np.where(r > 0, r, 1.0) - 1.0)))
                 for p, r in zip(peer.peak_displacements, ref.peak_displacements))
        note = ", ".join(f"{k} {v}" for k, v in peer.algorithms.items())
        if peer.subdivided_steps:
            note += f", {peer.subdivided_steps} halved"
        if not peer.converged:
            note += f"; FAILED: {peer.message}"
        lines.append(f"{dt:8.1e} {peer.impacts:7d} {peer.peak_force_N / ref.peak_force_N - 1:+9.2%} "
                     f"{peer.dissipated_energy_J / ref.dissipated_energy_J - 1:+9.2%} {du:9.3%} "
                     f"{peer.wall_time_s:8.2f}  {note}")
    return "\n".join(lines)
