"""Cost of one building.fmu step, per storey law and ground-motion hold (prints figures; no assertions).

    python benchmarks/bench_building_step.py [--repeat 5] [--fmpy]

Drives the ``Building`` slave class directly (its ``do_step``, no FMI layer) through 40 s of
El Centro at 0.3 g and prints the CPU time per communication step and per record interval
(best of ``--repeat`` runs; CPU time, so that other processes on the machine disturb it less
than wall time, but a loaded machine still inflates it: compare figures of one run), with the
work counters of the exact integrator (share of segments cleared by the cheap bound, peak
searches deferred / run (nothing reads the peaks here, so the deferred ones stay pending),
root searches, events).

Cases: the linear building with the ground acceleration held over 10 ms steps (the model of
earlier versions, bit for bit); the same with the record's knots (first-order hold) over 10 ms
steps (one record interval) and over 0.16 s steps (16 record intervals per step: the long
steps of issue 17); bilinear and Bouc-Wen storeys yielding to a ductility of about 3.

Then what a master pays around the steps, per call on the slave class (CPU, best of
``--repeat``): fmi2GetReal of the 14 outputs issue 17's master reads and of every output of the
used storeys, fmi2SetReal of ``ag``, a force and 33 interleaved knot pairs, each through the
slave base's access plans and through pythonfmu's own per-variable path (the same values), and
fmi2GetFMUstate / fmi2SetFMUstate with deferred peak searches pending.

``--fmpy`` also times the same calls through fmpy and the FMU's C layer (wall time): set +
doStep + getReal of every output for the linear and the bilinear building, and the floor of
pythonfmu itself: a getReal of one output, a setReal of one input, and a doStep whose Python
side is known (the difference is what pythonfmu and fmpy add per call).

``--scene NAME`` (repeatable) measures the building steps of a real run instead: the scene runs
once through the FMUs with every call the master makes on building.fmu's slave objects recorded
(pythonfmu's FMUs live in this interpreter), then the calls are replayed on the ``Building``
class of each ``--source`` tree (a checkout's root; default this one) in subprocesses taking
turns, ``--repeat`` rounds, and the CPU time per doStep is printed by kind of step (zero-order
hold, or the number of knots), best of the rounds, with the largest change of any output read
against the first source relative to that output's largest magnitude::

    python benchmarks/bench_building_step.py --scene default --scene kasai_maison \
        --source /path/to/main --source .

(one BLAS thread in the replays, ``OPENBLAS_NUM_THREADS=1``: a loaded machine made
multithreaded products 10 to 100 times slower and the figures meaningless.)
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# a replay (--replay) imports the slave class of the tree given by --source
_SOURCE = next((sys.argv[i + 1] for i, a in enumerate(sys.argv[:-1]) if a == "--source"), None) \
    if "--replay" in sys.argv else None
sys.path.insert(0, str(Path(_SOURCE).resolve() if _SOURCE else ROOT))

from fmu_src.building_slave import Building  # noqa: E402
from fmu_src.ground_records import G, load_record  # noqa: E402
from fmu_src.record_knots import step_knots  # noqa: E402

BUILDINGS = {3: 0.5, 5: 1.0, 15: 1.5}     # storeys: T1 (s), 300 t floors, uniform stiffness
STOP = 40.0


def make(n: int, model: str = "linear") -> Building:
    b = Building(instance_name=f"b{n}", resources=None, visible=False, logger=None)
    b.n_storeys = n
    b.T1 = BUILDINGS[n]
    b.m[:n] = 3e5
    b.k[:n] = 1.0
    if model != "linear":
        b.hysteresis = model
        # base shear strength 0.1 W tapering up the height: ductility ~3 under El Centro at 0.3 g
        b.Fy[:n] = 0.1 * n * 3e5 * G * np.linspace(1.0, 0.4, n)
    b.exit_initialization_mode()
    if b._error:
        raise SystemExit(b._error)
    return b


def drive(b: Building, rec, h: float, knots: bool) -> float:
    steps = int(round(STOP / h))
    inputs = []
    for i in range(steps):
        t0, t1 = i * h, (i + 1) * h
        if knots:
            kt, ka = step_knots(rec, t0, t1)
            inputs.append((t0, len(kt), kt, ka))
        else:
            inputs.append((t0, 0, rec.mean_over(t0, t1), None))
    start = time.process_time()
    for t0, count, a, b_ in inputs:
        if count:
            b.n_knots = count
            b.t_knot[:count] = a
            b.ag_knot[:count] = b_
        else:
            b.ag = a
        if not b.do_step(t0, h):
            raise SystemExit(f"step at {t0} failed")
    return time.process_time() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--fmpy", action="store_true", help="also time set + doStep + getReal through fmpy")
    parser.add_argument("--scene", action="append", default=[], help="replay the building steps of this scene")
    parser.add_argument("--source", action="append", default=[], help="tree whose Building class replays")
    parser.add_argument("--replay", help=argparse.SUPPRESS)        # (a subprocess of --scene)
    args = parser.parse_args(argv)
    if args.replay:
        return replay(args.replay, args.repeat)
    if args.scene:
        return scene_costs(args.scene, args.source or [str(ROOT)], args.repeat)
    rec = load_record("elcentro1940")
    rec = rec.scaled(0.3 * G / rec.pga)
    cases = [(n, "linear", 0.01, False) for n in BUILDINGS] + \
            [(n, "linear", 0.01, True) for n in (3, 5)] + [(n, "linear", 0.16, True) for n in (3, 5, 15)] + \
            [(n, "bilinear", 0.01, False) for n in (3, 5)] + [(3, "bilinear", 0.01, True), (3, "bilinear", 0.16, True)] + \
            [(3, "bouc_wen", 0.01, False)]
    print(f"{'storeys':>7} {'law':>9} {'hold':>6} {'h (s)':>6} {'us/step':>9} {'us/interval':>12} "
          f"{'cleared':>8} {'peaks d/s':>10} {'roots':>6} {'events':>7} {'max mu':>7}")
    for n, model, h, knots in cases:
        best, building = None, None
        for _ in range(args.repeat if model != "bouc_wen" else max(1, args.repeat // 3)):
            b = make(n, model)
            cpu = drive(b, rec, h, knots)
            if best is None or cpu < best:
                best, building = cpu, b
        steps = int(round(STOP / h))
        c = building.cost
        segments = steps if building._legacy and not knots else c.segments   # legacy: one per step
        cleared = f"{100.0 * c.cleared / max(segments, 1):.0f} %" if model != "bouc_wen" else "-"
        mu = float(np.max(building._state.peak_drift * building._inv_yield_drift))
        print(f"{n:>7} {model:>9} {'knots' if knots else 'ag':>6} {h:>6g} {1e6 * best / steps:>9.1f} "
              f"{1e6 * best / (STOP / rec.dt):>12.2f} {cleared:>8} {f'{c.peaks_deferred}/{c.peak_searches}':>10} {c.root_searches:>6} "
              f"{c.events:>7} {mu:>7.2f}")
    access_costs(rec, args.repeat)
    if args.fmpy:
        fmpy_costs()
    return 0


def access_costs(rec, repeat: int) -> None:
    """get_real / set_real / FMU state on the slave class: the access plans against pythonfmu's path."""
    import timeit

    from pythonfmu import Fmi2Slave

    n = 5
    b = make(n)
    t = 0.0
    for _ in range(25):                         # 4 s of long steps: deferred peak searches pending
        kt, ka = step_knots(rec, t, t + 0.16)
        b.n_knots = len(kt)
        b.t_knot[:len(kt)] = kt
        b.ag_knot[:len(kt)] = ka
        b.do_step(t, 0.16)
        t += 0.16
    ref = {var.name: vr for vr, var in b.vars.items()}
    read14 = [ref[f"{a}[{i}]"] for a in ("x", "v") for i in range(1, n + 1)][:6] + \
        [ref[name] for name in ("a[3]", "base_shear", "E_kinetic", "E_strain", "E_damping", "E_hysteretic",
                                "E_input", "E_external")]
    read_all = [vr for vr, var in b.vars.items() if var.causality.name == "output" and type(var).__name__ == "Real"
                and ("[" not in var.name or int(var.name.split("[")[1][:-1]) <= n)]
    write = [ref["ag"], ref["F[3]"]] + [ref[f"{a}[{k}]"] for k in range(1, 34) for a in ("t_knot", "ag_knot")]
    values = [0.0] * len(write)

    def cpu(f):
        timer = timeit.Timer(f, timer=time.process_time)
        return 1e6 * min(timer.repeat(repeat=max(repeat, 3), number=2000)) / 2000

    print(f"\nFMI access on the slave class (n = {n}, {len(b._state.pending)} peak searches pending), CPU us per call:")
    print(f"{'call':>44} {'plan':>8} {'pythonfmu':>10}")
    for label, vrs in ((f"get_real, {len(read14)} outputs (issue 17 master)", read14),
                       (f"get_real, every output of {n} storeys ({len(read_all)})", read_all)):
        def fresh_plan():
            b._derived_cache = None
            return b.get_real(vrs)

        def fresh_base():
            b._derived_cache = None
            return Fmi2Slave.get_real(b, vrs)
        print(f"{label:>44} {cpu(fresh_plan):>8.2f} {cpu(fresh_base):>10.2f}")
    label = f"set_real, ag, F and 33 knot pairs ({len(write)})"
    print(f"{label:>44} {cpu(lambda: b.set_real(write, values)):>8.2f} "
          f"{cpu(lambda: Fmi2Slave.set_real(b, write, values)):>10.2f}")
    print(f"{'fmi2GetFMUstate':>44} {cpu(b._get_fmu_state):>8.2f}")
    state = b._get_fmu_state()
    # the restore itself (the host-mistake checks of _checked_set_state count references, which
    # a benchmark's own references would confuse)
    print(f"{'fmi2SetFMUstate':>44} {cpu(lambda: Building._set_fmu_state(b, state)):>8.2f}")


