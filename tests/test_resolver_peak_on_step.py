"""The resolver's peak force is located on its accepted steps (fmu_src.resolver.ImpactResolver._sample).

Two oracles, both solve_ivp (DOP853, rtol 1e-12, dense output, the maximum polished by a bounded
search on the interpolant to 1e-13 of the interval), written here:

* a single impact of free masses, pushed or not by a constant external acceleration: the
  continuous solution, several contact laws;
* bodies whose structures' push changes inside the impact (held at 0, then a step of +-30 m/s^2,
  as a storey force that changes while the bodies are in contact): the resolver learns the push
  from the host's increments one step late and corrects its own state at the next step's start
  (rules 1-2).  The oracle is then the resolver's own accepted trajectory: every communication
  step re-integrated from the state the resolver started it from, with the external
  acceleration it used there.  The reported peak must be that trajectory's largest force.

The search it replaced started from the sample before the local maximum, that is, at a
communication step's boundary, from the previous step's end state before the correction and
with the previous step's external acceleration: a trajectory the resolver did not take.  It
fails test_peak_on_the_accepted_trajectory_when_the_push_changes by up to 7 % (measured with the
search of 3893349).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from fmu_src.contact_laws import law_for
from fmu_src.resolver import ImpactResolver
from fmu_src.single_impact import simulate_impact

LAWS = ["jankowski", "hunt_crossley", "hertzdamp", "kelvin_voigt", "hertz"]


def largest_force(law, v_imp, approaching, delta, rate, a0, a1, t0, t1):
    """Largest contact force [N] of ``delta'' = a0 + a1 (t - t0) - F(delta, delta') / m`` over
    [t0, t1] [s] from (delta [m], rate [m/s]), switching from approach to restitution at
    ``delta' = 0`` and stopping at separation (``delta = 0``)."""
    m, best, t, y = law.m, 0.0, t0, np.array([delta, rate])
    scale = law.length_scale(v_imp)
    while t < t1 - 1e-14 * t1:
        def rhs(s, z, approaching=approaching):
            return (z[1], a0 + a1 * (s - t0) - law.force(z[0], z[1], v_imp, approaching) / m)

        def event(s, z, approaching=approaching):
            return z[1] if approaching else z[0]
        event.terminal, event.direction = True, -1
        sol = solve_ivp(rhs, (t, t1), y, method="DOP853", rtol=1e-12, atol=[1e-14 * scale, 1e-14 * v_imp],
                        events=[event], dense_output=True)

        def force(s, sol=sol, approaching=approaching):
            return law.force(*sol.sol(s), v_imp, approaching)
        grid = np.linspace(sol.t[0], sol.t[-1], 201)
        values = [force(s) for s in grid]
        k = int(np.argmax(values))
        lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        polished = minimize_scalar(lambda s: -force(s), bounds=(lo, hi), method="bounded",
                                   options={"xatol": 1e-13 * (t1 - t0)})
        best = max(best, values[k], -polished.fun)
        if sol.status != 1 or not approaching:
            break
        t, y, approaching = float(sol.t[-1]), sol.y[:, -1].copy(), False
        y[1] = 0.0
    return best


def test_the_oracle_finds_a_known_peak():
    # Hertz (no damping), free masses: the peak is at the maximum penetration, where the energy
    # m v^2 / 2 is all in the spring: k d^(n+1) / (n+1) = m v^2 / 2, F = k d^n.
    law = law_for("hertz", 2.75e9, 1.5, 1e5, 1e5, 0.6)
    v = 1.0
    d_max = (law.m * v * v * 2.5 / (2.0 * law.k)) ** (1.0 / 2.5)
    assert largest_force(law, v, True, 0.0, v, 0.0, 0.0, 0.0, 1.0) == pytest.approx(law.k * d_max ** 1.5,
                                                                                        rel=1e-10)


@pytest.mark.parametrize("model", LAWS)
@pytest.mark.parametrize("push", [0.0, 5.0, -5.0])
def test_single_impact_peak_against_the_continuous_solution(model, push):
    # free masses under a constant push (learnt exactly from one step: no correction), the
    # onset inside a step, the impact over 3-30 steps or inside one: the resolver at rtol 1e-11
    # reports the continuous solution's peak to its integration error (observed <= 1.3e-9)
    law = law_for(model, 2.75e9, 1.5, 1e5, 1e5, 0.6)
    v0 = 1.0
    t_c = simulate_impact(law, v0).contact_duration
    for ratio, phase in ((0.03, 0.1), (0.37, 0.5), (1.3, 0.83)):
        h = ratio * t_c
        T = (3 + phase) * h                        # onset time: 3 steps of flight and a part
        v, d = v0 - push * T, -((v0 - push * T) * T + 0.5 * push * T * T)
        r = ImpactResolver(law, rtol=1e-11)
        r.trace = []
        for _ in range(int(3 * t_c / h) + 6):
            out = r.step(d, v, h)
            acc = push - out.mean_force / law.m
            d, v = d + v * h + 0.5 * acc * h * h, v + acc * h
            if r.ended:
                break
        assert r.impacts == 1
        truth = largest_force(law, r.v_imp, True, 0.0, r.v_imp, push, 0.0, 0.0, 10.0 * t_c)
        # DP5 at rtol 1e-11 against DOP853 at 1e-12: the peak to 1e-8 (observed <= 1.3e-9)
        assert r.F_max == pytest.approx(truth, rel=1e-8)
        assert r.F_max >= max(f for (_, _, f, _) in r.trace)


def pushed_in_contact(model, ratio, frac, push):
    """(reported peak, the accepted trajectory's largest force, largest sample) [N] of one impact
    (1 m/s) whose structures' push steps from 0 to ``push`` [m/s^2] ``frac`` contact durations
    after the onset; communication step ``ratio`` contact durations; the host exact."""
    law = law_for(model, 2.75e9, 1.5, 1e5, 1e5, 0.6)
    v0 = 1.0
    t_c = simulate_impact(law, v0).contact_duration
    h = ratio * t_c
    T = 3 * h                                      # onset at the end of the third step
    t_jump = T + frac * t_c
    r = ImpactResolver(law)
    r.trace = []
    starts, integrate = [], r._integrate

    def spy(t, h_, out):                           # the state each communication step starts from
        starts.append((r.approaching, r.sticking, r.d, r.u, r.a0 + r.a1 * t, r.a1, t, h_, r.v_imp))
        return integrate(t, h_, out)
    r._integrate = spy
    d, v, time, peaks = -v0 * T, v0, 0.0, []
    for _ in range(int(3 * t_c / h) + 8):
        n = len(starts)
        out = r.step(d, v, h)
        for approaching, sticking, d_s, u_s, a0, a1, t, h_, v_imp in starts[n:]:
            assert not sticking
            peaks.append(largest_force(law, v_imp, approaching, d_s * law.length_scale(v_imp), u_s * v_imp,
                                       a0, a1, t, h_))
        pushed = min(max(time + h - t_jump, 0.0), h)   # s of this step under the push
        d += v * h - 0.5 * out.mean_force / law.m * h * h + 0.5 * push * pushed * pushed
        v += -out.mean_force / law.m * h + push * pushed
        time += h
        if r.ended:
            break
    assert r.impacts == 1
    return r.F_max, max(peaks), max(f for (_, _, f, _) in r.trace)


@pytest.mark.parametrize("model", ["jankowski", "hunt_crossley", "hertz"])
def test_peak_on_the_accepted_trajectory_when_the_push_changes(model):
    worst = 0.0
    for ratio in (0.05, 0.1, 0.2):
        for frac in (0.1, 0.15, 0.2, 0.25, 0.3):
            for push in (30.0, -30.0):
                reported, accepted, sampled = pushed_in_contact(model, ratio, frac, push)
                assert reported >= sampled                    # never below the largest sample
                worst = max(worst, abs(reported / accepted - 1.0))
    # 1e-5: the resolver's own DP5 steps at rtol 1e-8 against DOP853 at 1e-12 (~1e-7), and a
    # maximum at a step's corrected start, where the force jumps with the correction, which the
    # bounded search over (0, step] reaches to first order only (_PEAK_XATOL of the step times
    # the force's slope: observed 1.6e-6).  The search from the previous step's end state (the
    # one this replaced) is off by up to 7e-2 here.
    assert worst <= 1e-5
