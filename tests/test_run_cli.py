"""The command line (cosim/run.py): default run, overrides, results folder, bad input."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.files import MARKER, OutputError
from cosim.master import output
from cosim.master.scene import SCENES
from cosim.cli import main as cli_main
from cosim.master.runner import run_scene

ROOT = Path(__file__).resolve().parents[1]


def run_cli(capsys, *args):
    code = cli_main(["run", *[str(a) for a in args]])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_nothing_written(out: Path):
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]


def test_readme_first_command_runs_the_default_scene(capsys, tmp_path, fmu_dir):
    # `python cosim/run.py` = default scene; shortened and pointed at the session's FMUs
    out = tmp_path / "default"
    code, stdout, stderr = run_cli(capsys, "--fmu-dir", fmu_dir, "--stop-time", 3, "--out", out)
    assert code == 0, stderr
    assert stdout.startswith("scene default:") and "peak displacement" in stdout and f"results: {out}" in stdout
    assert {p.name for p in out.iterdir()} == {"history.csv", "history_units.csv", "impacts.csv", "summary.json",
                                               "displacements.png", "energy.png", "contact_force.png",
                                               "hysteresis.png", MARKER}
    summary = json.loads((out / "summary.json").read_text())
    for key in ("peak_force_N", "impacts", "dissipated_energy_J", "wall_time_s", "communication_steps",
                "fmu_calls", "rollbacks", "energy_input_J", "energy_residual_J", "energy_residual_relative"):
        assert key in summary
    for b in ("left", "right"):
        assert {"peak_displacement_m", "peak_drift_m"} <= set(summary["buildings"][b])
    # long steps up to the first impact (2.02 s), 10 ms steps and refinements around it
    assert 50 < summary["communication_steps"] < 300 and summary["stop_time_s"] == 3.0
    # what the summary and the plots use, as instance.variable columns, at most one row per
    # 10 ms, at the communication points
    header = (out / "history.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "time"
    assert {"pounding_3.F", "pounding_3.impacts", "pounding_3.E_dissipated", "left.x[3]", "right.x[5]",
            "left.E_input", "right.E_damping"} <= set(header)
    assert "left.x[4]" not in header and "ground.ag_mean" not in header
    data = np.loadtxt(out / "history.csv", delimiter=",", skiprows=1)
    assert data.shape[1] == len(header) and data[0, 0] == 0.0 and data[-1, 0] == pytest.approx(3.0)
    assert 50 < data.shape[0] <= summary["communication_steps"] + 1
    assert np.all(np.diff(np.floor(data[:-1, 0] / 0.01 + 1e-9)) >= 1)


def test_record_all_at_an_output_interval(capsys, tmp_path, fmu_dir):
    """--record all: every output of every instance; --output-interval 0.1: a row per 0.1 s."""
    out = tmp_path / "all"
    code, _, stderr = run_cli(capsys, "--fmu-dir", fmu_dir, "--stop-time", 1, "--out", out, "--no-plots",
                              "--record", "all", "--output-interval", 0.1)
    assert code == 0, stderr
    header = (out / "history.csv").read_text().splitlines()[0].split(",")
    assert {"ground.ag_mean", "right.drift[5]", "pounding_3.in_contact", "left.x_peak[3]"} <= set(header)
    assert "left.x[4]" not in header  # only the storeys a building has
    data = np.loadtxt(out / "history.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(data[:, 0], np.arange(11) * 0.1, atol=1e-12)
    code, _, stderr = run_cli(capsys, "--fmu-dir", fmu_dir, "--stop-time", 1, "--out", tmp_path / "bad",
                              "--output-interval", -1)
    assert code == 2 and "output_interval = -1.0 must be a number >= 0" in stderr


def test_subprocess_smoke(tmp_path, fmu_dir):
    out = tmp_path / "fv"
    proc = subprocess.run([sys.executable, str(ROOT / "cosim" / "run.py"), "free_vibration", "--fmu-dir",
                           str(fmu_dir), "--stop-time", "1", "--out", str(out), "--no-plots",
                           "--set", "pounding.CR=0.5"], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "scene free_vibration" in proc.stdout
    assert json.loads((out / "summary.json").read_text())["scene"] == "free_vibration"


def test_overrides_and_coupling_reach_the_fmus(tmp_path, fmu_dir):
    run = run_scene("default", ["pounding.gap=0.05", "pounding.CR=0.5", "left.m[1]=2.5e5"], fmu_dir=fmu_dir,
                    stop_time=1.0, coupling="jacobi", step=0.02, write=False, progress=False)
    assert run.scene.contacts[0].parameters["gap"] == 0.05
    assert run.summary.coupling == "jacobi" and run.summary.cost.communication_steps == 50
    assert run.summary.step_s == 0.02


def test_bad_input_list(capsys):
    code, stdout, _ = run_cli(capsys, "--list")
    assert code == 0 and "kasai_maison" in stdout and "single_impact" in stdout


BAD_RECORD_LINES = "0.01\n0.02\n0.0x3\n0.04\n"


@pytest.mark.parametrize("case", ["missing_record", "malformed_record", "unknown_scene_key", "unknown_variable",
                                  "unknown_instance", "negative_mass", "negative_stiffness", "closed_gap",
                                  "fmu_range", "unknown_scene"])
def test_bad_input_is_one_line_before_anything_runs(capsys, tmp_path, fmu_dir, case):
    bad = tmp_path / "bad.txt"
    bad.write_text(BAD_RECORD_LINES)
    scene = tmp_path / "s.toml"
    scene.write_text((SCENES / "default.toml").read_text().replace("stop_time = 40.0", "stop_time = 1.0"))
    args, expect = {
        "missing_record": ([scene, "--set", f"ground.record={tmp_path / 'nothere.at2'}"], "nothere.at2"),
        "malformed_record": ([scene, "--set", f"ground.record={bad}", "--set", "ground.dt=0.01"],
                             f"{bad}, line 3"),
        "unknown_scene_key": ([scene, "--set", "left.mass=3"], "unknown key 'mass'"),
        "unknown_variable": ([scene, "--set", "pounding.gapp=0.02"], "no parameter 'gapp'"),
        "unknown_instance": ([scene, "--set", "middle.gap=0.02"], "no instance 'middle'"),
        "negative_mass": ([scene, "--set", "right.m[2]=-1e5"], "a mass must be > 0"),
        "negative_stiffness": ([scene, "--set", "left.k[1]=-1"], "a storey stiffness must be >= 0"),
        "closed_gap": ([scene, "--set", "left.x0[3]=0.05"], "already closed at t = 0"),
        "fmu_range": ([scene, "--set", "pounding.CR=1.5"], "CR = 1.5"),
        "unknown_scene": (["nosuchscene"], "not found"),
    }[case]
    if case == "unknown_scene_key":  # a key in the scene file itself
        scene.write_text(scene.read_text().replace("zeta = 0.05", "zeta = 0.05\nmass = 3", 1))
        args = [scene]
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(capsys, *args, "--fmu-dir", fmu_dir, "--out", out, "--no-progress")
    assert code == 2, (stdout, stderr)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and expect in lines[0], stderr
    assert stdout == ""
    assert_nothing_written(out)


def test_results_folder_is_complete_or_absent(tmp_path, fmu_dir, monkeypatch):
    run = run_scene("free_vibration", fmu_dir=fmu_dir, stop_time=0.5, write=False, progress=False)
    out = tmp_path / "r"

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(output, "plot_all", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        output.write_results(run.result, out)
    assert_nothing_written(out)
    monkeypatch.undo()
    output.write_results(run.result, out, plots=False)
    first = (out / "summary.json").read_text()
    # an earlier run's folder is replaced only on request, and then as a whole
    with pytest.raises(OutputError, match="--overwrite"):
        output.write_results(run.result, out, plots=False)
    output.write_results(run.result, out, plots=False, overwrite=True)
    assert (out / "summary.json").read_text() == first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r"]


def test_a_run_that_goes_unphysical_stops_with_one_line_and_writes_nothing(capsys, tmp_path, fmu_dir):
    # explicit penalty contact: the plain force law with 1e13 N/m^1.5 held over fixed 10 ms
    # steps cannot follow a contact that lasts a fraction of a millisecond
    out = tmp_path / "unstable"
    code, stdout, stderr = run_cli(capsys, "free_vibration", "--fmu-dir", fmu_dir, "--out", out, "--no-progress",
                                   "--set", "pounding.k=1e13", "--set", "pounding.resolve_impacts=false",
                                   "--set", "coupling=gauss-seidel", "--step", "0.01")
    assert code == 1 and stdout == ""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: pounding_1: t = ")
    assert_nothing_written(out)
