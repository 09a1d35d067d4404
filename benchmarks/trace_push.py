"""Where a resolved impact's peak-force error at the default step comes from (prints figures; no
assertions).

    python benchmarks/trace_push.py [--scenes kasai_maison sanfernando ...] [--table]

For each scene (default settings) and its largest impact (by the monolithic reference's peak
force, solve_ivp DOP853 rtol 1e-10):

* ``--table``: the structures' push ``a_ext`` (relative acceleration of the two floors without
  the contact force, m/s^2) per communication step of the impact: the mean the resolver
  *assumed* (``a0 + a1 h / 2``), the *host*'s (the clean mean its increments then showed, as the
  resolver learnt it) and the *reference*'s (``(increment of delta_dot + impulse / m) / h``);
* the peak force as run (the contact's steps replayed from the run's log, bit for bit the FMU's
  trajectory, as ``cosim/master/impacts.py`` does) and the onset speed, against the reference;
* the same impact *alone*: the resolver itself (``follow_host=False``) integrating
  ``delta_ddot = a_ext(t) - F / m`` on 0.1 ms steps from the reference's state 0.2 ms before
  onset, with a given push, ``a_ext`` linear over each 0.1 ms step:

  - the reference's push (checks the method: it must give the reference's peak);
  - the reference's push as one line per communication step, the line that keeps its rate and
    displacement increments over the step (what the resolver's in-step form ``b0 + b1 s`` can
    hold at best);
  - the host's push, the same line per step from the host's own increments (what the resolver
    would integrate if it predicted the host's push exactly).

  The peak's error with the host's push is what no prediction of the push inside ``pounding.fmu``
  can remove: it comes from the host's structures themselves, which receive the step's mean
  force held over the step (zero-order hold) instead of the impact's force history.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.fmus import default_fmu_dir  # noqa: E402
from cosim.master.coupling import get_strategy  # noqa: E402
from cosim.master.loader import load_scene  # noqa: E402
from cosim.master.models import contact_law  # noqa: E402
from cosim.master.runner import settings  # noqa: E402
from cosim.master.simulate import simulate  # noqa: E402
from cosim.master.system import Catalog, System  # noqa: E402
from cosim.peers.reference import reference_for_scene  # noqa: E402
from fmu_src.resolver import ImpactResolver  # noqa: E402

#: s, output interval of the reference: the push is its velocity's derivative on this grid
#: (central differences: error ~ dt^2 a''' / 6, 1e-5 of the push for a 20 ms contact)
REFERENCE_DT = 1e-4
#: s, the step on which the isolated impact is integrated (the push linear over each)
ISOLATED_STEP = 1e-4
#: s, the isolated impact starts this long before the reference's onset, in flight
LEAD_IN = 2e-4


class PushedResolver(ImpactResolver):
    """The resolver with a given structural push ``push(t)`` [m/s^2] and no host: over each step
    ``a_ext`` is the line through ``push`` at the step's ends."""

    def __init__(self, law, push, t0: float):
        super().__init__(law, follow_host=False)
        self.push, self.clock = push, t0

    def _follow(self, delta: float, delta_dot: float, h: float) -> None:
        a, b = self.push(self.clock), self.push(self.clock + h)
        self.a0, self.a1 = a, (b - a) / h
        self.clock += h


def step_line(push, t0: float, h: float, points: int = 401) -> tuple[float, float]:
    """(a0 [m/s^2], a1 [m/s^3]): the line over [t0, t0 + h] with the same rate increment
    ``int a`` and displacement from rest ``int (h - s) a`` as ``push`` (trapezoid on ``points``)."""
    s = np.linspace(0.0, h, points)
    a = np.array([push(t0 + x) for x in s])
    rate = np.trapezoid(a, s)
    moved = np.trapezoid(a * (h - s), s)
    a1 = 12.0 * (0.5 * rate * h - moved) / h ** 3      # as HostObserver._learn_step
    return rate / h - 0.5 * a1 * h, a1


def piecewise(starts: np.ndarray, lines: dict):
    """push(t) from per-step lines ``lines[k] = (a0, a1)`` over steps starting at ``starts``."""
    def push(t: float) -> float:
        k = int(np.searchsorted(starts, t, side="right")) - 1
        a0, a1 = lines[k]
        return a0 + a1 * (t - starts[k])
    return push


def isolated_peak(law, push, t_onset: float, t_end: float, rate_at) -> float:
    """Peak force [N] of the impact alone under ``push``, from the state ``LEAD_IN`` before onset."""
    t = t_onset - LEAD_IN
    resolver = PushedResolver(law, push, t)
    d, v = -rate_at(t) * LEAD_IN, rate_at(t)
    peak = 0.0
    while t < t_end:
        out = resolver.step(d, v, ISOLATED_STEP)
        peak = max(peak, out.peak_force)
        d, v = resolver.delta_end, resolver.delta_dot_end
        t += ISOLATED_STEP
    return peak


