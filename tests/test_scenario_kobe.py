"""scenes/kobe.toml: a seed-paper record scaled to PGA 0.3 g, default buildings."""
from __future__ import annotations

from scenario_checks import assert_record_scene, run


def test_kobe_record_scaled_and_pounding(fmu_dir):
    assert_record_scene(run("kobe", fmu_dir))
