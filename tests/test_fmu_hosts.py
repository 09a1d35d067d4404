"""The FMUs in a host that has only what they declare (issue 13, points 5 and 6).

Each test makes a fresh virtual environment with pip (wheels from pip's cache or the index),
copies the session's FMUs next to a small host script and runs it there, in its own process:

* with numpy, scipy and fmpy only (no pounding-cosim, no pythonfmu: the FMUs carry their own
  Python code, each under its own package name), the three FMUs run one after another through
  ``fmpy.simulate_fmu`` in every order, and each gives the same numbers whatever ran before
  it (``simulate_fmu`` deletes each FMU's extracted folder when it is done: with one package
  name shared by the three FMUs the second one failed with ``No module named
  'fmu_src.shear_building'``);
* without scipy, an FMU refuses to instantiate with a message naming scipy, on standard error
  (what a host shows when FMI logging is off: pythonfmu 0.7 forwards no message then) and,
  with logging on, in the FMI log; installing the FMU's own ``resources/requirements.txt``
  (what ``pythonfmu deploy`` does) makes it run.
"""
from __future__ import annotations

import itertools
import json
import math
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest
from venvs import make_venv, pip_install

from cosim.fmus import FMU_NAMES
from fmu_src.fmi_slave import HOST_REQUIREMENTS

pytestmark = pytest.mark.venv

#: building.fmu started at x0[1] = 1 cm, free vibration: closed form below
X0 = 0.01
HOST = textwrap.dedent('''
    import json, sys
    from fmpy import simulate_fmu

    START = {"building": {"x0[1]": %r}, "pounding": {}, "ground_motion": {}}
    STOP = {"building": 0.5, "pounding": 0.1, "ground_motion": 2.0}
    OUT = {"building": ["x[1]", "E_kinetic"], "pounding": ["F", "delta"], "ground_motion": ["ag", "pga"]}
    results = {}
    for name in sys.argv[1:]:
        r = simulate_fmu(name + ".fmu", stop_time=STOP[name], output_interval=0.01, start_values=START[name],
                         output=OUT[name])
        results[name] = {v: float(r[v][-1]) for v in OUT[name]}
    print(json.dumps(results), flush=True)
    # end like the package's own programs (cosim.master.fmi.exit_process): with pythonfmu
    # libraries loaded, the interpreter's normal exit now and then aborts on a corrupted heap
    # after everything is printed (docs/studies.md, "Workers aborting at exit": cause not found;
    # seen here twice in three runs of the suite on two workers under load, never in 420 runs of
    # this script alone), which this test is not about
    import os
    os._exit(0)
''' % X0)


@pytest.fixture(scope="module")
def host_dir(tmp_path_factory, fmu_dir) -> Path:
    """A folder with the session's FMUs and the host script, outside the source tree."""
    folder = tmp_path_factory.mktemp("host")
    for name in FMU_NAMES:
        shutil.copy(fmu_dir / f"{name}.fmu", folder)
    (folder / "host.py").write_text(HOST)
    return folder


@pytest.fixture(scope="module")
def host_python(tmp_path_factory) -> Path:
    """numpy, scipy (the FMUs' declared requirements) and fmpy: nothing else."""
    return make_venv(tmp_path_factory.mktemp("venv") / "host", [*HOST_REQUIREMENTS, "fmpy"])


def run_host(python: Path, folder: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(python), "-I", "host.py", *args], cwd=folder, capture_output=True, text=True,
                          timeout=300)


def test_the_fmus_in_every_order_in_a_host_with_only_the_declared_requirements(host_python, host_dir):
    # the environment really lacks the package and pythonfmu
    check = subprocess.run([str(host_python), "-I", "-c", "import importlib.util as u; "
                            "print([u.find_spec(m) is None for m in ('cosim', 'fmu_src', 'pythonfmu')])"],
                           cwd=host_dir, capture_output=True, text=True)
    assert check.stdout.strip() == "[True, True, True]", check.stdout + check.stderr
    outcomes = {}
    for order in itertools.permutations(FMU_NAMES):
        proc = run_host(host_python, host_dir, *order)
        assert proc.returncode == 0, f"order {order}:\n{proc.stderr[-3000:]}"
        outcomes[order] = json.loads(proc.stdout.strip().splitlines()[-1])
    first = next(iter(outcomes.values()))
    for order, results in outcomes.items():
        assert results == first, f"order {order} changed the numbers"   # bit for bit: same code, same inputs
    # and the numbers are right: one storey, T1 = 0.5 s, zeta = 0.05 (the FMU's defaults), free
    # vibration from x0 = 1 cm: x(t) = x0 e^(-zeta w t) (cos wd t + zeta w / wd sin wd t)
    w, zeta, t = 2.0 * math.pi / 0.5, 0.05, 0.5
    wd = w * math.sqrt(1.0 - zeta * zeta)
    x = X0 * math.exp(-zeta * w * t) * (math.cos(wd * t) + zeta * w / wd * math.sin(wd * t))
    assert first["building"]["x[1]"] == pytest.approx(x, rel=1e-9)    # exact propagator: round-off only
    assert first["pounding"] == {"F": 0.0, "delta": 0.0}               # bodies at rest, no gap closed
    assert first["ground_motion"]["pga"] == pytest.approx(0.3129 * 9.80665, rel=1e-3)   # El Centro, PGA 0.3129 g


