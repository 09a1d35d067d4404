"""Every bundled scene at the package's default settings against OpenSees at its cheapest
passing time step, in one run (prints figures; no assertions).

    python benchmarks/bench_scenes.py [--repeats 3] [--scenes default kobe ...] [--json FILE]

For each scene:

* the monolithic reference (solve_ivp DOP853, rtol 1e-10) that both are measured against, with
  the criteria of docs/accuracy.md (peak contact force within 1 %, the same impacts, dissipated
  energy within 2 %, peak floor displacements within 0.5 %);
* the scene at its default settings (FMUs loaded once; the fastest of ``--repeats`` runs of the
  simulation loop): wall time, communication steps, microseconds per step, FMI calls per step
  and the *floor* (FMI calls x 7 us, what the calls alone cost through fmpy and pythonfmu,
  whatever the master and the FMUs compute), its errors and whether it meets the criteria;
* OpenSees (Newmark average acceleration, the contact law's material, contact energy by the
  trapezoid its integrator conserves: cosim/peers/opensees.py) at the cheapest time step that
  meets the same criteria, found by halving from 8 ms (:func:`cosim.apps.accuracy.cheapest_passing_dt`),
  timed as its analysis loop (the fastest of ``--repeats``);
* the ratio OpenSees / default settings, from this one run, in wall time and in CPU time (the
  simulation loop's CPU time in this process, OpenSees' analysis loop's in its child process:
  steadier than wall time on a machine other processes load).

Ratios from one run on one machine are the figures to quote; absolute times depend on the
machine and on what else runs on it.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.apps.accuracy import (CRITERIA, DEFAULT_SETTINGS, cheapest_passing_dt,  # noqa: E402
                                 reference_metrics, run_cosim, run_peer)
from cosim.fmus import default_fmu_dir  # noqa: E402
from cosim.master.loader import bundled_scenes, load_scene  # noqa: E402
from cosim.master.system import Catalog  # noqa: E402
from cosim.peers.reference import reference_for_scene  # noqa: E402

#: us per set + doStep + get through fmpy and pythonfmu, measured (README, "hard facts")
US_PER_CALL = 7.0


def pct(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{100 * x:.3g} %"


def bench_scene(name: str, catalog, repeats: int, opensees: bool, log=print) -> dict:
    scene = load_scene(name, [], catalog)
    ref = reference_metrics(reference_for_scene(scene, {"rtol": 1e-10}))
    row = run_cosim(name, DEFAULT_SETTINGS, 0.0, catalog, ref, repeats=repeats)
    steps = max(row.communication_steps, 1)
    out = dict(scene=name, reference_wall_s=ref["wall_time_s"], impacts=ref["impacts"],
               wall_s=row.wall_time_s, cpu_s=row.cpu_time_s, steps=row.communication_steps,
               us_per_step=1e6 * row.wall_time_s / steps,
               calls_per_step=row.fmu_calls / steps, floor_s=row.fmu_calls * US_PER_CALL * 1e-6,
               err_force=row.err_peak_force, err_energy=row.err_dissipated_energy,
               err_displacement=row.err_peak_displacement, meets=row.meets_criteria, status=row.status)
    log(f"{name}: default settings {row.wall_time_s:.3f} s (CPU {row.cpu_time_s:.3f} s), {row.communication_steps} steps, "
        f"{out['us_per_step']:.1f} us/step, {out['calls_per_step']:.2f} FMI calls/step (floor {out['floor_s']:.3f} s); "
        f"F {pct(row.err_peak_force)}, E {pct(row.err_dissipated_energy)}, u {pct(row.err_peak_displacement)}, "
        f"impacts {row.impacts}/{ref['impacts']}, {'meets' if row.meets_criteria else 'FAILS'} the criteria")
    if opensees:
        passing, tried = cheapest_passing_dt(scene, ref, log=log)
        out["opensees_tried"] = [dict(dt=r.value, wall_s=r.wall_time_s, meets=r.meets_criteria, status=r.status,
                                      err_force=r.err_peak_force, err_energy=r.err_dissipated_energy,
                                      err_displacement=r.err_peak_displacement, impacts=r.impacts) for r in tried]
        if passing is not None:
            best = min([passing] + [run_peer(scene, passing.value, ref) for _ in range(max(repeats, 1) - 1)],
                       key=lambda r: r.wall_time_s)
            out.update(opensees_dt=best.value, opensees_wall_s=best.wall_time_s, opensees_cpu_s=best.cpu_time_s,
                       cpu_ratio=best.cpu_time_s / row.cpu_time_s if row.cpu_time_s > 0 else math.nan,
                       opensees_err_force=best.err_peak_force, opensees_err_energy=best.err_dissipated_energy,
                       opensees_err_displacement=best.err_peak_displacement,
                       ratio=best.wall_time_s / row.wall_time_s if row.wall_time_s > 0 else math.nan)
            log(f"  OpenSees cheapest passing dt = {best.value:g} s: {best.wall_time_s:.3f} s "
                f"(CPU {best.cpu_time_s:.3f} s); OpenSees / default = {out['ratio']:.2f} in wall time, "
                f"{out['cpu_ratio']:.2f} in CPU time")
        else:
            out.update(opensees_dt=None, ratio=math.nan)
            log("  OpenSees: no time step down to "
                f"{tried[-1].value:g} s meets the criteria")
    return out


def table(rows: list[dict]) -> str:
    lines = ["| scene | default: wall (CPU) | steps | us/step | FMI calls/step | floor (calls x 7 us) | F err | "
             "E err | u err | meets | OpenSees dt | OpenSees wall (CPU) | OpenSees / default: wall (CPU) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        os_dt = r.get("opensees_dt")
        ratio, cpu_ratio = r.get("ratio", math.nan), r.get("cpu_ratio", math.nan)
        os_wall = "-" if os_dt is None else f"{r['opensees_wall_s']:.3f} s ({r['opensees_cpu_s']:.3f})"
        ratios = "-" if not math.isfinite(ratio) else f"{ratio:.2f} ({cpu_ratio:.2f})"
        lines.append(
            f"| {r['scene']} | {r['wall_s']:.3f} s ({r['cpu_s']:.3f}) | {r['steps']} | {r['us_per_step']:.1f} | "
            f"{r['calls_per_step']:.2f} | {r['floor_s']:.3f} s | {pct(r['err_force'])} | {pct(r['err_energy'])} | "
            f"{pct(r['err_displacement'])} | {'yes' if r['meets'] else 'no'} | "
            f"{'-' if os_dt is None else f'{os_dt * 1e3:g} ms'} | {os_wall} | {ratios} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", help="bundled scene names (default: all)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per timing, the fastest is kept (default 3)")
    parser.add_argument("--no-opensees", action="store_true")
    parser.add_argument("--json", type=Path, help="also write the figures as JSON here (a new file)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    args = parser.parse_args(argv)
    from cosim.files import OutputError, file_target, written_file

    if args.json:                        # refused before the benchmark runs (minutes), never replaced unasked
        try:
            args.json = file_target(args.json, overwrite=args.overwrite)
        except OutputError as exc:
            print(f"error: {exc}")
            return 2
    from cosim.peers.opensees import opensees_available

    opensees = not args.no_opensees and opensees_available()
    if not args.no_opensees and not opensees:
        print("OpenSees: openseespy not usable, skipped")
    t = time.perf_counter()
    print(f"criteria: peak force {100 * CRITERIA['peak_force']:g} %, same impacts, dissipated energy "
          f"{100 * CRITERIA['dissipated_energy']:g} %, peak displacements {100 * CRITERIA['peak_displacement']:g} %")
    rows = []
    with Catalog(default_fmu_dir()) as catalog:
        for name in args.scenes or bundled_scenes():
            rows.append(bench_scene(name, catalog, args.repeats, opensees))
    print()
    print(table(rows))
    print(f"\n(benchmark wall time {time.perf_counter() - t:.0f} s)")
    if args.json:
        with written_file(args.json) as partial:
            partial.write_text(json.dumps(rows, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    from cosim.master.fmi import exit_process

    exit_process(main())
