"""Wall time of the in-step impact resolver per impact and per model (prints a markdown table).

    python benchmarks/bench_resolver.py [--repeats 20] [--cr 0.65]

One impact of two free masses (the worked example's k = 1.8974e11 N/m^1.5, m = 100 kg, 10 m/s),
the host moving them exactly under the held mean force, at communication steps of the whole
impact, 1/10 and 1/100 of the contact duration.  No assertion: the figures depend on the machine.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmu_src.contact_laws import MODELS, ContactLaw, published_zeta  # noqa: E402
from fmu_src.resolver import ImpactResolver  # noqa: E402
from fmu_src.single_impact import simulate_impact  # noqa: E402


def benchmark(repeats: int = 20, CR: float = 0.65, ratios=(None, 0.1, 0.01)) -> str:
    """Wall time of :class:`ImpactResolver` per impact, per model (prints a markdown table).

    ``ratios``: communication step / contact duration (None: the whole impact in one step).
    Each cell is the best of ``repeats`` impacts; ``substeps`` is the accepted internal steps.
    """
    head = " | ".join("one step" if r is None else f"h = t_c x {r:g}" for r in ratios)
    lines = [f"| model | {head} | substeps (one step) |", "|---|" + "---|" * (len(ratios) + 1)]
    for model in MODELS:
        law = ContactLaw(model, 1.8974e11, 1.5, 100.0, published_zeta(model, CR, 1.5))
        t_c = simulate_impact(law, 10.0, rtol=1e-8).contact_duration
        cells, subs = [], 0
        for ratio in ratios:
            h = 3.0 * t_c if ratio is None else ratio * t_c
            best = math.inf
            for _ in range(repeats):
                r = ImpactResolver(law)
                delta, rate, count = -0.3 * 10.0 * h, 10.0, 0
                t0 = time.perf_counter()
                while True:   # host: free masses moved exactly under the held mean force
                    out = r.step(delta, rate, h)
                    count += out.substeps
                    delta += rate * h - 0.5 * out.mean_force / law.m * h * h
                    rate -= out.mean_force / law.m * h
                    if r.impacts and not r.in_contact:
                        break
                best = min(best, time.perf_counter() - t0)
            cells.append(f"{best * 1e3:.2f} ms")
            if ratio is None:
                subs = count
        lines.append(f"| {model} | " + " | ".join(cells) + f" | {subs} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20, help="impacts per cell; the best is shown")
    parser.add_argument("--cr", type=float, default=0.65, help="coefficient of restitution")
    args = parser.parse_args(argv)
    print(benchmark(args.repeats, args.cr))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
