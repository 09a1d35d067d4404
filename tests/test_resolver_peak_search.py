"""The resolver's bounded peak search (fmu_src.resolver.bounded_minimum) against its oracle,
scipy.optimize.minimize_scalar(method="bounded"), which it replaced: the same minimum and the
same number of evaluations, bit for bit, on random smooth functions (peaks inside, at either
end, flat, steep) and on the force along a Dormand-Prince step the resolver actually searches."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from fmu_src.contact_laws import law_for
from fmu_src.resolver import ImpactResolver, bounded_minimum


def scipy_minimum(fun, upper, xatol):
    res = minimize_scalar(fun, bounds=(0.0, upper), method="bounded", options={"xatol": xatol})
    return float(res.fun), int(res.nfev)


def random_functions(rng, count):
    for _ in range(count):
        kind = rng.integers(5)
        c, w, a = rng.uniform(-0.5, 1.5), rng.uniform(0.05, 3.0), rng.uniform(-2.0, 2.0)
        if kind == 0:
            yield lambda x, c=c, w=w: -math.exp(-((x - c) / w) ** 2)
        elif kind == 1:
            yield lambda x, c=c, a=a: (x - c) ** 2 * (1.0 + a * x)
        elif kind == 2:
            yield lambda x, c=c, w=w: -math.sin(w * x + c) - 0.1 * x ** 3
        elif kind == 3:
            yield lambda x, a=a: a * x                       # the minimum at an end
        else:
            yield lambda x, c=c: abs(x - c) ** 1.5 - 1.0     # not smooth at its minimum


def test_same_as_scipy_on_random_functions():
    rng = np.random.default_rng(17)
    for fun in random_functions(rng, 400):
        upper = float(rng.choice([1.0, 1e-3, 37.0, rng.uniform(1e-6, 10.0)]))
        xatol = float(rng.choice([1e-7, 1e-5, 1e-10])) * upper

        def scaled(x, fun=fun, upper=upper):
            return fun(x / upper)
        assert bounded_minimum(scaled, upper, xatol) == scipy_minimum(scaled, upper, xatol)


def searches_along_a_step(model, seed):
    """60 searches the resolver runs (_refine_peak) for a law: (resolver, sample, span,
    minus_force) with minus_force(x) minus the force at the end of a DP step of length x from
    a sample near the force peak, approaching and restituting."""
    law = law_for(model, 2.75e9, 1.5, 1e5, 1e5, 0.65)
    r = ImpactResolver(law)
    rng = np.random.default_rng(seed)
    for _ in range(60):
        approaching = bool(rng.integers(2))
        f = r._kernels[approaching]
        d = rng.uniform(0.05, 1.2)
        u = rng.uniform(0.0, 1.0) * (1.0 if approaching else -1.0)
        al, al1 = rng.uniform(-0.2, 0.2), rng.uniform(-0.1, 0.1)
        acc = al - f(d, u)
        span = rng.uniform(1e-3, 0.5)

        def minus_force(x, f=f, d=d, u=u, al=al, al1=al1, acc=acc):
            dx, ux = r._dp_step(f, al, al1, d, u, acc, x, 1e-8, 1e-8)[:2]
            return -f(dx, ux)
        yield r, (0.0, f(d, u), d, u, acc, approaching, al, al1), span, minus_force


@pytest.mark.parametrize("model", ["jankowski", "crvk", "hertzdamp", "kelvin_voigt", "hertz"])
def test_same_as_scipy_on_the_force_along_a_step(model):
    """The search the resolver runs, bit for bit as scipy's."""
    for _, _, span, minus_force in searches_along_a_step(model, 3):
        assert bounded_minimum(minus_force, span, 1e-7 * span) == scipy_minimum(minus_force, span, 1e-7 * span)


@pytest.mark.parametrize("model", ["jankowski", "crvk", "hertzdamp", "kelvin_voigt", "hertz"])
def test_the_peak_search_tolerance_costs_nothing_measurable(model):
    """_refine_peak locates the maximum to _PEAK_XATOL of the span: the force it finds (or the
    samples at the span's ends, which the resolver takes with it) is short of the one a search
    to 1e-12 of the span finds by about F'' dx^2 / 2, at most a part _PEAK_XATOL^2 of the
    force's variation over the span: 1e-8 at 1e-4, a hundredth of the impact's own integration
    error (a tolerance of 1e-3 fails this bound)."""
    for r, sample, span, minus_force in searches_along_a_step(model, 5):
        found, calls = r._refine_peak(sample, span)
        # the resolver takes the larger of the search and the samples at the ends (_sample):
        # a maximum at an end is the sample's, found to first order only by the search
        ends = max(sample[1], -minus_force(span))
        found = max(found, ends)
        tight = max(-bounded_minimum(minus_force, span, 1e-12 * span)[0], ends)
        variation = tight - min(-minus_force(x) for x in np.linspace(1e-9 * span, span, 41))
        assert calls > 0 and found <= tight * (1.0 + 1e-15)
        # 1e-8 of the variation (a hundredth of the impact's integration error, ~1e-6 of the
        # force), +1e-15 of the force: round-off of the two searches' last digits
        assert tight - found <= 1e-8 * variation + 1e-15 * tight
