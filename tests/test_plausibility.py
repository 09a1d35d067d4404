"""The contact's self-protection and its energy bookkeeping (issue 13, points 1 and 2), at the
physics level (fmu_src.host_observer, resolver, plausibility): the host's delivery kernel, the timing energy int C A dt, the
inconsistent-host check and the plausibility watch.  The FMU-level behaviour (warnings in the
log, fmi2Discard) is in tests/test_host_matrix.py."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.peers import hosts
from fmu_src.contact_laws import law_for
from fmu_src.host_observer import HOSTS, _STANDARD_KERNELS, _hht_kernel, _mean_delay
from fmu_src.plain_contact import PlainContact
from fmu_src.plausibility import PlausibilityWatch
from fmu_src.resolver import ImpactResolver
from fmu_src.single_impact import simulate_impact


def free_host(resolver, m1, m2, v, h, steps, share=(1.0, 1.0), late=False):
    """Free masses closing at ``v`` [m/s], exact for the held force; ``share``: the part of the
    force the host applies to body 1 and body 2 (a wrongly wired host applies less)."""
    x1, v1, x2, v2 = -1.37 * v * h, v, 0.0, 0.0
    held = 0.0
    for _ in range(steps):
        F = resolver.step(x1 - x2, v1 - v2, h).mean_force
        F, held = (held, F) if late else (F, 0.0)
        a1, a2 = -share[0] * F / m1, share[1] * F / m2
        x1, v1 = x1 + v1 * h + 0.5 * a1 * h * h, v1 + a1 * h
        x2, v2 = x2 + v2 * h + 0.5 * a2 * h * h, v2 + a2 * h
    return v2 - v1


@pytest.mark.parametrize("late", [False, True])
def test_the_kernel_of_an_exact_host_is_found_exactly(late):
    law = law_for("jankowski", 2.75e9, 1.5, 1e5, 1e5, 0.65)
    t_c = simulate_impact(law, 1.0).contact_duration
    r = ImpactResolver(law)
    free_host(r, 1e5, 1e5, 1.0, 0.05 * t_c, 40, late=late)
    assert r.observer.kernel == ((0.0, 1.0) if late else (1.0,))
    assert r.observer.lead == (1.0 if late else 0.0)
    assert not r.observer.notices


def test_a_host_that_delivers_half_the_impulse_is_named():
    # F applied to body 2 only (a missing reaction on body 1): the host delivers half the impulse
    law = law_for("jankowski", 2.75e9, 1.5, 1e5, 1e5, 0.65)
    t_c = simulate_impact(law, 1.0).contact_duration
    r = ImpactResolver(law)
    free_host(r, 1e5, 1e5, 1.0, 0.05 * t_c, 60, share=(0.0, 1.0))
    assert r.observer.inconsistent and r.observer.kernel is None
    assert any("delivers 0.5 times the impulse" in n and "m1, m2" in n for n in r.observer.notices)


def test_standard_kernels_sum_to_one_and_hht_reduces_to_newmark():
    for w in _STANDARD_KERNELS:
        assert sum(w) == pytest.approx(1.0, abs=1e-15)
    assert _hht_kernel(0.0, False) == (0.5, 0.5)
    assert _hht_kernel(-0.1, False) == pytest.approx((0.54, 0.42, 0.04))
    assert _mean_delay(_hht_kernel(-0.1, True)) == pytest.approx(1.5)
    assert set(HOSTS) == {"any", "zoh", "zoh_late", "trapezoidal", "trapezoidal_late"}
    with pytest.raises(ValueError, match="host = 'jacobi' is not allowed: one of any, zoh"):
        ImpactResolver(law_for("hertz", 1e9, 1.5, 1.0, 1.0, 1.0), host="jacobi")


class _Unwithheld(ImpactResolver):
    """The resolver without its first-impact pay-back (ImpactResolver._withhold): every impulse
    handed over, so that the host shows the timing energy in full."""

    def _withhold(self, emitted, internal, h):
        return 0.0


def _first_impact_in_a_jacobi_host(resolver):
    """The two oscillators' first impact (0.17-0.25 s) and the settling after it in the exact
    host in Jacobi order at 10 ms, nothing declared; returns (energy created [J], the most
    timing energy booked [J], the most taken back [J], initial energy [J])."""
    case = hosts.two_oscillators()
    body = hosts.INTEGRATORS["zoh"](case.structure, case.x0, case.v0)
    r = resolver
    h, E0, damping, held = 0.01, body.energy(), 0.0, 0.0
    booked = repaid = 0.0
    C = case.structure.C
    for k in range(40):
        F = r.step(body.x[0] - body.x[1] - 0.01, body.v[0] - body.v[1], h).mean_force
        v0 = body.v.copy()
        body.advance(h, np.array([-held, held]))
        held = F
        damping += 0.5 * h * (v0 @ C @ v0 + body.v @ C @ body.v)
        booked, repaid = max(booked, r.observer.debt), max(repaid, r.observer.repaid)
    assert r.impacts == 1 and not r.in_contact
    return body.energy() + damping + r.dissipated_energy() - E0, booked, repaid, E0


def test_the_timing_energy_is_what_the_host_gains():
    """The argument of docs/fmi_hosts.md: over an impact the host gains int C A dt more than the
    contact takes from its own bodies.  In a Jacobi host at 10 ms, before the host's timing is
    known, the FMU books that energy: with every impulse handed over it must be what the host's
    energy balance shows created (measured 80-90 %: the formula is first order in the timing
    error)."""
    law = law_for("jankowski", 2.75e9, 1.5, 1e5, 1e5, 0.65)
    created, booked, _, E0 = _first_impact_in_a_jacobi_host(_Unwithheld(law))
    assert created > 0.02 * E0           # the case the pay-back is for (3.9 % of E0)
    assert booked == pytest.approx(created, rel=0.25)


def test_the_first_impact_takes_the_timing_energy_back():
    """The same impact with the pay-back: the impulse withheld from the late host takes back
    what the timing gave it (ImpactResolver._withhold), so that less than the issue's 1 % margin
    is created: measured 0.045 % of E0 against 3.9 % without.  The energy the FMU claims to have
    taken back is what the host shows (measured 0.88 of it; within 25 %, as the booking above)."""
    law = law_for("jankowski", 2.75e9, 1.5, 1e5, 1e5, 0.65)
    created_before, _, _, E0 = _first_impact_in_a_jacobi_host(_Unwithheld(law))
    created, booked, repaid, _ = _first_impact_in_a_jacobi_host(ImpactResolver(law))
    assert created < 0.01 * E0
    assert repaid == pytest.approx(created_before - created, rel=0.25)


class _Contact:
    """What PlausibilityWatch reads of a contact, set by hand."""

    def __init__(self, **kw):
        self.impacts, self.in_contact, self.v_imp, self.last_CR, self.last_E = 0, False, 0.0, float("nan"), 0.0
        self.__dict__.update(kw)


def test_impacts_multiplying_are_reported_once():
    law = law_for("jankowski", 2.75e9, 1.5, 1e5, 1e5, 0.65)
    watch = PlausibilityWatch(law)
    c = _Contact()
    kinds = []
    for k in range(12):                   # an impact every other step at nearly the same speed
        c.impacts, c.in_contact, c.v_imp = k // 2 + 1, k % 2 == 0, 1.0 - 0.01 * k
        kinds += [kind for kind, _ in watch.check(c, 1e-3)]
    assert kinds.count("multiplying") >= 1
    # an impact after a long flight is not
    watch, c = PlausibilityWatch(law), _Contact()
    for k in range(40):
        c.impacts, c.in_contact, c.v_imp = k // 20 + 1, k % 20 == 0, 1.0
        assert not watch.check(c, 1e-3)


def test_plain_law_rebound_and_coarse_step_are_reported():
    law = law_for("jankowski", 2.75e9, 1.5, 1e5, 1e5, 0.65)
    T = law.length_scale(1.0) / 1.0
    plain = PlainContact(law)
    watch = PlausibilityWatch(law)
    kinds = set()
    # a coarse step: the host overlaps deeply at the first step in contact, then flies apart faster
    plain.step(0.3 * T, 1.0, T)
    kinds |= {k for k, _ in watch.check(plain, T)}
    plain.step(-0.1 * T, -1.2, T)
    kinds |= {k for k, _ in watch.check(plain, T)}
    assert kinds == {"coarse_plain_step", "rebound"}