def fmpy_costs() -> None:
    """set (ag) + doStep + getReal of the outputs of the used storeys, through fmpy."""
    import timeit

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from cosim.fmus import build_all
    from cosim.master.fmi import exit_process

    path = build_all(names=("building",))["building"]
    md = read_model_description(str(path))
    variables = {v.name: v for v in md.modelVariables}
    unzipped = extract(str(path))
    print("\nthrough fmpy (n = 5, 10 ms steps): set ag + doStep + getReal of the outputs of 5 storeys")
    for model in ("linear", "bilinear"):
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=model)
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setInteger([variables["n_storeys"].valueReference], [5])
        fmu.setReal([variables["T1"].valueReference], [1.0])
        for i in range(5):
            fmu.setReal([variables[f"m[{i + 1}]"].valueReference, variables[f"k[{i + 1}]"].valueReference], [3e5, 1.0])
        if model == "bilinear":
            fmu.setString([variables["hysteresis"].valueReference], [model])
            fy = 0.1 * 5 * 3e5 * G * np.linspace(1.0, 0.4, 5)
            fmu.setReal([variables[f"Fy[{i + 1}]"].valueReference for i in range(5)], list(fy))
        fmu.exitInitializationMode()
        outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"
                   and ("[" not in v.name or int(v.name.split("[")[1][:-1]) <= 5)]
        ag_vr = [variables["ag"].valueReference]
        rng = np.random.default_rng(0)
        values = rng.normal(scale=2.0, size=4000)
        state = {"i": 0}

        def one_step():
            i = state["i"] % 4000
            fmu.setReal(ag_vr, [float(values[i])])
            fmu.doStep(0.01 * state["i"], 0.01)
            fmu.getReal(outputs)
            state["i"] += 1
        best = min(timeit.repeat(one_step, number=2000, repeat=5)) / 2000
        print(f"  {model:9s} {len(outputs)} outputs: {1e6 * best:.1f} us per step (wall, best of 5)")
        if model == "linear":
            floor(fmu, variables, values, state["i"])
        fmu.terminate()
        fmu.freeInstance()
    exit_process(0)


