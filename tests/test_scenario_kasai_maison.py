"""scenes/kasai_maison.toml: 15- and 8-storey buildings pounding floor to floor at floors 1-8."""
from __future__ import annotations

import pytest

from scenario_checks import assert_contact_work_reaches_the_floors, assert_energy_balance, run


@pytest.fixture(scope="module")
def kasai(fmu_dir):
    return run("kasai_maison", fmu_dir, stop_time=12.0)  # s: the strong motion of El Centro


def test_one_contact_instance_per_floor_level(kasai):
    scene = kasai.scene
    assert [c.name for c in scene.contacts] == [f"pounding_{f}" for f in range(1, 9)]
    assert [(lv.left, lv.floor_left, lv.right, lv.floor_right) for lv in scene.levels] == \
        [("tall", f, "low", f) for f in range(1, 9)]
    assert scene.n_storeys("tall") == 15 and scene.n_storeys("low") == 8
    # contact masses default to the floor masses at each level
    assert scene.contacts[7].parameters["m1"] == 9.0e5 and scene.contacts[7].parameters["m2"] == 4.5e5


def test_pounding_at_several_levels(kasai):
    contacts = kasai.summary.contacts
    assert sum(1 for c in contacts.values() if c.impacts > 0) >= 2
    # relative floor displacements grow with height: the top level pounds the most
    assert contacts["pounding_8"].impacts == max(c.impacts for c in contacts.values())


def test_every_level_hands_its_force_to_its_floors(kasai):
    assert_contact_work_reaches_the_floors(kasai.result, kasai.scene)


def test_energy_balance(kasai):
    assert_energy_balance(kasai.summary, 0.01)
