"""Parameter studies (cosim/study.py): same numbers as single runs, resume, failures, bad input.

A local Dask cluster of 2 worker processes is started once for the module
(a few seconds); the studies use short stop times to stay fast.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from dataclasses import replace

import pytest

from cosim.cli import main as cli_main
from cosim.master.results import Cost, Summary
from cosim.master.scene import Override
from cosim.apps.study import (StudyError, case_id, case_row, load_study, plot_results, read_results,
                         run_study)
from study_helpers import SMALL, local_client

ROOT = Path(__file__).resolve().parents[1]

# Columns that are pure functions of the simulation (wall times and worker names are not).
PHYSICS = ("peak_force_N", "impacts", "dissipated_energy_J", "max_penetration_m", "peak_impact_velocity_m_s",
           "first_impact_s", "left.peak_displacement_m", "left.peak_drift_m", "left.peak_base_shear_N",
           "right.peak_displacement_m", "right.peak_drift_m", "right.peak_base_shear_N",
           "left.hysteretic_energy_J", "right.residual_drift_m", "energy_input_J",
           "energy_residual_relative", "communication_steps")


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def client():
    yield from local_client(n_workers=2, silence_logs=40)



def test_small_study_matches_single_runs(tmp_path, fmu_dir, client):
    """3 gaps x 2 records on 2 worker processes: every row equals run_scene of the same case.

    Equality is exact: same FMUs, same start values, same coupling; the study
    only reuses instances through fmi2Reset, which must leave no trace.
    """
    from cosim.master.runner import run_scene
    from cosim.master.system import Catalog

    study = load_study(write(tmp_path / "small.toml", SMALL))
    result = run_study(study, tmp_path / "out", client=client, fmu_dir=fmu_dir, progress=False)
    assert (result.n_cases, result.ran, result.skipped) == (6, 6, 0)
    header, rows = read_results(result.csv)
    assert sorted(r["case"] for r in rows) == list(range(6))
    assert len({r["case_id"] for r in rows}) == 6
    assert len({r["worker"] for r in rows}) == 2  # both worker processes took cases
    assert sum(r["impacts"] or 0 for r in rows) > 0  # the comparison covers pounding, not only free motion
    assert sum(r["status"] == "ok" for r in rows) >= 4
    with Catalog(fmu_dir) as catalog:
        for case in study.cases():
            row = next(r for r in rows if r["case_id"] == case.id)
            try:
                alone = run_scene(study.scene, study.fixed + case.overrides, catalog=catalog, write=False,
                                  progress=False)
            except Exception as exc:  # noqa: BLE001 - a run the master refuses: the row says why
                assert row["status"] in ("failed", "unstable") and str(exc) in row["error"], case.values
                continue
            expected = case_row(alone.summary, study.energy_tolerance)
            assert row["status"] == expected["status"] == "ok"
            for column in PHYSICS:
                assert row[column] == expected[column], (case.values, column)

    # each worker built its FMU instances once and reset them for its other cases; a failed
    # case drops them (an FMU that refused a step is not trusted again), so it may add one build
    built = client.run(lambda dask_worker: (f"{os.uname().nodename}:{os.getpid()}",
                                            [p.runner.systems_built for n, p in dask_worker.plugins.items()
                                             if n.startswith("cosim-study-")]))
    for worker, counts in built.values():
        failed = sum(r["status"] != "ok" for r in rows if r["worker"] == worker)
        assert len(counts) == 1 and 1 <= counts[0] <= 1 + failed, (worker, counts, failed)

    import pyarrow.parquet as pq

    table = pq.read_table(result.parquet)
    assert table.num_rows == 6 and table.column("case").to_pylist() == list(range(6))
    assert table.column("peak_force_N").to_pylist() == [r["peak_force_N"] for r in sorted(rows, key=lambda r: r["case"])]

    png = plot_results(result.csv, "pounding.gap", "peak_force_N", by="ground.record")
    assert png.stat().st_size > 1000
    with pytest.raises(StudyError, match="another column varies"):
        plot_results(result.csv, "pounding.gap", "peak_force_N")  # two records on one curve


KILL = """
name = "killme"
scene = "default"
[set]
stop_time = 1.5
[vary]
"pounding.gap" = { start = 0.0, stop = 0.029, num = 30 }
"""


def test_resume_after_kill(tmp_path, fmu_dir, client):
    """A study killed (SIGKILL) midway, with a torn last line, is completed by --resume:
    every case exactly once, the rows written before the kill kept verbatim."""
    study_file = write(tmp_path / "kill.toml", KILL)
    out = tmp_path / "out"
    csv_path = out / "results.csv"
    proc = subprocess.Popen([sys.executable, str(ROOT / "cosim" / "study.py"), str(study_file), "--workers", "1",
                             "--out", str(out), "--fmu-dir", str(fmu_dir), "--no-progress"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if csv_path.exists() and csv_path.read_text().count("\n") >= 5:  # header + 4 rows
                break
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the study and its worker processes, all at once
        proc.wait()
    before = csv_path.read_text().splitlines(keepends=True)
    assert 5 <= len(before) < 31, "the study must be killed midway"
    with open(csv_path, "a") as f:
        f.write(before[-1][:40])  # a row torn by the kill

    with pytest.raises(StudyError, match="--resume"):
        run_study(study_file, out, client=client, fmu_dir=fmu_dir, progress=False)
    result = run_study(study_file, out, client=client, fmu_dir=fmu_dir, resume=True, progress=False)
    assert result.skipped == len(before) - 1 and result.ran == 30 - result.skipped
    after = csv_path.read_text().splitlines(keepends=True)
    assert after[:len(before)] == before  # nothing written before the kill was changed
    header, rows = read_results(csv_path)
    ids = [r["case_id"] for r in rows]
    assert len(ids) == 30 and set(ids) == {c.id for c in load_study(study_file).cases()}
    assert all(r["status"] == "ok" for r in rows)

    again = run_study(study_file, out, client=client, fmu_dir=fmu_dir, resume=True, progress=False)
    assert (again.ran, again.skipped) == (0, 30)


def test_a_failing_case_is_recorded_and_the_study_goes_on(tmp_path, fmu_dir, client):
    """gap 0 with the left roof already displaced 5 cm: that one combination overlaps at t = 0."""
    study = write(tmp_path / "fail.toml", """