def floor(fmu, variables, values, steps_done: int) -> None:
    """What pythonfmu (and fmpy's ctypes call) add per FMI call: the same call through the FMU and
    on an in-process slave of the same parameters and inputs (wall, best of 5)."""
    import timeit

    b = make(5)
    x1 = [variables["x[1]"].valueReference]
    ag_vr = [variables["ag"].valueReference]
    clock = {"fmu": steps_done, "slave": steps_done}

    def best(f):
        return 1e6 * min(timeit.repeat(f, number=2000, repeat=5)) / 2000

    def fmu_step():
        i = clock["fmu"]
        fmu.setReal(ag_vr, [float(values[i % 4000])])
        fmu.doStep(0.01 * i, 0.01)
        clock["fmu"] += 1

    def slave_step():
        i = clock["slave"]
        b.set_real(ag_vr, [float(values[i % 4000])])
        b.do_step(0.01 * i, 0.01)
        clock["slave"] += 1
    for i in range(steps_done):                # the same history as the FMU's instance
        b.set_real(ag_vr, [float(values[i % 4000])])
        b.do_step(0.01 * i, 0.01)
    rows = [("getReal of x[1]", best(lambda: fmu.getReal(x1)), best(lambda: b.get_real(x1))),
            ("setReal of ag", best(lambda: fmu.setReal(ag_vr, [0.1])), best(lambda: b.set_real(ag_vr, [0.1]))),
            ("setReal of ag + doStep (10 ms, linear)", best(fmu_step), best(slave_step))]
    print("\n  the floor of one FMI call (wall us): through fmpy + pythonfmu, on the slave in-process, difference")
    for label, through, inside in rows:
        print(f"  {label:>40} {through:8.2f} {inside:8.2f} {through - inside:8.2f}")


