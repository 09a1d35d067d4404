"""scenes/free_vibration.toml: no ground motion, released from an initial displacement."""
from __future__ import annotations

import pytest

from scenario_checks import assert_contact_work_reaches_the_floors, assert_energy_balance, run


@pytest.fixture(scope="module")
def free(fmu_dir):
    return run("free_vibration", fmu_dir)


def test_no_ground_motion_fmu(free):
    assert free.summary.instances == ["pounding_1", "left", "right"]
    assert not any(c.startswith("ground.") for c in free.result.columns)
    assert free.summary.energy_input_J == free.summary.energy_initial_J > 0


def test_energy_decays(free):
    r, s = free.result, free.summary
    mech = sum(r[f"{b}.E_kinetic"] + r[f"{b}.E_strain"] for b in ("left", "right"))
    # 2 % damping over 10 s (about 15 periods of the stiffer building) plus pounding
    assert mech[-1] < 0.5 * mech[0]
    assert s.impacts >= 1


def test_the_contact_never_feeds_energy_into_the_buildings(free):
    # a dissipative contact element can only take energy out of the buildings
    r = free.result
    assert r["left.E_external"][-1] + r["right.E_external"][-1] <= 0.0


def test_energy_balance(free):
    assert_contact_work_reaches_the_floors(free.result, free.scene)
    assert_energy_balance(free.summary, 0.01)
