"""What a run logs for its replays (cosim/master/steplog.py): every doStep a contact FMU takes, with
its inputs, and the buildings around contacts; the replays made from them (cosim/master/impacts.py)
equal the FMUs' own outputs whatever the coupling, the dormant contacts, long steps, rollbacks,
recorded set and output interval."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.master.coupling.adaptive import Adaptive
from cosim.master.impacts import replay_contact
from cosim.master.names import column
from cosim.master.results import impact_table
from cosim.master.steplog import LoggedContact
from scenario_checks import simulate_scene


class _Port:
    def __init__(self, names):
        self.names = list(names)
        self.values = np.zeros(len(names))


class _Instance:
    """A fake contact instance: its state is the number of steps it took."""

    def __init__(self):
        self.steps, self.freed, self.calls = 0, [], 0

    def do_step(self, t, h):
        self.steps += 1

    def get_state(self):
        return [self.steps]          # a fresh object per state, as fmi2GetFMUstate

    def set_state(self, state):
        self.steps = state[0]

    def free_state(self, state):
        self.freed.append(state)

    def reset(self):
        self.steps = 0


def test_a_restored_state_takes_its_steps_out_of_the_log():
    port = _Port(["x1", "v1", "x2", "v2"])
    contact = LoggedContact(_Instance(), port)
    port.values[:] = (1.0, 2.0, 3.0, 4.0)
    contact.do_step(0.0, 0.01)
    saved = contact.get_state()
    for k in (1, 2):
        port.values[0] = 10.0 + k
        contact.do_step(0.01 * k, 0.01)
    assert contact.steps().t.tolist() == [0.0, 0.01, 0.02] and contact.steps().input("x1").tolist() == [1, 11, 12]
    contact.set_state(saved)                          # the two steps were rolled back
    assert contact.steps().t.tolist() == [0.0] and contact.steps().input("v2").tolist() == [4.0]
    contact.do_step(0.01, 0.005)
    contact.set_state(saved)                          # a state can be restored again
    assert len(contact.steps()) == 1
    contact.free_state(saved)
    assert contact.freed == [saved] and contact.calls == 0     # the rest is the instance's
    contact.do_step(0.01, 0.01)
    contact.reset()
    assert len(contact.steps()) == 0 and contact.steps().table.shape == (0, 7)   # t, h, 4 inputs, gap_open


def _assert_replay_is_the_fmu(result):
    """Every contact of every contact instance replayed: the FMU's onsets and peak forces, bit for
    bit (the same arithmetic on the same doubles), each trajectory in time order."""
    rows = impact_table(result)
    assert rows
    for contact in result.scene.contacts:
        mine = [r for r in rows if r["contact"] == contact.name]
        replayed = replay_contact(result, contact.name)
        assert len(replayed) == len(mine)
        for trajectory, row in zip(replayed, mine):
            assert trajectory.t_onset == row["t_onset_s"]
            assert trajectory.F_peak == row["peak_force_N"]
            assert np.all(np.diff(trajectory.time) >= 0.0) and trajectory.time[0] >= trajectory.t_onset
        steps = result.contact_steps[contact.name]
        # every doStep once, but those of rolled-back steps
        assert len(steps) == result.cost.do_steps[contact.name] - result.cost.rollbacks


@pytest.mark.parametrize("overrides, options", [
    ([], {}),                                                      # dormant contacts, long steps
    ([], dict(record="summary", output_interval=0.5)),             # two rows a second
    (['coupling="gauss-seidel"'], {}),
    (['coupling="jacobi"'], {}),                                   # the resolver looks ahead (probes)
    (["pounding_3.resolve_impacts=false"], dict(record="summary", output_interval=None)),
], ids=["adaptive", "decimated", "gauss-seidel", "jacobi", "plain-law"])
def test_the_replay_is_the_fmu(catalog, overrides, options):
    result = simulate_scene(catalog, "default", ["stop_time=6"] + overrides, **options)
    _assert_replay_is_the_fmu(result)
    if not overrides and not options:
        assert result.stats["dormant_steps"] > 0 and result.stats["long_steps"] > 0


class _LatePrediction(Adaptive):
    """Closure predicted 4 times too late (as tests/test_adaptive.py): steps that close a gap
    are rolled back and retried."""

    name = "late-prediction"

    def _plan(self):
        h_target, closures = super()._plan()
        if not closures:
            return h_target, closures
        return min(self.h_max, 4.0 * h_target), [(4.0 * s, h_keep) for s, h_keep in closures]


def test_rolled_back_steps_leave_the_log(catalog):
    # the plain law's contact step (1/64 of the impact's time scale) is what the late closures
    # overshoot (a resolved contact takes steps of half of it: no rollback to see)
    result = simulate_scene(catalog, "default", ["stop_time=4.2", "pounding_3.resolve_impacts=false"],
                            strategy=_LatePrediction, risk_factor=1e9, dormancy=False, long_steps=False)
    assert result.cost.rollbacks >= 3
    steps = result.contact_steps["pounding_3"]
    # the contact stepped every accepted step once, nothing of the rejected ones is left
    assert steps.t.tolist() == result.time[:-1].tolist()
    np.testing.assert_array_equal(steps.t + steps.h, result.time[1:])
    _assert_replay_is_the_fmu(result)


def test_the_contact_windows_are_the_steps_with_a_force(catalog):
    """The windows hold every step in which a contact force acts or acted at its start, with the
    floors' states at both ends as the history has them (read the same way, logged apart)."""
    result = simulate_scene(catalog, "default", ["stop_time=6"])
    windows = result.contact_windows
    F = result["pounding_3.F"]
    forced = (F[1:] != 0.0) | (F[:-1] != 0.0)
    np.testing.assert_array_equal(windows.t0, result.time[:-1][forced])
    np.testing.assert_array_equal(windows.t1, result.time[1:][forced])
    rows = np.flatnonzero(forced)
    for name in windows.columns:
        np.testing.assert_array_equal(windows.at_start(name), result[name][rows])
        np.testing.assert_array_equal(windows.at_end(name), result[name][rows + 1])
    # the buildings' inputs: the contact's force held (GS: this step's mean force), the ground
    left = windows.inputs["left"].held_forces(3)
    np.testing.assert_array_equal(left[:, 2], -windows.at_end("pounding_3.F"))
    assert not left[:, :2].any()
    assert column("right", "a[5]") in windows.columns
