"""The separation of a scene (cosim/apps/separation_scene.py, ``pounding-cosim separation``) and the
spectrum command: the exact answer checked by co-simulation runs just below and above it, the
bisection method against the exact one, files and bad input."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from cosim.apps.separation import RULE_NAMES, Separation, uncoupled_separation
from cosim.apps.separation_scene import (CHECK_FACTORS, bisect_separation, scene_separations, separation_csv,
                                         write_separations)
from cosim.apps.spectra import MAX_SAMPLE_PERIODS, period_grid, record_spectra
from cosim.cli import main
from cosim.master.loader import load_scene
from cosim.peers.reference import scene_inputs, solve_reference
from fmu_src.ground_records import load_record
from fmu_src.response_spectrum import response_spectrum

RECORDS = ("elcentro1940", "kobe1995", "sanfernando1971", "parkfield1966")


@pytest.fixture(scope="module")
def seed_rows(catalog):
    """The default pair under the four seed records at 0.3 g, checked by co-simulation."""
    return scene_separations("default", records=RECORDS, pga_g=0.3, catalog=catalog)


def test_default_pair_under_the_seed_records_is_confirmed_by_cosimulation(seed_rows):
    assert [r.record for r in seed_rows] == list(RECORDS)
    scene = load_scene("default")
    inputs = scene_inputs(scene)
    left, right = inputs["buildings"]
    for row in seed_rows:
        assert row.method == "exact" and row.level == "pounding_3"
        rec = load_record(row.record, target_pga_g=0.3)
        # the command's answer is the core's (cosim/apps/separation.py, tested against the
        # monolithic reference there) for this record: identical numbers
        assert row.separation_m == uncoupled_separation(left, right, 3, 3, rec.acceleration, rec.dt).gap
        assert row.pga_g == pytest.approx(0.3, rel=1e-12)
        # the check: at 0.99 S the floors touch in the co-simulation, at 1.01 S they never do
        assert row.check is not None and row.check.factors == CHECK_FACTORS
        assert row.check.contacts_below >= 1, row
        assert row.check.contacts_above == 0, row
        assert row.check.passed
        # the code rules bracket nothing in general, but ABS is an upper bound of the exact answer
        # for linear buildings (|x_l - x_r| <= |x_l| + |x_r| at every instant)
        assert row.estimate.rules_history["ABS"] >= row.separation_m
    # the table of docs/running.md (phase 1 numbers, m, rounded to 0.1 mm)
    assert [round(r.separation_m, 4) for r in seed_rows] == [0.1368, 0.1435, 0.0626, 0.0884]


def test_bisection_through_cosimulation_agrees_with_the_exact_separation(catalog):
    # the hook for yielding buildings, run on linear ones where the exact answer is known; 8 s
    # hold El Centro's peak closing (4.89 s)
    overrides = ["stop_time=8"]
    exact = scene_separations("default", overrides, check=False, catalog=catalog)[0]
    bisected = scene_separations("default", overrides, check=False, method="bisection", catalog=catalog)[0]
    assert bisected.method == "bisection" and bisected.runs >= 3
    # the bracket ends at max(1e-5 m, 1e-4 S) = 1.4e-5 m; the co-simulation's own position error
    # before the first impact is 3e-5 m on El Centro (docs/accuracy.md): 1e-4 m covers both
    assert bisected.separation_m == pytest.approx(exact.separation_m, abs=1e-4)
    # peaks of the uncoupled co-simulation run: building.fmu's in-step peaks (x_peak, the final
    # read: its long steps keep few rows), exact for the record across knots; steps inside one
    # record interval hold the ground's mean there.  Measured against the exact modal peaks:
    # -1.2e-7 (left) and +9.1e-7 (right) relative; 5e-6 leaves room for round-off of other platforms
    for k in range(2):
        assert bisected.estimate.peaks_history[k] == pytest.approx(exact.estimate.peaks_history[k], rel=5e-6)


def test_yielding_buildings_separation_by_bisection_against_the_reference(catalog):
    """default_inelastic (bilinear storeys): the command picks bisection; its answer against the
    monolithic reference's uncoupled responses (solve_ivp with the same storey law, sampled every
    0.1 ms), confirmed by the runs at 0.99 and 1.01 times it, and far from the linear answer."""
    overrides = ["stop_time=6"]        # the peak closing is at 3.01 s; both buildings yield before
    row = scene_separations("default_inelastic", overrides, catalog=catalog)[0]
    assert row.method == "bisection" and row.runs >= 5
    scene = load_scene("default_inelastic", overrides)
    inputs = scene_inputs(scene)
    inputs.update(contacts=[], output_dt=1e-4)
    ref = solve_reference(**inputs)
    closing = ref.displacements(0)[:, 2] - ref.displacements(1)[:, 2]
    # at the peak the relative velocity is zero: sampling 0.1 ms misses at most a dt^2 / 2 = 5e-8 m
    assert row.separation_m == pytest.approx(float(closing.max()), abs=5e-5)   # measured 1.4e-5 m
    assert row.estimate.exact.time == pytest.approx(float(ref.t[np.argmax(closing)]), abs=0.02)
    assert min(float(np.max(mu)) for mu in ref.ductility) > 2.0       # both buildings yield clearly
    assert row.check is not None and row.check.passed, row.check
    linear = scene_separations("default_inelastic", overrides + ["left.hysteresis=linear", "right.hysteresis=linear"],
                               check=False)[0]
    assert linear.method == "exact" and linear.separation_m > 1.2 * row.separation_m


def test_bisection_brackets_a_known_threshold():
    calls = []

    def touches(gap):
        calls.append(gap)
        return gap < 0.123456

    found = bisect_separation(touches, Separation(0.12, 1.0))
    assert 0.123456 <= found.gap <= 0.123456 + max(1e-5, 1e-4 * 0.1235)
    assert len(calls) < 30


def test_files_and_table(seed_rows, tmp_path):
    folder = write_separations(seed_rows, tmp_path / "sep")
    rows = list(csv.DictReader((folder / "separation.csv").open()))
    assert [r["record"] for r in rows] == list(RECORDS)
    for name in RULE_NAMES:
        assert float(rows[0][f"{name}_m"]) == pytest.approx(seed_rows[0].estimate.rules_history[name], rel=1e-5)
        assert float(rows[0][f"{name}_spectrum_m"]) == pytest.approx(seed_rows[0].estimate.rules_spectrum[name],
                                                                     rel=1e-5)
    assert all(r["check"] == "passed" for r in rows)
    assert (folder / "separation.png").stat().st_size > 10_000
    assert "0.99 S / 1.01 S" in (folder / "separation.txt").read_text()
    assert separation_csv(seed_rows).splitlines()[0].startswith("level,left,right,record,pga_g,method,separation_m")


def test_separation_command(fmu_dir, tmp_path, capsys):
    code = main(["separation", "default", "--records", "kobe1995", "--pga", "0.3", "--no-check", "--fmu-dir",
                 str(fmu_dir), "--out", str(tmp_path / "s")])
    out = capsys.readouterr().out
    assert code == 0
    assert "kobe1995" in out and "0.1435" in out
    assert (tmp_path / "s" / "separation.csv").exists()


@pytest.mark.parametrize("argv, message", [
    (["separation", "free_vibration"], "has no ground motion"),
    (["separation", "one_building"], "has no pounding level"),
    (["separation", "default", "--pga", "-1"], "--pga -1.0: a PGA in g must be > 0"),
    (["separation", "default", "--records", "nosuchrecord"], "nosuchrecord"),
])
def test_separation_bad_input(argv, message, fmu_dir, tmp_path, capsys):
    code = main(argv + ["--fmu-dir", str(fmu_dir), "--out", str(tmp_path / "never")])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()


# -- spectrum command -----------------------------------------------------------------------------------
def test_spectrum_command_writes_the_spectrum(tmp_path, capsys):
    code = main(["spectrum", "elcentro1940", "--periods", "0.1", "0.5", "2", "--damping", "0.02", "--out",
                 str(tmp_path)])
    assert code == 0
    assert "elcentro1940: PGA 0.313 g; 2% damping" in capsys.readouterr().out
    lines = (tmp_path / "elcentro1940_zeta0.02.csv").read_text().splitlines()
    assert lines[0].startswith("# elastic response spectra, damping ratio 0.02")
    table = list(csv.DictReader(lines[1:]))
    rec = load_record("elcentro1940")
    expected = response_spectrum(rec.acceleration, rec.dt, [0.1, 0.5, 2.0], 0.02)
    # written with 10 significant digits
    assert [float(r["elcentro1940.Sd_m"]) for r in table] == pytest.approx(expected.displacement, rel=1e-9)
    assert (tmp_path / "elcentro1940_zeta0.02.png").stat().st_size > 10_000
    # never over an existing file
    assert main(["spectrum", "elcentro1940", "--periods", "0.1", "--damping", "0.02", "--out", str(tmp_path)]) == 2
    assert "exists: spectra are never written over a file" in capsys.readouterr().err


def test_spectrum_scaling_and_period_grids():
    grid = period_grid(["0.05:5:30"])
    assert grid.size == 30 and grid[0] == pytest.approx(0.05) and grid[-1] == pytest.approx(5.0)
    assert np.allclose(np.diff(np.log(grid)), np.log(100) / 29)
    assert period_grid(None).size == 100
    a, b = record_spectra(["kobe1995", "kobe1995"], [0.3, 1.0], target_pga_g=0.3)
    assert (a.name, b.name) == ("kobe1995", "kobe1995_2")
    rec = load_record("kobe1995")
    raw = response_spectrum(rec.acceleration, rec.dt, [0.3, 1.0])
    # a spectrum is linear in the record: scaled to 0.3 g it is raw * 0.3 g / PGA
    assert a.displacement == pytest.approx(raw.displacement * 0.3 / rec.pga_g, rel=1e-12)


@pytest.mark.parametrize("argv, message", [
    (["spectrum", "elcentro1940", "--periods", "0:5:30"], "needs 0.001 <= START < STOP <= 100 s"),
    (["spectrum", "elcentro1940", "--periods", "1:2"], "write START:STOP:NUM"),
    (["spectrum", "elcentro1940", "--periods", "200"], "period 200 s is outside the allowed range"),
    (["spectrum", "elcentro1940", "--damping", "1.5", "--periods", "1"], "outside the allowed range 0 <= damping < 1"),
    (["spectrum", "/nonexistent/rec.csv"], "/nonexistent/rec.csv"),
    (["spectrum", "elcentro1940", "kobe1995", "sanfernando1971", "parkfield1966", "--periods", "0.01:10:1000"],
     f"the limit is {MAX_SAMPLE_PERIODS:.0e}"),
])
def test_spectrum_bad_input(argv, message, tmp_path, capsys):
    code = main(argv + ["--out", str(tmp_path / "never")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()
