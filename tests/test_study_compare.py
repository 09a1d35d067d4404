"""`pounding-cosim study compare`: two variants of a study side by side (cosim/apps/study/compare.py),
and the bundled inelastic_vs_elastic study that uses it (issue 18)."""
from __future__ import annotations

import csv

import pytest

from cosim.apps.study import StudyError, load_study, resolve_study
from cosim.apps.study.compare import paired, write_comparison
from cosim.cli import main

HEADER = ["case_id", "case", "ground.record", "left.hysteresis", "pounding.gap", "status", "error", "peak_force_N",
          "impacts"]


def results(tmp_path, rows):
    path = tmp_path / "results.csv"
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(HEADER)
        writer.writerows(rows)
    return path


ROWS = [["a", 0, "kobe1995", "linear", 0.0, "ok", "", 4.0e6, 10],
        ["b", 1, "kobe1995", "linear", 0.05, "ok", "", 2.0e6, 4],
        ["c", 2, "kobe1995", "bilinear", 0.0, "ok", "", 1.0e6, 5],
        ["d", 3, "kobe1995", "bilinear", 0.05, "failed", "boom", "", ""],
        ["e", 4, "elcentro1940", "linear", 0.0, "ok", "", 3.0e6, 8],
        ["f", 5, "elcentro1940", "bilinear", 0.0, "ok", "", 1.5e6, 2]]


def test_table_pairs_the_variants_and_gives_their_ratio(tmp_path):
    path = results(tmp_path, ROWS)
    md, png = write_comparison(path, "pounding.gap", "left.hysteresis", "ground.record", ["peak_force_N", "impacts"],
                               tmp_path / "out")
    text = md.read_text()
    assert "linear against bilinear (ratio = bilinear / linear)" in text and "1 failed or unstable row(s)" in text
    assert "| kobe1995 | 0 | 4e+06 | 1e+06 | 0.25 | 10 | 5 | 0.5 |" in text
    assert "| kobe1995 | 0.05 | 2e+06 |  |  | 4 |  |  |" in text          # the failed variant left empty
    assert "| elcentro1940 | 0 | 3e+06 | 1.5e+06 | 0.5 | 8 | 2 | 0.25 |" in text
    assert png.stat().st_size > 5_000


def test_compare_needs_two_variants_and_one_row_each(tmp_path):
    with pytest.raises(StudyError, match="takes 1 value"):
        paired(results(tmp_path, [r for r in ROWS if r[3] == "linear"]), "pounding.gap", "left.hysteresis",
               "ground.record", ["impacts"])
    with pytest.raises(StudyError, match="several rows share"):
        paired(results(tmp_path, ROWS), "pounding.gap", "left.hysteresis", None, ["impacts"])
    with pytest.raises(StudyError, match="no column 'nope'"):
        paired(results(tmp_path, ROWS), "pounding.gap", "left.hysteresis", None, ["nope"])


def test_command_line(tmp_path, capsys):
    path = results(tmp_path, ROWS)
    assert main(["study", "compare", str(path), "--x", "pounding.gap", "--pair", "left.hysteresis", "--panels",
                 "ground.record", "--y", "peak_force_N", "--out", str(tmp_path / "cli")]) == 0
    assert (tmp_path / "cli" / "comparison.md").exists()
    assert main(["study", "compare", str(tmp_path / "missing.csv"), "--x", "a", "--pair", "b", "--y", "c",
                 "--out", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err


def test_the_bundled_study_pairs_elastic_and_yielding_buildings():
    study = load_study(resolve_study("inelastic_vs_elastic"))
    cases = study.cases()
    assert len(cases) == 4 * 2 * 11
    variants = {(c.values["left.hysteresis"], c.values["right.hysteresis"]) for c in cases}
    assert variants == {("linear", "linear"), ("bilinear", "bilinear")}
    gaps = sorted({c.values["pounding.gap"] for c in cases})
    assert gaps[0] == 0.0 and gaps[-1] == 0.1 and len(gaps) == 11
