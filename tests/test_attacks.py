"""Issue 14's attacks, each with the outcome it must have, so that none of them can come back.

103 attacks were tried on the command lines and the FMUs as a careless or unlucky user would;
the ones that failed or were weak are here (the issue lists them; the rest held).  The outcome
every one of them must have:

* the user's files intact (compared byte for byte), no hidden ``.partial``/``.old`` debris;
* bad input: exit 2 and one line ``error: ...`` naming the value, the limit or range and the
  place (``--set``, file and line, the FMU file); a run that failed: exit 1 and one line; an
  interrupt: exit 130 and ``interrupted``; never a traceback;
* an unbounded request refused before it allocates or runs, in under 5 s;
* FMUs: an FMI error status (fmi2Discard for a step, fmi2Fatal where pythonfmu allows nothing
  else) with a logged message, and a host that goes on.

Most cases run the command line in a child process (what a user runs: exit code, standard
error, signals, a private read-only or tiny filesystem); fast ones in this process.  Cases that
belong to other work in progress (the study application, issue 14's study items; record files,
issue 14's record items) are marked ``xfail(strict=True)`` while that work is not in this tree,
detected by what the issue asks for (the study command's ``--retry-failed``; a declared bound on
the ground motion's ``target_pga``): once it lands the mark falls away by itself and the cases
must pass.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.files import MARKER

ROOT = Path(__file__).resolve().parents[1]
#: refusing an unbounded request may take this long, process start and imports included (issue 14);
#: the child processes import numpy, scipy and fmpy, about 1-2 s on the CI machine
REFUSAL_S = 5.0
#: waiting for a child to reach a state (partial folder present, run started); generous: a
#: loaded 2-core machine; the test fails only if the state is never reached
WAIT_S = 60.0
#: the cases that assert REFUSAL_S of wall time run with no other test of the suite beside them
#: (tests/conftest.py): the bound is on this package's work, not on a neighbour's load
EXCLUSIVE = pytest.mark.exclusive



def _study_items_present() -> bool:
    """The study command has issue 14's ``--retry-failed`` (H16's study work is in this tree)."""
    from cosim.cli import build_parser

    study = build_parser()[1]["study"]
    return any("--retry-failed" in action.option_strings for action in study._actions)


def _record_items_present() -> bool:
    """The ground motion declares an upper bound on ``target_pga`` (H15's record work is in this tree)."""
    from fmu_src.ground_motion_slave import GroundMotion

    return next(v for v in GroundMotion.VARIABLES if v.name == "target_pga").high is not None


H16 = pytest.mark.xfail(not _study_items_present(), strict=True,
                        reason="study items of issue 14: H16's work, not yet in this tree")
H15 = pytest.mark.xfail(not _record_items_present(), strict=True,
                        reason="record items of issue 14: H15's work, not yet in this tree")


# -- helpers ---------------------------------------------------------------------------------------
class Done:
    """A finished child: exit ``code``, ``out``, ``err`` (text) and wall ``seconds``."""

    def __init__(self, code: int, out: str, err: str, seconds: float):
        self.code, self.out, self.err, self.seconds = code, out, err, seconds

    def __repr__(self) -> str:
        return f"exit {self.code} after {self.seconds:.1f} s\nstdout: {self.out[-2000:]}\nstderr: {self.err[-2000:]}"


#: address space a child may use when a case must show bounded memory (bytes): a run of the
#: default scene peaks at 2.4 GB of address space (mostly thread stacks and libraries reserved,
#: 0.1 GB resident); 3 GB turns an unbounded allocation into a quick MemoryError
MEMORY_CAP = 3 * 2**30


def _cap_memory() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


def cli(*args, cwd: Path, timeout: float = 120, prefix: tuple = (), capped: bool = False) -> Done:
    """``pounding-cosim ARGS`` in a child process (``prefix``: e.g. ``unshare`` to run it in a
    private mount namespace; ``capped``: address space limited to :data:`MEMORY_CAP`)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    proc = subprocess.run([*prefix, sys.executable, "-m", "cosim.cli", *[str(a) for a in args]], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout,
                          preexec_fn=_cap_memory if capped else None)
    return Done(proc.returncode, proc.stdout, proc.stderr, time.perf_counter() - t0)


@pytest.fixture
def main(capsys):
    """``pounding-cosim ARGS`` in this process (for cases where the process boundary adds nothing)."""
    from cosim.cli import main as cli_main

    def run(*args) -> Done:
        t0 = time.perf_counter()
        code = cli_main([str(a) for a in args])
        captured = capsys.readouterr()
        return Done(code, captured.out, captured.err, time.perf_counter() - t0)
    return run


def one_line(done: Done, code: int, *fragments: str, prefix: str = "error: ") -> str:
    """``done`` ended with ``code`` and one line on standard error holding every fragment."""
    assert done.code == code, done
    assert "Traceback" not in done.err and "Traceback" not in done.out, done
    lines = done.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(prefix), done
    for fragment in fragments:
        assert fragment in lines[0], (fragment, done)
    return lines[0]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes (to show nothing was touched)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def debris(parent: Path) -> list[str]:
    return [p.name for p in parent.iterdir() if ".partial-" in p.name or ".old-" in p.name]


def user_folder(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "notes.txt").write_text("my notes, not a result\n")
    (path / "data").mkdir()
    (path / "data" / "measurements.csv").write_text("t,x\n0,1\n")
    return path


@pytest.fixture(scope="module")
def quick(fmu_dir):
    """Common arguments of a quick run: the session's FMUs, no plots, no progress bar."""
    return ("--fmu-dir", fmu_dir, "--no-plots", "--no-progress")


def namespace_available() -> bool:
    """A private mount namespace (``unshare -rm``) in which tmpfs can be mounted."""
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
                           capture_output=True)
    return probe.returncode == 0


