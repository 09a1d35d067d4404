"""The OpenSees side of the OpenSees peer, run as a child process (numpy and openseespy only).

    python opensees_worker.py --worker MODEL.json RESULT.npz
    python opensees_worker.py --check

The parent (:mod:`cosim.peers.opensees`) writes the model as plain numbers (JSON), runs this
file as a script with ``-P`` (nothing of the package on ``sys.path``: the child needs only
numpy and openseespy) and the wheel's ``openseespylinux/lib`` on ``LD_LIBRARY_PATH``, and
reads the histories back (npz).  OpenSees keeps one global domain per process, hence a
process per run.  This is a child-process protocol, not a command line.
"""
from __future__ import annotations

import ctypes
import importlib.util
import json
import math
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np

FALLBACK_ALGORITHMS = ("Newton", "KrylovNewton", "NewtonLineSearch", "ModifiedNewton")
_LIBRARIES = ("libquadmath.so.0", "libgfortran.so.4", "libgomp.so.1", "libblas.so.3", "liblapack.so.3")


def opensees_library_dir() -> Path | None:
    """The wheel's private library folder (``openseespylinux/lib``), or None if not installed."""
    try:
        spec = importlib.util.find_spec("openseespylinux")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    lib = Path(list(spec.submodule_search_locations)[0]) / "lib"
    return lib if lib.is_dir() else None


def _preload_libraries() -> None:
    """Load the wheel's BLAS/LAPACK/Fortran runtime globally so ``opensees.so`` resolves them."""
    lib = opensees_library_dir()
    if lib is None:
        return
    for name in _LIBRARIES:
        path = lib / name
        if path.exists():
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)


def _storey_material(ops, mat: int, k: float, damping: float, storey: dict | None) -> None:
    """The storey spring's material: ``Elastic`` with the stiffness-proportional damping
    tangent for a linear storey; ``Steel01`` or ``BoucWen`` (arguments given by the parent,
    :func:`cosim.peers.opensees.storey_spec`) for a yielding one, whose damping is a separate
    dashpot element (see :func:`_build`)."""
    if storey is None:
        ops.uniaxialMaterial("Elastic", mat, k, damping)                 # storey spring + a1 K dashpot
    elif storey["material"] == "Steel01":
        ops.uniaxialMaterial("Steel01", mat, *storey["args"])
    else:
        ops.uniaxialMaterial("BoucWen", mat, *storey["args"][:-1], int(storey["args"][-1]))


def _build(ops, spec: dict):
    """Define the model; returns floor node tags (global dof order), contact element tags and
    storey element tags (global storey order)."""
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ground_node = 1
    ops.node(ground_node, 0.0)
    ops.fix(ground_node, 1)
    tag = 1
    mat = 0
    floors = []
    initial = []
    storey_tags = []
    for b in spec["buildings"]:
        below = ground_node
        storeys = b.get("storeys") or [None] * len(b["mass"])
        for m, k, x0, v0, storey in zip(b["mass"], b["k"], b["x0"], b["v0"], storeys):
            tag += 1
            node = tag
            ops.node(node, 0.0, "-mass", m)
            floors.append(node)
            mat += 1
            _storey_material(ops, mat, k, b["a1"] * k, storey)
            ops.element("zeroLength", 1000 + mat, below, node, "-mat", mat, "-dir", 1)
            storey_tags.append(1000 + mat)
            if storey is not None and b["a1"] > 0.0:
                # the a1 K part of Rayleigh damping on the initial stiffness, beside the yielding spring
                mat += 1
                ops.uniaxialMaterial("Elastic", mat, 0.0, b["a1"] * k)
                ops.element("zeroLength", 1000 + mat, below, node, "-mat", mat, "-dir", 1)
            if b["a0"] > 0.0:
                mat += 1
                ops.uniaxialMaterial("Elastic", mat, 0.0, b["a0"] * m)  # a0 M dashpot to the ground
                ops.element("zeroLength", 1000 + mat, ground_node, node, "-mat", mat, "-dir", 1)
            below = node
            initial.append((node, x0, v0))
    offsets = np.concatenate(([0], np.cumsum([len(b["mass"]) for b in spec["buildings"]])))
    contact_tags = []
    for c in spec["contacts"]:
        mat += 1
        if spec["material"] == "JankowskiImpact":
            ops.uniaxialMaterial("JankowskiImpact", mat, c["k"], c["zeta"], c["m"], -c["gap"], c["n"])
        else:
            ops.uniaxialMaterial("Hertzdamp", mat, c["k"], c["zeta"], -c["gap"], c["n"])
        left = floors[offsets[c["left"]] + c["left_floor"] - 1]
        right = floors[offsets[c["right"]] + c["right_floor"] - 1]
        etag = 5000 + len(contact_tags)
        ops.element("zeroLength", etag, left, right, "-mat", mat, "-dir", 1)
        contact_tags.append(etag)
    # Initial conditions only after every element exists: a zeroLength element stores the
    # relative displacement and velocity of its nodes when it is added to the domain and
    # subtracts them ever after (ZeroLength::setDomain, d0/v0), which would shift the gap and
    # hide the approach rate from the contact dashpot.
    for node, x0, v0 in initial:
        if x0:
            ops.setNodeDisp(node, 1, x0, "-commit")
        if v0:
            ops.setNodeVel(node, 1, v0, "-commit")
    if spec["ground"] is not None:
        ops.timeSeries("Path", 1, "-time", *spec["ground"]["times"], "-values", *spec["ground"]["values"])
        ops.pattern("UniformExcitation", 1, 1, "-accel", 1)
    ops.constraints("Plain")
    ops.numberer("Plain")
    ops.system("FullGeneral")
    ops.test("NormDispIncr", spec["tol"], spec["max_iter"])
    ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    return floors, contact_tags, storey_tags


