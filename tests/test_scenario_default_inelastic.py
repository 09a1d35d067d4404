"""cosim/scenes/default_inelastic.toml: the default scene with bilinear storeys (issue 18).

What the issue asks the scene to show, at the package's default settings, against the
monolithic reference (cosim/peers/reference.py with the same storeys, rtol 1e-10): the same
impacts, peak force within 1 %, dissipated contact energy within 2 %, peak drift and
residual drift within 1 %, and an energy balance that closes with the storeys' hysteretic
energy to 0.5 % of the input; and how its yield shears were chosen (the scene file's
comment), recomputed here.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from cosim.master.loader import load_scene
from cosim.master.names import column, element_name
from cosim.master.output import format_summary
from cosim.master.results import energy_history
from cosim.peers.reference import reference_for_scene, scene_inputs
from fmu_src.building_response import integrator_for
from fmu_src.ground_records import load_record
from fmu_src.hysteresis import StoreyHysteresis
from fmu_src.record_knots import step_knots
from scenario_checks import run


@pytest.fixture(scope="module")
def inelastic(fmu_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("default_inelastic") / "run"
    from cosim.master.runner import run_scene

    result = run_scene("default_inelastic", [], fmu_dir=fmu_dir, out=out, progress=False)
    ref = reference_for_scene(result.scene, {"rtol": 1e-10, "output_dt": 0.01})
    return result, ref


def final(result, building, variable, n):
    # the final read (every output), whatever history.csv keeps
    return np.array([result.result.value_at_end(column(building, element_name(variable, i))) for i in range(1, n + 1)])


def test_yield_shears_are_the_elastic_storey_shears_over_r(catalog):
    """Fy[i] = peak elastic shear of storey i of the building alone (in-step peaks, first-order
    hold on the record) / 2.5, to two digits, as the scene file says."""
    scene = load_scene("default_inelastic", [], catalog)
    inputs = scene_inputs(scene)
    rec = load_record("elcentro1940")
    rec = rec.scaled(2.942 / rec.pga)
    for b, spec in enumerate(scene.buildings):
        building = inputs["buildings"][b]
        it = integrator_for(building, StoreyHysteresis())
        n = building.n
        state = it.initial_state(np.zeros(n), np.zeros(n))
        for i in range(4000):
            t0, t1 = 0.01 * i, 0.01 * (i + 1)
            kt, ka = step_knots(rec, t0, t1)
            it.advance(state, kt - t0, ka, np.zeros(n))
        it.resolve_peaks(state)
        elastic = state.peak_drift * building.stiffnesses
        fy = np.array([float(spec.value(element_name("Fy", i))) for i in range(1, n + 1)])
        np.testing.assert_array_equal(fy, [float(f"{v / 2.5:.2g}") for v in elastic])


def test_at_default_settings_it_matches_the_reference(inelastic):
    result, ref = inelastic
    s = result.summary
    assert (result.scene.coupling, result.scene.step) == ("adaptive", 0.01)
    assert s.impacts == ref.impacts >= 2
    assert s.peak_force_N == pytest.approx(ref.peak_force_N, rel=0.01)                 # measured 0.38 %
    assert s.dissipated_energy_J == pytest.approx(ref.energies.contact_dissipated[-1], rel=0.02)   # 0.11 %
    for b, spec in enumerate(result.scene.buildings):
        n = result.scene.n_storeys(spec.name)
        summary = s.buildings[spec.name]
        # in-step peaks of every storey (measured within 0.18 %; 0.5 % while a step inside one
        # record interval held the ground acceleration's mean, before yielding buildings got the
        # record's knots over every step)
        np.testing.assert_allclose(final(result, spec.name, "drift_peak", n), ref.peak_drifts[b], rtol=0.01)
        np.testing.assert_allclose(final(result, spec.name, "mu", n), ref.ductility[b], rtol=0.01)
        assert summary.peak_ductility == pytest.approx(ref.ductility[b].max(), rel=0.01)
        # the residual drift the summary reports (the storey of largest magnitude); every storey
        # within 1 % of that building's largest (measured 0.11 %; 0.74 % with the held mean)
        k = int(np.argmax(np.abs(ref.residual_drifts[b])))
        assert summary.residual_drift_storey == k + 1
        assert summary.residual_drift_m == pytest.approx(ref.residual_drifts[b][k], rel=0.01)
        residual = final(result, spec.name, "drift_residual", n)
        assert np.abs(residual - ref.residual_drifts[b]).max() < 0.01 * abs(ref.residual_drifts[b][k])
        assert summary.hysteretic_energy_J == pytest.approx(ref.hysteretic_energy_J[b], rel=0.01)
        # what the scene was designed for: peak ductility 2 to 4 in each building
        assert 2.0 <= summary.peak_ductility <= 4.0
    # long steps where the proof keeps every gap open and every storey elastic
    # (cosim/master/gap_bound.py): measured 936 steps (4000 base steps without that proof)
    assert result.result.cost.communication_steps < 1200
    assert result.result.stats["long_steps"] > 0


def test_peak_base_shear_does_not_depend_on_the_masters_steps(inelastic, fmu_dir):
    """summary.json's peak_base_shear_N of the yielding buildings is building.fmu's in-step
    V_peak[1]: the default run's long steps (up to 0.32 s through yielding) give the base-step
    run's (10 ms everywhere) to 0.1 % (measured: equal, 0.0), where the step ends alone fell 0.98 %
    and 0.58 % short."""
    from cosim.master.runner import run_scene

    result, _ = inelastic
    base = run_scene("default_inelastic", [], fmu_dir=fmu_dir, write=False, progress=False, long_steps=False)
    assert base.result.stats.get("long_steps", 0) == 0
    assert result.result.cost.communication_steps < 0.5 * base.result.cost.communication_steps
    short_by = []
    for name in ("left", "right"):
        long_run = result.summary.buildings[name].peak_base_shear_N
        assert long_run == pytest.approx(base.summary.buildings[name].peak_base_shear_N, rel=1e-3)
        assert long_run == result.result.value_at_end(column(name, "V_peak[1]"))
        sampled, _ = result.result.peaks[column(name, "base_shear")]
        short_by.append(1.0 - sampled / long_run)
    # what the summary reported before V_peak: a test on the step ends' value would fail
    assert max(short_by) > 3e-3, short_by
    # a history without V_peak (an older run, another building FMU) keeps the step ends' peak
    from dataclasses import replace

    from cosim.master.results import summarize

    older = replace(result.result, final={c: v for c, v in result.result.final.items() if "V_peak" not in c})
    for name in ("left", "right"):
        sampled, _ = result.result.peaks[column(name, "base_shear")]
        assert summarize(older).buildings[name].peak_base_shear_N == sampled


def test_energy_balance_closes_with_the_hysteretic_energy(inelastic):
    result, ref = inelastic
    s = result.summary
    e = energy_history(result.result)
    assert s.energy_hysteretic_J == pytest.approx(sum(b.hysteretic_energy_J for b in s.buildings.values()),
                                                  rel=1e-12)
    # yielding dissipates about half of the input here: without the term the residual would be
    # that large (9.5 % on a scene with one bilinear building before this term existed)
    assert s.energy_hysteretic_J > 0.3 * s.energy_input_J
    assert abs(s.energy_residual_relative) < 0.005                                     # measured 0.01 %
    assert np.max(np.abs(e["residual"])) < 0.005 * s.energy_input_J
    # and the reference's own balance, with the same terms
    assert ref.energy_residual < 1e-8 * ref.energies.input[-1]


def test_summary_terminal_and_loop_plot_report_the_yielding(inelastic):
    result, _ = inelastic
    folder = result.folder
    data = json.loads((folder / "summary.json").read_text())
    left = data["buildings"]["left"]
    assert left["hysteresis"] == "bilinear"
    for key in ("peak_ductility", "peak_ductility_storey", "residual_drift_m", "residual_drift_storey",
                "hysteretic_energy_J"):
        assert left[key] == getattr(result.summary.buildings["left"], key)
    assert data["energy_hysteretic_J"] == result.summary.energy_hysteretic_J
    text = format_summary(result.summary)
    assert "bilinear storeys: peak ductility" in text and "hysteretic energy" in text
    assert (folder / "storey_loops.png").stat().st_size > 10_000


def test_a_linear_building_reports_no_yielding(fmu_dir):
    """The linear default: hysteretic energy 0, no ductility without yield shears, no loop plot."""
    result = run("default", fmu_dir, ["stop_time=2"])
    left = result.summary.buildings["left"]
    assert (left.hysteresis, left.peak_ductility, left.residual_drift_m, left.hysteretic_energy_J) == \
        ("linear", None, 0.0, 0.0)
    assert result.summary.energy_hysteretic_J == 0.0
    assert "storeys: peak ductility" not in format_summary(result.summary)
