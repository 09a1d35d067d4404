"""OpenSees (openseespy, optional) as an independent peer of the reference solver.

Skipped when openseespy cannot be imported.  The scene is small on purpose: two SDOF
buildings (T = 0.5 s and 1.0 s, 5 % Rayleigh), 1 cm apart, a 2 s sampled sine record at
1.25 Hz and 1 m/s^2 that makes them pound 5 times; contact k = 1e10 N/m^1.5, CR = 0.6.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.peers.opensees import contact_work, model_description, opensees_available, run_opensees
from cosim.peers.reference import Contact, solve_reference
from fmu_src.contact_laws import law_for
from fmu_src.ground_records import Record
from fmu_src.shear_building import ShearBuilding

pytestmark = pytest.mark.skipif(not opensees_available(), reason="openseespy is not importable")


def scene(model: str):
    left = ShearBuilding.from_period(0.5, [2e5], [1.0], 0.05)
    right = ShearBuilding.from_period(1.0, [3e5], [1.0], 0.05)
    law = law_for(model, 1e10, 1.5, 2e5, 3e5, 0.6)
    dt = 0.01
    record = Record("sine", dt, np.sin(2 * math.pi * 1.25 * np.arange(201) * dt))
    return [left, right], record, [Contact(0, 1, 1, 1, law, gap=0.01)], 2.0


@pytest.fixture(scope="module")
def jankowski():
    args = scene("jankowski")
    return args, solve_reference(*args)


def errors(peer, ref):
    return dict(
        force=peer.peak_force_N / ref.peak_force_N - 1.0,
        energy=peer.dissipated_energy_J / ref.dissipated_energy_J - 1.0,
        disp=max(abs(p[0] / r[0] - 1.0) for p, r in zip(peer.peak_displacements, ref.peak_displacements)),
    )


def test_jankowski_impact_converges_to_reference(jankowski):
    args, ref = jankowski
    assert ref.impacts == 5
    runs = {dt: run_opensees(*args, dt=dt) for dt in (2e-3, 4e-4, 2e-4, 1e-4)}
    for dt, peer in runs.items():
        assert peer.converged, peer.message
        assert peer.impacts == ref.impacts
    err = {dt: errors(peer, ref) for dt, peer in runs.items()}
    # At dt = 1e-4 s (a contact of 35-70 ms takes 350-700 steps) measured: force 0.05 %,
    # dissipated energy 0.03 %, peak displacements 0.02 %.  Newmark is 2nd order for smooth
    # forces, but the Jankowski dashpot ~ delta^0.25 at onset and the onset inside a step make
    # the contact error first order: 1 % on force and energy and 0.2 % on displacements leave
    # a factor >= 5 of margin and still catch a wrong xi, mEff or damping (each moves them by
    # several %).
    assert abs(err[1e-4]["force"]) < 1e-2
    assert abs(err[1e-4]["energy"]) < 1e-2
    assert err[1e-4]["disp"] < 2e-3
    # The peak-force error shrinks with dt, at least linearly: 4x smaller dt, error below 1/3
    # of it (measured 0.28 %, 0.12 %, 0.047 %: 1/6).  The dissipated energy (the work the
    # element took out of the discrete solution, see test_energy_balance_...) is already within
    # 0.04 % from dt = 4e-4 s on, where the onset timing dominates and the error no longer
    # falls steadily (measured +0.024 %, +0.037 %, +0.028 %); from dt = 2e-3 s (+0.89 %) to
    # 1e-4 s it falls more than 10 times.
    f = [abs(err[dt]["force"]) for dt in (4e-4, 2e-4, 1e-4)]
    assert f[0] > f[1] > f[2]
    assert f[2] < f[0] / 3.0
    assert abs(err[2e-3]["energy"]) > 10.0 * abs(err[1e-4]["energy"])


def test_hertzdamp_agrees_with_reference():
    """Hertzdamp latches xi from the rate of the first closed step; on these slow-rising
    Hertz contacts that costs little: 0.2 % at dt = 2e-4 s is a 5x margin on what is measured."""
    args = scene("hertzdamp")
    ref = solve_reference(*args)
    peer = run_opensees(*args, dt=2e-4, material="Hertzdamp")
    assert peer.converged and peer.impacts == ref.impacts
    err = errors(peer, ref)
    assert abs(err["force"]) < 5e-3
    assert abs(err["energy"]) < 5e-3
    assert err["disp"] < 2e-3


def test_material_parameters_match_our_law():
    """JankowskiImpact(Kh, xi, mEff, gap, n) gets k, zeta, the effective mass m1 m2/(m1+m2)
    and the gap; a law OpenSees cannot represent is refused with its name."""
    buildings, record, contacts, stop = scene("jankowski")
    spec = model_description(buildings, record, contacts, stop, 1e-3)
    c = spec["contacts"][0]
    law = contacts[0].law
    assert (c["k"], c["n"], c["zeta"], c["gap"]) == (1e10, 1.5, law.zeta, 0.01)
    assert c["m"] == pytest.approx(2e5 * 3e5 / 5e5, rel=1e-15)
    b = spec["buildings"][0]
    a0, a1 = buildings[0].rayleigh_coefficients
    assert (b["a0"], b["a1"]) == (a0, a1)
    crvk = [Contact(0, 1, 1, 1, law_for("crvk", 1e10, 1.5, 2e5, 3e5, 0.6), 0.01)]
    with pytest.raises(ValueError, match="not 'crvk'"):
        model_description(buildings, record, crvk, stop, 1e-3)


def test_initial_conditions_reach_the_contact():
    """Two free masses with initial displacements and velocities (the seed's worked example
    with Jankowski's law).  OpenSees' zeroLength stores the nodes' relative displacement and
    velocity when it is created and subtracts them ever after, so initial conditions set
    before the contact element exists shift its gap and hide the approach rate from the
    dashpot (an elastic rebound, 0 J dissipated); this catches that."""
    law = law_for("jankowski", 1.8974e11, 1.5, 200.0, 200.0, 0.4)
    free = [ShearBuilding([200.0], [0.0], 0.0), ShearBuilding([200.0], [0.0], 0.0)]
    args = (free, None, [Contact(0, 1, 1, 1, law, gap=0.005)], 0.004)
    init = dict(x0=[[-0.002], [0.001]], v0=[[5.0], [-5.0]])
    ref = solve_reference(*args, **init)
    peer = run_opensees(*args, dt=2e-6, **init)
    assert peer.converged and peer.impacts == ref.impacts == 1
    onset = peer.t[np.argmax(peer.contact_force[:, 0] > 0.0)]
    assert onset == pytest.approx(ref.impact_list[0].t_onset, abs=2e-6)    # gap 8 mm closes at 10 m/s
    # 190 steps per 0.38 ms contact: measured 0.14 % on the loop area, 0.44 % on peak force
    assert peer.dissipated_energy_J == pytest.approx(ref.dissipated_energy_J, rel=1e-2)
    assert peer.peak_force_N == pytest.approx(ref.peak_force_N, rel=2e-2)


def _newmark_energy_terms(buildings, record, peer):
    """Work of every force of the OpenSees model over the recorded steps, each as the trapezoid
    of the force over its own displacement increment (J): kinetic energy change, ground input,
    storey springs and dashpots, mass-proportional dashpots, contacts."""
    t, u, v = peer.t, peer.u, peer.v
    ag = np.interp(t, record.times, record.acceleration)

    def trapezoid(force, displacement):
        return float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(displacement)))

    kinetic = inputs = storeys = ground_dashpots = 0.0
    for b, building in enumerate(buildings):
        o0, o1 = peer.floor_offsets[b], peer.floor_offsets[b + 1]
        a0, a1 = building.rayleigh_coefficients
        k = np.asarray(building.stiffnesses)
        below_u, below_v = np.zeros(t.size), np.zeros(t.size)
        for i, floor in enumerate(range(o0, o1)):
            m = building.masses[i]
            kinetic += 0.5 * m * (v[-1, floor] ** 2 - v[0, floor] ** 2)
            inputs += trapezoid(-m * ag, u[:, floor])
            e, e_dot = u[:, floor] - below_u, v[:, floor] - below_v
            storeys += trapezoid(k[i] * e + a1 * k[i] * e_dot, e)
            ground_dashpots += trapezoid(a0 * m * v[:, floor], u[:, floor])
            below_u, below_v = u[:, floor], v[:, floor]
    contacts = sum(trapezoid(peer.contact_force[:, c], peer.penetration[:, c])
                   for c in range(peer.contact_force.shape[1]))
    return kinetic, inputs, storeys, ground_dashpots, contacts


def test_energy_balance_of_the_discrete_solution_closes_with_the_consistent_rule():
    """The peer's dissipated energy is the work the contact took out of the discrete Newmark
    solution: with gamma = 1/2, beta = 1/4, kinetic energy changes by the trapezoid of every
    force over its own displacement increment, so the balance kinetic + storeys + dashpots +
    contact = input closes to the solver's tolerance with the contact's trapezoid over its
    unclipped penetration (what contact_work sums), and misses by the clipped rule's difference
    with the penetration clipped at zero (the rule this peer used before)."""
    buildings, record, contacts, stop = scene("jankowski")
    peer = run_opensees(buildings, record, contacts, stop, dt=2e-3, record_velocity=True)
    assert peer.converged and peer.subdivided_steps == 0 and peer.impacts == 5
    kinetic, inputs, storeys, dashpots, contact = _newmark_energy_terms(buildings, record, peer)
    assert contact == pytest.approx(contact_work(peer.contact_force[:, 0], peer.penetration[:, 0]), rel=1e-15)
    residual = kinetic + storeys + dashpots + contact - inputs
    # Newton stops at a displacement increment of 1e-12 m (tol): with forces up to ~1e6 N the
    # step's work is known to ~1e-6 J; 1e-9 of the input (~1e3 J here) leaves room for that
    assert abs(residual) < 1e-9 * abs(inputs)
    clipped = sum(float(np.sum(0.5 * (peer.contact_force[1:, c] + peer.contact_force[:-1, c])
                               * np.diff(np.maximum(peer.penetration[:, c], 0.0))))
                  for c in range(peer.contact_force.shape[1]))
    # the clipped rule leaves a residual that is a visible part of the contact's dissipation
    assert abs(kinetic + storeys + dashpots + clipped - inputs) > 100 * abs(residual) + 1e-3 * abs(contact)
    # and the peer's dissipated energy is the consistent work (the run ends out of contact)
    assert peer.contact_force[-1, 0] == 0.0
    assert peer.dissipated_energy_J == pytest.approx(contact, rel=1e-15)
# -- yielding storeys (issue 18): Steel01 and BoucWen against the reference ---------------------
def yielding_building(model: str):
    """The 3-storey building of tests/test_reference_inelastic.py, El Centro at 0.3 g, 6 s."""
    from fmu_src.ground_records import G, load_record
    from fmu_src.hysteresis import StoreyHysteresis

    mass = 3e5
    fy = [0.2 * 3 * mass * G, 0.17 * 3 * mass * G, 0.12 * 3 * mass * G]
    b = ShearBuilding.from_period(0.5, [mass] * 3, [1.0, 0.8, 0.6], 0.05)
    rec = load_record("elcentro1940")
    return b, rec.scaled(0.3 * G / rec.pga), StoreyHysteresis(model, fy, 0.05), 6.0


def storey_errors(peer, ref):
    dy = max(abs(r) for r in ref.residual_drifts[0]) or 1.0
    return dict(u=float(np.max(np.abs(peer.peak_displacements[0] / ref.peak_displacements[0] - 1))),
                mu=float(np.max(np.abs(peer.ductility[0] / ref.ductility[0] - 1))),
                residual=float(np.max(np.abs(peer.residual_drifts[0] - ref.residual_drifts[0]))) / dy,
                energy=abs(peer.hysteretic_energy_J[0] / ref.hysteretic_energy_J[0] - 1))


def test_steel01_storeys_converge_to_the_reference_at_second_order():
    """Steel01 with b = alpha (no isotropic hardening) is our bilinear law: Newmark's average
    acceleration then converges at second order (measured on 10 s: peak displacements
    2.3e-3, 5.5e-4, 1.5e-4 at dt = 4, 2, 1 ms); a wrong b, Fy or damping would stall it."""
    b, rec, hy, stop = yielding_building("bilinear")
    ref = solve_reference([b], rec, [], stop, hystereses=[hy])
    assert ref.ductility[0].max() > 2.0
    err = {dt: storey_errors(run_opensees([b], rec, [], stop, dt, hystereses=[hy], record_storeys=True), ref)
           for dt in (2e-3, 1e-3)}
    assert err[1e-3]["u"] < 1e-3 and err[1e-3]["mu"] < 2e-3 and err[1e-3]["residual"] < 5e-3
    assert err[1e-3]["energy"] < 1e-3
    # second order: halving dt divides the displacement error by about 4 (3 or more)
    assert err[1e-3]["u"] < err[2e-3]["u"] / 3.0


def test_bouc_wen_material_is_our_law_at_first_order():
    """OpenSees BoucWen (z in metres: gamma and beta divided by dy^n) integrates z by backward
    Euler over each strain increment: first order, so halving dt halves the error (measured
    on 10 s: 2.8e-3, 1.4e-3, 6.7e-4 on peak displacements at 2, 1, 0.5 ms).  Converging to our
    law at that rate shows the parameter mapping; a wrong scaling of gamma or beta leaves an
    error that does not shrink."""
    b, rec, hy, stop = yielding_building("bouc_wen")
    ref = solve_reference([b], rec, [], stop, hystereses=[hy])
    err = {dt: storey_errors(run_opensees([b], rec, [], stop, dt, hystereses=[hy]), ref) for dt in (2e-3, 1e-3)}
    assert err[1e-3]["u"] < 3e-3 and err[1e-3]["mu"] < 1e-2
    assert 1.6 < err[2e-3]["u"] / err[1e-3]["u"] < 2.5


def test_storey_materials_carry_our_parameters():
    from cosim.peers.opensees import BOUC_WEN_TOL, storey_spec
    from fmu_src.hysteresis import StoreyHysteresis

    bil = storey_spec(StoreyHysteresis("bilinear", [2e6], 0.05), 1e8, 2e6)
    assert bil == {"material": "Steel01", "args": [2e6, 1e8, 0.05, 0.0, 1.0, 0.0, 1.0]}
    bw = storey_spec(StoreyHysteresis("bouc_wen", [2e6], 0.1, bw_n=2.0, bw_beta=0.6, bw_gamma=0.4), 1e8, 2e6)
    dy = 0.02
    assert bw["material"] == "BoucWen"
    assert bw["args"] == pytest.approx([0.1, 1e8, 2.0, 0.4 / dy ** 2, 0.6 / dy ** 2, 1.0, 0.0, 0.0, 0.0,
                                        BOUC_WEN_TOL, 50], rel=1e-15)
    assert storey_spec(StoreyHysteresis("linear"), 1e8, 0.0) is None
    b, rec, hy, stop = yielding_building("bilinear")
    with pytest.raises(ValueError, match="Fy has 1 value"):
        model_description([b], rec, [], stop, 1e-3, hystereses=[StoreyHysteresis("bilinear", [1e6])])



def test_a_contact_shallower_than_graze_depth_is_no_impact():
    """The peer counts impacts as pounding.fmu and the reference do: a contact whose penetration
    never reaches the contact's graze_depth is a graze (Kasai-Maison at its default settings:
    the reference and the co-simulation count 39 impacts, OpenSees counted 41 with its grazes)."""
    from cosim.peers.opensees import count_impacts

    delta = np.array([-1, 2, 5, 1, -1, -2, 1, -1, -3, 4, -1, 3], dtype=float) * 1e-4    # m
    force = 1e10 * np.maximum(delta, 0.0) ** 1.5                                        # N
    # four contacts, 0.5, 0.1, 0.4 and 0.3 mm deep (the last still closed at the end)
    assert [count_impacts(force, delta, d) for d in (0.0, 3e-4, 4e-4, 4.5e-4)] == [4, 3, 2, 1]
