"""The accuracy/time study (cosim/accuracy.py), reduced: the default scene's first 4.2 s
(three impacts), one or two settings per strategy, no OpenSees (its own tests cover it)."""
from __future__ import annotations

import csv
import math

import pytest

from cosim.apps.accuracy import CRITERIA, REDUCED_FAMILIES, Row, markdown, run_study, score, write_study
from cosim.files import MARKER
from cosim.master.system import Catalog


@pytest.fixture(scope="module")
def study(fmu_dir):
    with Catalog(fmu_dir) as catalog:
        return run_study("default", catalog=catalog, families=REDUCED_FAMILIES, opensees_dts=(),
                         stop_time=4.2, reference_rtol=1e-9, log=None)


def rows(study, method):
    return [r for r in study.rows if r.method == method]


def test_every_strategy_is_measured(study):
    assert study.reference["impacts"] == 3
    assert {r.method for r in study.rows} == {"default settings", "jacobi", "gauss-seidel", "gauss-seidel-resolved",
                                              "adaptive", "adaptive-resolved", "adaptive-resolved-0.04"}
    for r in study.rows:
        assert r.status == "ok"
        assert r.wall_time_s > 0 and r.communication_steps > 0 and r.fmu_calls > r.communication_steps
        assert all(math.isfinite(x) for x in (r.err_peak_force, r.err_dissipated_energy, r.err_peak_displacement))


def test_adaptive_converges_and_meets_the_criteria(study):
    coarse, fine = sorted(rows(study, "adaptive"), key=lambda r: -r.value)
    # first order in the contact step: 4 times finer, about 4 times smaller errors (at least 2)
    assert fine.err_peak_force < coarse.err_peak_force / 2
    assert fine.err_dissipated_energy < coarse.err_dissipated_energy / 2
    assert fine.meets_criteria
    assert fine.impacts == study.reference["impacts"]
    # onsets within a millisecond (the contact step is ~0.3 ms)
    assert fine.err_impact_time_s < 1e-3
    # plain-law Gauss-Seidel and the adaptive scheme close the energy balance to round-off
    assert abs(fine.energy_residual_relative) < 1e-8


def test_default_settings_meet_the_criteria(study):
    """The package's default (adaptive, 0.01 s, resolved impacts) meets the criteria in about
    as many steps as a fixed 0.01 s step (it refines only around the onsets)."""
    (default,) = rows(study, "adaptive-resolved")
    assert default.meets_criteria
    assert default.communication_steps < 1.2 * study.stop_time / 0.01


def test_the_coarse_family_is_cheaper_and_coarser(study):
    """The front's coarse end (base step 0.04 s, contact_fraction 2, beyond the old range (0, 1])
    runs, finds the reference's impacts in fewer than half the default settings' steps, and pays
    for it in accuracy: measured 47 steps against 114, errors 1.6 / 9.1 / 0.45 % against 0.044 /
    0.043 / 0.070 % (so the study lists it, and the front uses it only where it is good enough)."""
    (coarse,) = rows(study, "adaptive-resolved-0.04")
    (default,) = rows(study, "adaptive-resolved")
    assert coarse.status == "ok" and coarse.value == 2.0
    assert coarse.impacts == study.reference["impacts"]
    assert coarse.communication_steps < default.communication_steps / 2
    assert coarse.err_peak_force > default.err_peak_force and coarse.error > default.error
    assert "| adaptive-resolved-0.04 | contact_fraction = 2 |" in markdown(study)


def test_contact_fraction_range(catalog):
    """The adaptive strategy takes contact fractions up to CONTACT_FRACTION_MAX (the coarse
    family's 2) and refuses a larger one before the first step, naming the range; the study's
    families stay inside it (checked at import, _check_families)."""
    from cosim.master.coupling.adaptive import CONTACT_FRACTION_MAX
    from cosim.master.loader import load_scene
    from cosim.master.simulate import simulate
    from cosim.master.system import System

    assert CONTACT_FRACTION_MAX == 2.0
    scene = load_scene("free_vibration", ["stop_time=0.08", "step=0.04"], catalog)
    with System(scene, catalog) as system:
        assert simulate(system, progress=False, contact_fraction=CONTACT_FRACTION_MAX).cost.communication_steps >= 2
        with pytest.raises(ValueError, match=r"contact_fraction = 2\.5 must be in \(0, 2\]"):
            simulate(system, progress=False, contact_fraction=2.5)


def test_fraction_labels():
    from cosim.apps.accuracy import _fraction_label

    assert [_fraction_label(v) for v in (1 / 64, 1 / 2, 1.0, 2.0)] == ["1/64", "1/2", "1", "2"]


def test_adaptive_beats_fixed_steps(study):
    """Plain-law Gauss-Seidel at a fixed 1 ms step takes more steps than the adaptive scheme
    at 1/64 and is less accurate (it steps finely where nothing happens, coarsely in contact)."""
    (fixed,) = rows(study, "gauss-seidel")
    fine = min(rows(study, "adaptive"), key=lambda r: r.value)
    assert fixed.communication_steps > fine.communication_steps
    assert fixed.err_peak_force > fine.err_peak_force
    assert fixed.err_dissipated_energy > fine.err_dissipated_energy
    (jacobi,) = rows(study, "jacobi")
    assert jacobi.err_peak_force > fixed.err_peak_force      # one step of delay on top