def in_namespace(mount: str) -> tuple:
    """A prefix that runs the child in a private mount namespace after ``mount`` (shell)."""
    return ("unshare", "-rm", "sh", "-c", f'{mount} && exec "$@"', "sh")


needs_namespace = pytest.mark.skipif(not namespace_available(), reason="no private mount namespace (unshare -rm)")


# -- data loss -------------------------------------------------------------------------------------
def test_out_holding_the_users_files_is_refused(tmp_path, quick):
    out = user_folder(tmp_path / "mine")
    before = snapshot(out)
    for extra in ((), ("--overwrite",)):     # --overwrite replaces only what this package wrote
        done = cli("run", "free_vibration", "--stop-time", "0.1", "--out", out, *extra, *quick, cwd=tmp_path)
        one_line(done, 2, str(out), "did not write", "never replaced")
        assert snapshot(out) == before and debris(tmp_path) == []


def test_out_that_is_a_file_is_refused(tmp_path, quick):
    out = tmp_path / "results.txt"
    out.write_text("precious\n")
    done = cli("run", "free_vibration", "--stop-time", "0.1", "--out", out, *quick, cwd=tmp_path)
    one_line(done, 2, str(out), "is a regular file")
    assert out.read_text() == "precious\n" and sorted(p.name for p in tmp_path.iterdir()) == ["results.txt"]


@pytest.mark.parametrize("name", [".", "..", "a/b", ".hidden"])
def test_scene_names_are_plain_names(tmp_path, quick, main, monkeypatch, name):
    earlier = tmp_path / "out" / "free_vibration"
    earlier.mkdir(parents=True)
    (earlier / "summary.json").write_text("{}")
    before = snapshot(tmp_path / "out")
    monkeypatch.chdir(tmp_path)   # no --out: out/<name> under the current folder
    done = main("run", "free_vibration", "--stop-time", "0.1", "--set", f"name={name}", *quick)
    one_line(done, 2, f"--set name={name}", "not a plain name")
    assert snapshot(tmp_path / "out") == before and debris(tmp_path) == debris(tmp_path / "out") == []


def test_readme_example_does_not_replace_earlier_results(tmp_path, quick):
    """README: ``run.py default --set ground.record=kobe1995 --set stop_time=5`` after a default
    run: the earlier results stay, the new ones go to out/default-2 (and the output says so)."""
    first = cli("run", "default", "--stop-time", "0.3", *quick, cwd=tmp_path)
    assert first.code == 0 and "results: " + str(tmp_path / "out" / "default") in first.out, first
    before = snapshot(tmp_path / "out" / "default")
    second = cli("run", "default", "--set", "ground.record=kobe1995", "--set", "stop_time=0.2", *quick, cwd=tmp_path)
    assert second.code == 0 and f"results: {tmp_path / 'out' / 'default-2'}" in second.out, second
    assert snapshot(tmp_path / "out" / "default") == before
    assert json.loads((tmp_path / "out" / "default-2" / "summary.json").read_text())["stop_time_s"] == 0.2
    # --overwrite replaces the earlier run's folder, as a whole
    third = cli("run", "default", "--stop-time", "0.1", "--overwrite", *quick, cwd=tmp_path)
    assert third.code == 0 and f"results: {tmp_path / 'out' / 'default'}\n" in third.out, third
    assert json.loads((tmp_path / "out" / "default" / "summary.json").read_text())["stop_time_s"] == 0.1
    # ... but not once a person has put a file of their own into it
    (tmp_path / "out" / "default" / "my_plot.png").write_bytes(b"mine")
    before = snapshot(tmp_path / "out")
    fourth = cli("run", "default", "--stop-time", "0.1", "--out", tmp_path / "out" / "default", "--overwrite",
                 *quick, cwd=tmp_path)
    one_line(fourth, 2, "my_plot.png", "never replaced")
    assert snapshot(tmp_path / "out") == before and debris(tmp_path / "out") == []


