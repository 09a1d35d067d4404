"""cosim/scenes/kasai_maison_inelastic.toml at its default settings meets the accuracy criteria.

The criteria of docs/accuracy.md (:data:`cosim.apps.accuracy.CRITERIA`: peak contact force
within 1 %, the same impacts, dissipated contact energy within 2 %, peak floor displacements
within 0.5 %, peak and residual storey drifts within 1 %) against the monolithic reference
(cosim/peers/reference.py with the same bilinear storeys, rtol 1e-10).  It missed them (peak
force 1.53 %, energy 3.4 %) while its yielding buildings held the ground acceleration's mean over
a step inside one record interval: that hold's error in the buildings' own motion (relative floor
velocity 0.22 % off the reference's before the first impact) reached the impacts.  Yielding
buildings now get the record's knots over every step (cosim/master/system.py,
``Node.pull_with_knots``): the motion before the first impact is the reference's to 1e-10.
"""
from __future__ import annotations

from cosim.apps.accuracy import CRITERIA, DEFAULT_SETTINGS, reference_metrics, run_cosim
from cosim.master.loader import load_scene
from cosim.peers.reference import reference_for_scene


def test_default_settings_meet_the_criteria(catalog):
    scene = load_scene("kasai_maison_inelastic", [], catalog)
    assert (scene.coupling, scene.step) == ("adaptive", 0.01)
    ref = reference_metrics(reference_for_scene(scene, {"rtol": 1e-10}))
    row = run_cosim("kasai_maison_inelastic", DEFAULT_SETTINGS, 0.0, catalog, ref)
    assert row.status == "ok"
    assert row.impacts == ref["impacts"] == 4
    # measured (one run): peak force 0.026 %, energy 0.65 %, displacements 2e-6 %, peak drifts
    # 0.031 %, residual drifts 0.10 % (of the largest)
    assert abs(row.err_peak_force) < CRITERIA["peak_force"]
    assert abs(row.err_dissipated_energy) < CRITERIA["dissipated_energy"]
    assert abs(row.err_peak_displacement) < CRITERIA["peak_displacement"]
    assert abs(row.err_peak_drift) < CRITERIA["peak_drift"]
    assert abs(row.err_residual_drift) < CRITERIA["residual_drift"]
    assert row.meets_criteria
    # long steps where the gaps and the storeys are proven quiet: measured 1439 steps, 4000 without
    assert row.communication_steps < 2000
