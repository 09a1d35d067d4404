"""cosim/report.py --quick: every figure file and the claims table, with numbers that follow from physics."""
from __future__ import annotations

import math
import re

import pytest

from cosim.apps.report import COMMAND, build_report

FIGURES = ("fig1_hysteresis.png", "fig5_worked_example.png", "fig6_cr_accuracy.png", "fig7_experiment.png",
           "fig7b_experiment_sensitivity.png", "fig8a_gap.png", "fig8b_velocity.png", "fig8c_cr.png")


@pytest.fixture(scope="module")
def report(fmu_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "reproduction"
    folder = build_report(out, quick=True, fmu_dir=fmu_dir, jobs=1)
    return folder, (folder / "report.md").read_text(encoding="utf-8")


def test_every_figure_is_written_and_linked(report):
    folder, text = report
    for name in FIGURES:
        path = folder / name
        assert path.is_file(), name
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert path.stat().st_size > 20_000, name     # a plot with axes, labels and curves, not an empty canvas
        assert f"]({name})" in text, name
    assert not folder.with_name(folder.name + ".partial").exists()


def test_top_line_is_the_command(report):
    _, text = report
    assert text.splitlines()[0].startswith(f"Regenerate: `{COMMAND}`")


def test_claims_table(report):
    _, text = report
    table = text[text.index("## Claims table"):text.index("## Fig 1")]
    rows = [r for r in table.splitlines() if r.startswith("| ") and not r.startswith("| where")]
    assert len(rows) >= 20
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert len(cells) == 4 and all(cells), row
    verdicts = {cells[1]: cells[3] for cells in ([c.strip() for c in r.strip("|").split("|")] for r in rows)}
    assert verdicts["Goldsmith loss 4200 kN mm"] == "yes"
    assert verdicts["peak force approximately 12000 kN"] == "no"
    assert verdicts["error about 0.007 %"] == "no"
    assert any("physically impossible" in v for v in verdicts.values())


def test_worked_example_numbers(report):
    """The paper's 4189 J implies CR = sqrt(1 - 2 E / (m v^2)) with m = 100 kg, v = 10 m/s."""
    _, text = report
    cr = math.sqrt(1.0 - 2.0 * 4189.0 / (100.0 * 10.0 ** 2))
    assert f"4189 J implies CR {cr:.4f}" in text
    assert "| Goldsmith loss | 4200 kN mm | 4200.0 J |" in text
    # the calibrated crvk impact through the FMUs reaches CR 0.4 (printed to 5 decimals)
    assert re.search(r"\| achieved CR \| 0\.3527 \| 0\.40000 calibrated", text)
