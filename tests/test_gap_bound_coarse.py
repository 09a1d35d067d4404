"""The coarse bound of a sleeping contact's gap (:meth:`cosim.master.gap_bound._LinearPair.coarse_bound`).

The master tries it before the proof on the grid for the levels of sleeping contacts while
others are awake, and skips that proof where it says every gap stays open: the run's decisions
must stay those of the proof.  So the coarse bound must

* hold: the penetration of the motion itself (solve_ivp, ``tests/test_gap_bound.py``'s oracle)
  never exceeds it over the horizon, with held forces and ground motion;
* lie above the proof's bound on every grid interval: with each gap set so that the coarse bound
  sits just below ``-COARSE_MARGIN`` (the hardest case: the gap shifts both bounds alike), the
  proof on the grid must answer the whole horizon for every level;
* answer what the proof answers through :meth:`OpenGaps.horizons` (random subsets, forces).
"""
from __future__ import annotations

import numpy as np
import pytest

from cosim.master.gap_bound import COARSE_MARGIN, EXACT_MIN_HORIZON, GroundAhead, ModalBound, OpenGaps, running_max_abs
from fmu_src.shear_building import ShearBuilding
from test_gap_bound import motion


def building(rng, n):
    masses = list(rng.uniform(0.5, 2.0, n) * 1e5)
    stiffnesses = list(rng.uniform(0.5, 2.0, n))
    damping = "modal" if rng.random() < 0.5 else "rayleigh"
    return ShearBuilding.from_period(float(rng.uniform(0.2, 1.5)), masses, stiffnesses, float(rng.uniform(0.0, 0.2)),
                                     damping)


def case(seed):
    """Two random buildings, levels on common floors, a state, knots of a ground motion, forces."""
    rng = np.random.default_rng(seed)
    nl, nr = int(rng.integers(1, 9)), int(rng.integers(1, 9))
    bl, br = building(rng, nl), building(rng, nr)
    m = min(nl, nr)
    floors = np.sort(rng.choice(m, size=int(rng.integers(1, m + 1)), replace=False))
    scale = float(rng.choice([0.002, 0.01, 0.03]))
    ul, vl = rng.normal(0, scale, nl), rng.normal(0, 10 * scale, nl)
    ur, vr = rng.normal(0, scale, nr), rng.normal(0, 10 * scale, nr)
    times = np.linspace(-0.05, 0.5, 40)
    values = rng.normal(0.0, 3.0, times.size)
    forces = {}
    if seed % 3:                                    # a contact force on one floor of each building
        f = int(rng.integers(m))
        forces = {"left": np.where(np.arange(nl) == f, -3e5 * rng.random(), 0.0),
                  "right": np.where(np.arange(nr) == f, 3e5 * rng.random(), 0.0)}
    H = float(rng.choice([0.01, 0.02, 0.05, 0.17]))
    return rng, bl, br, floors, np.concatenate((ul, vl, ur, vr)), times, values, forces, H


def gaps_for(bl, br, floors, gaps):
    nl, nr = bl.n, br.n
    buildings = {"left": (ModalBound(bl), np.arange(nl), nl + np.arange(nl)),
                 "right": (ModalBound(br), 2 * nl + np.arange(nr), 2 * nl + nr + np.arange(nr))}
    return OpenGaps(buildings, [("left", int(f), "right", int(f), float(g)) for f, g in zip(floors, gaps)])


def the_pair(opengaps):
    (pair,) = opengaps._linear_plan(None, False)
    return pair


@pytest.mark.parametrize("seed", range(12))
def test_coarse_bound_holds_against_the_motion(seed):
    _, bl, br, floors, y, times, values, forces, H = case(seed)
    pair = the_pair(gaps_for(bl, br, floors, np.zeros(floors.size)))
    peak = GroundAhead(times, values, 0.0, H).peak()
    bound = pair.coarse_bound(y, H, peak, forces)
    nl, nr = bl.n, br.n
    points = H * np.linspace(0.0, 1.0, 201)
    xl = motion(bl, y[:nl], y[nl:2 * nl], times, values, forces.get("left", np.zeros(nl)), H, points)
    xr = motion(br, y[2 * nl:2 * nl + nr], y[2 * nl + nr:], times, values, forces.get("right", np.zeros(nr)), H,
                points)
    penetration = (xl[:, floors] - xr[:, floors]).max(axis=0)       # gap 0
    # 1e-10 m: the oracle's tolerance (rtol 1e-11 on displacements of a few cm)
    assert np.all(penetration <= bound + 1e-10), (penetration, bound)