def test_a_missing_requirement_is_named_and_the_fmus_requirements_file_installs_it(tmp_path, host_dir):
    python = make_venv(tmp_path / "noscipy", [r for r in HOST_REQUIREMENTS if r.startswith("numpy")] + ["fmpy"])
    script = ("import sys\nfrom fmpy import simulate_fmu\n"
              "try:\n    simulate_fmu('pounding.fmu', stop_time=0.01, debug_logging=sys.argv[1] == 'on')\n"
              "except Exception as exc:\n    print('host:', exc)\nelse:\n    print('host: ran')\n")
    (host_dir / "noscipy.py").write_text(script)
    silent = subprocess.run([str(python), "-I", "noscipy.py", "off"], cwd=host_dir, capture_output=True, text=True)
    logged = subprocess.run([str(python), "-I", "noscipy.py", "on"], cwd=host_dir, capture_output=True, text=True)
    # FMI logging off: pythonfmu 0.7 forwards no message; the FMU's own line on standard error names scipy
    assert "host: Failed to instantiate model" in silent.stdout
    assert "scipy" not in silent.stdout
    assert "error: pounding.fmu cannot start" in silent.stderr and "(missing: scipy)" in silent.stderr
    assert "requirements.txt" in silent.stderr
    # FMI logging on: the same text reaches the host's FMI logger (fmpy prints it) with status Fatal
    assert "[FATAL]" in logged.stdout and "(missing: scipy)" in logged.stdout
    # what pythonfmu deploy does: pip install -r the FMU's resources/requirements.txt; then it runs
    with zipfile.ZipFile(host_dir / "pounding.fmu") as z:
        requirements = z.read("resources/requirements.txt").decode()
    assert requirements.split() == list(HOST_REQUIREMENTS)
    (tmp_path / "requirements.txt").write_text(requirements)
    installed = pip_install(python, "-r", str(tmp_path / "requirements.txt"))
    assert installed.returncode == 0, installed.stderr[-2000:]
    fixed = subprocess.run([str(python), "-I", "noscipy.py", "off"], cwd=host_dir, capture_output=True, text=True)
    assert "host: ran" in fixed.stdout, fixed.stdout + fixed.stderr


def test_pythonfmu_deploy_finds_the_requirements(fmu_dir, monkeypatch):
    """``pythonfmu deploy -f X.fmu`` reads resources/requirements.txt and pip-installs it (the pip
    call is intercepted: it would install into this environment)."""
    from pythonfmu import deploy

    calls = []
    monkeypatch.setattr(deploy.subprocess, "run", lambda cmd, **kw: calls.append(
        (cmd, Path(cmd[cmd.index("-r") + 1]).read_text())))
    for name in FMU_NAMES:
        deploy.deploy(fmu_dir / f"{name}.fmu")
    assert [c[1].split() for c in calls] == [list(HOST_REQUIREMENTS)] * len(FMU_NAMES)
    assert all(c[0][1:4] == ["-m", "pip", "install"] for c in calls)


def test_each_fmu_ships_its_own_package_and_says_what_the_host_needs(fmu_dir):
    from fmpy import read_model_description

    packages = set()
    for name in FMU_NAMES:
        with zipfile.ZipFile(fmu_dir / f"{name}.fmu") as z:
            names = z.namelist()
        tops = {n.split("/")[1] for n in names if n.startswith("resources/") and n.count("/") >= 2}
        own = {t for t in tops if t.startswith(f"pounding_cosim_{name}_")}
        assert len(own) == 1 and "fmu_src" not in tops, tops
        packages |= own
        description = read_model_description(str(fmu_dir / f"{name}.fmu")).description
        assert f"Python {sys.version_info[0]}.{sys.version_info[1]} host with numpy and scipy" in description
    assert len(packages) == len(FMU_NAMES)