def test_score_applies_the_criteria():
    ref = dict(peak_force_N=100.0, impacts=2, dissipated_energy_J=10.0, peak_displacements_m=[1.0, 2.0],
               impact_times_s=[1.0, 2.0])
    ok = score(Row("x", "step", 1.0), ref, 100.9, 2, 10.19, [1.004, 2.0], [1.001, 2.0])
    assert ok.meets_criteria and ok.err_impact_time_s == pytest.approx(0.001)
    assert ok.error == pytest.approx(0.019)
    assert not score(Row("x", "step", 1.0), ref, 101.1, 2, 10.0, [1.0, 2.0], [1.0, 2.0]).meets_criteria
    assert not score(Row("x", "step", 1.0), ref, 100.0, 3, 10.0, [1.0, 2.0], [1.0, 1.5, 2.0]).meets_criteria
    miss = score(Row("x", "step", 1.0), ref, 100.0, 3, 10.0, [1.0, 2.0], [1.0, 1.5, 2.0])
    assert math.isnan(miss.err_impact_time_s)
    assert not score(Row("x", "step", 1.0), ref, 100.0, 2, 10.0, [1.006, 2.0], [1.0, 2.0]).meets_criteria


def test_written_files(study, tmp_path):
    folder = write_study(study, tmp_path / "acc")
    assert {p.name for p in folder.iterdir()} == {"accuracy.csv", "accuracy.md", "accuracy.png", "front.png",
                                                  MARKER}
    with open(folder / "accuracy.csv") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == len(study.rows)
    assert float(table[0]["wall_time_s"]) == pytest.approx(study.rows[0].wall_time_s, rel=1e-5)
    text = markdown(study)
    assert "| adaptive | contact_fraction = 1/64 |" in text
    assert "| default settings | the scene's |" in text
    # the front: the wall time to reach each error level (no OpenSees in this reduced study)
    assert "| largest error within | package: fastest run |" in text and "| 2 % | " in text
    assert (folder / "accuracy.png").stat().st_size > 10_000
    assert (folder / "front.png").stat().st_size > 10_000


def test_front_is_the_lower_envelope():
    """front(): the runs no other run beats in both wall time and error, ordered by wall time;
    time_to_reach(): the fastest run with all three errors within a level."""
    from cosim.apps.accuracy import front, time_to_reach

    def row(wall, err, impacts=3):
        r = Row("m", "step", 0.0, wall_time_s=wall, impacts=impacts, err_peak_force=err, err_dissipated_energy=err,
                err_peak_displacement=err)
        r.error = err
        return r

    rows = [row(1.0, 0.05), row(2.0, 0.01), row(1.5, 0.02), row(3.0, 0.03), row(0.5, 0.001, impacts=2)]
    assert front(rows, "err_peak_force", 3) == [(1.0, 0.05), (1.5, 0.02), (2.0, 0.01)]
    assert time_to_reach(rows, 0.02, 3).wall_time_s == 1.5
    assert time_to_reach(rows, 0.005, 3) is None            # the wrong-impacts run does not count


@pytest.fixture(scope="module")
def inelastic_study(fmu_dir):
    """default_inelastic's first 4.2 s (three impacts, storeys yielding): the default settings
    and OpenSees (Steel01 storeys) at 1 ms."""
    from cosim.apps.accuracy import FAMILIES
    from cosim.peers.opensees import opensees_available

    default = [f for f in FAMILIES if f.name == "adaptive-resolved"]
    with Catalog(fmu_dir) as catalog:
        return run_study("default_inelastic", catalog=catalog, families=default,
                         opensees_dts=(1e-3,) if opensees_available() else (), stop_time=4.2,
                         reference_rtol=1e-10, log=None)


def test_inelastic_scene_is_scored_on_its_drifts(inelastic_study):
    study = inelastic_study
    assert study.reference["yielding"] == [0, 1] and study.reference["impacts"] == 3
    assert max(max(mu) for mu in study.reference["ductility"]) > 1.5
    default = next(r for r in study.rows if r.method == "adaptive-resolved" and r.value == 0.5)
    assert default.status == "ok" and default.meets_criteria
    assert math.isfinite(default.err_peak_drift) and default.err_peak_drift < CRITERIA["peak_drift"]
    assert default.err_residual_drift < CRITERIA["residual_drift"]
    text = markdown(study)
    assert "peak drift err % | residual drift err %" in text and "Yielding storeys: peak ductility" in text


def test_inelastic_scene_against_opensees(inelastic_study):
    from cosim.peers.opensees import opensees_available

    if not opensees_available():
        pytest.skip("openseespy is not importable")
    study = inelastic_study
    peer = next(r for r in study.rows if r.method == "opensees")
    assert peer.status.startswith("ok") and math.isfinite(peer.err_peak_drift)
    agreement = study.peer_agreement()
    # the package's default settings and OpenSees (Steel01, Newmark at 1 ms) on the same model
    assert agreement["dt"] == 1e-3
    assert agreement["peak_displacement"] < 0.01 and agreement["ductility"] < 0.01
    assert "Default settings against OpenSees at its finest tested step" in markdown(study)


