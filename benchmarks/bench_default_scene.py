"""Cost of the default scene at the package's default settings, against the reference and OpenSees.

    python benchmarks/bench_default_scene.py [--repeats 3] [--scene default] [--no-opensees]

Prints wall time, communication steps, rollbacks, FMI calls, microseconds per FMI call and the
ratios to the monolithic reference (solve_ivp DOP853, rtol 1e-10) and to OpenSees at the
cheapest time step that meets the same accuracy criteria (docs/accuracy.md; with yielding
storeys also the drift criteria), found by halving dt from 8 ms, never assumed.  Wall times are the fastest of
``--repeats`` runs, FMUs built and loaded beforehand (``build/fmus``).  No assertion: the
figures depend on the machine and on what else runs on it.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.apps.accuracy import CRITERIA, Family, Row, reference_metrics, run_cosim, run_peer  # noqa: E402
from cosim.master.system import Catalog  # noqa: E402
from cosim.peers.reference import reference_for_scene  # noqa: E402
from cosim.fmus import default_fmu_dir  # noqa: E402
from cosim.master.loader import load_scene  # noqa: E402

#: the package's default settings, chosen from the accuracy study (docs/accuracy.md)
DEFAULT = Family("adaptive (default)", "adaptive", True, "contact_fraction", (1 / 2,), base_step=1e-2)
#: OpenSees' first time step; halved until a run meets the criteria (or below the last)
OPENSEES_FIRST_DT = 8e-3
OPENSEES_LAST_DT = 2.5e-4


def line(label: str, row: Row) -> str:
    return (f"{label:<28} wall {row.wall_time_s:7.3f} s  steps {row.communication_steps:6d}  "
            f"rollbacks {row.rollbacks:3d}  FMI calls {row.fmu_calls:7d}  "
            f"{row.us_per_fmu_call:5.1f} us/call  | peak F {100 * row.err_peak_force:.3f} %  "
            f"E {100 * row.err_dissipated_energy:.3f} %  u {100 * row.err_peak_displacement:.3f} %  "
            f"impacts {row.impacts}  {'meets' if row.meets_criteria else 'FAILS'} the criteria")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="default")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-opensees", action="store_true")
    args = parser.parse_args(argv)

    catalog = Catalog(default_fmu_dir())
    scene = load_scene(args.scene, [], catalog)
    t = time.perf_counter()
    ref_result = reference_for_scene(scene, {"rtol": 1e-10})
    ref = reference_metrics(ref_result)
    print(f"scene {scene.name}: {scene.description}")
    print(f"reference: solve_ivp DOP853 rtol 1e-10, {ref['wall_time_s']:.3f} s, {ref['nfev']} RHS evaluations, "
          f"{ref['impacts']} impacts, peak force {ref['peak_force_N']:.6g} N")
    print(f"criteria: peak force {100 * CRITERIA['peak_force']:g} %, same impacts, dissipated energy "
          f"{100 * CRITERIA['dissipated_energy']:g} %, peak displacements {100 * CRITERIA['peak_displacement']:g} %"
          + (f", peak drifts {100 * CRITERIA['peak_drift']:g} %, residual drifts {100 * CRITERIA['residual_drift']:g} % "
             f"(yielding storeys)" if ref.get("yielding") else ""))
    row = run_cosim(args.scene, DEFAULT, DEFAULT.values[0], catalog, ref, repeats=args.repeats)
    print(line("adaptive+resolved, 1/2, 0.01", row)
          + (f"  drift {100 * row.err_peak_drift:.3f} %  residual {100 * row.err_residual_drift:.3f} %"
             if ref.get("yielding") else ""))
    print(f"  {1e6 * row.wall_time_s / max(row.communication_steps, 1):.1f} us per communication step; "
          f"reference / default = {ref['wall_time_s'] / row.wall_time_s:.1f}x")
    if not args.no_opensees:
        from cosim.peers.opensees import opensees_available

        if opensees_available():
            dt = OPENSEES_FIRST_DT
            while dt >= OPENSEES_LAST_DT * (1 - 1e-9):
                peers = [run_peer(scene, dt, ref) for _ in range(args.repeats)]
                peer = min(peers, key=lambda r: r.wall_time_s)
                drifts = (f"  drift {100 * peer.err_peak_drift:.3f} %  residual {100 * peer.err_residual_drift:.3f} %"
                          if ref.get("yielding") and peer.status.startswith("ok") else "")
                print(f"{'OpenSees dt = ' + format(dt, 'g') + ' s':<28} wall {peer.wall_time_s:7.3f} s  "
                      f"steps {peer.communication_steps:6d}  | peak F {100 * peer.err_peak_force:.3f} %  "
                      f"E {100 * peer.err_dissipated_energy:.3f} %  u {100 * peer.err_peak_displacement:.3f} %{drifts}  "
                      f"{'meets' if peer.meets_criteria else 'FAILS'} the criteria  ({peer.status[:80]})")
                if peer.meets_criteria:
                    print(f"  cheapest OpenSees run meeting the criteria: dt = {dt:g} s; "
                          f"OpenSees / default = {peer.wall_time_s / row.wall_time_s:.2f}x")
                    break
                dt /= 2.0
            else:
                print(f"  no OpenSees run down to dt = {OPENSEES_LAST_DT:g} s meets the criteria")
        else:
            print("OpenSees: openseespy not usable, skipped")
    catalog.close()
    print(f"(benchmark wall time {time.perf_counter() - t:.0f} s)")
    return 0


if __name__ == "__main__":
    from cosim.master.fmi import exit_process

    exit_process(main())
