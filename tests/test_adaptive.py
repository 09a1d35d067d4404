"""The adaptive coupling with rollback (cosim/adaptive.py) and the stability guard."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.master.coupling.adaptive import Adaptive, closure_time, proof_horizon
from cosim.master.guard import InstabilityError, StabilityGuard
from cosim.master.coupling import STRATEGIES, get_strategy
from cosim.master.simulate import simulate
from cosim.master.system import System
from cosim.peers.reference import reference_for_scene
from cosim.master.results import energy_history
from cosim.master.loader import load_scene
from scenario_checks import simulate_scene as run

PLAIN_ADAPTIVE = ['coupling="adaptive"', "pounding.resolve_impacts=false"]


# -- the closure prediction ---------------------------------------------------------------------
@pytest.mark.parametrize("delta, rate, accel", [(-0.03, 0.5, 0.0), (-0.03, 0.5, 4.0), (-0.03, -0.2, 4.0),
                                                 (-1e-9, 1e-3, 1e3), (-0.02, 0.0, 2.0)])
def test_closure_time_solves_the_bound(delta, rate, accel):
    """s* is the positive root of delta + rate s + accel s^2 / 2 = 0 (the earliest closure)."""
    s = closure_time(delta, rate, accel)
    assert s > 0.0
    assert delta + rate * s + 0.5 * accel * s * s == pytest.approx(0.0, abs=1e-12 * max(1.0, abs(delta)))
    # and no earlier closure: the bound is negative just before
    assert delta + rate * 0.999 * s + 0.5 * accel * (0.999 * s) ** 2 < 0.0


def test_closure_time_edge_cases():
    assert closure_time(0.001, -1.0, 0.0) == 0.0              # already closed
    assert closure_time(-0.01, -1.0, 0.0) == math.inf         # receding, no acceleration bound
    assert closure_time(-0.01, 2.0, 0.0) == pytest.approx(0.005)


def test_registered():
    assert get_strategy("adaptive") is Adaptive
    assert STRATEGIES["adaptive"] is Adaptive
    assert load_scene("default", ['coupling="adaptive"']).coupling == "adaptive"


# -- steps, counters, energy --------------------------------------------------------------------
@pytest.fixture(scope="module")
def short_default(catalog):
    """The default scene for 4.2 s (three impacts, the third the strongest), adaptive plain law."""
    return run(catalog, "default", PLAIN_ADAPTIVE + ["stop_time=4.2"])


def test_steps_are_aligned_dyadic_fractions(short_default):
    result = short_default
    h = np.diff(result.time)
    h_max = result.scene.step
    levels = np.log2(h_max / h[:-1])   # the last step may be clipped to stop_time
    np.testing.assert_allclose(levels, np.round(levels), atol=1e-9)
    # each step starts on a multiple of its own length (time is a count of the finest step)
    ratio = result.time[:-2] / h[:-1]
    np.testing.assert_allclose(ratio, np.round(ratio), atol=1e-6)
    # plain contacts take long steps where every gap provably stays open (up to 0.32 s)
    assert h_max < h.max() <= 0.32 + 1e-9
    assert h.min() < h_max / 16          # refined at the contacts
    # up to the base step, growth by at most a factor 2 per step
    short = h[1:-1] <= h_max * (1.0 + 1e-9)
    assert np.all((h[1:-1] / h[:-2])[short] <= 2.0 + 1e-9)


def assert_do_steps(result):
    """Each building steps once per accepted step plus once per rejected one; the ground motion
    once per chunk it is read ahead; each contact once per step it did not sleep through plus
    the steps it caught up with (cosim/master/dormancy.py)."""
    cost, stats = result.cost, result.stats
    attempts = cost.communication_steps + cost.rollbacks
    for b in result.scene.buildings:
        assert cost.do_steps[b.name] == attempts, b.name
    assert cost.do_steps["ground"] == stats["ground_steps"] < attempts
    (contact,) = result.scene.contacts
    assert cost.do_steps[contact.name] == attempts - stats["dormant_steps"] + stats["catch_up_steps"]
    assert stats["dormant_steps"] > 0


def test_counters(short_default):
    result = short_default
    assert_do_steps(result)
    assert result.cost.communication_steps == result.time.size - 1
    assert result.stats["missed_events"] == 0
    assert result.cost.fmu_calls > 4 * result.cost.communication_steps


def test_energy_balance_closes(short_default):
    """Plain force law under Gauss-Seidel: the contact's work F (delta_new - delta_old) is what
    the buildings receive, so the balance closes to round-off (1e-9 of the input)."""
    e = energy_history(short_default)
    # while the contact is closed the residual is the elastic energy it holds
    open_ = short_default["pounding_3.F"] == 0.0
    assert np.max(np.abs(e["residual"][open_])) <= 1e-9 * np.max(np.abs(e["input"]))
    assert short_default.energy_residual_J == pytest.approx(e["residual"][-1])


def test_agrees_with_reference(catalog, short_default):
    """Within the accuracy criteria of docs/accuracy.md: peak force 1 %, same impacts,
    dissipated energy 2 %, peak displacements 0.5 %."""
    scene = short_default.scene
    ref = reference_for_scene(scene, {"rtol": 1e-9})
    result = short_default
    assert ref.impacts == 3
    assert result["pounding_3.impacts"][-1] == ref.impacts
    assert result["pounding_3.F_max"][-1] == pytest.approx(ref.peak_force_N, rel=0.01)
    assert result["pounding_3.E_dissipated"][-1] == pytest.approx(ref.dissipated_energy_J, rel=0.02)
    for b, peak in zip(scene.buildings, ref.peak_displacements):
        # the building's peaks located inside the steps (long steps span whole oscillations)
        u = max(result[f"{b.name}.x_peak[{i}]"][-1] for i in range(1, scene.n_storeys(b.name) + 1))
        assert u == pytest.approx(float(np.max(peak)), rel=0.005)
    # the onsets land within one contact step of the reference's
    onsets = result.time[np.flatnonzero(np.diff(result["pounding_3.impacts"]) > 0)]
    np.testing.assert_allclose(onsets, [i.t_onset for i in ref.impact_list], atol=1e-3)


class LatePrediction(Adaptive):
    """Adaptive whose closure prediction is 4 times too late (a failing prediction), saving
    states before every step that may close a gap."""

    name = "late-prediction"

    def _plan(self):
        h_target, closures = super()._plan()
        if not closures:          # in contact, or no closure possible: unchanged
            return h_target, closures
        return min(self.h_max, 4.0 * h_target), [(4.0 * s, h_keep) for s, h_keep in closures]


def test_rollback_when_the_prediction_fails(catalog):
    """With a prediction that is too late, the steps that close a gap are rolled back
    (fmi2SetFMUstate on every FMU) and retried shorter; the result agrees with the normal run
    to the accuracy of the scheme, and each FMU stepped once per accepted or rejected step."""
    overrides = PLAIN_ADAPTIVE + ["stop_time=4.2"]
    late = run(catalog, "default", overrides, strategy=LatePrediction, risk_factor=1e9)
    normal = run(catalog, "default", overrides)
    assert late.cost.rollbacks >= 3           # at least one per impact
    assert late.stats["missed_events"] == 0
    assert late["pounding_3.impacts"][-1] == normal["pounding_3.impacts"][-1] == 3
    # both first order in the same contact step: the same impacts to 1 %
    assert late["pounding_3.F_max"][-1] == pytest.approx(normal["pounding_3.F_max"][-1], rel=0.01)
    assert late["pounding_3.E_dissipated"][-1] == pytest.approx(normal["pounding_3.E_dissipated"][-1], rel=0.01)
    assert_do_steps(late)
    # a restored step leaves no trace: the energy balance still closes to round-off
    e = energy_history(late)
    open_ = late["pounding_3.F"] == 0.0
    assert np.max(np.abs(e["residual"][open_])) <= 1e-9 * np.max(np.abs(e["input"]))


# -- the stability guard ------------------------------------------------------------------------
def test_guard_stops_a_plain_law_step_longer_than_the_contact(catalog):
    """Plain force law at a fixed 1 ms step on a 40 us contact: stopped, with what to change."""
    scene = {"name": "stiff", "stop_time": 0.05, "step": 1e-3, "coupling": "gauss-seidel",
             "buildings": {"left": {"m": [1.0], "k": [0.0], "zeta": 0.0, "v0": [0.5]},
                           "right": {"m": [1.0], "k": [0.0], "zeta": 0.0, "v0": [-0.5]}},
             "pounding": {"floors": [1], "gap": 0.0105, "k": 1e12, "resolve_impacts": False}}
    with pytest.raises(InstabilityError) as info:
        run(catalog, scene)
    error = info.value
    assert error.reason in ("penetration", "energy")
    assert error.instance == "pounding_1"
    text = str(error)
    assert "resolve_impacts=true" in text and "adaptive" in text
    step = float(text.split("step below ")[1].split(" s")[0])
    # 2 % of the impact time scale (~1.2e-5 s at the 1 m/s approach; shorter at the speed the
    # blown-up step reached when the guard stopped it)
    assert 1e-9 < step <= 0.02 * 1.2e-5
    # the advice works: resolved impacts at the same step, or adaptive, run through
    run(catalog, scene, ["pounding.resolve_impacts=true"])
    run(catalog, scene, ['coupling="adaptive"'])
    # and the guard can be switched off (numbers then mean nothing)
    run(catalog, scene, check_stability=False)


def test_guard_stops_a_plain_law_that_cannot_resolve_the_impacts_and_warns_below(catalog):
    """Plain law, fixed Gauss-Seidel on the default scene (first three impacts): at 10 ms, 0.43 of
    the impact time scale, stopped; at 2 ms it completes with a warning whose estimate (energy off
    by about h / T) matches the error against the reference."""
    plain = ["pounding.resolve_impacts=false", "stop_time=4.2"]
    with pytest.raises(InstabilityError) as info:
        run(catalog, "default", plain, strategy="gauss-seidel", step=0.01)
    assert info.value.reason == "resolution" and info.value.instance == "pounding_3"
    assert "resolve_impacts=true" in str(info.value) and "step below" in str(info.value)

    from cosim.master.results import summarize
    result = run(catalog, "default", plain, strategy="gauss-seidel", step=0.002)
    summary = summarize(result)
    ratio = summary.contacts["pounding_3"].step_over_time_scale
    assert 0.02 < ratio < StabilityGuard.max_step_over_time_scale
    assert len(summary.warnings) == 1 and f"{ratio:.0%}" in summary.warnings[0]
    ref = reference_for_scene(result.scene, {"rtol": 1e-9})
    error = abs(summary.dissipated_energy_J / ref.dissipated_energy_J - 1.0)
    # the estimate is an order of magnitude, not a bound: within a factor 2 either way
    assert 0.5 * ratio < error < 2.0 * ratio
    # resolved impacts at the same step: no plain contact, nothing to warn about
    resolved = summarize(run(catalog, "default", ["stop_time=4.2"], strategy="gauss-seidel", step=0.002))
    assert resolved.warnings == [] and resolved.contacts["pounding_3"].step_over_time_scale is None


def test_guard_flags_non_finite_and_energy(catalog):
    loaded = load_scene("default", ["stop_time=0.1"], catalog)
    with System(loaded, catalog) as system:
        simulate(system, progress=False)
        guard = StabilityGuard(system)
        assert guard.problem(0.1, 0.01) is None
        i = system.columns.index("left.x[2]")
        system.y[i] = math.nan
        error = guard.problem(0.1, 0.01)
        assert error.reason == "non-finite" and "left.x[2]" in str(error)
        system.y[i] = 0.0
        j = system.columns.index("pounding_3.E_dissipated")
        system.y[j] = -1.0 - 0.02 * guard.E_avail
        assert guard.problem(0.1, 0.01).reason == "energy"
        system.y[j] = 0.0
        k = system.columns.index("pounding_3.delta")
        system.y[k] = 1.0      # a metre of concrete penetration
        assert guard.problem(0.1, 0.01).reason == "penetration"


@pytest.mark.parametrize("t, level", [(2.20, -2), (2.22, -1)])
def test_a_proof_that_ends_where_the_step_needs_it_allows_it(monkeypatch, t, level):
    """A proof made at 2.17 s for 0.08 s covers [2.20, 2.24] + one base step, and [2.22, 2.24] +
    one: the long-step choice takes those steps (40 ms, 20 ms), although the proof's end time,
    a sum of floats, lies a hair short of where they need it (round-off: the steps were halved
    twice on the default scene, 692 steps instead of 543).  Without the slack it refuses them."""
    from cosim.master.coupling import adaptive

    strategy = Adaptive.__new__(Adaptive)
    strategy.h_max, strategy.max_halvings, strategy.long_levels = 0.01, 16, 5
    strategy.h_min = strategy.h_max / 2 ** strategy.max_halvings
    strategy.t0, strategy.t_bound, strategy._look = 0.0, 40.0, None
    strategy._tick = round(t / strategy.h_min)
    strategy._proven = [2.17 + 0.08]
    strategy._prove_quiet = lambda t, H: pytest.fail("no new proof is needed")
    assert strategy._long_level(t) == level
    monkeypatch.setattr(adaptive, "PROOF_SLACK", 0.0)
    assert strategy._long_level(t) > level


def test_proof_horizon_is_one_value_per_level_and_covers_the_step():
    """A proof over a step spans the step's nominal length: the round-off variants of a step
    (t_next - t from tick counts, as Adaptive.step computes it) share one horizon, never
    shorter than the step itself (a shorter horizon would leave the step's end unproven)."""
    h_base = 0.01
    h_min = h_base / 2 ** 16
    for level in range(0, 5):
        nominal = h_base * 2.0 ** -level
        ticks = 1 << (16 - level)
        variants = {(t0 + (k + ticks) * h_min) - (t0 + k * h_min)
                    for t0 in (0.0, 0.3, 7.0) for k in range(0, 40 * 2 ** 16, 7919 * ticks)}
        assert len(variants) > 1                        # the round-off this guards against is real
        horizons = {proof_horizon(h, nominal, h_base) for h in variants}
        assert len(horizons) == 1
        H = horizons.pop()
        assert H >= max(variants)
        assert H - nominal <= 1e-9 * h_base * (1 + 1e-6)   # only the stated slack beyond the step
    # a step longer than its nominal length plus the slack (impossible from step(), but not
    # assumed) keeps its own length
    assert proof_horizon(0.02, 0.01, 0.01) == 0.02
