"""What a run reads and keeps (cosim/master/recording.py): rows at the output interval, the
recorded set, peaks and impacts from every step, one fmi2GetReal per instance per step."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from cosim.master.loader import load_scene
from cosim.master.recording import recorded_columns
from cosim.master.scene import SceneError
from cosim.master.simulate import simulate
from cosim.master.system import System
from scenario_checks import simulate_scene


@pytest.fixture(scope="module")
def thinned_and_full(catalog):
    """The default scene's first 6 s (five impacts) recorded at 50 ms with the summary set,
    and the same run recorded at every communication point with every output."""
    over = ["stop_time=6.0"]
    thin = simulate_scene(catalog, "default", over, output_interval=0.05, record="summary")
    # rows asked for at 50 ms = 5 base steps: no long step could land on them all, so none is
    # taken (adaptive.row_step); the same steps for the run that records every point
    full = simulate_scene(catalog, "default", over, long_steps=False)
    assert thin.stats["h_max_used"] == full.stats["h_max_used"] == pytest.approx(0.01)
    return thin, full


def test_rows_at_the_output_interval(thinned_and_full):
    thin, full = thinned_and_full
    t = thin.time
    assert t[0] == 0.0 and t[-1] == pytest.approx(6.0)
    # every row is a communication point, the first at or after each multiple of 50 ms
    assert np.all(np.isin(t, full.time))
    k = np.floor(t / 0.05 + 1e-9)
    assert np.all(np.diff(k) >= 1)
    assert set(range(int(k[-1]) + 1)) <= set(k.astype(int).tolist())
    assert full.time.size > 2 * t.size          # the adaptive steps are finer near the impacts


def test_summary_is_the_same_whatever_is_recorded(thinned_and_full):
    """Peaks, impacts, their times and the energies come from every step and the final read,
    not from the rows: the summary of the thinned run equals that of the full one."""
    from cosim.master.results import summarize

    thin, full = (summarize(r).to_dict() for r in thinned_and_full)
    for key in ("wall_time_s", "fmu_calls"):
        thin.pop(key), full.pop(key)
    assert thin["impacts"] == 5
    assert thin == full


def test_recorded_sets(catalog):
    scene = load_scene("default", ["stop_time=0.5"], catalog)
    with System(scene, catalog) as system:
        summary = recorded_columns(system, "summary")
        assert recorded_columns(system, "all") == system.columns
        assert "left.x[3]" in summary and "pounding_3.impacts" in summary and "ground.ag" not in summary
        assert recorded_columns(system, ["right.v[5]", "ground.ag"]) == ["right.v[5]", "ground.ag"]
        with pytest.raises(SceneError, match="no column 'left.x\\[9\\]'"):
            recorded_columns(system, ["left.x[9]"])
        with pytest.raises(SceneError, match="record = 'everything'"):
            recorded_columns(system, "everything")
        with pytest.raises(SceneError, match="output_interval = -0.1 s must be a number >= 0"):
            simulate(system, progress=False, output_interval=-0.1)
        result = simulate(system, progress=False, record=["right.v[5]"], output_interval=0.1)
        assert result.columns == ["right.v[5]"] and result.values.shape == (6, 1)


def test_output_interval_scene_key(catalog):
    assert load_scene("default", ["output_interval=0.25"], catalog).output_interval == 0.25
    assert load_scene("default", [], catalog).output_interval is None
    with pytest.raises(SceneError, match="output_interval = -1.0 must be a number >= 0"):
        load_scene("default", ["output_interval=-1.0"], catalog)


def calls_per_instance(catalog, coupling, stop):
    scene = load_scene("default", [f"stop_time={stop}", f'coupling="{coupling}"'], catalog)
    with System(scene, catalog) as system:
        # base steps: what one step calls (long steps: tests/test_scenario_default.py)
        simulate(system, progress=False, **({"long_steps": False} if coupling == "adaptive" else {}))
        return {n.name: n.instance.calls for n in system.nodes}, system


@pytest.mark.parametrize("coupling", ["gauss-seidel", "adaptive"])
def test_one_get_per_instance_per_step(catalog, coupling):
    """Between 1 s and 2 s of the default scene nothing touches (the first impact is at 2.02 s):
    per step, Gauss-Seidel calls the ground motion twice (doStep, getReal), and the contact and
    each building three times (setReal, doStep, getReal).  The adaptive coupling calls each
    building three times per step, reads the ground motion ahead in chunks of up to 0.32 s
    (doStep, getInteger, getReal per chunk), and lets the contact sleep: it catches up at the
    end in steps of 4 base steps (setReal, doStep each: 0.5 calls per step)."""
    short, _ = calls_per_instance(catalog, coupling, 1.0)
    long, _ = calls_per_instance(catalog, coupling, 2.0)
    steps = 100                       # 10 ms steps, no refinement before the first impact
    per_step = {name: (long[name] - short[name]) / steps for name in long}
    assert per_step["left"] == per_step["right"] == 3
    if coupling == "gauss-seidel":
        assert per_step == {"ground": 2, "pounding_3": 3, "left": 3, "right": 3}
    else:
        assert per_step["ground"] <= 0.1 and per_step["pounding_3"] <= 0.5


def test_300_s_record_in_bounded_memory(tmp_path, fmu_dir):
    """A 300 s run (the record, then free vibration) with --output-interval 0.1 stays far
    below 300 MB of peak resident memory (the whole process: Python, numpy, scipy, fmpy and
    three pythonfmu FMUs).

    The peak is the child's own: ``VmHWM`` of ``/proc/self/status``, the high-water mark of the
    memory map the command runs in.  ``getrusage(RUSAGE_SELF).ru_maxrss`` is not: Linux keeps
    it across ``execve`` and starts a forked child from the parent's mark (getrusage(2)), so
    the child of a pytest process that had grown to 400 MB reported 400 MB for a 170 MB run.
    """
    if not os.path.exists("/proc/self/status"):
        pytest.skip("needs Linux's /proc/self/status (VmHWM)")
    out = tmp_path / "run"
    code = ("import sys; from cosim.cli import main; rc = main(sys.argv[1:]); "
            "print([line for line in open('/proc/self/status') if line.startswith('VmHWM:')][0].strip()); "
            "from cosim.master.fmi import exit_process; exit_process(rc)")
    proc = subprocess.run([sys.executable, "-c", code, "run", "default", "--set", "stop_time=300",
                           "--output-interval", "0.1", "--no-plots", "--no-progress", "--fmu-dir", str(fmu_dir),
                           "--out", str(out)], capture_output=True, text=True, timeout=900,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == 0, proc.stderr
    value, unit = proc.stdout.split("VmHWM:")[1].split()[:2]
    assert unit == "kB", proc.stdout
    rss_mb = int(value) / 1024
    print(f"peak resident memory of the 300 s run: {rss_mb:.0f} MB")
    rows = sum(1 for _ in open(out / "history.csv")) - 1
    assert rows == 3001
    # measured 140-180 MB, of which ~150 MB is the interpreter with numpy, scipy, fmpy and the FMUs
    assert rss_mb < 300, rss_mb


def test_rows_asked_for_land_long_steps_on_them():
    """adaptive.row_step: the longest dyadic step whose aligned steps land on every row."""
    from cosim.master.coupling.adaptive import row_step

    assert row_step(0.32, 0.01) == pytest.approx(0.32)
    assert row_step(0.1, 0.01) == pytest.approx(0.02)       # 10 base steps = 2 x 5
    assert row_step(0.05, 0.01) == pytest.approx(0.01)      # 5: no long step
    assert row_step(0.015, 0.01) == pytest.approx(0.01)     # not a whole number of base steps
    assert row_step(0.004, 0.01) == pytest.approx(0.01)


def test_the_memory_bound_counts_the_rows_the_output_interval_keeps(monkeypatch):
    """limits.check_run_size sizes the history as the recorder keeps it: one row per step, or
    per output interval when that is longer, and the listed columns only; so a long record at
    a coarse output interval is not refused for memory it will not use, and the same run with
    a row per step is (here with 100 MB said to be available)."""
    from cosim.master import limits

    monkeypatch.setattr(limits, "available_memory", lambda: 100 * 10**6)
    per_step = load_scene("default", ["stop_time=3000"])            # 300 001 rows x 194 columns: 931 MB
    with pytest.raises(limits.LimitError, match="more than half of the 100 MB available"):
        limits.check_run_size(per_step, record="all")
    coarse = load_scene("default", ["stop_time=3000", "output_interval=1.0"])
    size = limits.check_run_size(coarse, record="all")               # 3002 rows
    assert size.rows == 3002 and size.steps == 300_000
    listed = limits.check_run_size(per_step, record=["left.x[1]", "right.x[1]"])   # 300 001 x 3 x 16 B
    assert listed.columns == 2 and listed.memory_bytes < 50 * 10**6
