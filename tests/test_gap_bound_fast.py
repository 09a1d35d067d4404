"""OpenGaps' proof for linear buildings (:meth:`OpenGaps._linear_horizons`) answers bit for bit as
the general proof does (:meth:`OpenGaps.horizons` through :class:`FloorMotion`), which
``tests/test_gap_bound.py`` checks against the motion itself.

The fast proof keeps each building's modal state and free motion per horizon across calls,
gathers only the levels' floors from them, and finds every answer
with one comparison and one ``argmax``: none of that may change a horizon by one bit.  Random
pairs of buildings (1 to 15 storeys, Rayleigh or modal damping), levels on any floors and
subsets of them, states from closed to wide open, held forces, repeated states and horizons.
"""
from __future__ import annotations

import numpy as np
import pytest

from cosim.master.gap_bound import ModalBound, OpenGaps, constant_bound, running_max_abs
from fmu_src.shear_building import ShearBuilding


def building(rng, n):
    """A random shear building (masses kg, relative stiffnesses), Rayleigh or modal damping."""
    masses = list(rng.uniform(0.5, 2.0, n) * 1e5)
    stiffnesses = list(rng.uniform(0.5, 2.0, n))
    damping = "modal" if rng.random() < 0.5 else "rayleigh"
    return ShearBuilding.from_period(float(rng.uniform(0.2, 1.5)), masses, stiffnesses, 0.05, damping)


@pytest.mark.parametrize("seed", range(8))
def test_linear_proof_answers_as_the_general_one_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    nl, nr = int(rng.integers(1, 16)), int(rng.integers(1, 16))
    bl, br = building(rng, nl), building(rng, nr)
    ix_l, iv_l = np.arange(nl), nl + np.arange(nl)
    ix_r, iv_r = 2 * nl + np.arange(nr), 2 * nl + nr + np.arange(nr)
    buildings = {"left": (ModalBound(bl), ix_l, iv_l), "right": (ModalBound(br), ix_r, iv_r)}
    m = min(nl, nr)
    floors = rng.choice(m, size=int(rng.integers(1, m + 1)), replace=False)
    levels = [("left", int(f), "right", int(f), float(rng.uniform(0.01, 0.05))) for f in floors]
    fast = OpenGaps(buildings, levels)
    general = OpenGaps(buildings, levels)
    general._all_linear = False                 # the general proof (FloorMotion per building)
    assert fast._all_linear
    knots = np.linspace(-0.1, 1.0, 60)
    values = rng.normal(0.0, 3.0, knots.size)
    states = [np.concatenate((rng.normal(0, s, nl), rng.normal(0, 10 * s, nl),
                              rng.normal(0, s, nr), rng.normal(0, 10 * s, nr))) for s in (0.002, 0.01, 0.03)]
    kinds = set()
    for k in range(60):
        y = states[int(rng.integers(len(states)))]     # states repeat: kept ones must answer alike
        H = float(rng.choice([0.01, 0.05, 0.33, 0.17 + 1e-15]))
        ground = running_max_abs(knots, values, 0.0, H) if k % 3 else constant_bound(0.0)
        forces = None
        if k % 4 == 1:
            forces = {"left": np.where(np.arange(nl) == floors[0], -2e5 * rng.random(), 0.0),
                      "right": np.where(np.arange(nr) == floors[0], 2e5 * rng.random(), 0.0)}
        which = None if k % 5 else sorted(rng.choice(len(levels), size=int(rng.integers(1, len(levels) + 1)),
                                                     replace=False).tolist())
        got = fast.horizons(y, H, ground, forces, which)
        want = general.horizons(y, H, ground, forces, which)
        assert got == want, (k, H, which)
        assert got == OpenGaps(buildings, levels).horizons(y, H, ground, forces, which)   # nothing kept
        kinds.update("closed" if s == 0.0 else "open" if s == H else "short" for s in got)
    # the sequence meets every kind of answer, so a wrong one would show
    assert {"open", "short"} <= kinds