def trace(scene_name: str, catalog, table: bool) -> None:
    scene = load_scene(scene_name, settings(), catalog)
    ref = reference_for_scene(scene, {"rtol": 1e-10, "output_dt": REFERENCE_DT})
    with System(scene, catalog) as system:
        result = simulate(system, progress=False)
    big = max(ref.impact_list, key=lambda i: i.peak_force_N)
    spec, level = scene.contacts[big.contact], scene.levels[big.contact]
    name = spec.name
    law = contact_law(spec)
    m = law.m
    # the reference's relative rate and push at the contact's two floors
    index = {b.name: j for j, b in enumerate(scene.buildings)}
    left = ref.floor_offsets[index[level.left]] + int(level.floor_left) - 1
    right = ref.floor_offsets[index[level.right]] + int(level.floor_right) - 1
    tr = ref.t
    rate_ref = ref.v[:, left] - ref.v[:, right]
    force_ref = ref.contact_force[:, big.contact]
    push_ref_grid = np.gradient(rate_ref, tr) + force_ref / m

    def push_ref(t):
        return float(np.interp(t, tr, push_ref_grid))

    def rate_at(t):
        return float(np.interp(t, tr, rate_ref))

    impulse_ref = np.concatenate(([0.0], np.cumsum(0.5 * (force_ref[1:] + force_ref[:-1]) * np.diff(tr))))

    def impulse_at(t):                    # N s, the contact's impulse since the run's start
        return float(np.interp(t, tr, impulse_ref))

    # the contact's steps replayed (cosim/master/impacts.py): assumed and host pushes per step
    steps = result.contact_steps[name]
    gap = float(spec.value("gap"))
    delta = steps.input("x1") - steps.input("x2") - gap
    rate = steps.input("v1") - steps.input("v2")
    declared = steps.input("gap_open") != 0.0
    host = str(spec.value("host")) if "host" in spec.parameters else get_strategy(result.strategy).host
    model = ImpactResolver(law, host=host, graze_depth=float(spec.value("graze_depth")))
    observer = model.observer
    if not observer.exact_positions:
        raise SystemExit(f"{scene_name}: host {host!r} does not declare exact positions; the host's "
                         f"push per step is learnt from both increments only for zoh hosts")
    starts = steps.t
    assumed, shown, mean_force = {}, {}, {}
    peak_run, v_run = 0.0, float("nan")
    for k in range(len(steps)):
        means, started = observer.means, model.started
        out = model.step(float(delta[k]), float(rate[k]), float(steps.h[k]), bool(declared[k]))
        if observer.means is not means and k > 0:
            # learnt from both increments of step k - 1: observer.a0 is the line's value at
            # that step's end (HostObserver._learn_step); back to its start
            shown[k - 1] = (observer.a0 - observer.a1 * observer.spans[0], observer.a1)
        assumed[k] = (model.a0, model.a1)
        mean_force[k] = out.mean_force
        if model.started != started and abs(starts[k] + model.onset_offset - big.t_onset) < float(steps.h[k]):
            v_run = model.v_imp
        if big.t_onset - float(steps.h[k]) <= starts[k] <= big.t_separation:
            peak_run = max(peak_run, out.peak_force)
    P = big.peak_force_N
    print(f"{scene_name}: largest impact {name} at {big.t_onset:.5f} s, v {big.v_impact:.5g} m/s, "
          f"{1e3 * big.duration:.1f} ms, reference peak {P:.6g} N; effective mass {m:.6g} kg")
    print(f"  as run: peak {peak_run:.6g} N ({100 * (peak_run / P - 1):+.3f} %), onset speed "
          f"{100 * (v_run / big.v_impact - 1):+.3f} %")
    inside = [k for k in range(len(steps))
              if starts[k] + steps.h[k] > big.t_onset - 0.01 and starts[k] < big.t_separation + 0.01]
    if table:
        print("    t [s]    h [ms]  assumed   host      reference  host-ref  assumed-host  F/m [m/s^2]")
        for k in inside:
            h = float(steps.h[k])
            a = assumed[k][0] + 0.5 * assumed[k][1] * h
            s = shown[k][0] + 0.5 * shown[k][1] * h if k in shown else float("nan")
            t0, t1 = float(starts[k]), float(starts[k]) + h
            r = (rate_at(t1) - rate_at(t0) + (impulse_at(t1) - impulse_at(t0)) / m) / h
            print(f"  {starts[k]:9.5f} {1e3 * h:6.2f} {a:9.4f} {s:9.4f} {r:9.4f} {s - r:9.4f} {a - s:9.4f} "
                  f"{mean_force[k] / m:9.4g}")
    lines_ref = {k: step_line(push_ref, float(starts[k]), float(steps.h[k])) for k in inside}
    cases = (("reference push", push_ref),
             ("reference push, one line per step", piecewise(starts, {**shown, **lines_ref})),
             ("host push, one line per step", piecewise(starts, shown)))
    t_end = big.t_separation + 1e-3
    for label, push in cases:
        p = isolated_peak(law, push, big.t_onset, t_end, rate_at)
        print(f"  alone, {label}: peak {p:.6g} N ({100 * (p / P - 1):+.3f} %)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=["kasai_maison", "sanfernando", "kasai_maison_inelastic",
                                                        "default"], help="bundled scene names")
    parser.add_argument("--table", action="store_true", help="print the push per step of the impact")
    args = parser.parse_args(argv)
    with Catalog(default_fmu_dir()) as catalog:
        for name in args.scenes:
            trace(name, catalog, args.table)
    return 0


if __name__ == "__main__":
    from cosim.master.fmi import exit_process

    exit_process(main())
