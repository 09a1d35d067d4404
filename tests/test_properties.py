"""Property-based checks (hypothesis) of the contact physics over random inputs.

The example-based tests pin the numbers at chosen points; these ask the same physical
questions at points nobody chose: no tension, nothing non-finite, no energy from nowhere, and
an impact whose outcome does not depend on where the communication points fall, also when the
host changes its step from one step to the next.
"""
from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from fmu_src.contact_laws import MODELS, law_for
from fmu_src.resolver import ImpactResolver
from fmu_src.single_impact import simulate_impact

models = st.sampled_from(MODELS)
restitution = st.floats(0.05, 1.0)


def log_uniform(lo: float, hi: float):
    """Floats spread evenly over the decades from ``lo`` to ``hi``."""
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: 10.0 ** e)


@settings(max_examples=400, deadline=None)
@given(model=models, CR=restitution, k=log_uniform(1e6, 1e12), n=st.sampled_from([1.0, 1.5]),
       m1=log_uniform(1.0, 1e6), m2=log_uniform(1.0, 1e6),
       delta=st.floats(-1.0, 1.0), delta_dot=st.floats(-50.0, 50.0), v_imp=st.floats(0.0, 50.0))
# found by this test: a denormal latched speed overflowed the Hertz-damp ratio delta_dot / v_imp
@example(model="hertzdamp", CR=0.5, k=1e6, n=1.0, m1=1.0, m2=1.0, delta=1.0, delta_dot=1.0, v_imp=5e-324)
def test_force_is_finite_and_never_tensile(model, CR, k, n, m1, m2, delta, delta_dot, v_imp):
    law = law_for(model, k, n, m1, m2, CR)
    F = law.force(delta, delta_dot, v_imp)
    assert math.isfinite(F) and F >= 0.0
    if delta <= 0.0:
        assert F == 0.0          # an open gap carries no force


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(model=models, CR=st.floats(0.05, 0.95), v=log_uniform(1e-3, 10.0), m1=log_uniform(1.0, 1e6),
       mass_ratio=log_uniform(0.01, 100.0), k=log_uniform(1e7, 1e12), onset=st.floats(0.0, 1.0),
       step_ratios=st.lists(log_uniform(1e-3, 2.0), min_size=1, max_size=40))
def test_resolved_impact_of_free_masses_with_varying_steps(model, CR, v, m1, mass_ratio, k, onset, step_ratios):
    """Two free masses driven by the resolver's mean force, with a different communication step
    at every step (1/1000 to 2 contact durations, cycled): the impact matches the
    independent solve_ivp integration whatever the step sequence."""
    m2 = m1 * mass_ratio
    law = law_for(model, k, 1.5, m1, m2, CR)
    ref = simulate_impact(law, v)
    t_c = ref.contact_duration
    resolver = ImpactResolver(law)
    x1, v1, x2, v2 = -onset * v * step_ratios[0] * t_c, v, 0.0, 0.0
    p0, E0 = m1 * v, 0.5 * m1 * v * v
    t, i = 0.0, 0
    while t < (onset * step_ratios[0] + 1.5) * t_c or resolver.in_contact:
        h = step_ratios[i % len(step_ratios)] * t_c
        F = resolver.step(x1 - x2, v1 - v2, h).mean_force
        assert math.isfinite(F) and F >= 0.0                     # no tension, no NaN
        x1 += v1 * h - 0.5 * F / m1 * h * h
        v1 -= F / m1 * h
        x2 += v2 * h + 0.5 * F / m2 * h * h
        v2 += F / m2 * h
        t += h
        i += 1
        assert i < 200_000
    assert resolver.impacts == 1
    # the impulse acts on both bodies: momentum to round-off
    assert m1 * v1 + m2 * v2 == pytest.approx(p0, rel=1e-12, abs=1e-12 * p0)
    E_lost = E0 - 0.5 * (m1 * v1 * v1 + m2 * v2 * v2)
    E_diss = resolver.dissipated_energy()
    m = law.m
    E_rel = 0.5 * m * v * v              # energy of the relative motion: all an impact can take
    # no energy from nowhere and no more lost than the relative motion had (1e-9: round-off)
    assert -1e-9 * E_rel <= E_diss <= E_rel * (1.0 + 1e-9)
    # the contact's dissipation is what the bodies lost: 0.1 % of E_rel, the contract's tolerance
    assert abs(E_diss - E_lost) <= 1e-3 * E_rel
    # outcome equals the reference: CR to 0.005 (contract), peak force to 1 %
    assert -(v1 - v2) / v == pytest.approx(ref.achieved_CR, abs=5e-3)
    assert resolver.F_max == pytest.approx(ref.peak_force, rel=1e-2)
