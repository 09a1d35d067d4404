"""The contact law table is the one place a law lives (fmu_src/contact_laws.py, ``LAWS``).

* Adding a law is one entry: a copy of this checkout with a test-only eleventh law added to the
  table, and nothing else changed, builds a ``pounding.fmu`` that runs it (plain and resolved),
  and its reference solver, report labels, calibration and CR table know it; the numbers are
  checked against the copy's own single-impact integrator (solve_ivp).
* An unknown law name is refused by every component, with the allowed names.
* Every consumer reads the table: the families, the OpenSees mapping, the labels, the
  separation rules.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from fmu_src.contact_laws import (APPROACH_ONLY_MODELS, CLIPPED_MODELS, DAMPED_MODELS, DASHPOT_MODELS,
                                  HERTZDAMP_MODELS, LAWS, MODELS, ContactLaw, law_for, law_spec, published_label)

ROOT = Path(__file__).resolve().parents[1]

#: the one entry the test adds (a Hertz-damp law with its own constant)
ENTRY = '''    LawSpec("test_law", HERTZDAMP, ALWAYS, FORCE_WHEN_PULLED, zeta_test_law,
            "2 (1 - CR) / (1 + CR), test only", "Test law (test only)", opensees="Hertzdamp"),
'''
CONSTANT = '''def zeta_test_law(CR: float) -> float:
    """A test-only law's constant: ``2 (1 - CR) / (1 + CR)``."""
    return 2.0 * (1.0 - CR) / (1.0 + CR)


'''

#: run in the modified copy, in its own process: every component with the new law
PROBE = textwrap.dedent('''
    import json, sys
    import cosim, fmu_src
    from cosim.fmus import build_all
    from cosim.master.runner import run_scene
    from cosim.master.scene import Override
    from cosim.peers.reference import Contact, solve_reference
    from cosim.apps.report import PUBLISHED_LABELS
    from cosim.apps.calibrate import calibrate
    from cosim.apps.cr_table import cr_table
    from cosim.peers.opensees import material_for
    from fmu_src.contact_laws import MODELS, law_for
    from fmu_src.shear_building import ShearBuilding
    from fmu_src.single_impact import simulate_impact

    fmus = build_all(sys.argv[1])
    out = {"models": list(MODELS), "label": PUBLISHED_LABELS["test_law"], "material": material_for("test_law"),
           "files": [cosim.__file__, fmu_src.__file__]}
    # the worked example's two free 200 kg masses at 10 m/s (single_impact scene), CR 0.6
    law = law_for("test_law", 1.8974e11, 1.5, 200.0, 200.0, 0.6)
    out["solve_ivp_CR"] = simulate_impact(law, 10.0, rtol=1e-10).achieved_CR
    for resolved, step in ((True, 2e-5), (False, 2e-7)):
        run = run_scene("single_impact", [Override("pounding", "model", "test_law"), Override("pounding", "CR", 0.6),
                                          Override("pounding", "resolve_impacts", resolved)],
                        step=step, stop_time=0.002, fmu_dir=sys.argv[1], write=False, progress=False,
                        record="all", output_interval=0.0)
        r = run.result
        v_in = r["left.v[1]"][0] - r["right.v[1]"][0]
        v_out = r["right.v[1]"][-1] - r["left.v[1]"][-1]
        out["fmu_resolved_CR" if resolved else "fmu_plain_CR"] = v_out / v_in
        out["impacts"] = run.summary.impacts
    free = ShearBuilding([200.0], [0.0], 0.0)
    ref = solve_reference([free, free], None, [Contact(0, 1, 1, 1, law, 0.01)], 0.002, v0=[[5.0], [-5.0]],
                          output_dt=1e-4)
    v = ref.velocities(1)[-1, 0] - ref.velocities(0)[-1, 0]
    out["reference_CR"] = v / 10.0
    out["calibrated_CR"] = calibrate("test_law", 0.6, m1=200.0, m2=200.0, k=1.8974e11, v_imp=10.0, fmu=False).achieved_CR
    out["cr_table_row"] = [line for line in cr_table(crs=(0.6,), rtol=1e-8).splitlines() if "test_law" in line]
    print(json.dumps(out))
