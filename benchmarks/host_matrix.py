"""The host matrix of pounding.fmu (issue 13, point 3): every host of cosim/peers/hosts.py, both
coupling orders, every contact model for free masses, two structural cases at 0.1-10 ms.

    python benchmarks/host_matrix.py [--fmu PATH] [--quick]

Prints the markdown tables quoted in docs/fmi_hosts.md and the wall time.  The tests
(tests/test_host_matrix.py) assert the same criteria on the same cells (cosim.peers.hosts).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.peers import hosts  # noqa: E402
from fmu_src.contact_laws import MODELS  # noqa: E402

RATIOS = (1e-3, 1e-2, 0.1, 0.5, 2.0)
STEPS = (1e-4, 1e-3, 5e-3, 1e-2)
HOSTS = [(i, o) for i in hosts.INTEGRATORS for o in hosts.ORDERS]


def free_table(unzip_dir) -> list[str]:
    lines = ["| model | worst peak force error | worst CR error | impacts | cells passing |", "|---|---|---|---|---|"]
    for model in MODELS:
        peak = cr = 0.0
        impacts, passing, total = set(), 0, 0
        for ratio in RATIOS:
            case, ref, h = hosts.free_masses(model, ratio)
            for integrator, order in HOSTS:
                v = hosts.judge_free(hosts.run_case(unzip_dir, case, integrator, order, h), ref)
                peak, cr = max(peak, abs(v.peak_error)), max(cr, abs(v.energy_error))
                impacts.add(v.impacts)
                passing += not v.misses
                total += 1
        lines.append(f"| {model} | {peak:.1e} | {cr:.1e} | {', '.join(map(str, sorted(impacts)))} | {passing}/{total} |")
    return lines


def model_table(unzip_dir) -> list[str]:
    """The two oscillators with every law at 1 ms (hertz, elastic, at 0.1 ms), worst over the 8 hosts."""
    lines = ["| model | h | reference impacts | hosts with the same impacts | worst peak force error | "
             "worst contact energy error | most energy created | cells passing |", "|---|---|---|---|---|---|---|---|"]
    for model in MODELS:
        h = 1e-4 if model == "hertz" else 1e-3
        case = hosts.two_oscillators(model)
        ref = hosts.reference(case)
        verdicts = [hosts.judge_structure(hosts.run_case(unzip_dir, case, i, o, h), ref, h) for i, o in HOSTS]
        same = sum(v.impacts == ref.impacts for v in verdicts)
        lines.append(f"| {model} | {h * 1e3:g} ms | {ref.impacts} | {same}/8 | "
                     f"{max(abs(v.peak_error) for v in verdicts):.2%} | {max(abs(v.energy_error) for v in verdicts):.2%} | "
                     f"{max(v.created for v in verdicts):+.3%} | {sum(not v.misses for v in verdicts)}/8 |")
    return lines


def structure_table(unzip_dir, case, steps) -> list[str]:
    ref = hosts.reference(case)
    head = " | ".join(f"h = {h * 1e3:g} ms" for h in steps)
    lines = [f"{case.name}: reference {ref.impacts} impacts, peak {ref.peak_force_N:.4g} N, contact energy "
             f"{float(ref.energies.contact_dissipated[-1]):.4g} J", "",
             f"| host | order | {head} |", "|---|---|" + "---|" * len(steps)]
    for integrator, order in HOSTS:
        cells = []
        for h in steps:
            v = hosts.judge_structure(hosts.run_case(unzip_dir, case, integrator, order, h), ref, h)
            mark = "" if not v.misses else (" **(warned)**" if v.warned else " **(fails)**")
            cells.append(f"{v.impacts} imp, {v.peak_error:+.2%}, {v.energy_error:+.2%}, {v.created:+.2%}{mark}")
        lines.append(f"| {integrator} | {order} | " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", default=None, help="pounding.fmu to test (default: built into build/fmus)")
    parser.add_argument("--quick", action="store_true", help="steps 1 and 10 ms only, no free masses")
    args = parser.parse_args(argv)
    from fmpy import extract

    from cosim.fmus import build_all

    fmu = args.fmu or str(build_all(names=("pounding",))["pounding"])
    unzip_dir = extract(fmu)
    t0 = time.perf_counter()
    if not args.quick:
        print("Free masses (the worked example, CR 0.4): each model in 8 hosts at h = "
              + ", ".join(f"{r:g}" for r in RATIOS) + " contact durations\n")
        print("\n".join(free_table(unzip_dir)), "\n")
    if not args.quick:
        print("Two oscillators with every contact law (worst over the 8 hosts; hertz is elastic, its "
              "energy error is relative to 1e-3 of the initial energy)\n")
        print("\n".join(model_table(unzip_dir)), "\n")
    steps = (1e-3, 1e-2) if args.quick else STEPS
    print("Structures: cell = impacts, peak force error, contact energy error, energy created "
          "(relative to the initial energy)\n")
    for case in (hosts.two_oscillators(), hosts.two_shear_buildings()):
        print("\n".join(structure_table(unzip_dir, case, steps)), "\n")
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    from cosim.master.fmi import exit_process

    exit_process(main())
