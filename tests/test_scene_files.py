"""Scene files: every bundled scene validates; bad scenes and overrides give one-line errors."""
from __future__ import annotations

import re
import textwrap

import pytest

from cosim.master.loader import bundled_scenes, load_scene
from cosim.master.scene import SceneError

REQUIRED = {"default", "elcentro", "kobe", "sanfernando", "parkfield", "single_impact",
            "free_vibration", "one_building", "kasai_maison", "default_inelastic", "kasai_maison_inelastic"}


BASE = """
name = "t"
stop_time = 1.0
step = 0.01
[ground]
record = "elcentro1940"
[buildings.left]
m = [1.0e5, 2.0e5]
k = [4.0e7, 3.0e7]
[buildings.right]
m = [3.0e5]
k = [5.0e7]
[pounding]
floors = [1]
gap = 0.02
"""


def write(tmp_path, text=BASE, name="t.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def one_line_error(excinfo) -> str:
    text = str(excinfo.value)
    assert "\n" not in text
    return text


def test_required_scenes_are_bundled():
    assert REQUIRED <= set(bundled_scenes())


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_bundled_scene_validates_against_the_fmus(name, catalog):
    scene = load_scene(name, catalog=catalog)
    assert scene.name == name and scene.description
    kinds = [s.fmu for s in scene.instances()]
    # only what the scene calls for
    assert kinds.count("ground_motion") == (0 if name in ("single_impact", "free_vibration") else 1)
    assert kinds.count("pounding") == {"one_building": 0, "kasai_maison": 8, "kasai_maison_inelastic": 8}.get(name, 1)
    assert kinds.count("building") == (1 if name == "one_building" else 2)


def test_instances_connections_and_default_contact_masses(tmp_path, catalog):
    scene = load_scene(write(tmp_path), catalog=catalog)
    assert [s.name for s in scene.instances()] == ["ground", "pounding_1", "left", "right"]
    left = scene.instance("left").parameters
    assert left["n_storeys"] == 2 and left["m[2]"] == 2.0e5 and left["k[1]"] == 4.0e7
    contact = scene.instance("pounding_1").parameters
    assert contact["m1"] == 1.0e5 and contact["m2"] == 3.0e5  # floor masses at the level
    # each body takes its own signed force (F1 = -F on the left, F2 = F on the right), no factors
    forces = {(c.target, c.input): (c.output, c.factor) for c in scene.connections() if c.output in ("F1", "F2")}
    assert forces == {("left", "F[1]"): ("F1", 1.0), ("right", "F[1]"): ("F2", 1.0)}
    assert ("ground", "ag_mean", "left", "ag") in {(c.source, c.output, c.target, c.input)
                                                   for c in scene.connections()}


def test_explicit_contact_mass_and_floor_pairs(tmp_path, catalog):
    text = BASE.replace("floors = [1]", "floors = [1, [2, 1]]\nm1 = 5.0e4")
    scene = load_scene(write(tmp_path, text), catalog=catalog)
    assert [c.name for c in scene.contacts] == ["pounding_1", "pounding_2_1"]
    assert all(c.parameters["m1"] == 5.0e4 for c in scene.contacts)
    assert scene.contacts[1].parameters["m2"] == 3.0e5


def test_overrides(tmp_path, catalog):
    text = BASE.replace("floors = [1]", "floors = [1, [2, 1]]")
    scene = load_scene(write(tmp_path, text), ["pounding.gap=0.05", "pounding_1.CR=0.5", "left.m[1]=7e4",
                                               "ground.record=kobe1995", "stop_time=3"], catalog)
    assert [c.parameters["gap"] for c in scene.contacts] == [0.05, 0.05]
    assert scene.contacts[0].parameters["CR"] == 0.5 and "CR" not in scene.contacts[1].parameters
    assert scene.instance("left").parameters["m[1]"] == 7.0e4
    assert scene.contacts[0].parameters["m1"] == 7.0e4  # the default follows the overridden mass
    assert scene.ground.parameters["record"] == "kobe1995" and scene.stop_time == 3.0


@pytest.mark.parametrize("override, match", [
    ("nowhere.gap=0.1", "no instance 'nowhere'"),
    ("pounding.gapp=0.1", "no parameter 'gapp'.*did you mean 'gap'"),
    ("left.mass[1]=1", "no parameter 'mass\\[1\\]'"),
    ("left.x[1]=1", "is an output, not a parameter"),
    ("pounding.CR=high", "CR = 'high' must be a Real"),
    ("duration=3", "unknown top-level key 'duration'"),
    ("gap", "expected instance.variable=value"),
    # a bad value from --set is located at the --set, not at a file line that holds a good one
    ("left.m[1]=-5", r"^--set left\.m\[1\]=-5: buildings\.left\.m\[1\] = -5\.0 kg: a mass must be > 0$"),
    ("pounding.gap=-0.1", r"^--set pounding\.gap=-0\.1: pounding\.gap = -0\.1 m is outside the allowed range 0 <= gap "
                          r"\(pounding\.fmu\)$"),
    ("pounding_1.k=0", r"^--set pounding_1\.k=0: pounding_1\.k = 0\.0 must be > 0$"),
    ("step=-1", r"^--set step=-1: step = -1 must be a number > 0"),
    # the --set as typed: the value as written, not as parsed
    ("left.m=[-5.0, 3.0e5]", r"^--set left\.m=\[-5\.0, 3\.0e5\]: buildings\.left\.m\[1\] = -5\.0 kg"),
])
def test_bad_override_is_a_one_line_error(tmp_path, catalog, override, match):
    with pytest.raises(SceneError) as info:
        load_scene(write(tmp_path), [override], catalog)
    assert re.search(match, one_line_error(info)), str(info.value)


def test_a_bad_file_value_beside_a_good_override_is_located_in_the_file(tmp_path, catalog):
    path = write(tmp_path, BASE.replace("m = [1.0e5, 2.0e5]", "m = [1.0e5, -2.0e5]"))
    with pytest.raises(SceneError) as info:
        load_scene(path, ["left.m[1]=5.0e4"], catalog)
    assert re.search(r"t\.toml, line 8: buildings\.left\.m\[2\] = -200000\.0 kg", one_line_error(info))


def test_override_of_an_instance_the_scene_does_not_have(catalog):
    with pytest.raises(SceneError, match="no ground motion"):
        load_scene("free_vibration", ["ground.target_pga=3"], catalog)
    with pytest.raises(SceneError, match="no contact instance"):
        load_scene("one_building", ["pounding.gap=0.1"], catalog)


@pytest.mark.parametrize("edit, match", [
    (("step = 0.01", "step = 0.01\nduraton = 3"), r"t\.toml, line 5: unknown key 'duraton'"),
    (("k = [5.0e7]", "k = [5.0e7]\nmass = 3"), r"line 13: unknown key 'mass' in \[buildings.right\]"),
    (("gap = 0.02", "gap = 0.02\nCoR = 0.5"), r"unknown key 'CoR' in \[pounding\].*did you mean 'CR'"),
    (("m = [3.0e5]", "m = [-3.0e5]"), r"buildings.right.m\[1\] = -300000.0 kg: a mass must be > 0"),
    (("k = [4.0e7, 3.0e7]", "k = [4.0e7, -3.0e7]"), r"k\[2\] = -30000000.0 N/m: a storey stiffness must be >= 0"),
    (("k = [4.0e7, 3.0e7]", "k = [4.0e7]"), r"k has 1 values for n_storeys = 2"),
    (("gap = 0.02", "gap = -0.02"), r"line \d+: pounding.gap = -0.02 m is outside the allowed range 0 <= gap"),
    (("floors = [1]", "floors = [3]"), r"floors entry 3: left has floors 1..2, right has floors 1..1"),
    (("step = 0.01", "step = 0"), r"step = 0 must be a number > 0"),
    (("name = \"t\"", "name = \"a b\""), r"name = 'a b' is not a plain name"),
    (("step = 0.01", "step = 0.01\ncoupling = \"newton\""), r"coupling = 'newton' is not one of"),
    (("[ground]", "[ground\n"), r"invalid TOML"),
    # the storey law's own rules (issue 18's bad input), at the line of the parameter
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "bilinear"\nFy = [1e5, 0.0]'),
     r"line 11: buildings.left.Fy\[2\] = 0.0 N is outside the allowed range 0 < Fy\[2\]"),
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "bilinear"\nFy = [1e5, -2e5]'),
     r"line 11: buildings.left.Fy\[2\] = -200000.0 N is outside the allowed range 0 < Fy\[2\]"),
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "bilinear"\nFy = 1e5\nalpha = 1.0'),
     r"line 12: buildings.left.alpha = 1.0 is outside the allowed range 0 <= alpha < 1"),
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "bouc_wen"\nFy = 1e5\nbw_gamma = 0.9'),
     r"line 12: buildings.left.bw_beta - bw_gamma = -0.4 is outside the allowed range"),
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "bouc_wen"\nFy = 1e5\nbw_beta = -0.6\nbw_gamma = -0.6'),
     r"line 12: buildings.left.bw_beta \+ bw_gamma = -1.2 is outside the allowed range bw_beta \+ bw_gamma > 0"),
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "elastoplastic"'),
     r"line 10: buildings.left.hysteresis = 'elastoplastic' is not allowed: one of 'linear'"),
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "bilinear"\nFy = 1e5\nx0 = [0.01, 0.01]'),
     r"line 12: buildings.left: the initial drift of storey 1 \(x0\) is 0.01 m, beyond its yield drift"),
    (("k = [4.0e7, 3.0e7]", 'k = [4.0e7, 3.0e7]\nhysteresis = "bilinear"\nFy = 1e5\nzeta = 0.0\nalpha = 0.0'),
     r"buildings.left.alpha = 0 with zeta = 0: a yielded storey without hardening"),
])
def test_bad_scene_is_a_one_line_error(tmp_path, catalog, edit, match):
    old, new = edit
    assert old in BASE
    with pytest.raises(SceneError) as info:
        load_scene(write(tmp_path, BASE.replace(old, new, 1)), catalog=catalog)
    assert re.search(match, one_line_error(info)), str(info.value)