#: a study of 3 x NUM quick cases (one impact of two free masses each; 12 cases took about 20 s
#: with one worker on a loaded 2-core machine, Dask's start included)
SMALL_STUDY = """name = "attack"
scene = "single_impact"
[set]
"pounding.gap" = 0.0
stop_time = 0.015
[vary]
"pounding.CR" = [0.4, 0.65, 0.9]
[[zip]]
"left.v0[1]" = { start = 0.5, stop = 10.0, num = NUM }
"right.v0[1]" = { start = -0.5, stop = -10.0, num = NUM }
"""


def start_study(tmp_path: Path, fmu_dir: Path, out: Path, num: int = 4, *extra: str) -> subprocess.Popen:
    """``study`` in a child process of its own process group (its Dask workers with it, so that
    :func:`stop` ends them all)."""
    study = tmp_path / "attack.toml"
    study.write_text(SMALL_STUDY.replace("NUM", str(num)))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "cosim.cli", "study", str(study), "--out", str(out), "--workers",
                             "1", "--fmu-dir", str(fmu_dir), "--no-progress", *extra], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def stop(proc: subprocess.Popen) -> None:
    """Kill a study child and its workers if it is still running."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def study_rows(out: Path) -> list[str]:
    """The case ids of the complete rows of ``out/results.csv``."""
    path = out / "results.csv"
    if not path.exists():
        return []
    import csv

    rows = list(csv.reader(path.read_text().splitlines()))
    return [row[0] for row in rows[1:] if len(row) == len(rows[0])]   # a torn last line is left out


def wait_for_rows(out: Path, proc: subprocess.Popen, count: int) -> None:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline and proc.poll() is None and len(study_rows(out)) < count:
        time.sleep(0.05)
    assert len(study_rows(out)) >= count and proc.poll() is None, "the study never wrote its first rows"


@H16
def test_two_resumes_of_one_study_at_once(tmp_path, fmu_dir):
    """A second writer of a study folder (``--resume`` while the first still writes) is refused
    with one line naming the holder, and no case is written twice (before: 70 rows for 40
    cases, 30 duplicates).  60 cases: the first still runs when the second has started (Dask's
    start takes up to 20 s here); it is then interrupted, which keeps its finished rows."""
    out = tmp_path / "study"
    first = start_study(tmp_path, fmu_dir, out, 20)
    second = None
    try:
        wait_for_rows(out, first, 1)
        # the first held still (SIGSTOP to its process group, its Dask worker with it) while the
        # second starts: it still writes then, whatever the load of the machine
        os.killpg(first.pid, signal.SIGSTOP)
        try:
            second = start_study(tmp_path, fmu_dir, out, 20, "--resume")
            # refused at once; 30 s would allow a lock taken only after Dask's start (up to 20 s
            # here): a second writer still running then is writing the same cases
            try:
                out_text, err_text = second.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                raise AssertionError("the second writer of the study folder was not refused within 30 s") from None
        finally:
            os.killpg(first.pid, signal.SIGCONT)
        one_line(Done(second.returncode, out_text, err_text, 0.0), 2, str(first.pid))
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=WAIT_S)
    finally:
        stop(first)
        if second is not None:
            stop(second)
    rows = study_rows(out)
    assert rows and len(rows) == len(set(rows)), rows


# -- unbounded work or memory ----------------------------------------------------------------------
@EXCLUSIVE
@pytest.mark.parametrize("args, fragments", [
    (("--set", "stop_time=1e9"), ("--set stop_time=1e9", "1e+11 communication steps", "1,000,000", "--max-steps")),
    (("--step", "1e-12"), ("--step 1e-12", "4e+13 communication steps", "1,000,000", "--max-steps")),
])
def test_unbounded_runs_are_refused_at_once(tmp_path, quick, args, fragments):
    done = cli("run", "default", *args, *quick, cwd=tmp_path, capped=True)   # refused before it allocates
    one_line(done, 2, *fragments)
    assert done.seconds < REFUSAL_S, done
    assert not (tmp_path / "out").exists()


def test_max_steps_raises_the_limit_on_purpose(tmp_path, quick, main):
    args = ("run", "free_vibration", "--stop-time", "0.05", "--step", "1e-4", "--coupling", "gauss-seidel",
            "--out", tmp_path / "r", *quick)
    one_line(main(*args, "--max-steps", "100"), 2, "500 communication steps", "limit of 100")
    done = main(*args, "--max-steps", "1000")
    assert done.code == 0 and "500 steps" in done.out, done


@EXCLUSIVE
@H15
def test_dev_zero_as_a_record_is_refused(tmp_path, quick):
    done = cli("run", "default", "--set", "ground.record=/dev/zero", "--set", "ground.dt=0.01", *quick, cwd=tmp_path,
               timeout=REFUSAL_S + 0.5, capped=True)
    one_line(done, 2, "/dev/zero")
    assert done.seconds < REFUSAL_S


def test_a_huge_dashpot_is_stopped_by_the_guard(tmp_path, quick):
    """pounding.zeta = 1e6 held the floors together and the adaptive coupling followed it in
    0.6 us steps: 3 simulated seconds took 331 s.  The guard stops it, naming the dashpot."""
    done = cli("run", "default", "--stop-time", "3", "--set", "pounding.zeta=1e6", *quick, cwd=tmp_path)
    one_line(done, 1, "pounding_3", "refined communication steps", "zeta = 1e+06", "dashpot", "lower zeta")
    assert not (tmp_path / "out").exists()


def test_crvk_at_a_tiny_restitution_ends_with_its_energy_balanced(tmp_path, quick):
    """crvk at CR 0.001 stuck and its in-step integration chattered (64 s, +2 % residual, no
    warning).  Since the in-step resolver of issue 13 the run completes (40 s of El Centro in
    3.8 s of wall time, measured on a loaded machine) with a residual of -0.31 %; it must stay
    within 1 %, the share the guard treats as created by the coupling.  Should it chatter
    again, the guard's bound on a contact's internal steps stops it (tested below)."""
    out = tmp_path / "r"
    done = cli("run", "default", "--set", "pounding.model=crvk", "--set", "pounding.CR=0.001", "--out", out, *quick,
               cwd=tmp_path)
    assert done.code == 0 and "Traceback" not in done.err, done
    summary = json.loads((out / "summary.json").read_text())
    assert abs(summary["energy_residual_J"]) < 0.01 * summary["energy_input_J"], summary["energy_residual_J"]


def test_the_guard_stops_a_contact_whose_internal_steps_explode(fmu_dir, monkeypatch):
    """The guard reads every contact FMU's ``substeps`` and stops a run whose internal work since
    an impact exceeds its bound, naming the contact, the law and the stuck contact.  Shown on
    the default scene with the bound lowered below what a resolved impact takes (40-90)."""
    from cosim.master import guard
    from cosim.master.runner import run_scene

    monkeypatch.setattr(guard, "MAX_SUBSTEPS_PER_IMPACT", 10)
    monkeypatch.setattr(guard, "SUBSTEPS_PER_STEP", 0)
    with pytest.raises(guard.InstabilityError, match=r"pounding_3: t = .* internal steps in .* since its impact"):
        run_scene("default", ["stop_time=3"], fmu_dir=fmu_dir, write=False, progress=False)


@EXCLUSIVE
@H16
def test_a_study_range_of_1e8_cases_is_refused_in_a_dry_run(tmp_path, fmu_dir):
    study = tmp_path / "huge.toml"
    study.write_text('name = "huge"\nscene = "default"\n[vary]\n"pounding.gap" = { start = 0.0, stop = 0.1, '
                     'num = 100000000 }\n')
    done = cli("study", study, "--dry-run", "--fmu-dir", fmu_dir, cwd=tmp_path, timeout=REFUSAL_S + 0.5, capped=True)
    one_line(done, 2, "100000000")
    assert done.seconds < REFUSAL_S


# -- work thrown away, debris ----------------------------------------------------------------------
@EXCLUSIVE
@needs_namespace
def test_read_only_out_is_refused_before_running(tmp_path, quick):
    ro = tmp_path / "ro"
    ro.mkdir()
    mount = f"mount -t tmpfs -o size=1m,ro tmpfs {ro}"
    done = cli("run", "default", "--out", ro / "x", *quick, cwd=tmp_path, prefix=in_namespace(mount))
    one_line(done, 2, str(ro), "read-only filesystem")
    assert done.seconds < REFUSAL_S, done
    cal = cli("calibrate", "--model", "crvk", "--m1", 200, "--m2", 200, "--k", 1.8974e11, "--v", 10, "--cr", 0.4,
              "--out", ro / "cal", "--fmu-dir", quick[1], cwd=tmp_path, prefix=in_namespace(mount))
    one_line(cal, 2, str(ro), "read-only filesystem")
    assert cal.seconds < REFUSAL_S, cal


@EXCLUSIVE
def test_out_under_a_regular_file_is_refused_before_running(tmp_path, quick):
    (tmp_path / "file.txt").write_text("x")
    done = cli("run", "default", "--out", tmp_path / "file.txt" / "sub", *quick, cwd=tmp_path)
    one_line(done, 2, "file.txt is not a folder")
    assert done.seconds < REFUSAL_S
    cal = cli("calibrate", "--model", "crvk", "--m1", 200, "--m2", 200, "--k", 1.8974e11, "--v", 10, "--cr", 0.4,
              "--out", tmp_path / "file.txt" / "cal", "--fmu-dir", quick[1], cwd=tmp_path)
    one_line(cal, 2, "file.txt is not a folder")
    assert cal.seconds < REFUSAL_S
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


def test_export_ssp_onto_a_folder_or_a_file(tmp_path, fmu_dir):
    folder = user_folder(tmp_path / "pkg")
    before = snapshot(folder)
    one_line(cli("export-ssp", "default", folder, "--fmu-dir", fmu_dir, cwd=tmp_path), 2, "is a folder")
    assert snapshot(folder) == before
    target = tmp_path / "default.ssp"
    target.write_text("an older package\n")
    one_line(cli("export-ssp", "default", target, "--fmu-dir", fmu_dir, cwd=tmp_path), 2, "already exists",
             "--overwrite")
    assert target.read_text() == "an older package\n"
    done = cli("export-ssp", "default", target, "--overwrite", "--fmu-dir", fmu_dir, cwd=tmp_path)
    assert done.code == 0 and target.read_bytes()[:2] == b"PK", done
    assert debris(tmp_path) == []


def test_out_dot_is_refused_and_leaves_nothing(tmp_path, quick):
    (tmp_path / "mine.txt").write_text("x")
    done = cli("run", "free_vibration", "--stop-time", "0.1", "--out", ".", *quick, cwd=tmp_path)
    one_line(done, 2, "never replaced")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.txt"]
    assert debris(tmp_path.parent) == []


def test_a_killed_runs_partial_folder_is_removed_by_the_next_run(tmp_path, quick):
    """SIGKILL mid-run leaves the hidden folder the run was to write into (claimed before the
    run); the next run into the same parent removes it, and nothing that is not this
    package's (a hidden folder of the same shape without the marker)."""
    parent = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "run", "kasai_maison", "--out", parent / "long",
                             *[str(a) for a in quick]], cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + WAIT_S
        # mid-run: the claim is complete once its marker is in place (the folder is made first and
        # the marker written into it after; a kill between the two, seen once under load with
        # pytest -n 2, leaves an unmarked folder, which by design is not this package's to remove)
        while time.monotonic() < deadline and not (parent.exists() and any(
                (parent / name / MARKER).exists() for name in debris(parent))):
            time.sleep(0.05)
    finally:
        proc.kill()
        proc.wait()
    left = [parent / name for name in debris(parent)]
    assert len(left) == 1 and json.loads((left[0] / MARKER).read_text())["state"] == "partial"
    foreign = parent / ".notes.partial-1-abcdef12"   # a person's folder that merely looks like one
    foreign.mkdir()
    (foreign / "keep.txt").write_text("mine")
    done = cli("run", "free_vibration", "--stop-time", "0.1", "--out", parent / "next", *quick, cwd=tmp_path)
    assert done.code == 0, done
    assert sorted(p.name for p in parent.iterdir()) == [".notes.partial-1-abcdef12", "next"]
    assert (foreign / "keep.txt").read_text() == "mine"


