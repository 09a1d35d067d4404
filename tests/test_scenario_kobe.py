"""scenes/kobe.toml: a seed-paper record scaled to PGA 0.3 g, default buildings."""
from __future__ import annotations

import pytest

from cosim.peers.reference import reference_for_scene
from cosim.master.results import summarize
from cosim.master.loader import load_scene
from scenario_checks import assert_record_scene, run, simulate_scene


def test_kobe_record_scaled_and_pounding(fmu_dir):
    assert_record_scene(run("kobe", fmu_dir))


@pytest.fixture(scope="module")
def kobe_reference(catalog):
    return reference_for_scene(load_scene("kobe", [], catalog))


@pytest.mark.parametrize("h", [0.01, 0.005, 0.002])
def test_fixed_step_gauss_seidel_converges_on_the_long_attached_impacts(catalog, kobe_reference, h):
    # Kobe's first impact starts with 413 N in its first 5 ms step and its contacts last up to
    # 160 ms while the storeys push.  The contact FMU once read that weak first step as a host
    # holding the force one step late (Jacobi) and kept the error: at h = 5 ms it lost 4.3 % of
    # the dissipated energy, 20 times more than at 10 ms.  Measured now: 0.34, 0.02, 0.001 %.
    ref = kobe_reference
    result = simulate_scene(catalog, "kobe", ["coupling=\"gauss-seidel\"", f"step={h}"])
    s = summarize(result)
    assert s.impacts == ref.impacts == 9
    # 1 %: the accuracy study's criterion for peak force and dissipated energy
    assert s.peak_force_N == pytest.approx(ref.peak_force_N, rel=0.01)
    assert s.dissipated_energy_J == pytest.approx(ref.dissipated_energy_J, rel=0.01)
    # the energy balance closes within 0.3 % of the input (0.21 % at 10 ms, 0.05 % at 5 ms)
    assert abs(s.energy_residual_J) <= 0.003 * s.energy_input_J