_RECORDED = ("set_real", "get_real", "set_integer", "set_string", "set_boolean", "do_step", "setup_experiment",
             "enter_initialization_mode", "exit_initialization_mode")


def record_scene(scene: str) -> list:
    """The calls a run of ``scene`` makes on its building.fmu slave objects: ``(instance,
    method, args, result)``; FMU states are left out (a replay does not restore them)."""
    from cosim import run_scene

    run_scene(scene, write=False, progress=False)           # builds and loads the FMUs
    classes = [m.Building for name, m in list(sys.modules.items())
               if name.startswith("pounding_cosim_building") and name.endswith(".building_slave")]
    trace, ids = [], {}
    saved = []
    for cls in classes:
        for method in _RECORDED + ("__init__",):
            original = getattr(cls, method)
            saved.append((cls, method, original))

            def wrapped(self, *args, _original=original, _method=method, **kwargs):
                result = _original(self, *args, **kwargs)
                key = ids.setdefault(id(self), len(ids))
                if _method == "__init__":
                    trace.append((key, _method, (kwargs.get("instance_name"),), None))
                else:
                    trace.append((key, _method, tuple(list(a) if isinstance(a, (list, tuple)) else a for a in args),
                                  list(result) if isinstance(result, list) else result))
                return result
            setattr(cls, method, wrapped)
    try:
        run_scene(scene, write=False, progress=False)
    finally:
        for cls, method, original in saved:
            setattr(cls, method, original)
    return trace


