"""scenes/default.toml: two buildings of different periods pounding under El Centro 1940."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.master.simulate import simulate
from cosim.master.system import Catalog, System
from cosim.master.results import impact_times, summarize
from cosim.master.loader import load_scene
from scenario_checks import assert_contact_work_reaches_the_floors, assert_energy_balance


@pytest.fixture(scope="module")
def default_run(fmu_dir):
    """The whole 40 s record, every output at every communication point; keeps the instances
    alive to read the FMUs directly."""
    with Catalog(fmu_dir) as catalog:
        scene = load_scene("default", catalog=catalog)
        with System(scene, catalog) as system:
            result = simulate(system, progress=False, record="all", output_interval=0.0)
            reported = {c.name: c.instance.get(["E_dissipated", "impacts"]) for c in system.contacts}
            yield scene, result, summarize(result), reported


def test_only_the_instances_the_scene_calls_for(default_run):
    scene, result, summary, _ = default_run
    assert summary.instances == ["ground", "pounding_3", "left", "right"]
    # adaptive coupling: long steps (up to 0.32 s) where every gap is proven open, 10 ms steps
    # near a possible contact, dyadic refinements only around the impacts (11 here)
    steps = summary.cost.communication_steps
    stats = result.stats
    assert summary.stop_time_s == 40.0 and 300 < steps < 1000 and stats["long_steps"] > 100
    # most of the run in long steps (measured 37.6 of the 40 s since the proof computes the
    # ground's response, 411 steps; the rest are 10 ms steps in sustained contact)
    h_all = np.diff(result.time)
    assert h_all[h_all > 0.01 * (1 + 1e-9)].sum() > 0.75 * 40.0
    # the buildings step with every step; the ground motion is read ahead in chunks of up to
    # 0.32 s (knots); the contact sleeps where its gap provably stays open and catches up in
    # steps of at most 40 ms (cosim/master/dormancy.py): fewer calls than 10 ms steps would make
    assert result.cost.do_steps == {"ground": stats["ground_steps"], "left": steps, "right": steps,
                                    "pounding_3": steps - stats["dormant_steps"] + stats["catch_up_steps"]}
    assert stats["ground_steps"] < 40.0 / 0.32 + 20 and result.cost.do_steps["pounding_3"] < 4000 / 2
    h = np.diff(result.time)
    assert h.max() == pytest.approx(0.32, rel=1e-12) and h.min() < 0.01 / 2
    # every refined step ends within 0.2 s of an impact: before it the predicted closure of the
    # gap, during it the contact time scale, after it the step grows back by at most 2x per step
    refined = result.time[1:-1][h[:-1] < 0.01 * (1 - 1e-9)]   # the last step is clipped at stop_time
    onsets = impact_times(result, "pounding_3")
    assert refined.size and np.all(np.min(np.abs(refined[:, None] - onsets[None, :]), axis=1) < 0.2)
    assert summary.cost.rollbacks == 0 and summary.cost.fmu_calls > 4 * steps


def test_the_buildings_pound_several_times(default_run):
    _, result, summary, _ = default_run
    assert summary.impacts >= 3
    assert summary.peak_force_N > 0 and summary.dissipated_energy_J > 0
    # the force acts only while the gap is closed somewhere in the step
    force = result["pounding_3.F"]
    assert np.all(force >= 0)


def test_contact_dissipation_is_what_the_pounding_fmus_report(default_run):
    _, result, summary, reported = default_run
    assert summary.dissipated_energy_J == sum(r["E_dissipated"] for r in reported.values())
    assert summary.impacts == sum(r["impacts"] for r in reported.values())
    assert summary.energy_contact_J == summary.dissipated_energy_J


def test_gauss_seidel_hands_the_impulse_over_in_the_same_step(default_run):
    scene, result, _, _ = default_run
    assert_contact_work_reaches_the_floors(result, scene)


def test_energy_balance_closes_within_one_percent(default_run):
    assert_energy_balance(default_run[2], 0.01)


def test_jacobi_runs_with_the_same_counters(fmu_dir):
    from scenario_checks import run

    r = run("default", fmu_dir, coupling="jacobi", stop_time=5.0)
    assert r.summary.coupling == "jacobi" and r.summary.cost.communication_steps == 500
    assert set(r.result.cost.do_steps.values()) == {500}


def test_system_reset_reuses_the_instances_for_a_new_case(fmu_dir):
    # parameter studies build the System once and reset it per case (fmi2Reset)
    with Catalog(fmu_dir) as catalog:
        case_a = load_scene("default", ["stop_time=4", "pounding.gap=0.03"], catalog)
        case_b = load_scene("default", ["stop_time=4", "pounding.gap=0.01", "pounding.CR=0.5"], catalog)
        with System(case_a, catalog) as system:
            instances = [n.instance for n in system.nodes]
            simulate(system, progress=False)
            system.reset(case_b)
            reused = simulate(system, progress=False)
            assert [n.instance for n in system.nodes] == instances
        with System(case_b, catalog) as fresh_system:
            fresh = simulate(fresh_system, progress=False)
    assert reused.columns == fresh.columns
    np.testing.assert_array_equal(reused.values, fresh.values)  # bit-identical after fmi2Reset
    with Catalog(fmu_dir) as catalog, System(case_a, catalog) as system:
        other = load_scene("kasai_maison", catalog=catalog)
        with pytest.raises(ValueError, match="other instances"):
            system.reset(other)
