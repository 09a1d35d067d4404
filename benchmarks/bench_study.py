"""Throughput of parameter studies (pounding-cosim study) on Dask clusters.  Prints, asserts nothing.

    python benchmarks/bench_study.py                       # LocalCluster, 1 and 2 workers + the Fig 8a sweep
    python benchmarks/bench_study.py --quick               # throughput only
    python benchmarks/bench_study.py --cluster loopback    # + a real cluster on 127.0.0.1 (dask scheduler and
                                                           #   dask worker processes), 1 and 2 workers
    python benchmarks/bench_study.py --scheduler tcp://head:8786   # + an existing cluster, as it is
    python benchmarks/bench_study.py --cases 40 --stop-time 5

Figures, one line per cluster and number of workers:

* throughput (cases per minute) from the first submitted case to the last row written
  (start-up reported apart: the cluster's processes, then connecting and checking the workers'
  environments), and its ratio to the LocalCluster with as many workers;
* per-case overhead beyond the simulation itself:
  - in the worker: median of ``case_time_s - wall_time_s`` (scene loading,
    fmi2Reset, start values, summary), the first case of each worker
    excepted: it instantiates the FMUs, once ("instantiate s");
  - dispatch: ``(workers * elapsed - sum of case_time_s) / n`` (scheduling,
    transfer, the CSV row and its fsync, idle workers at the end);
  - end to end: ``workers * elapsed / n - mean simulation time``, all of it
    including the one-time instantiation spread over the cases (the aim: under 20 ms);
* without ``--quick``: the seed paper's Fig 8a sweep (21 gaps x 4 records, full records) on a
  LocalCluster of 2 workers, start-up included.

The FMUs are built from the current sources into a temporary folder.  Timings from a machine
other programs load are not figures: rerun on a quiet machine.
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

from cosim.apps.study import load_study, read_results, run_study  # noqa: E402
from cosim.apps.study.loopback import LoopbackCluster  # noqa: E402
from cosim.fmus import build_all  # noqa: E402


def throughput(study_file: Path, fmu_dir: Path, out: Path, workers: int | None = None,
               scheduler: str | None = None) -> dict:
    """One run of the study (a LocalCluster of ``workers``, or the cluster at ``scheduler``)."""
    start = time.perf_counter()
    result = run_study(study_file, out, workers=workers, scheduler=scheduler, fmu_dir=fmu_dir, progress=False)
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


HEADER = (f"{'cluster':<10} {'workers':>7} {'cases/min':>10} {'vs local':>9} {'elapsed s':>10} {'processes s':>11} "
          f"{'start-up s':>10} {'sim/case s':>10} {'in worker ms':>13} {'dispatch ms':>12} {'end-to-end ms':>14} "
          f"{'instantiate s':>14}")


def line(cluster: str, r: dict, local: dict[int, float], processes_s: float | None) -> str:
    ratio = r["per_minute"] / local[r["workers"]] if r["workers"] in local else None
    return (f"{cluster:<10} {r['workers']:>7} {r['per_minute']:>10.1f} "
            + (f"{ratio:>9.2f}" if ratio is not None else f"{'-':>9}")
            + f" {r['elapsed']:>10.2f} " + (f"{processes_s:>11.2f}" if processes_s is not None else f"{'-':>11}")
            + f" {r['startup']:>10.2f} {r['sim_mean']:>10.3f} {1e3 * r['overhead_worker']:>13.1f} "
              f"{1e3 * r['dispatch']:>12.1f} {1e3 * r['overhead_total']:>14.1f} {r['instantiate']:>14.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=48, help="cases of the throughput study")
    parser.add_argument("--stop-time", type=float, default=10.0, help="s, simulated per throughput case")
    parser.add_argument("--quick", action="store_true", help="skip the Fig 8a sweep")
    parser.add_argument("--cluster", choices=("local", "loopback"), default="local",
                        help="loopback: also a cluster of `dask scheduler` and `dask worker` processes on "
                             "127.0.0.1 started by the benchmark, with 1 and 2 workers")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="also the existing cluster at ADDRESS, as it is")
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
    print("processes s: starting the loopback cluster's processes (the scheduler and the first worker, then the "
          "second worker); start-up s: connecting and checking the workers (local: starting the LocalCluster too)")
    print(HEADER)
    local: dict[int, float] = {}
    for workers in (1, 2):
        r = throughput(study_file, fmu_dir, tmp / f"local{workers}", workers=workers)
        local[r["workers"]] = r["per_minute"]
        print(line("local", r, local, None), flush=True)
    if args.cluster == "loopback":
        t0 = time.perf_counter()
        with LoopbackCluster(tmp / "loopback") as cluster:   # the scheduler: counted with the first worker
            for workers in (1, 2):
                cluster.add_worker(f"w{workers}")
                processes_s = time.perf_counter() - t0
                r = throughput(study_file, fmu_dir, tmp / f"loopback{workers}", scheduler=cluster.address)
                print(line("loopback", r, local, processes_s), flush=True)
                t0 = time.perf_counter()
    if args.scheduler:
        r = throughput(study_file, fmu_dir, tmp / "scheduler", scheduler=args.scheduler)
        print(line("scheduler", r, local, None), flush=True)
    if args.quick:
        return
    n = load_study("fig8a_gap").n_cases
    start = time.perf_counter()
    result = run_study("fig8a_gap", tmp / "fig8a", workers=2, fmu_dir=fmu_dir, progress=True)
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