@EXCLUSIVE
@needs_namespace
def test_a_full_disk_is_refused_before_running(tmp_path, quick):
    small = tmp_path / "small"
    small.mkdir()
    done = cli("run", "default", "--stop-time", "1", "--out", small / "r", *quick, cwd=tmp_path,
               prefix=in_namespace(f"mount -t tmpfs -o size=256k tmpfs {small}"))
    one_line(done, 2, "needs about", "free")
    assert done.seconds < REFUSAL_S


@needs_namespace
def test_a_disk_that_fills_up_while_writing_leaves_nothing(tmp_path, fmu_dir):
    """The free-space check is an estimate: a disk that fills up anyway (another program writes)
    ends with one line, exit 1, and nothing partial.  Here the check is told there is plenty of
    room on a 256 kB filesystem; what is left on it is listed from inside the namespace.  The
    run writes about 1 MB: every output at every point of 500 fixed steps (history.csv
    0.78 MB, measured) and the plots (~0.15 MB); with the adaptive coupling's long steps and the
    default recorded set, 2 s wrote 0.17 MB, which fitted."""
    small = tmp_path / "small"
    small.mkdir()
    code = (f"import collections, shutil; "
            f"shutil.disk_usage = lambda p: collections.namedtuple('u', 'total used free')(1 << 40, 0, 1 << 40); "
            f"from cosim.cli import console; console(['run', 'default', '--stop-time', '5', '--coupling', "
            f"'gauss-seidel', '--record', 'all', '--output-interval', '0', '--out', "
            f"'{small / 'r'}', '--fmu-dir', '{fmu_dir}', '--no-progress'])")
    script = (f"mount -t tmpfs -o size=256k tmpfs {small} && {sys.executable} -c \"{code}\"; "
              f"rc=$?; echo LEFT: $(ls -A {small}); exit $rc")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run(["unshare", "-rm", "sh", "-c", script], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=120)
    one_line(Done(proc.returncode, "", proc.stderr, 0.0), 1, "the disk filled up", "nothing was written")
    assert proc.stdout.strip().splitlines()[-1].strip() == "LEFT:", proc.stdout   # nothing partial


