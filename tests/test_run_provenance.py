"""Results that say what was run (issue 15 point 5): the scene as run, the overrides, the package
version, FMU and record checksums in summary.json; the terminal header from the effective
parameters; record paths relative to the scene file; summary.json fed back as a scene."""
from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from cosim import __version__
from cosim.cli import main
from cosim.master.loader import load_scene
from cosim.master.output import format_summary
from cosim.master.runner import run_scene
from cosim.master.scene import SceneError
from fmu_src.ground_records import BUNDLED

OVERRIDES = ["ground.record=kobe1995", "stop_time=6", "pounding_3.CR=0.5", "left.m[1]=2.5e5", "pounding.gap=0.005"]


def sha256(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


@pytest.fixture(scope="module")
def first_run(fmu_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("first") / "run"
    return run_scene("default", OVERRIDES, fmu_dir=fmu_dir, out=out, plots=False, progress=False)


def test_summary_json_says_what_ran(first_run, fmu_dir):
    summary = json.loads((first_run.folder / "summary.json").read_text())
    assert summary["overrides"] == ["ground.record='kobe1995'", "stop_time=6", "pounding_3.CR=0.5",
                                    "left.m[1]=250000.0", "pounding.gap=0.005"]
    scene = summary["scene_as_run"]
    assert scene["ground"]["record"] == "kobe1995" and scene["stop_time"] == 6.0
    assert scene["buildings"]["left"]["m[1]"] == 2.5e5 and scene["buildings"]["left"]["m[2]"] == 3.0e5
    assert scene["pounding"]["CR"] == 0.5 and scene["pounding"]["gap"] == 0.005
    # every parameter is there, defaults included: the file does not depend on later defaults
    assert scene["ground"]["sa_damping"] == 0.05 and scene["buildings"]["right"]["damping"] == "rayleigh"
    assert "m[4]" not in scene["buildings"]["left"]            # only the floors the building has
    made = summary["provenance"]
    assert made["package_version"] == __version__
    for name in ("ground_motion", "building", "pounding"):
        assert made["fmus"][name]["sha256"] == sha256(fmu_dir / f"{name}.fmu")
    assert made["record"] == dict(parameter="kobe1995", file=str(BUNDLED["kobe1995"].path),
                                  sha256=sha256(BUNDLED["kobe1995"].path))
    # the line of what ran comes from the effective parameters, not the file's description
    assert summary["system"] == ("left 3-storey (T1 = 0.5 s) and right 5-storey (T1 = 1 s); pounding at floor 3: "
                                 "gap 0.005 m, jankowski CR 0.5; under kobe1995 (PGA 0.3 g)")
    assert "El Centro" in summary["description"]                # the file's own text, kept as written


def test_terminal_header_follows_the_overrides(first_run):
    text = format_summary(first_run.summary)
    first = text.splitlines()[0]
    assert first.startswith("scene default: left 3-storey") and "under kobe1995 (PGA 0.3 g)" in first
    assert "El Centro" not in text and "3 cm" not in text
    assert text.splitlines()[1] == "  overrides: " + ", ".join(first_run.summary.overrides)


def test_summary_json_fed_back_as_a_scene_reproduces_the_run(first_run, fmu_dir, tmp_path):
    again = run_scene(first_run.folder / "summary.json", fmu_dir=fmu_dir, out=tmp_path / "again", plots=False,
                      progress=False)
    # bit for bit: the same parameters reach the same FMUs
    assert again.result.columns == first_run.result.columns
    assert np.array_equal(again.result.time, first_run.result.time)
    assert np.array_equal(again.result.values, first_run.result.values)
    assert (tmp_path / "again" / "history.csv").read_bytes() == (first_run.folder / "history.csv").read_bytes()
    assert again.summary.scene_as_run == first_run.summary.scene_as_run
    assert again.summary.impacts == first_run.summary.impacts > 0


def test_a_json_that_is_not_a_summary_is_refused(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('{"scene": "default"}')
    with pytest.raises(SceneError, match="must be a run's summary.json with the key 'scene_as_run'"):
        load_scene(path)
    path.write_text("{not json")
    with pytest.raises(SceneError, match="invalid JSON"):
        load_scene(path)


def test_per_level_parameters_round_trip():
    scene = load_scene("kasai_maison", ["pounding_3.CR=0.5", "pounding_5.gap=0.05"])
    raw = scene.as_run()
    # what differs between levels is written per level (floor masses m1, m2 differ too), the rest once
    p = raw["pounding"]
    assert p["pounding_3"]["CR"] == 0.5 and p["pounding_4"]["CR"] == 0.65 and "CR" not in p and p["k"] == 2.75e9
    assert p["pounding_5"]["gap"] == 0.05 and p["pounding_4"]["gap"] == 0.04 and "gap" not in p
    assert raw["pounding"]["floors"] == [[i, i] for i in range(1, 9)]
    again = load_scene(raw)
    assert [{k: c.value(k) for k in scene.contacts[0].parameters} for c in again.contacts] == \
        [{k: c.value(k) for k in scene.contacts[0].parameters} for c in scene.contacts]
    assert again.as_run() == raw
    raw["pounding"]["pounding_99"] = {"CR": 0.5}
    with pytest.raises(SceneError, match="'pounding_99' is not a contact instance"):
        load_scene(raw)


def test_record_paths_are_relative_to_the_scene_file(tmp_path, monkeypatch, fmu_dir):
    folder = tmp_path / "project"
    folder.mkdir()
    t = np.arange(0.0, 2.0, 0.01)
    (folder / "pulse.csv").write_text("time,acc\n" + "\n".join(f"{x:.2f},{0.2 * np.sin(8 * x):.6f}" for x in t))
    text = (load_scene("default").path.read_text()
            .replace('record = "elcentro1940"', 'record = "pulse.csv"').replace("stop_time = 40.0", "stop_time = 1.0"))
    (folder / "scene.toml").write_text(text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)                    # the scene works from any folder
    scene = load_scene(folder / "scene.toml")
    assert scene.ground.parameters["record"] == str(folder / "pulse.csv")
    run = run_scene(folder / "scene.toml", fmu_dir=fmu_dir, write=False, progress=False)
    assert run.summary.provenance["record"]["sha256"] == sha256(folder / "pulse.csv")
    # given with --set, a relative path is the working folder's (as every command-line path)
    (elsewhere / "mine.csv").write_text((folder / "pulse.csv").read_text())
    scene = load_scene(folder / "scene.toml", ["ground.record=mine.csv"])
    assert scene.ground.parameters["record"] == str(elsewhere / "mine.csv")
    # bundled names stay names
    assert load_scene("default").ground.parameters["record"] == "elcentro1940"


def test_run_command_header(fmu_dir, tmp_path, capsys):
    code = main(["run", "default", "--set", "ground.record=kobe1995", "--set", "stop_time=2", "--set",
                 "pounding.gap=0", "--fmu-dir", str(fmu_dir), "--out", str(tmp_path / "r"), "--no-plots",
                 "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0
    assert "under kobe1995 (PGA 0.3 g)" in out and "gap 0 m" in out and "El Centro" not in out