def replay(path: str, repeat: int) -> int:
    """Replay a recorded trace on this tree's Building class: prints a JSON line with the CPU
    time per doStep by kind (best of ``repeat``) and every output read."""
    import json
    import pickle

    with open(path, "rb") as f:
        trace = pickle.load(f)
    best: dict[int, float] = {}
    counts: dict[int, int] = {}
    outputs = []
    for round_ in range(repeat):
        instances, spent, steps = {}, {}, {}
        clock = time.process_time
        for key, method, args, result in trace:
            if method == "__init__":
                instances[key] = Building(instance_name=args[0], resources=None, visible=False, logger=None)
                continue
            b = instances[key]
            if method == "do_step":
                kind = int(b.n_knots)
                start = clock()
                ok = b.do_step(*args)
                spent[kind] = spent.get(kind, 0.0) + clock() - start
                steps[kind] = steps.get(kind, 0) + 1
                if ok != result:
                    raise SystemExit(f"the replayed doStep{args} gave {ok}, the run {result}: {b._error}")
            elif method == "get_real":
                values = b.get_real(*args)
                if round_ == 0:
                    outputs.append((key, args[0], values))
            else:
                getattr(b, method)(*args)
        for kind, cpu in spent.items():
            best[kind] = min(best.get(kind, math.inf), cpu / steps[kind])
        counts = steps
    print(json.dumps({"us": {k: 1e6 * v for k, v in best.items()}, "steps": counts}))
    with open(path + ".out", "wb") as f:
        pickle.dump(outputs, f)
    return 0


def scene_costs(scenes, sources, repeat: int) -> None:
    """CPU us per building doStep of each scene's recorded run, per source tree, interleaved."""
    import json
    import os
    import pickle
    import subprocess
    import tempfile

    from cosim.master.fmi import exit_process

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes:
            trace_path = str(Path(tmp) / f"{scene}.trace")
            with open(trace_path, "wb") as f:
                pickle.dump(record_scene(scene), f)
            best = {src: {} for src in sources}
            outputs = {}
            for _ in range(repeat):
                for src in sources:
                    done = subprocess.run([sys.executable, __file__, "--replay", trace_path, "--source", src,
                                           "--repeat", "2"], env=env, capture_output=True, text=True)
                    if done.returncode:
                        raise SystemExit(done.stderr[-2000:])
                    figures = json.loads(done.stdout.strip().splitlines()[-1])
                    for kind, us in figures["us"].items():
                        best[src][int(kind)] = min(best[src].get(int(kind), math.inf), us)
                    counts = {int(k): v for k, v in figures["steps"].items()}
                    with open(trace_path + ".out", "rb") as f:
                        outputs[src] = pickle.load(f)
            total = sum(counts.values())
            print(f"\n{scene}: {total} building doSteps (kinds: 0 = ag held, k = k knots), CPU us per doStep, "
                  f"best of {repeat} rounds (one BLAS thread)")
            reference = outputs[sources[0]]
            for src in sources:
                mean = sum(best[src][k] * counts[k] for k in counts) / total
                scale, change = {}, {}
                for (key, vrs, values), (_, _, ref) in zip(outputs[src], reference):
                    for vr, a, r in zip(vrs, values, ref):
                        scale[key, vr] = max(scale.get((key, vr), 0.0), abs(r))
                        change[key, vr] = max(change.get((key, vr), 0.0), abs(a - r))
                worst = max((change[k] / scale[k] for k in change if scale[k] > 0.0), default=0.0)
                kinds = "  ".join(f"{k}: {best[src][k]:.1f} ({counts[k]})" for k in sorted(counts))
                print(f"  {src}: {mean:.1f} us per doStep;  by kind (steps): {kinds};  outputs vs "
                      f"{sources[0]}: {worst:.1e} of their scale")
    exit_process(0)


if __name__ == "__main__":
    raise SystemExit(main())