def test_gap_closed_at_start_needs_an_explicit_choice(tmp_path, catalog):
    text = BASE.replace("m = [3.0e5]", "m = [3.0e5]\nx0 = [-0.03]")  # x1 - x2 - gap = 0 + 0.03 - 0.02 > 0
    with pytest.raises(SceneError) as info:
        load_scene(write(tmp_path, text), catalog=catalog)
    msg = one_line_error(info)
    assert "already closed at t = 0" in msg and "allow_initial_overlap" in msg and "0.01 m > 0" in msg
    scene = load_scene(write(tmp_path, text.replace("gap = 0.02", "gap = 0.02\nallow_initial_overlap = true")),
                       catalog=catalog)
    assert scene.allow_initial_overlap
    # a gap that is exactly closed (touching, no penetration) is allowed
    load_scene(write(tmp_path, text.replace("x0 = [-0.03]", "x0 = [-0.02]")), catalog=catalog)


def test_scalar_arrays_and_single_elements(tmp_path, catalog):
    text = BASE.replace("m = [1.0e5, 2.0e5]\nk = [4.0e7, 3.0e7]", 'n_storeys = 3\nm = 1.0e5\nk = 4.0e7\n"x0[3]" = -0.01')
    scene = load_scene(write(tmp_path, text), catalog=catalog)
    p = scene.instance("left").parameters
    assert [p[f"m[{i}]"] for i in (1, 2, 3)] == [1.0e5] * 3 and p["x0[3]"] == -0.01