''')


def tracked_copy(dest: Path) -> Path:
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    for name in files:
        if name.startswith(("cosim/", "fmu_src/")) and (ROOT / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)
    return dest


def test_an_eleventh_law_is_one_entry_and_works_everywhere(tmp_path):
    copy = tracked_copy(tmp_path / "src")
    laws = copy / "fmu_src" / "contact_laws.py"
    text = laws.read_text()
    anchor = "    LawSpec(\"crvk\", CRVK,"
    assert text.count(anchor) == 1 and text.count("\n# the table\n") == 1
    # the one entry (its constant is a one-line function next to the others' formulas)
    text = text.replace(anchor, ENTRY + anchor).replace("def zeta_elastic(", CONSTANT + "def zeta_elastic(")
    laws.write_text(text)
    changed = [p.relative_to(copy) for p in copy.rglob("*.py") if "__pycache__" not in p.parts
               and p.read_bytes() != (ROOT / p.relative_to(copy)).read_bytes()]
    assert changed == [Path("fmu_src/contact_laws.py")]
    (tmp_path / "probe.py").write_text(PROBE)
    # PYTHONPATH first on sys.path: the copy's packages, not this checkout's (the editable install)
    proc = subprocess.run([sys.executable, "probe.py", str(tmp_path / "fmus")], cwd=tmp_path,
                          env={"PYTHONPATH": str(copy), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)},
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert all(Path(f).is_relative_to(copy) for f in out["files"]), out["files"]
    assert out["models"][-2:] == ["test_law", "crvk"] and len(out["models"]) == 11
    assert out["label"] == "Test law (test only)" and out["material"] == "Hertzdamp"
    cr = out["solve_ivp_CR"]
    assert 0.3 < cr < 0.95 and out["impacts"] == 1      # a damped law, not the published target (as hertzdamp)
    # resolved impacts: the FMU integrates the same law as solve_ivp, to its rtol 1e-8 (the
    # bound 1e-5 is the CR check of tests/test_pounding_fmu.py)
    assert out["fmu_resolved_CR"] == pytest.approx(cr, abs=1e-5)
    # plain law at a step of 1/1750 of the contact: first order in h, within 1 % (docs/accuracy.md)
    assert out["fmu_plain_CR"] == pytest.approx(cr, rel=1e-2)
    # the monolithic reference (DOP853 at rtol 1e-10, events) on the same two masses
    assert out["reference_CR"] == pytest.approx(cr, abs=1e-6)
    assert out["calibrated_CR"] == pytest.approx(0.6, abs=1e-6)         # the cyclic calibration reaches CR
    assert len(out["cr_table_row"]) == 1 and out["cr_table_row"][0].startswith("| test_law | ")


def test_an_unknown_law_is_refused_by_every_component(fmu_path):
    from cosim.apps.calibrate import CalibrationError, calibrate
    from cosim.apps.report import printed_zeta
    from cosim.master.fmi import FMU, FMUError
    from cosim.master.loader import load_scene
    from cosim.master.scene import Override
    from cosim.peers.opensees import material_for
    from cosim.peers.reference import scene_inputs
    from fmu_src.single_impact import calibrate_zeta

    allowed = "one of " + ", ".join(MODELS)
    for refuse in (lambda: law_spec("foo"), lambda: ContactLaw("foo", 1.0, 1.5, 1.0, 0.1),
                   lambda: law_for("foo", 1.0, 1.5, 1.0, 1.0, 0.5), lambda: published_label("foo"),
                   lambda: printed_zeta("foo", 0.5), lambda: material_for("foo"),
                   lambda: calibrate_zeta("foo", 0.5)):
        with pytest.raises(ValueError, match=f"model = 'foo' is not allowed: {allowed}"):
            refuse()
    # the reference solver builds its laws by name from a scene
    scene = load_scene("single_impact", [Override("pounding", "model", "foo")])
    with pytest.raises(ValueError, match="model = 'foo' is not allowed"):
        scene_inputs(scene)
    # the calibration tool
    with pytest.raises(CalibrationError, match="model = 'foo' is not allowed"):
        calibrate("foo", 0.5, m1=1.0, m2=1.0, k=1.0, v_imp=1.0, fmu=False)
    # the FMU: its parameter check at initialisation, with the allowed values
    with FMU(fmu_path("pounding")) as fmu:
        inst = fmu.instantiate("p")
        inst.setup(0.0, 1.0)
        inst.set({"model": "foo"})
        with pytest.raises(FMUError, match="model = 'foo' is not allowed: one of 'hertz'"):
            inst.exit_initialization()
        inst.free()
    # a law OpenSees has no equivalent of is refused by the peer, naming those it has
    with pytest.raises(ValueError, match="has no OpenSees equivalent; laws that have one: jankowski"):
        material_for("crvk")


def test_every_list_of_laws_is_derived_from_the_table():
    from cosim.apps.report import PUBLISHED_LABELS
    from cosim.peers.opensees import MATERIAL_MODELS

    assert MODELS == tuple(LAWS)
    assert DAMPED_MODELS == tuple(n for n in MODELS if n != "hertz")
    assert DASHPOT_MODELS == ("kelvin_voigt", "jankowski", "barros2013")
    assert HERTZDAMP_MODELS == ("hertzdamp", "ye", "naderpour2013", "hunt_crossley", "gonthier")
    assert APPROACH_ONLY_MODELS == ("jankowski", "barros2013", "crvk")
    # the laws whose raw force can reach 0 before the penetration does (the reference's force-separation event)
    assert CLIPPED_MODELS == ("kelvin_voigt",) + HERTZDAMP_MODELS
    assert PUBLISHED_LABELS == {n: LAWS[n].label for n in DAMPED_MODELS}
    assert MATERIAL_MODELS == {"JankowskiImpact": ("jankowski", "barros2013"), "Hertzdamp": HERTZDAMP_MODELS}
    # the seed paper's printed constant differs from the published (calibrated) one only for crvk
    assert [n for n, s in LAWS.items() if s.printed] == ["crvk"]


@pytest.mark.parametrize("model", MODELS)
def test_the_scaled_kernels_are_the_dimensional_law(model):
    """The resolver's scaled kernel of each branch equals ContactLaw.force in the impact's scales."""
    law = law_for(model, 2.0e9, 1.5, 1.0e5, 3.0e5, 0.5)
    v = 0.7
    L = law.length_scale(v)
    F0 = law.k * L ** law.n
    for approaching in (True, False):
        kernel = law.spec.kernel(law.zeta, law.n, approaching)
        for d, u in ((0.3, 0.8), (1.1, -0.4), (0.05, 0.01)):
            F = law.force(d * L, u * v, v, approaching)
            # the same expression in other scales: equal to round-off (1e-12 relative)
            assert kernel(d, u) == pytest.approx(F / F0, rel=1e-12, abs=1e-15)