@pytest.mark.parametrize("seed", range(4))
def test_free_tables_of_all_modes_at_once_equal_mode_by_mode(seed):
    """ModalBound's free-motion tables, computed for every underdamped mode at once, equal bit for
    bit each mode's ``exp(-zeta w s) cos(wd s)`` and ``exp(-zeta w s) sin(wd s) / wd`` computed
    alone (the proofs' numbers may not change with the vectorisation); stiffness factors give
    overdamped modes too, which keep their own branch."""
    rng = np.random.default_rng(seed)
    b = building(rng, int(rng.integers(1, 16)))
    for factor in (1.0, 0.02, 1e-4):
        bound = ModalBound(b, factor) if factor != 1.0 else ModalBound(b)
        s = float(rng.uniform(0.01, 2.0)) * np.arange(65) / 64
        Ac, As = bound._free_tables(s)
        for j in range(bound.n):
            wj, zj = bound.w[j], bound.zeta[j]
            if not (wj > 0.0 and zj < 1.0):
                continue
            decay = np.exp(-zj * wj * s)
            wd = wj * np.sqrt(1.0 - zj * zj)
            assert np.array_equal(Ac[j], decay * np.cos(wd * s))
            assert np.array_equal(As[j], decay * np.sin(wd * s) / wd)


@pytest.mark.parametrize("seed", range(6))
def test_bilinear_proof_answers_as_the_general_one_bit_for_bit(seed):
    """Two bilinear buildings (:class:`cosim.master.gap_bound._BilinearPair`: both buildings'
    arithmetic stacked) answer as the per-building pieces do, bit for bit: states elastic and
    yielding (a storey beyond its elastic range), residual drifts, the linear proof cut short by
    the gap or by the storeys' ranges and the proof through yielding after it, levels on any
    floors and subsets of them, repeated states and horizons; held forces take the pieces."""
    from cosim.master.gap_bound import ElasticRange

    rng = np.random.default_rng(100 + seed)
    nl, nr = int(rng.integers(1, 9)), int(rng.integers(1, 9))
    bl, br = building(rng, nl), building(rng, nr)
    buildings, elastic, yielded, offset, ranges = {}, {}, {}, 0, {}
    for name, b, n in (("left", bl, nl), ("right", br, nr)):
        ix, iv, ir = (offset + np.arange(n) + k * n for k in range(3))
        offset += 3 * n
        alpha = float(rng.uniform(0.02, 0.2))
        dy = rng.uniform(0.005, 0.02, n)                    # yield drifts (m)
        buildings[name] = (ModalBound(b), ix, iv)
        elastic[name] = ElasticRange(alpha, dy, ir)
        yielded[name] = ModalBound.through_yielding(b, alpha, dy * np.asarray(b.stiffnesses))
        ranges[name] = (n, alpha, dy)
    m = min(nl, nr)
    floors = rng.choice(m, size=int(rng.integers(1, m + 1)), replace=False)
    levels = [("left", int(f), "right", int(f), float(rng.uniform(0.005, 0.05))) for f in floors]
    fast = OpenGaps(buildings, levels, elastic, yielded)
    general = OpenGaps(buildings, levels, elastic, yielded)
    general.stacked = False

    def state(scale, yield_storey):
        y = []
        for name in ("left", "right"):
            n, alpha, dy = ranges[name]
            r = rng.uniform(-0.5, 0.5, n) * dy                # residual drifts (m)
            drifts = r / (1.0 - alpha) * alpha + rng.uniform(-0.9, 0.9, n) * dy * scale
            if yield_storey and name == "left":
                drifts[0] = r[0] / (1.0 - alpha) * alpha + 1.5 * dy[0]   # beyond the elastic range
            u = np.cumsum(r) + np.cumsum(drifts)
            y += [u, rng.normal(0, 5 * scale * dy.mean() / 0.05, n), r]
        return np.concatenate(y)

    knots = np.linspace(-0.1, 1.0, 60)
    values = rng.normal(0.0, 3.0, knots.size)
    states = [state(s, k == 3) for k, s in enumerate((0.05, 0.3, 0.9, 0.5))]
    kinds = set()
    for k in range(50):
        y = states[int(rng.integers(len(states)))]
        H = float(rng.choice([0.01, 0.05, 0.33, 0.17 + 1e-15]))
        ground = running_max_abs(knots, values, 0.0, H) if k % 3 else constant_bound(0.0)
        forces = None
        if k % 7 == 1:
            forces = {"left": np.where(np.arange(nl) == floors[0], -2e5 * rng.random(), 0.0)}
        which = None if k % 5 else sorted(rng.choice(len(levels), size=int(rng.integers(1, len(levels) + 1)),
                                                     replace=False).tolist())
        got = fast.horizons(y, H, ground, forces, which)
        want = general.horizons(y, H, ground, forces, which)
        assert got == want, (k, H, which)
        kinds.update("closed" if s == 0.0 else "open" if s == H else "short" for s in got)
    assert {"open", "short"} <= kinds
    assert any(p is not None for p in fast._bilinear_plan(None))