# -- messages --------------------------------------------------------------------------------------
@pytest.mark.parametrize("override, fragments", [
    ("left.n_storeys=21", ("--set left.n_storeys=21", "room for 1 to 20 storeys", "N_MAX = 20")),
    ("left.m[25]=1e5", ("--set left.m[25]=1e5", "floor 25", "room for 1 to 20 storeys")),
    ("left.m=1e-300", ("--set left.m=1e-300", "m[1] = 1e-300 kg", "1e-06 <= m[1] <= 1e+12")),
    ("left.m=1e300", ("--set left.m=1e300", "1e-06 <= m[1] <= 1e+12")),
    ("left.T1=1e300", ("--set left.T1=1e300", "T1 = 1e+300 s", "0 <= T1 <= 100")),
])
def test_bad_building_values_are_named_with_their_range(tmp_path, quick, main, override, fragments):
    done = main("run", "default", "--set", override, "--out", tmp_path / "r", *quick)
    line = one_line(done, 2, *fragments)
    for wrong in ("unknown key", "LAPACK", "algorithm failed", "input ag", "mechanism", "nan"):
        assert wrong not in line, line


def test_a_list_longer_than_the_storey_capacity_names_the_file_line(tmp_path, quick, main):
    scene = tmp_path / "tall.toml"
    text = (ROOT / "cosim" / "scenes" / "default.toml").read_text()
    tall = "m = [" + ", ".join(["3.0e5"] * 21) + "]"
    scene.write_text(text.replace("m = [3.0e5, 3.0e5, 3.0e5]", tall, 1))
    line_no = next(i for i, line in enumerate(scene.read_text().splitlines(), 1) if line.startswith(tall))
    one_line(main("run", scene, "--out", tmp_path / "r", *quick), 2, f"{scene}, line {line_no}", "has 21 values",
             "room for 1 to 20 storeys")


