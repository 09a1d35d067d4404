"""Reproduction report of the seed paper (Naderpour, Barros, Khatami et al., c. 2016), figure by figure.

    pounding-cosim report --out docs/reproduction            # full report, a few minutes on 2 cores
    pounding-cosim report --out /tmp/quick --quick           # reduced grids (the test runs this)

Writes ``report.md`` and one PNG per claim into ``--out`` (replaced as a whole: the folder
is built under a temporary name and renamed when complete).  Every number is recomputed:

* single impacts at the physics level (:func:`fmu_src.single_impact.simulate_impact`, solve_ivp at
  tight tolerance) for the many-case figures (Fig 1, Fig 6 grids, sensitivities);
* through the FMUs (:mod:`cosim.apps.calibrate`: ``pounding.fmu`` between two free-mass
  ``building.fmu``) for the worked example, the calibrations the claims rest on and a subset
  of Fig 6;
* earthquake runs of the four record scenes (``cosim/scenes/{elcentro,kobe,sanfernando,parkfield}.toml``)
  through :class:`cosim.apps.study.CaseRunner` (FMUs loaded once, systems reset between cases) for Fig 8.

The paper's claims are numbers to check, not truth: the claims table says for each one what
we get and whether it holds.

Modules: :mod:`.common` (the paper's inputs, settings, the report being written),
:mod:`.single_impacts` (Figs 1, 5, 6, 7), :mod:`.earthquakes` (Fig 8), :mod:`.claims`
(the claims table), and here :func:`build_report`.
"""
from __future__ import annotations

import time
from pathlib import Path

from ...files import output_target, written_folder
from ..calibrate import FMURunner
from .claims import claims
from .common import COMMAND, PUBLISHED_LABELS, Claim, Report, Settings, printed_zeta
from .earthquakes import fig8
from .single_impacts import fig1, fig5, fig6, fig7

__all__ = ["build_report", "COMMAND", "PUBLISHED_LABELS", "Claim", "Report", "Settings", "printed_zeta"]


# ----------------------------------------------------------------------------------------------
def build_report(out: str | Path, quick: bool = False, fmu_dir: str | Path | None = None, jobs: int = 1,
                 overwrite: bool = False) -> Path:
    """Regenerate the report into ``out``; returns the folder.  The folder follows the output
    rule (:mod:`cosim.files`: a new or empty folder, or an earlier report's with ``overwrite``),
    is claimed before the work starts and written complete or not at all."""
    t0 = time.perf_counter()
    target = output_target(out, overwrite=overwrite)
    with written_folder(target, "report", overwrite=overwrite) as pending:
        _write_report(pending.path, quick, fmu_dir, jobs, t0)
    return pending.target


def _write_report(tmp: Path, quick: bool, fmu_dir, jobs: int, t0: float) -> None:
    rep = Report(Settings.make(quick), tmp, jobs=max(1, int(jobs)))
    timings = {}
    with FMURunner(fmu_dir) as runner:
        t = time.perf_counter()
        r1 = fig1(rep)
        timings["Fig 1"] = time.perf_counter() - t
        t = time.perf_counter()
        r5 = fig5(rep, runner, r1)
        timings["Fig 5"] = time.perf_counter() - t
        t = time.perf_counter()
        r6 = fig6(rep, runner)
        timings["Fig 6"] = time.perf_counter() - t
        t = time.perf_counter()
        r7 = fig7(rep, runner)
        timings["Fig 7"] = time.perf_counter() - t
        t = time.perf_counter()
        r8 = fig8(rep, runner)
        timings["Fig 8"] = time.perf_counter() - t
        fmu_runs = runner.runs
    claims(rep, r1, r5, r6, r7, r8)
    total = time.perf_counter() - t0
    head = [
        f"Regenerate: `{COMMAND}`" + (" (this is the reduced `--quick` version)" if quick else ""),
        "",
        "# Reproduction of the seed paper",
        "",
        "Naderpour, Barros, Khatami et al., \"Suggestion of an equation of motion to calculate the damping "
        "ratio during earthquake based on a cyclic procedure\", J. Theoretical and Applied Mechanics (c. 2016). "
        "Every number below is recomputed by this package; the paper's numbers are claims to check. SI units; "
        "1 kN mm = 1 J. Conventions: penetration delta > 0 in contact, CR = rebound / approach relative speed, "
        "Goldsmith's loss E_G = 0.5 m (1 - CR^2) v^2 with m = m1 m2 / (m1 + m2). The paper's crvk law (Eqs "
        "3.1, 3.4-3.9) is used in its regularised closed form (docs/contact_models.md), its constant either "
        "printed or calibrated.",
        "",
        f"Generated in {total:.0f} s ({', '.join(f'{k} {v:.0f} s' for k, v in timings.items())}; "
        f"{fmu_runs} single-impact co-simulations, {r8['count']} earthquake co-simulations).",
        "",
    ]
    text = "\n".join(head) + "\n" + "\n".join(rep.sections)
    (tmp / "report.md").write_text(text, encoding="utf-8")
