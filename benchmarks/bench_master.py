"""Wall time of the master on the bundled scenes (prints figures; no assertions).

    python benchmarks/bench_master.py [--fmu-dir DIR] [--repeat 3]

For each scene: the first and the best of ``repeat`` runs of the simulation loop (FMUs
loaded and instantiated once, ``System.reset`` between runs, nothing written), the cost
per communication step and the FMI calls.  ``--profile`` also profiles one more run of every
scene and prints the time spent in ``cosim/`` itself (own time of its functions: the
master's bookkeeping; the FMUs' Python and the FMI calls excluded), in total and per step
(cProfile inflates Python-heavy code, so this over-estimates the master's share: compare
trees with it, not with the wall times).  ``--proofs`` also times, in one more run, every
proof that gaps stay open (``OpenGaps.horizons``, the ground bound it evaluates included):
their number and the microseconds per proof.
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.master.simulate import simulate
from cosim.master.system import Catalog, System  # noqa: E402
from cosim.master.loader import load_scene  # noqa: E402

SCENES = ("default", "single_impact", "free_vibration", "one_building", "kasai_maison", "default_inelastic")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu-dir", type=Path)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--profile", action="store_true", help="profile every scene: the master's own time per step")
    parser.add_argument("--proofs", action="store_true", help="time every proof that gaps stay open (OpenGaps.horizons)")
    args = parser.parse_args(argv)
    if args.fmu_dir is None:
        from cosim.fmus import default_fmu_dir

        args.fmu_dir = default_fmu_dir()
    print(f"{'scene':<16}{'steps':>7}{'instances':>10}{'first run s':>13}{'best s':>9}{'us/step':>9}{'FMI calls':>11}")
    with Catalog(args.fmu_dir) as catalog:
        for name in SCENES:
            scene = load_scene(name, catalog=catalog)
            with System(scene, catalog) as system:
                times = []
                for _ in range(args.repeat):
                    result = simulate(system, progress=False)
                    times.append(result.cost.wall_time_s)
                best = min(times)
                n = result.cost.communication_steps
                print(f"{name:<16}{n:>7}{len(system.nodes):>10}{times[0]:>13.3f}{best:>9.3f}"
                      f"{1e6 * best / n:>9.1f}{result.cost.fmu_calls:>11}")
                if args.profile:
                    profiler = cProfile.Profile()
                    profiler.enable()
                    simulate(system, progress=False)
                    profiler.disable()
                    stats = pstats.Stats(profiler)
                    total = stats.total_tt
                    master = sum(v[2] for k, v in stats.stats.items() if "/cosim/" in k[0])
                    print(f"  profile of {name}: {total:.3f} s in total, {master:.3f} s "
                          f"({100 * master / total:.0f} %, {1e6 * master / n:.0f} us/step) in cosim/ itself (own time)")
                if args.proofs:
                    calls, seconds = proof_times(system)
                    if calls:
                        print(f"  proofs of {name}: {calls} calls, {seconds:.4f} s, {1e6 * seconds / calls:.1f} us/proof")
    return 0


def proof_times(system) -> tuple[int, float]:
    """``(calls, seconds)`` of ``OpenGaps.horizons`` over one more run of ``system`` (the class's
    method wrapped for that run only)."""
    from cosim.master.gap_bound import OpenGaps

    original = OpenGaps.horizons
    spent = [0, 0.0]

    def timed(self, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return original(self, *args, **kwargs)
        finally:
            spent[0] += 1
            spent[1] += time.perf_counter() - t0
    OpenGaps.horizons = timed
    try:
        simulate(system, progress=False)
    finally:
        OpenGaps.horizons = original
    return spent[0], spent[1]


if __name__ == "__main__":
    from cosim.master.fmi import exit_process

    exit_process(main())