@H15
def test_a_huge_target_pga_is_named(tmp_path, quick, main):
    line = one_line(main("run", "default", "--set", "ground.target_pga=1e300", "--out", tmp_path / "r", *quick), 2,
                    "target_pga")
    assert "input ag" not in line


def test_a_corrupt_fmu_is_named(tmp_path, fmu_dir, main):
    broken = tmp_path / "fmus"
    shutil.copytree(fmu_dir, broken)
    (broken / "pounding.fmu").write_bytes(b"this is not a zip archive")
    one_line(main("run", "default", "--stop-time", "0.1", "--fmu-dir", broken, "--out", tmp_path / "r"), 2,
             str(broken / "pounding.fmu"), "not a usable FMU", "build-fmus --force")


def test_a_run_ending_in_contact_has_no_stored_energy_residual(fmu_dir):
    """The single impact stopped halfway through its 0.35 ms contact: the contact spring then holds
    energy k delta^(n+1)/(n+1), part of the balance, not a residual (before: 6.5 % 'residual')."""
    from cosim.master.fmi import exit_process  # noqa: F401 - imported to keep the FMU process rules visible
    from cosim.master.runner import run_scene

    full = run_scene("single_impact", fmu_dir=fmu_dir, write=False, progress=False)
    t, delta = full.result.time, full.result["pounding_1.delta"]
    inside = t[delta > 0]
    stop = float(inside[len(inside) // 2])
    half = run_scene("single_impact", [f"stop_time={stop!r}"], fmu_dir=fmu_dir, write=False, progress=False).summary
    energy = half.energy_input_J
    assert half.energy_contact_stored_J > 0.05 * energy        # a real share of the energy is in the spring
    # the coupling error of the resolved single impact: 1e-7 of the input measured; 1e-5 allows
    # round-off of the energy sums a hundred times over
    assert abs(half.energy_residual_J) < 1e-5 * energy, half.energy_residual_J


# -- interrupts ------------------------------------------------------------------------------------
def interrupted(args: tuple, cwd: Path, ready, out: Path | None = None) -> Done:
    """Start ``pounding-cosim ARGS``, send SIGINT once ``ready()`` is true, and wait."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", *[str(a) for a in args]], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline and proc.poll() is None and not ready():
            time.sleep(0.05)
        time.sleep(0.3)   # well inside the work
        proc.send_signal(signal.SIGINT)
        out_text, err_text = proc.communicate(timeout=WAIT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return Done(proc.returncode, out_text, err_text, time.perf_counter() - t0)


def claimed(parent: Path):
    """True once a run has claimed its folder in ``parent`` (it then runs)."""
    return lambda: parent.exists() and bool(debris(parent))


@pytest.mark.parametrize("command", ["run", "calibrate", "accuracy", "report"])
def test_ctrl_c_ends_with_interrupted_and_writes_nothing(tmp_path, fmu_dir, command):
    parent = tmp_path / "out"
    args = {
        "run": ("run", "kasai_maison", "--out", parent / "r", "--fmu-dir", fmu_dir, "--no-progress"),
        "calibrate": ("calibrate", "--model", "crvk", "--m1", 200, "--m2", 200, "--k", 1.8974e11, "--v", 10, "--cr",
                      0.4, "--out", parent / "c", "--fmu-dir", fmu_dir),
        "accuracy": ("accuracy", "default", "--out", parent / "a", "--fmu-dir", fmu_dir),
        "report": ("report", "--out", parent / "rep", "--quick", "--fmu-dir", fmu_dir),
    }[command]
    done = interrupted(args, tmp_path, claimed(parent))
    one_line(done, 130, prefix="interrupted")
    assert not parent.exists() or sorted(parent.iterdir()) == [], done   # nothing written, no debris


#: a child that presses Ctrl-C while pythonfmu imports the slave's module during fmi2Instantiate
#: (an import hook at the front of sys.meta_path: the import machinery's frames, called from C,
#: run before any of the module's own), inside deferred_interrupts as the command line runs
CTRL_C_DURING_INSTANTIATION = """
import os, signal, sys
from cosim.fmus import PACKAGE_PREFIX
from cosim.master.fmi import FMU, deferred_interrupts

class CtrlCOnImport:
    def find_spec(self, name, path=None, target=None):
        if name.startswith(PACKAGE_PREFIX):
            os.kill(os.getpid(), signal.SIGINT)
        return None

sys.meta_path.insert(0, CtrlCOnImport())
fmu = FMU(sys.argv[1])
try:
    with deferred_interrupts():
        fmu.instantiate("x")
    print("not interrupted")
except KeyboardInterrupt:
    print("interrupted")
except BaseException as exc:
    print(f"{type(exc).__name__}: {exc}")
os._exit(0)
"""


def test_ctrl_c_while_an_fmu_is_instantiated_is_an_interrupt(fmu_path, tmp_path):
    """Ctrl-C during fmi2Instantiate ends as KeyboardInterrupt (the command line's 'interrupted'),
    not as pythonfmu's "Failed to instantiate model": the cause of the calibrate case of
    test_ctrl_c_ends_with_interrupted_and_writes_nothing failing now and then under load, where
    the SIGINT 0.3 s after the claim landed in the first instantiation (session 29)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", CTRL_C_DURING_INSTANTIATION, str(fmu_path("pounding"))], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=WAIT_S)
    assert proc.stdout.strip() == "interrupted", (proc.returncode, proc.stdout, proc.stderr)


def test_ctrl_c_in_a_study_keeps_the_finished_rows(tmp_path, fmu_dir):
    """Ctrl-C while a study runs its cases: 'interrupted', exit 130, no traceback, and the rows
    finished before it stay.  (Ctrl-C while Dask starts, where the tornado NameError came from,
    depends on timing within the start-up: the study's own tests.)"""
    out = tmp_path / "study"
    proc = start_study(tmp_path, fmu_dir, out)
    try:
        wait_for_rows(out, proc, 2)
        done_before = study_rows(out)
        proc.send_signal(signal.SIGINT)
        out_text, err_text = proc.communicate(timeout=WAIT_S)
    finally:
        stop(proc)
    one_line(Done(proc.returncode, out_text, err_text, 0.0), 130, prefix="interrupted")
    rows = study_rows(out)
    assert set(done_before) <= set(rows) and len(rows) == len(set(rows)), (done_before, rows)


@H16
def test_resume_retries_failed_cases(tmp_path, fmu_dir):
    done = cli("study", "fig8a_gap", "--resume", "--retry-failed", "--dry-run", "--fmu-dir", fmu_dir, cwd=tmp_path)
    assert done.code == 0, done


# -- FMUs ------------------------------------------------------------------------------------------
class Raw:
    """One FMU instance through fmpy alone (no master), with its log."""

    def __init__(self, path: Path, name: str = "attacked"):
        from fmpy import extract, read_model_description
        from fmpy.fmi1 import calloc, free
        from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.log: list[tuple[int, str]] = []
        self._callbacks = fmi2CallbackFunctions()
        self._logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: self.log.append(
            (status, msg.decode(errors="replace"))))
        self._callbacks.logger = self._logger
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)

    def start(self, **reals):
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        if reals:
            self.fmu.setReal([self.vr[n] for n in reals], list(reals.values()))
        self.fmu.exitInitializationMode()

    def status_of(self, call, *args) -> int:
        from fmpy.fmi1 import FMICallException

        try:
            call(*args)
        except FMICallException as exc:
            return exc.status
        return 0

    def errors(self) -> list[str]:
        return [m for s, m in self.log if s >= 3]

    def close(self):
        self.fmu.freeInstance()


@pytest.mark.parametrize("hysteresis, fragments", [
    ("linear", ("h = 1000000.0 s", "arithmetic")),               # the step matrix overflows
    ("bilinear", ("segment of 1e+06 s", "limit is 4096")),       # quadrature chunks of the fastest mode
    ("bouc_wen", ("step of 1e+06 s", "limit is 8192")),          # ran for minutes before
])
def test_building_refuses_a_step_its_arithmetic_cannot_take(fmu_path, hysteresis, fragments):
    b = Raw(fmu_path("building"))
    b.fmu.setupExperiment(startTime=0.0)
    b.fmu.enterInitializationMode()
    b.fmu.setString([b.vr["hysteresis"]], [hysteresis])
    b.fmu.setReal([b.vr["x0[1]"], b.vr["Fy[1]"]], [0.01, 1e6])   # yield drift 0.063 m: starts elastic
    b.fmu.exitInitializationMode()
    assert b.status_of(b.fmu.doStep, 0.0, 0.01) == 0
    watched = [b.vr[name] for name in ("x[1]", "v[1]", "E_damping", "x_peak[1]")]
    before = b.fmu.getReal(watched)
    t0 = time.perf_counter()
    assert b.status_of(b.fmu.doStep, 0.01, 1e6) == 2          # fmi2Discard, with the reason logged
    assert time.perf_counter() - t0 < REFUSAL_S
    assert any(all(f in m for f in fragments) and "shorter step" in m for m in b.errors()), b.log
    assert b.fmu.getReal(watched) == before and np.isfinite(before).all()   # nothing changed
    assert b.status_of(b.fmu.doStep, 0.01, 0.01) == 0         # and the instance goes on
    b.close()


def test_bouc_wen_work_per_step_is_bounded(monkeypatch):
    """The Runge-Kutta budget of one communication step is enforced (here lowered to 10 steps,
    which a 1 s step of a 0.5 s building needs 30 of) and named in the refusal."""
    from fmu_src import building_response
    from fmu_src.hysteresis import StoreyHysteresis
    from fmu_src.shear_building import ShearBuilding

    building = ShearBuilding(np.full(3, 1e5), np.full(3, 1.579e7), 0.05, "rayleigh")
    integrator = building_response.integrator_for(
        building, StoreyHysteresis("bouc_wen", np.full(3, 1e6), 0.05, 2.0, 0.5, 0.5))
    state = integrator.initial_state(np.zeros(3), np.zeros(3), np.zeros(3))
    monkeypatch.setattr(building_response, "BOUC_WEN_MAX_RK_STEPS", 10)
    with pytest.raises(ValueError, match="more than 10 Runge-Kutta steps in one step of 1 s"):
        integrator.advance(state, (0.0, 1.0), (3.0, -3.0), np.zeros(3))
    monkeypatch.setattr(building_response, "BOUC_WEN_MAX_RK_STEPS", 1000)
    assert integrator.advance(state, (0.0, 1.0), (3.0, -3.0), np.zeros(3)).rk_steps > 10


def test_bad_parameters_are_refused_at_exit_initialization(fmu_path):
    p = Raw(fmu_path("pounding"))
    p.fmu.setupExperiment(startTime=0.0)
    p.fmu.enterInitializationMode()
    p.fmu.setReal([p.vr["CR"]], [1.5])
    assert p.status_of(p.fmu.exitInitializationMode) == 4    # fmi2Fatal: all pythonfmu can answer there
    assert any("CR = 1.5" in m and "0 < CR <= 1" in m for m in p.errors()), p.log
    assert p.status_of(p.fmu.doStep, 0.0, 0.01) == 2          # and every step after
    p.fmu.reset()                                             # the instance is still the host's to reuse
    p.start()
    assert p.status_of(p.fmu.doStep, 0.0, 0.01) == 0
    p.close()


def test_fixed_parameters_cannot_change_after_initialization(fmu_path):
    b = Raw(fmu_path("building"))
    b.start(**{"m[1]": 2e5})
    assert b.status_of(b.fmu.setReal, [b.vr["m[1]"]], [1.0]) == 4
    assert any("m[1] is a fixed parameter" in m for m in b.errors()), b.log
    assert b.fmu.getReal([b.vr["m[1]"]]) == [2e5]
    b.close()


@pytest.mark.parametrize("fmu", ["building", "pounding", "ground_motion"])
def test_a_state_freed_twice_is_refused_and_the_host_lives_on(fmu_path, fmu):
    b = Raw(fmu_path(fmu))
    b.start()
    for _ in range(200):    # a live state is never taken for a freed one
        state = b.fmu.getFMUstate()
        b.fmu.setFMUstate(state)
        b.fmu.freeFMUstate(state)
    state = b.fmu.getFMUstate()
    b.fmu.freeFMUstate(state)
    assert b.status_of(b.fmu.setFMUstate, state) == 4         # used after it was freed
    assert any("state that was freed" in m for m in b.errors()), b.log
    twice = b.fmu.getFMUstate()
    b.fmu.freeFMUstate(twice)
    b.fmu.freeFMUstate(twice)
    assert b.status_of(b.fmu.getFMUstate) == 4               # noticed at the next state call
    assert any("freed an FMU state twice" in m for m in b.errors()), b.log
    assert b.status_of(b.fmu.doStep, 0.0, 0.01) == 0          # the instance itself is fine
    good = b.fmu.getFMUstate()                                # and states work as before
    b.fmu.doStep(0.01, 0.01)
    b.fmu.setFMUstate(good)
    b.fmu.freeFMUstate(good)
    b.close()
