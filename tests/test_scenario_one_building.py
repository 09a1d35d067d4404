"""scenes/one_building.toml, and a gap that never closes: exactly the uncoupled responses."""
from __future__ import annotations

import tomllib

import numpy as np

from cosim.master.scene import SCENES
from scenario_checks import run


def test_one_building_has_no_contact_instance(fmu_dir):
    r = run("one_building", fmu_dir, stop_time=5.0)
    assert r.summary.instances == ["ground", "right"]
    assert not any(c.startswith("pounding") for c in r.result.columns)
    assert r.summary.impacts == 0 and r.summary.contacts == {}
    # a linear building alone: its energy balance closes to the accuracy of its integrator
    assert abs(r.summary.energy_residual_relative) < 1e-6


def test_a_gap_that_never_closes_gives_exactly_the_uncoupled_responses(fmu_dir):
    stop = 15.0  # s: covers the strong motion of El Centro
    wide = run("default", fmu_dir, ["pounding.gap=1.0"], stop_time=stop)
    assert wide.summary.instances == ["ground", "pounding_3", "left", "right"]
    assert wide.summary.impacts == 0
    assert np.all(wide.result["pounding_3.F"] == 0.0)           # exactly zero, every step
    assert np.all(wide.result["pounding_3.F_max"] == 0.0)
    assert np.all(wide.result["pounding_3.E_dissipated"] == 0.0)
    raw = tomllib.loads((SCENES / "default.toml").read_text())
    for name in ("left", "right"):
        alone = {k: v for k, v in raw.items() if k not in ("buildings", "pounding")}
        alone["name"] = f"{name}_alone"
        alone["buildings"] = {name: raw["buildings"][name]}
        single = run(alone, fmu_dir, stop_time=stop)
        assert single.summary.instances == ["ground", name]
        for column in single.result.columns:
            if column.startswith(f"{name}."):
                # bit-identical: the contact FMU hands over F = 0.0 exactly
                np.testing.assert_array_equal(wide.result[column], single.result[column], err_msg=column)