name = "fail"
scene = "default"
[set]
stop_time = 0.5
[vary]
"pounding.gap" = [0.1, 0.0]
"left.x0[3]" = [0.0, 0.05]
""")
    result = run_study(study, tmp_path / "out", client=client, fmu_dir=fmu_dir, progress=False)
    _, rows = read_results(result.csv)
    assert (result.ran, result.failed, len(rows)) == (4, 1, 4)
    bad = [r for r in rows if r["status"] != "ok"]
    assert len(bad) == 1 and bad[0]["pounding.gap"] == 0.0 and bad[0]["left.x0[3]"] == 0.05
    assert bad[0]["status"] == "failed" and "already closed at t = 0" in bad[0]["error"]


# -- bad input: a clear error before any case runs -------------------------------------------------
def bad(tmp_path, body: str) -> Path:
    return write(tmp_path / "bad.toml", 'name = "bad"\nscene = "default"\n' + body)


def test_unknown_variable(tmp_path, fmu_dir):
    study = bad(tmp_path, '[vary]\n"pounding.gapp" = [0.0, 0.1]\n')
    with pytest.raises(StudyError, match=r"gapp.*did you mean 'gap'"):
        run_study(study, tmp_path / "out", fmu_dir=fmu_dir, scheduler="tcp://127.0.0.1:1", progress=False)
    assert not (tmp_path / "out").exists()
    study = bad(tmp_path, '[vary]\n"middle.m[1]" = [1.0, 2.0]\n')
    with pytest.raises(StudyError, match=r"no instance 'middle'"):
        run_study(study, tmp_path / "out", fmu_dir=fmu_dir, progress=False)


@pytest.mark.parametrize("spec, message", [
    ("{ start = 0.0, stop = 0.2, num = 0 }", "num = 0"),
    ("[]", "has no values"),
    ("{ start = 0.0, stop = 0.2 }", "missing"),
    ("0.1", "a fixed value goes in"),
])
def test_empty_or_malformed_range(tmp_path, spec, message):
    with pytest.raises(StudyError, match=message) as info:
        load_study(bad(tmp_path, f'[vary]\n"pounding.gap" = {spec}\n'))
    assert "bad.toml, line 4" in str(info.value)


def test_zip_lengths_must_match(tmp_path):
    with pytest.raises(StudyError, match="one length"):
        load_study(bad(tmp_path, '[[zip]]\n"left.v0[1]" = [1.0, 2.0]\n"right.v0[1]" = [-1.0]\n'))


def test_value_out_of_the_fmu_range_reports_the_fmu_message(tmp_path, fmu_dir, capsys):
    """CR = 1.5: the scene loader accepts any number; the pounding FMU's own check refuses it."""
    study = bad(tmp_path, '[vary]\n"pounding.CR" = [0.5, 1.5]\n')
    assert cli_main(["study", str(study), "--fmu-dir", str(fmu_dir), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "pounding.CR=1.5" in err and "CR = 1.5" in err and "0 < CR <= 1" in err
    assert not (tmp_path / "out").exists()


def test_unreachable_scheduler(tmp_path, fmu_dir):
    study = bad(tmp_path, '[set]\nstop_time = 0.1\n[vary]\n"pounding.gap" = [0.0]\n')
    start = time.monotonic()
    with pytest.raises(StudyError, match="cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'"):
        run_study(study, tmp_path / "out", fmu_dir=fmu_dir, scheduler="tcp://127.0.0.1:9", connect_timeout=1.0,
                  progress=False)
    assert time.monotonic() - start < 30  # validation + a 1 s connection timeout, not a hang
    assert not (tmp_path / "out").exists()


# -- pieces ----------------------------------------------------------------------------------------
def test_case_identity_and_ranges(tmp_path):
    assert case_id({"a": 1, "b": "x"}) == case_id({"b": "x", "a": 1.0})  # order and int/float spelling
    assert case_id({"a": 0.03}) != case_id({"a": 0.030000000000000002})
    study = load_study(bad(tmp_path, '[vary]\n"pounding.gap" = { start = 0.0, stop = 0.2, num = 21 }\n'
                                     '"ground.record" = ["kobe1995", "elcentro1940"]\n'))
    cases = study.cases()
    assert len(cases) == 42 and cases[6].values == {"pounding.gap": 0.03, "ground.record": "kobe1995"}
    assert cases[7].values == {"pounding.gap": 0.03, "ground.record": "elcentro1940"}  # last axis fastest
    assert cases[6].overrides == [Override("pounding", "gap", 0.03), Override("ground", "record", "kobe1995")]


def test_energy_created_is_unstable():
    """A negative energy residual beyond the tolerance is energy nobody put in: status unstable."""
    summary = Summary(scene="s", description="", coupling="adaptive", step_s=0.01, stop_time_s=1.0, instances=[],
                      peak_force_N=1.0, impacts=1, dissipated_energy_J=1.0, buildings={}, contacts={},
                      energy_initial_J=0.0, energy_input_J=100.0, energy_kinetic_J=0.0, energy_strain_J=0.0,
                      energy_damping_J=0.0, energy_contact_J=1.0, energy_residual_J=-20.0,
                      energy_residual_relative=-0.2, cost=Cost(0.1, 10, 0, 50))
    row = case_row(summary, energy_tolerance=0.05)
    assert row["status"] == "unstable" and "energy created: 0.2" in row["error"]
    assert case_row(replace(summary, energy_residual_relative=-0.01), 0.05)["status"] == "ok"
    assert case_row(replace(summary, peak_force_N=float("nan")), 0.05)["status"] == "unstable"
