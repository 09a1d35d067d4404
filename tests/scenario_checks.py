"""Shared checks for the tests/test_scenario_*.py files (one file per bundled scene)."""
from __future__ import annotations

import numpy as np

from cosim.master.runner import run_scene


def run(name, fmu_dir, overrides=(), **kwargs):
    """Run a bundled scene in memory (no result folder, no progress bar)."""
    return run_scene(name, overrides, fmu_dir=fmu_dir, write=False, progress=False, **kwargs)


def simulate_scene(catalog, scene, overrides=(), **options):
    """Load ``scene`` (name, path or dict) with ``overrides`` and simulate it on ``catalog``'s FMUs."""
    from cosim.master.simulate import simulate
    from cosim.master.system import System
    from cosim.master.loader import load_scene

    loaded = load_scene(scene, list(overrides), catalog)
    with System(loaded, catalog) as system:
        return simulate(system, progress=False, **options)


def assert_contact_work_reaches_the_floors(result, scene):
    """The buildings receive each contact's mean force F of [t, t+h] in the same step, on
    the right floors and with opposite signs.

    Under a zero-order hold a constant force F on floor f does the work F * (x_f(t+h) - x_f(t))
    over the step, so the increments of each building's E_external must equal the sum over
    the contact levels acting on it of -F dx (left body) or +F dx (right body).  A wrong
    sign, floor or a step of delay (F of [t-h, t]) breaks the identity by the size of the
    work itself.
    """
    for b in scene.buildings:
        expected = np.zeros(len(result.time) - 1)
        delayed = np.zeros_like(expected)
        for level in scene.levels:
            if b.name not in (level.left, level.right):
                continue
            floor = level.floor_left if b.name == level.left else level.floor_right
            sign = -1.0 if b.name == level.left else 1.0
            force = result[f"{level.instance}.F"]
            dx = np.diff(result[f"{b.name}.x[{floor}]"])
            expected += sign * force[1:] * dx
            delayed += sign * force[:-1] * dx
        work = np.diff(result[f"{b.name}.E_external"])
        scale = max(np.abs(work).max(), 1.0)
        # 1e-9: round-off of the building's exact integration, far below a step's work
        np.testing.assert_allclose(work, expected, rtol=0, atol=1e-9 * scale)
        if np.abs(expected).max() > 0:
            assert np.abs(work - delayed).max() > 1e-3 * scale


def assert_energy_balance(summary, tolerance=0.01):
    """E_initial + E_input = kinetic + strain + structural damping + contact dissipation,
    within ``tolerance`` of the input energy (the residual holds the coupling error)."""
    total_in = summary.energy_input_J
    assert total_in > 0
    assert abs(summary.energy_residual_J) <= tolerance * total_in, (
        f"energy residual {summary.energy_residual_J:.4g} J = "
        f"{100 * summary.energy_residual_relative:.3g} % of the input {total_in:.4g} J")


def assert_record_scene(run_result, target_pga=2.942):
    """A paper-record scene: the record is scaled to the common PGA and the buildings pound."""
    r, s = run_result.result, run_result.summary
    # the ground FMU reports the PGA of the scaled record: the scene's target, to round-off
    assert r["ground.pga"][-1] == __import__("pytest").approx(target_pga, rel=1e-12)
    # the buildings see the scaled record: no sample above its PGA
    assert np.abs(r["ground.ag_mean"]).max() <= target_pga * (1 + 1e-12)
    assert s.impacts >= 1 and s.peak_force_N > 0
    assert s.energy_input_J > 0
    assert_contact_work_reaches_the_floors(r, run_result.scene)