@pytest.mark.parametrize("seed", range(24))
def test_where_the_coarse_bound_holds_the_proof_answers_the_whole_horizon(seed):
    """Each gap set so that the coarse bound lies just below ``-COARSE_MARGIN``: the proof on the
    grid must then answer ``H`` for every level (its bound lies under the coarse one)."""
    _, bl, br, floors, y, times, values, forces, H = case(seed)
    ahead = GroundAhead(times, values, 0.0, H)
    peak = ahead.peak()
    # the coarse bound of each level with gap 0; a gap shifts it (and the proof's) by itself
    level_bound = the_pair(gaps_for(bl, br, floors, np.zeros(floors.size))).coarse_bound(y, H, peak, forces)
    gaps = level_bound + 1.5 * COARSE_MARGIN
    pair = the_pair(gaps_for(bl, br, floors, gaps))
    assert pair.open_throughout(y, H, peak, forces)
    out = [0.0] * floors.size
    pair.prove(y, H, running_max_abs(times, values, 0.0, H), forces, out)
    assert out == [H] * floors.size


@pytest.mark.parametrize("seed", range(8))
def test_horizons_with_the_coarse_bound_answer_as_without(seed):
    """OpenGaps.horizons for subsets of the levels (where the coarse bound is tried) answers as
    the proof on the grid alone, over gaps from closed to wide open."""
    rng, bl, br, floors, y, times, values, forces, H = case(100 + seed)
    for gap in (0.0, 0.002, 0.01, 0.03, 0.1, 0.5):
        gaps = gaps_for(bl, br, floors, np.full(floors.size, gap))
        for k in range(6):
            which = sorted(rng.choice(floors.size, size=int(rng.integers(1, floors.size + 1)), replace=False).tolist())
            # the ground ahead as the master gives it (its peak taken for the coarse bound; a
            # horizon that long is proven with the ground's response: a bound on the grid instead)
            ground = GroundAhead(times, values, 0.0, H) if H < EXACT_MIN_HORIZON else \
                (lambda: running_max_abs(times, values, 0.0, H))
            got = gaps.horizons(y, H, ground, forces, which)
            plan = gaps._linear_plan(which, False)
            want = [0.0] * len(which)            # a gap closed now: 0 (as horizons starts)
            for pair in plan:
                pair.prove(y, H, running_max_abs(times, values, 0.0, H), forces, want)
            assert got == want, (gap, which)


@pytest.mark.parametrize("kind", ["pushed together", "moving apart"])
def test_coarse_bound_holds_where_one_term_dominates(kind):
    """States where one term of the coarse bound carries it, against the motion: from rest with a
    force pressing the floors together and no ground motion (the held force's term: a floor
    pressed alone moves by ``F s^2 / (2 m)`` at first, which that term equals), and floors moving
    apart fast (the bound's largest value is at ``s = 0``, not at the horizon's end)."""
    rng = np.random.default_rng(7)
    bl, br = building(rng, 4), building(rng, 3)
    floors = np.array([1, 2])
    y = np.zeros(14)
    forces = {}
    if kind == "pushed together":
        forces = {"left": np.array([0.0, 4e5, 0.0, 0.0]), "right": np.array([0.0, -4e5, 0.0])}
        H = 0.01
    else:
        y[4:8] = -0.5                               # left floors' velocities (m/s)
        y[11:14] = 0.5
        H = 0.05
    times, values = np.array([-1.0, 1.0]), np.zeros(2)
    pair = the_pair(gaps_for(bl, br, floors, np.zeros(floors.size)))
    bound = pair.coarse_bound(y, H, 0.0, forces)
    points = H * np.linspace(0.0, 1.0, 101)
    xl = motion(bl, y[:4], y[4:8], times, values, forces.get("left", np.zeros(4)), H, points)
    xr = motion(br, y[8:11], y[11:14], times, values, forces.get("right", np.zeros(3)), H, points)
    penetration = (xl[:, floors] - xr[:, floors]).max(axis=0)
    assert np.all(penetration <= bound + 1e-10), (penetration, bound)
    if kind == "pushed together":   # the pressed level's bound is the force's term, nearly the motion
        assert bound[0] - penetration[0] <= 0.05 * penetration[0], (penetration, bound)
