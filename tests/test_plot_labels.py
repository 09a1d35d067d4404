"""Plots a person would rather look at (issue 15 point 6): units on the study plots' axes, real
force-penetration loops from each impact's own trajectory."""
from __future__ import annotations

import pytest

from cosim.apps.study.plot import axis_label


@pytest.mark.parametrize("name, label", [
    ("pounding.gap", "pounding.gap [m]"), ("peak_force_N", "peak_force_N [N]"),
    ("left.peak_displacement_m", "left.peak_displacement_m [m]"), ("ground.target_pga", "ground.target_pga [m/s2]"),
    ("left.m[1]", "left.m[1] [kg]"), ("energy_residual_relative", "energy_residual_relative [1]"),
    ("impacts", "impacts"), ("pounding.model", "pounding.model")])
def test_study_axes_carry_units(name, label):
    assert axis_label(name) == label


def test_hysteresis_plot_draws_the_largest_impacts_loops(fmu_dir, tmp_path, monkeypatch):
    """The loops drawn are the replayed trajectories of the largest impacts (by peak force), each
    from zero force at onset back to zero at separation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cosim.master import output
    from scenario_checks import run

    result = run("default", fmu_dir, ["stop_time=6"]).result
    drawn = []
    real_plot = matplotlib.axes.Axes.plot

    def spy(ax, *args, **kwargs):
        drawn.append((args, kwargs))
        return real_plot(ax, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "plot", spy)
    output.plot_hysteresis(result, tmp_path / "h.png", plt)
    assert (tmp_path / "h.png").stat().st_size > 0
    # 5 impacts in the first 6 s, all drawn (fewer than LOOPS_PLOTTED), labelled with their onsets
    assert len(drawn) == 5 and all(kw["label"].startswith("pounding_3 at ") for _, kw in drawn)
    for (d, f), _ in drawn:
        assert f[0] == pytest.approx(0.0, abs=1.0) and f[-1] == pytest.approx(0.0, abs=1.0)   # kN
        assert f.max() > 1e3 and (f >= 0.0).all()
