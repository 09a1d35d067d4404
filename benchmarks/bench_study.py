"""Throughput of parameter studies (cosim/study.py) on a local Dask cluster.  Prints, asserts nothing.

    python benchmarks/bench_study.py               # throughput 1 and 2 workers + the Fig 8a gap sweep
    python benchmarks/bench_study.py --quick       # throughput only
    python benchmarks/bench_study.py --cases 40 --stop-time 5

Figures:

* throughput (cases per minute) with 1 and 2 worker processes, from the first
  submitted case to the last row written (cluster start-up reported apart);
* per-case overhead beyond the simulation itself:
  - in the worker: median of ``case_time_s - wall_time_s`` (scene loading,
    fmi2Reset, start values, summary), the first case of each worker
    excepted: it instantiates the FMUs, once ("instantiate s");
  - dispatch: ``(workers * elapsed - sum of case_time_s) / n`` (scheduling,
    transfer, the CSV row and its fsync, idle workers at the end);
  - end to end: ``workers * elapsed / n - mean simulation time``, all of it
    including the one-time instantiation spread over the cases;
* the seed paper's Fig 8a sweep (21 gaps x 4 records, full records) with
  2 workers, start-up included.

The FMUs are built from the current sources into a temporary folder.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.fmus import build_all  # noqa: E402
from cosim.apps.study import load_study, read_results, run_study  # noqa: E402


def throughput(study_file: Path, fmu_dir: Path, workers: int, out: Path) -> dict:
    start = time.perf_counter()
    result = run_study(study_file, out, workers=workers, fmu_dir=fmu_dir, progress=False)
    total = time.perf_counter() - start
    _, rows = read_results(result.csv)
    sim = [r["wall_time_s"] for r in rows if r["wall_time_s"] is not None]
    first = {}
    for r in sorted(rows, key=lambda r: r["case"]):
        first.setdefault(r["worker"], r["case_id"])
    in_worker = [r["case_time_s"] - r["wall_time_s"] for r in rows
                 if r["wall_time_s"] is not None and r["case_id"] not in first.values()]
    instantiate = [r["case_time_s"] - (r["wall_time_s"] or 0.0) for r in rows if r["case_id"] in first.values()]
    n = len(rows)
    busy = sum(r["case_time_s"] for r in rows)
    return dict(workers=result.workers, cases=n, failed=result.failed, elapsed=result.elapsed_s, total=total,
                startup=result.startup_s, validation=result.validation_s,
                per_minute=60.0 * n / result.elapsed_s, sim_mean=statistics.fmean(sim),
                overhead_worker=statistics.median(in_worker) if in_worker else float("nan"),
                instantiate=statistics.fmean(instantiate),
                dispatch=(result.workers * result.elapsed_s - busy) / n,
                overhead_total=result.workers * result.elapsed_s / n - statistics.fmean(sim))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=48, help="cases of the throughput study")
    parser.add_argument("--stop-time", type=float, default=10.0, help="s, simulated per throughput case")
    parser.add_argument("--quick", action="store_true", help="skip the Fig 8a sweep")
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_study_"))
    fmu_dir = tmp / "fmus"
    build_all(fmu_dir)
    study_file = tmp / "throughput.toml"
    study_file.write_text(f"""
name = "throughput"
scene = "default"
[set]
stop_time = {args.stop_time!r}
[vary]
"pounding.gap" = {{ start = 0.01, stop = 0.2, num = {args.cases} }}
""")
    print(f"throughput study: default scene (3 + 5 storeys, 1 contact), El Centro, {args.stop_time:g} s simulated "
          f"per case (h = 0.01 s), {args.cases} gaps")
    print(f"{'workers':>7} {'cases/min':>10} {'elapsed s':>10} {'start-up s':>10} {'sim/case s':>10} "
          f"{'in worker ms':>13} {'dispatch ms':>12} {'end-to-end ms':>14} {'instantiate s':>14}")
    base = None
    for workers in (1, 2):
        r = throughput(study_file, fmu_dir, workers, tmp / f"out{workers}")
        base = base or r["per_minute"]
        print(f"{r['workers']:>7} {r['per_minute']:>10.1f} {r['elapsed']:>10.2f} {r['startup']:>10.2f} "
              f"{r['sim_mean']:>10.3f} {1e3 * r['overhead_worker']:>13.1f} {1e3 * r['dispatch']:>12.1f} "
              f"{1e3 * r['overhead_total']:>14.1f} {r['instantiate']:>14.2f}"
              + (f"   speed-up {r['per_minute'] / base:.2f}" if workers > 1 else ""))
    if args.quick:
        return
    fig8 = ROOT / "studies" / "fig8a_gap.toml"
    n = load_study(fig8).n_cases
    start = time.perf_counter()
    result = run_study(fig8, tmp / "fig8a", workers=2, fmu_dir=fmu_dir, progress=True)
    total = time.perf_counter() - start
    _, rows = read_results(result.csv)
    sim = sum(r["wall_time_s"] for r in rows if r["wall_time_s"] is not None)
    statuses = {s: sum(r["status"] == s for r in rows) for s in ("ok", "failed", "unstable")}
    print(f"Fig 8a gap sweep ({n} cases, full records, 2 workers): {total:.1f} s in all "
          f"(validation {result.validation_s:.1f} s, start-up {result.startup_s:.1f} s, cases {result.elapsed_s:.1f} s; "
          f"{sim:.1f} s of simulation), rows {statuses}")
    print(f"results: {result.csv}")


if __name__ == "__main__":
    from cosim.master.fmi import exit_process

    exit_process(main())