def test_drift_criteria_apply_to_yielding_scenes_only():
    ref = dict(peak_force_N=100.0, impacts=1, dissipated_energy_J=10.0, peak_displacements_m=[1.0],
               impact_times_s=[1.0], yielding=[0], peak_drifts_m=[[0.02, 0.01]], residual_drifts_m=[[0.004, -0.002]])
    good = score(Row("x", "step", 1.0), ref, 100.0, 1, 10.0, [1.0], [1.0], [[0.0201, 0.01]], [[0.00403, -0.002]])
    assert good.meets_criteria
    assert good.err_peak_drift == pytest.approx(0.005) and good.err_residual_drift == pytest.approx(0.0075)
    assert not score(Row("x", "step", 1.0), ref, 100.0, 1, 10.0, [1.0], [1.0], [[0.0203, 0.01]],
                     [[0.004, -0.002]]).meets_criteria
    assert not score(Row("x", "step", 1.0), ref, 100.0, 1, 10.0, [1.0], [1.0], [[0.02, 0.01]],
                     [[0.004, -0.00205]]).meets_criteria
    linear = dict(ref, yielding=[])
    assert math.isnan(score(Row("x", "step", 1.0), linear, 100.0, 1, 10.0, [1.0], [1.0]).err_peak_drift)


# -- the timing rule: the package's runs and OpenSees' timed alike ------------------------------------
class _Timed:
    """Wraps a callable returning an object with a ``wall_time_s`` (the package's run cost or
    OpenSees' result), replacing each timing by the next of ``walls`` (s)."""

    def __init__(self, call, walls, cost=False):
        self.call, self.walls, self.cost, self.calls = call, list(walls), cost, 0

    def __call__(self, *args, **kwargs):
        result = self.call(*args, **kwargs)
        wall = self.walls[self.calls]
        self.calls += 1
        target = result.cost if self.cost else result
        object.__setattr__(target, "wall_time_s", wall)
        return result


@pytest.mark.parametrize("walls, below, calls, kept", [
    ((0.30, 0.20, 0.25), 1.0, 3, 0.20),     # cheap: timed three times, the fastest kept
    ((1.50, 0.20, 0.25), 1.0, 1, 1.50),     # one slow timing: not repeated
    ((0.30, 0.20, 0.25), math.inf, 3, 0.20),
])
def test_cheap_runs_are_timed_repeatedly_and_the_fastest_kept(fmu_dir, monkeypatch, walls, below, calls, kept):
    import cosim.apps.accuracy as accuracy
    from cosim.apps.accuracy import DEFAULT_SETTINGS, run_cosim

    timed = _Timed(accuracy.simulate, walls, cost=True)
    monkeypatch.setattr(accuracy, "simulate", timed)
    ref = {"impacts": 3, "peak_force_N": 1.0, "dissipated_energy_J": 1.0, "peak_displacements_m": [1.0, 1.0], "impact_times_s": []}
    with Catalog(fmu_dir) as catalog:
        row = run_cosim("default", DEFAULT_SETTINGS, 0.0, catalog, ref, stop_time=0.5, repeats=3,
                        repeat_below_s=below)
    assert (timed.calls, row.wall_time_s) == (calls, kept)


def test_opensees_runs_follow_the_same_timing_rule(monkeypatch):
    import cosim.apps.accuracy as accuracy
    from cosim.master.loader import load_scene
    from cosim.peers.opensees import opensees_available

    if not opensees_available():
        pytest.skip("openseespy is not importable")
    timed = _Timed(accuracy.opensees_for_scene, (0.30, 0.20, 0.25, 2.0, 0.1))
    monkeypatch.setattr(accuracy, "opensees_for_scene", timed)
    scene = load_scene("default", ["stop_time=0.5"])
    ref = {"impacts": 0, "peak_force_N": 0.0, "dissipated_energy_J": 0.0, "peak_displacements_m": [1.0, 1.0], "impact_times_s": []}
    row = accuracy.run_peer(scene, 4e-3, ref, repeats=3, repeat_below_s=1.0)
    assert (timed.calls, row.wall_time_s) == (3, 0.20)
    row = accuracy.run_peer(scene, 4e-3, ref, repeats=3, repeat_below_s=1.0)
    assert (timed.calls, row.wall_time_s) == (4, 2.0)


def test_study_timings_per_run_are_bounded(tmp_path):
    from cosim.apps.accuracy import MAX_TIMING_REPEATS, study_and_write

    for bad in (0, MAX_TIMING_REPEATS + 1, 2.5):
        with pytest.raises(ValueError, match=f"repeats = {bad!r}: .* 1 to {MAX_TIMING_REPEATS}"):
            study_and_write("default", tmp_path / "out", repeats=bad, log=None)
    assert not (tmp_path / "out").exists()
