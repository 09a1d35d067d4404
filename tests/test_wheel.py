"""The package as a user installs it: a wheel in a fresh virtual environment, used from anywhere.

The wheel is built from a copy of the tracked sources (nothing of this checkout's build
folders can leak into it), installed with pip into a new environment (``pip install
WHEEL``, not editable), and ``pounding-cosim run --no-plots --out DIR`` runs the default
scene from an unrelated directory.  It must build the FMUs into the per-user cache
(``$XDG_CACHE_HOME/pounding-cosim/fmus/<version>-<hash>/``, here a temporary folder), never
into site-packages, and give the numbers of the run in this checkout, bit for bit.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from venvs import make_venv

from cosim import __version__
from cosim.master.runner import run_scene
from fmu_src.ground_records import BUNDLED

pytestmark = pytest.mark.venv
ROOT = Path(__file__).resolve().parents[1]


def tracked_copy(dest: Path) -> Path:
    """The files git tracks (and new ones not ignored), copied into ``dest``."""
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    for name in files:
        source = ROOT / name
        if source.is_file():
            target = dest / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)
    return dest


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if "__pycache__" not in p.parts}


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """``(python, bin folder)`` of a fresh environment with the wheel installed."""
    base = tmp_path_factory.mktemp("wheel")
    source = tracked_copy(base / "src")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(base / "dist"),
                            str(source)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]
    wheel = next((base / "dist").glob("pounding_cosim-*.whl"))
    # (``listing`` ignores __pycache__: the environment is installed without byte-compiling)
    return make_venv(base / "venv", [str(wheel)]), base


def test_the_installed_command_runs_the_default_scene_like_the_checkout(installed, tmp_path, fmu_dir):
    python, base = installed
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    before = listing(site)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    cache = tmp_path / "cache"
    env = {"PATH": f"{python.parent}:/usr/bin:/bin", "HOME": str(tmp_path), "XDG_CACHE_HOME": str(cache)}
    version = subprocess.run([str(python.parent / "pounding-cosim"), "--version"], cwd=elsewhere, env=env,
                             capture_output=True, text=True)
    assert version.stdout.strip() == f"pounding-cosim {__version__}"
    out = elsewhere / "out"
    proc = subprocess.run([str(python.parent / "pounding-cosim"), "run", "--no-plots", "--no-progress", "--out",
                           str(out)], cwd=elsewhere, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "scene default:" in proc.stdout and f"results: {out}" in proc.stdout
    # the FMUs were built into the per-user cache, and nothing was written into site-packages
    built = sorted(p.relative_to(cache) for p in cache.rglob("*.fmu"))
    assert [str(p.parent.parent) for p in built] == ["pounding-cosim/fmus"] * 3, built
    assert built[0].parent.name.startswith(f"{__version__}-")
    assert listing(site) == before
    # the numbers are the checkout's
    theirs = json.loads((out / "summary.json").read_text())
    ours = run_scene("default", fmu_dir=fmu_dir, write=False, progress=False).summary.to_dict()
    for summary in (theirs, ours):
        summary.pop("wall_time_s")
        # FMU files built elsewhere (zip timestamps differ) and their paths; the record is the same file
        made = summary.pop("provenance")
        assert made["record"]["sha256"] == hashlib.sha256(BUNDLED["elcentro1940"].path.read_bytes()).hexdigest()
    assert theirs == json.loads(json.dumps(ours))


def test_the_installed_shims_and_modules_answer_help(installed, tmp_path):
    python, base = installed
    for args in (["-m", "cosim", "--help"], ["-m", "cosim.cli", "--help"], ["-m", "cosim.run", "--help"],
                 ["-m", "cosim.study", "--help"], ["-m", "cosim.calibrate", "--help"], ["-m", "cosim.report", "--help"]):
        proc = subprocess.run([str(python), *args], cwd=tmp_path, capture_output=True, text=True)
        assert proc.returncode == 0 and proc.stdout.startswith("usage:"), (args, proc.stderr[-1000:])
    proc = subprocess.run([str(python), "-c", "import cosim, importlib.resources as r; print(cosim.__version__, "
                           "r.files('cosim').joinpath('py.typed').is_file(), "
                           "len(list(r.files('cosim').joinpath('scenes').iterdir())))"],
                          cwd=tmp_path, capture_output=True, text=True)
    scenes = len(list((ROOT / "cosim" / "scenes").glob("*.toml")))   # every bundled scene is in the wheel
    assert proc.stdout.split() == [__version__, "True", str(scenes)], proc.stderr
