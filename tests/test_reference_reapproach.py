"""A contact that loads again while unloading: cosim/reference.py against an independent solution
(issue 13, point 4).

crvk's force drops at maximum penetration (the approach branch lies above the restitution
branch at the same penetration).  When the buildings push the bodies together during
restitution with a force between the two branches, neither branch holds: the reference must
stick (Filippov's sliding motion: the penetration stays, the force is the push) until the push
exceeds the approach branch or falls below the restitution branch.  Before the fix the
reference re-entered the approach branch, whose maximum-penetration event then never fired
(``delta'`` already negative): the contact never separated and later impacts were lost, while
the energy balance still closed.

The independent solution below uses another event formulation: no branch events at all, the
branch switch smoothed over a rate ``eps`` (``F = F_r + (F_a - F_r) (1 + tanh(delta' / eps)) / 2``),
integrated with LSODA (stiff where the bodies stick), events only at onset (to latch the
approach speed) and separation.  As ``eps -> 0`` it tends to the sliding motion; it is checked
to have converged (two ``eps`` a factor 10 apart agree) before it is used.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cosim.peers.reference import Contact, scene_inputs, solve_reference
from fmu_src.contact_laws import law_for
from fmu_src.shear_building import ShearBuilding


def smoothed_reference(buildings, ground, contacts, stop_time, x0, v0, eps, rtol=1e-9):
    """Impacts (onset, separation, approach speed, peak force, dissipated energy) of the system
    with the branch switch smoothed over ``eps`` [m/s] (module docstring)."""
    masses = np.concatenate([np.asarray(b.masses, dtype=float) for b in buildings])
    n = masses.size
    K, C = np.zeros((n, n)), np.zeros((n, n))
    offsets = np.concatenate(([0], np.cumsum([len(b.masses) for b in buildings])))
    for b, o in zip(buildings, offsets[:-1]):
        K[o:o + len(b.masses), o:o + len(b.masses)] = b.K
        C[o:o + len(b.masses), o:o + len(b.masses)] = b.C
    left = [offsets[c.left] + c.left_floor - 1 for c in contacts]
    right = [offsets[c.right] + c.right_floor - 1 for c in contacts]
    ag = (lambda t: 0.0) if ground is None else getattr(ground, "at", ground)
    y = np.concatenate([np.concatenate(x0), np.concatenate(v0), np.zeros(len(contacts))])
    closed = [False] * len(contacts)
    v_imp = [0.0] * len(contacts)
    impacts, current = [], {}

    def force(c, d, r):
        law = contacts[c].law
        if d <= 0.0:
            return 0.0
        fa = law.force(d, 0.0, v_imp[c], approaching=True)
        fr = law.force(d, 0.0, v_imp[c], approaching=False)
        return fr + (fa - fr) * 0.5 * (1.0 + math.tanh(r / eps))

    def rhs(t, s):
        u, v = s[:n], s[n:2 * n]
        f = -(K @ u) - C @ v
        work = np.zeros(len(contacts))
        for c in range(len(contacts)):
            if closed[c]:
                d, r = u[left[c]] - u[right[c]] - contacts[c].gap, v[left[c]] - v[right[c]]
                F = force(c, d, r)
                f[left[c]] -= F
                f[right[c]] += F
                work[c] = F * r
        return np.concatenate([v, f / masses - ag(t), work])

    t = 0.0
    while t < stop_time:
        events = []
        for c in range(len(contacts)):
            def gap_event(tt, s, c=c):
                return s[left[c]] - s[right[c]] - contacts[c].gap
            gap_event.terminal = True
            gap_event.direction = -1 if closed[c] else 1
            events.append(gap_event)
        sol = solve_ivp(rhs, (t, stop_time), y, method="LSODA", rtol=rtol, atol=1e-12, events=events,
                        dense_output=True, max_step=0.01)
        assert sol.status >= 0, sol.message
        for c in range(len(contacts)):
            if closed[c]:
                ts = np.linspace(t, sol.t[-1], 2000)
                ys = sol.sol(ts)
                d = ys[left[c]] - ys[right[c]] - contacts[c].gap
                r = ys[n + left[c]] - ys[n + right[c]]
                current[c]["peak"] = max(current[c]["peak"], max(force(c, a, b) for a, b in zip(d, r)))
        t, y = float(sol.t[-1]), sol.y[:, -1].copy()
        if sol.status != 1:
            break
        c = next(i for i, te in enumerate(sol.t_events) if len(te))
        t, y = float(sol.t_events[c][0]), sol.y_events[c][0].copy()
        if not closed[c]:
            closed[c], v_imp[c] = True, y[n + left[c]] - y[n + right[c]]
            current[c] = dict(onset=t, v=v_imp[c], peak=0.0, work0=y[2 * n + c])
        else:
            closed[c] = False
            rec = current.pop(c)
            impacts.append((rec["onset"], t, rec["v"], rec["peak"], y[2 * n + c] - rec["work0"]))
        t = np.nextafter(t, np.inf)
    return sorted(impacts)


# -- the case: El Centro, crvk, CR 0.65 ----------------------------------------------------
@pytest.fixture(scope="module")
def elcentro_crvk(catalog):
    from cosim.master.loader import load_scene

    # the first 10 s hold 8 impacts, six of them with a re-approach during unloading
    scene = load_scene("default", ['pounding.model="crvk"', "stop_time=10.0"], catalog)
    return scene_inputs(scene)


def test_elcentro_crvk_matches_an_independent_solution(elcentro_crvk):
    inputs = elcentro_crvk
    ref = solve_reference(**inputs)
    # the reference sticks where the push lies between the branches, and leaves again
    assert ref.event_counts.get("reapproach", 0) >= 3 and ref.event_counts.get("unloading", 0) >= 3
    fine, finer = (smoothed_reference(inputs["buildings"], inputs["ground"], inputs["contacts"], inputs["stop_time"],
                                      inputs["x0"], inputs["v0"], eps) for eps in (1e-4, 1e-5))
    # the smoothed solution has converged in eps (factor 10): measured 4e-4 in energy, 3e-5 s
    assert len(fine) == len(finer) == ref.impacts == 8
    for a, b in zip(fine, finer):
        assert abs(a[0] - b[0]) < 1e-4 and a[4] == pytest.approx(b[4], rel=2e-3)
    for imp, (onset, separation, v, peak, energy) in zip(ref.impact_list, finer):
        # the same impacts at the same times, what the reference lost before the fix (it found
        # a 9th impact at 3.90 s and 10.68 kJ instead of 10.86 kJ for the 2nd); measured
        # agreement 1e-5 s and 3e-5 in energy, bounds 10 times that
        assert imp.t_onset == pytest.approx(onset, abs=1e-4)
        assert imp.t_separation == pytest.approx(separation, abs=1e-4)
        assert imp.v_impact == pytest.approx(v, rel=1e-4)
        assert imp.peak_force_N == pytest.approx(peak, rel=1e-4)
        assert imp.dissipated_energy_J == pytest.approx(energy, rel=5e-4)
    assert ref.dissipated_energy_J == pytest.approx(sum(i[4] for i in finer), rel=2e-4)


# -- a constructed case: a building leaning on its neighbour ---------------------------------------
def leaning_pair():
    """A one-storey building (T = 0.5 s, 100 t) 1 cm from a heavy stiff neighbour (1000 t,
    T = 0.1 s), both at rest, shaken by a ground-acceleration pulse of 3 m/s^2 for 0.4 s: it
    leans towards the neighbour (1.9 cm static), so while the contact unloads its storey spring
    and the pulse keep pushing with a force between crvk's two branches (CR 0.3): three
    stick phases, two impacts in 1.5 s."""
    left = ShearBuilding.from_period(0.5, [1e5], [1.0], 0.05)
    right = ShearBuilding.from_period(0.1, [1e6], [1.0], 0.05)
    law = law_for("crvk", 2.75e9, 1.5, 1e5, 1e6, 0.3)
    return [left, right], _Pulse(-3.0, 0.4), [Contact(0, 1, 1, 1, law, 0.01)], [np.zeros(1), np.zeros(1)]


class _Pulse:
    """Ground acceleration ``value`` [m/s^2] for ``0 <= t < duration`` [s], then 0."""

    def __init__(self, value: float, duration: float):
        self.value, self.duration = value, duration
        self.breakpoints = (duration,)

    def __call__(self, t: float) -> float:
        return self.value if t < self.duration else 0.0


def test_a_leaning_contact_sticks_and_matches_the_smoothed_solution():
    buildings, ground, contacts, x0 = leaning_pair()
    v0 = [np.zeros(1), np.zeros(1)]
    ref = solve_reference(buildings, ground, contacts, 1.5, x0, v0, output_dt=1e-3)
    assert ref.event_counts.get("unloading", 0) + ref.event_counts.get("loading", 0) >= 3, ref.event_counts
    fine, finer = (smoothed_reference(buildings, ground, contacts, 1.5, x0, v0, eps) for eps in (1e-5, 1e-6))
    assert len(fine) == len(finer) == ref.impacts == 2
    # measured: onsets 1e-7 s, separations 2e-5 s, energies 1e-4; the reference before the fix
    # started the second impact at 0.2521 s instead of 0.2445 s and dissipated 132 J in it, not
    # 160 J, while its energy balance closed to 5e-6 J
    for imp, (onset, separation, v, peak, energy) in zip(ref.impact_list, finer):
        assert imp.t_onset == pytest.approx(onset, abs=1e-5)
        assert imp.t_separation == pytest.approx(separation, abs=2e-4)
        assert imp.peak_force_N == pytest.approx(peak, rel=1e-3)
        assert imp.dissipated_energy_J == pytest.approx(energy, rel=1e-3)
    assert abs(ref.energy_residual) <= 1e-3   # J, against 2.1 kJ dissipated


def test_pounding_fmu_sticks_like_the_reference(catalog, elcentro_crvk):
    """The in-step resolver holds a crvk contact between its branches the same way (it chattered
    between them before: +3.0 % dissipated energy on the whole record at 10 ms)."""
    from cosim.master.loader import load_scene
    from cosim.master.simulate import simulate
    from cosim.master.system import System

    scene = load_scene("default", ['pounding.model="crvk"', "stop_time=10.0"], catalog)
    with System(scene, catalog) as system:
        result = simulate(system, progress=False)
    ref = solve_reference(**elcentro_crvk)
    assert int(result["pounding_3.impacts"][-1]) == ref.impacts == 8
    # the default scene's criteria (docs/accuracy.md): peak force 1 %, dissipated energy 2 %;
    # measured on the whole record at 10 ms: +0.45 %, -0.02 %
    assert result["pounding_3.F_max"][-1] == pytest.approx(ref.peak_force_N, rel=0.01)
    assert result["pounding_3.E_dissipated"][-1] == pytest.approx(ref.dissipated_energy_J, rel=0.02)