def _advance(ops, dt: float, depth: int, spec: dict, stats: dict) -> bool:
    """One step of ``dt``: each fallback algorithm in turn, then two half steps."""
    for name in FALLBACK_ALGORITHMS:
        ops.algorithm(name)
        if ops.analyze(1, dt) == 0:
            stats["algorithms"][name] = stats["algorithms"].get(name, 0) + 1
            if name != "Newton":
                ops.algorithm("Newton")
            return True
    ops.algorithm("Newton")
    if depth >= spec["max_subdivisions"]:
        return False
    stats["subdivided_steps"] += 1
    return _advance(ops, 0.5 * dt, depth + 1, spec, stats) and _advance(ops, 0.5 * dt, depth + 1, spec, stats)


def _worker(spec: dict) -> tuple[dict, dict]:
    _preload_libraries()
    import openseespy.opensees as ops

    t0 = time.perf_counter()
    floors, contact_tags, storey_tags = _build(ops, spec)
    build_time = time.perf_counter() - t0
    offsets = np.concatenate(([0], np.cumsum([len(b["mass"]) for b in spec["buildings"]])))
    dofs = [(offsets[c["left"]] + c["left_floor"] - 1, offsets[c["right"]] + c["right_floor"] - 1, c["gap"])
            for c in spec["contacts"]]
    dt, stop = spec["dt"], spec["stop_time"]
    n_steps = int(round(stop / dt))
    if abs(n_steps * dt - stop) > 1e-9 * stop:
        n_steps = int(math.ceil(stop / dt))
    t = np.zeros(n_steps + 1)
    u = np.zeros((n_steps + 1, len(floors)))
    force = np.zeros((n_steps + 1, len(contact_tags)))
    # storey shears (restoring, without damping) at every step only when asked: the loops and
    # the hysteretic energy need them, the peaks and the residual drift only the last step's
    shear_history = spec.get("record_storeys", False)
    shear = np.zeros((n_steps + 1 if shear_history else 1, len(storey_tags)))
    u[0] = [ops.nodeDisp(node, 1) for node in floors]
    if shear_history:
        shear[0] = [ops.eleResponse(etag, "basicForce")[0] for etag in storey_tags]
    stats = {"algorithms": {}, "subdivided_steps": 0}
    converged, message, k = True, "", 0
    t_start = time.perf_counter()
    for k in range(1, n_steps + 1):
        if not _advance(ops, dt, 0, spec, stats):
            converged = False
            message = f"no convergence at t = {ops.getTime():.6g} s after every fallback"
            k -= 1
            break
        t[k] = ops.getTime()
        u[k] = [ops.nodeDisp(node, 1) for node in floors]
        for c, etag in enumerate(contact_tags):
            force[k, c] = max(0.0, -ops.eleResponse(etag, "basicForce")[0])
        if shear_history:
            shear[k] = [ops.eleResponse(etag, "basicForce")[0] for etag in storey_tags]
    wall = time.perf_counter() - t_start
    if not shear_history:
        shear[0] = [ops.eleResponse(etag, "basicForce")[0] for etag in storey_tags]
    ops.wipe()
    t, u, force = t[:k + 1], u[:k + 1], force[:k + 1]
    if shear_history:
        shear = shear[:k + 1]
    delta = np.column_stack([u[:, i] - u[:, j] - gap for i, j, gap in dofs]) if dofs else np.zeros((t.size, 0))
    summary = dict(converged=converged, message=message, wall_time_s=wall, build_time_s=build_time, **stats)
    return dict(t=t, u=u, force=force, delta=delta, storey_shear=shear), summary


def _worker_main(argv: Sequence[str]) -> int:
    if len(argv) != 2:
        print("usage: python opensees_worker.py --worker MODEL.json RESULT.npz", file=sys.stderr)
        return 2
    spec = json.loads(Path(argv[0]).read_text(encoding="utf-8"))
    arrays, summary = _worker(spec)
    np.savez(argv[1], summary=np.array(json.dumps(summary)), **arrays)
    return 0


def main(argv: Sequence[str]) -> int:
    if argv and argv[0] == "--worker":
        return _worker_main(argv[1:])
    if argv and argv[0] == "--check":
        _preload_libraries()
        import openseespy.opensees  # noqa: F401
        return 0
    print("usage: python opensees_worker.py --worker MODEL.json RESULT.npz | --check", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