def test_ground_scaling_targets_as_engineers_write_them(tmp_path, catalog):
    """target_sa = {period, value[, damping]} and target_pga_g become ground_motion.fmu parameters."""
    path = write(tmp_path, BASE.replace('record = "elcentro1940"',
                                        'record = "elcentro1940"\ntarget_sa = {period = 0.5, value = 4.9}'))
    ground = load_scene(path, catalog=catalog).ground.parameters
    assert ground["target_sa"] == 4.9 and ground["sa_period"] == 0.5 and "sa_damping" not in ground
    ground = load_scene(path, ["ground.target_sa={period=1.0, value=3.0, damping=0.02}"],
                        catalog=catalog).ground.parameters
    assert (ground["target_sa"], ground["sa_period"], ground["sa_damping"]) == (3.0, 1.0, 0.02)
    ground = load_scene(path, ["ground.target_sa=0", "ground.target_pga_g=0.3"], catalog=catalog).ground.parameters
    assert ground["target_pga_g"] == 0.3


@pytest.mark.parametrize("ground, overrides, match", [
    ('target_sa = {period = 0.5}', [],
     r"t\.toml, line 7: ground\.target_sa = \{'period': 0\.5\}: missing 'value'; write target_sa = "
     r"\{period = <s>, value = <m/s\^2>\}"),
    ('target_sa = {period = 0.5, value = 4.9, T = 1}', [], r"t\.toml, line 7: .*unknown key 'T'"),
    ('target_sa = {period = 0.5, value = 4.9}\nsa_period = 1.0', [],
     r"t\.toml, line 7: ground\.sa_period is given twice: as sa_period and as target_sa\.period"),
    ('target_pga = 2.9\ntarget_pga_g = 0.3', [],
     r"t\.toml, line 8: \[ground\]: at most one of target_pga, target_pga_g, target_sa may be set; "
     r"got target_pga = 2\.9 and target_pga_g = 0\.3 \(set the others to 0\)"),
    ('target_pga = 2.9', ["ground.target_sa={period=0.5, value=4.9}"],
     r"^--set ground\.target_sa=\{period=0\.5, value=4\.9\}: \[ground\]: at most one of"),   # as typed
])
def test_bad_scaling_targets_are_one_line_errors(tmp_path, catalog, ground, overrides, match):
    path = write(tmp_path, BASE.replace('record = "elcentro1940"', 'record = "elcentro1940"\n' + ground))
    with pytest.raises(SceneError) as info:
        load_scene(path, overrides, catalog=catalog)
    assert re.search(match, one_line_error(info)), str(info.value)
