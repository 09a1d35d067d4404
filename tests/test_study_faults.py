"""Parameter studies against a careless or unlucky user (issue 14's study items).

* two studies writing one folder: the second is refused at once, naming the first (pid, host,
  start); a lock left by a killed study is taken over;
* an unbounded study (a range of 100 million values) is refused in well under 5 s with the
  limit stated, ``--max-cases`` raises the limit on purpose, ``--dry-run`` prints the cases;
* Ctrl-C (SIGINT to the whole process group, as a terminal sends it): "interrupted", exit 130,
  no traceback, the finished rows kept and no process left;
* ``--resume --retry-failed`` runs the failed cases again, and only them and the missing ones;
* the output folder: a file, or a folder holding someone else's files, is refused untouched.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cosim.apps.study import MAX_CASES, StudyError, StudyLock, load_study, read_results, run_study
from cosim.cli import main as cli_main
from cosim.master.scene import Override
from study_helpers import SMALL, local_client

SLOW = """
name = "slow"
scene = "default"
[set]
stop_time = 4.0          # s: a few tenths of a second per case, so that a study lasts a few seconds
[vary]
"pounding.gap" = { start = 0.0, stop = 0.03, num = 16 }
"""

FAIL = """
name = "fail"
scene = "default"
[set]
stop_time = 0.5
[vary]
"pounding.gap" = [0.1, 0.0]
"left.x0[3]" = [0.0, 0.05]   # gap 0 with the left roof displaced 5 cm: overlapping at t = 0, failed
"""

TIMEOUT_S = 120   # bound on every study process of this module (they take seconds)


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def command(study: Path, out: Path, fmu_dir: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "cosim.cli", "study", str(study), "--out", str(out), "--fmu-dir", str(fmu_dir),
            "--no-progress", *extra]


@pytest.fixture
def processes():
    """Processes a test starts: their process groups are killed at the end, pass or fail."""
    started: list[subprocess.Popen] = []
    yield started
    for p in started:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait(10)


def start(argv: list[str], cwd: Path, processes: list) -> subprocess.Popen:
    p = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    processes.append(p)
    return p


def wait_for(condition, what: str, process: subprocess.Popen | None = None, timeout: float = TIMEOUT_S) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        if process is not None and process.poll() is not None:
            pytest.fail(f"the study ended before {what}: {process.communicate()}")
        time.sleep(0.02)
    pytest.fail(f"no {what} within {timeout} s")


def rows_in(csv: Path) -> int:
    return csv.read_text().count("\n") - 1 if csv.exists() else 0


@pytest.fixture(scope="module")
def client():
    yield from local_client(n_workers=1, silence_logs=50)


# -- one writer per folder -------------------------------------------------------------------------
def test_a_second_writer_is_refused_naming_the_first(tmp_path, fmu_dir, processes):
    """Two `--resume` on one folder (the attack: 70 rows, 30 duplicates): while the first writes,
    the second is refused with exit 2, naming the first's pid, host and start; the first ends
    with every case exactly once."""
    study = write(tmp_path / "slow.toml", SLOW)
    out = tmp_path / "out"
    first = start(command(study, out, fmu_dir, "--workers", "1", "--resume"), tmp_path, processes)
    wait_for(lambda: rows_in(out / "results.csv") >= 2, "2 rows", first)
    # the first study, its Dask worker with it, held still (SIGSTOP to its process group) while
    # the second starts: it still writes then whatever the load (with the suite on two workers,
    # the second's start and imports once took longer than the first's 14 remaining cases)
    os.killpg(first.pid, signal.SIGSTOP)
    try:
        t0 = time.monotonic()
        second = subprocess.run(command(study, out, fmu_dir, "--workers", "1", "--resume"), cwd=tmp_path,
                                capture_output=True, text=True, timeout=TIMEOUT_S)
        refused_s = time.monotonic() - t0
        assert first.poll() is None   # refused while the first was still writing
    finally:
        os.killpg(first.pid, signal.SIGCONT)
    assert second.returncode == 2, second.stderr
    assert "another study is writing here" in second.stderr and f"pid {first.pid} on host {os.uname().nodename}" \
        in second.stderr and " since 20" in second.stderr, second.stderr
    assert "Traceback" not in second.stderr and len(second.stderr.strip().splitlines()) == 1
    assert refused_s < 30   # the interpreter's start and imports; the lock is taken before anything runs
    assert first.wait(TIMEOUT_S) == 0, first.communicate()
    _, rows = read_results(out / "results.csv")
    assert len(rows) == 16 and len({r["case_id"] for r in rows}) == 16
    assert not (out / "study.lock").exists()


def test_lock_in_one_process_and_a_stale_lock_is_taken_over(tmp_path, fmu_dir, client):
    """Two locks of one folder in one process conflict too (flock is per open file); the lock
    file of a study killed with SIGKILL names a dead process, and the next study takes it over
    and says so."""
    folder = tmp_path / "out"
    folder.mkdir()
    with StudyLock(folder):
        with pytest.raises(StudyError, match=rf"another study is writing here \(pid {os.getpid()} on host"):
            StudyLock(folder).acquire()
    assert not (folder / "study.lock").exists()

    holder = subprocess.Popen([sys.executable, "-c", "import sys, time\nfrom cosim.apps.study.lock import StudyLock\n"
                               f"StudyLock({str(folder)!r}).acquire(); print('locked', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(StudyError, match=f"pid {holder.pid} "):
            run_study(write(tmp_path / "fail.toml", FAIL), folder, client=client, fmu_dir=fmu_dir, progress=False)
    finally:
        holder.kill()
        holder.wait(10)
    assert (folder / "study.lock").exists()   # left behind by the killed holder
    result = run_study(tmp_path / "fail.toml", folder, client=client, fmu_dir=fmu_dir, progress=False)
    assert result.ran == 4 and result.stale_lock["pid"] == holder.pid
    assert not (folder / "study.lock").exists()


# -- bounded work ----------------------------------------------------------------------------------
@pytest.mark.exclusive   # asserts a wall time: no other test of the suite beside it (tests/conftest.py)
def test_an_unbounded_study_is_refused_at_once(tmp_path, fmu_dir, capsys):
    """num = 100000000 under --dry-run (the attack: MemoryError after 105 s): exit 2 in well under
    5 s, naming the file, line, value and the limit; two axes whose product is beyond the limit
    likewise.  --max-cases raises the limit on purpose."""
    huge = write(tmp_path / "huge.toml", 'name = "huge"\nscene = "default"\n[vary]\n'
                                         '"pounding.gap" = { start = 0.0, stop = 0.2, num = 100000000 }\n')
    t0 = time.monotonic()
    assert cli_main(["study", str(huge), "--dry-run", "--fmu-dir", str(fmu_dir)]) == 2
    assert time.monotonic() - t0 < 5
    err = capsys.readouterr().err
    assert f"huge.toml, line 4: [vary] pounding.gap: num = 100000000 values, more than the {MAX_CASES} cases" in err
    assert "--max-cases" in err

    product = write(tmp_path / "product.toml", 'name = "p"\nscene = "default"\n[vary]\n'
                                               '"pounding.gap" = { start = 0.0, stop = 0.2, num = 5000 }\n'
                                               '"pounding.CR" = { start = 0.1, stop = 0.9, num = 5000 }\n')
    t0 = time.monotonic()
    with pytest.raises(StudyError, match=f"5000 x 5000 = 25000000 cases, more than the {MAX_CASES}"):
        load_study(product)
    assert time.monotonic() - t0 < 5

    small = write(tmp_path / "small.toml", 'name = "s"\nscene = "default"\n[vary]\n'
                                           '"pounding.gap" = [0.0, 0.01, 0.02]\n"pounding.CR" = [0.5, 0.7]\n')
    assert cli_main(["study", str(small), "--dry-run", "--max-cases", "5", "--fmu-dir", str(fmu_dir)]) == 2
    assert "3 x 2 = 6 cases, more than the 5" in capsys.readouterr().err
    assert cli_main(["study", str(small), "--dry-run", "--max-cases", "6", "--fmu-dir", str(fmu_dir)]) == 0
    lines = capsys.readouterr().out.splitlines()
    cases = load_study(small).cases()
    assert lines[0].startswith("s: 6 cases of scene") and lines[1].split() == ["case", "case_id", "values"]
    assert [line.split() for line in lines[2:]] == [
        [str(c.index), c.id, f"pounding.gap={c.values['pounding.gap']!r}", f"pounding.CR={c.values['pounding.CR']!r}"]
        for c in cases]
    assert not (tmp_path / "out").exists() and not Path("out/studies/s").exists()   # a dry run writes nothing


# -- Ctrl-C ------------------------------------------------------------------------------------------
def as_a_terminal_starts_it(argv: list[str]) -> list[str]:
    """``argv`` run with SIGINT at its default disposition, as a terminal's foreground job has it.

    A test runner started in the background by a script (``pytest ... &``: the shell makes such
    jobs ignore SIGINT) would pass the ignored SIGINT on to the study (an ignored signal stays
    ignored across ``exec``), which then rightly ignores a Ctrl-C: exit 0 after every case.
    """
    reset = "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); os.execv(sys.argv[1], sys.argv[1:])"
    return [sys.executable, "-c", reset, *argv]


def test_ctrl_c_ends_the_study_with_130_and_keeps_the_rows(tmp_path, fmu_dir, processes, client):
    """SIGINT to the study's whole process group (the local cluster's workers included, as a
    terminal's Ctrl-C): one line "interrupted...", exit 130, no traceback from the study or its
    workers, the rows written kept and no row written after the one in progress, no process of
    the group left; --resume completes it."""
    study = write(tmp_path / "slow.toml", SLOW)
    for attempt in range(3):
        out = tmp_path / f"out{attempt}"
        p = start(as_a_terminal_starts_it(command(study, out, fmu_dir, "--workers", "2")), tmp_path, processes)
        wait_for(lambda out=out: rows_in(out / "results.csv") >= 3, "3 rows", p)
        os.killpg(p.pid, signal.SIGINT)
        at_signal = rows_in(out / "results.csv")   # the signal is pending in the study once killpg returns
        stdout, err = p.communicate(timeout=TIMEOUT_S)
        if at_signal < 16:
            break
        # every case had finished before the signal (a loaded machine held this process back
        # while the study ran 13 cases): it may end either way, and says nothing about Ctrl-C
        assert p.returncode in (0, 130), (stdout, err)
    else:
        pytest.fail("the study finished every case before the signal, 3 times")
    assert p.returncode == 130, (at_signal, stdout, err)
    assert err.strip() == "interrupted: the finished cases are in the results; complete them with --resume"
    _, rows = read_results(out / "results.csv")
    # the study's main thread writes the rows one at a time: at most the row being written when
    # the signal came is added after it
    assert 3 <= len(rows) <= at_signal + 1 and len({r["case_id"] for r in rows}) == len(rows)
    assert not (out / "study.lock").exists() and (out / "results.parquet").exists()

    def group_gone() -> bool:
        try:
            os.killpg(p.pid, 0)
        except ProcessLookupError:
            return True
        return False

    wait_for(group_gone, "end of every process of the study's group", timeout=30)
    result = run_study(study, out, client=client, fmu_dir=fmu_dir, resume=True, progress=False)
    assert result.skipped == len(rows) and result.ran == 16 - len(rows)


def test_ctrl_c_while_the_fmus_validate_the_study_waits_for_them(tmp_path, catalog):
    """SIGINT while validate_study runs the FMUs in this process: the FMU calls are not disturbed
    (a KeyboardInterrupt inside one would come back as "the FMU refused it"), and the interrupt
    is raised once they are over."""
    import threading

    from cosim.apps.study.cluster import ctrl_c_deferred
    from cosim.apps.study.runner import validate_study

    study = load_study(write(tmp_path / "slow.toml", SLOW))
    timer = threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT))
    validated = []
    # A pytest started as a background job inherits SIGINT ignored, and ctrl_c_deferred rightly
    # leaves an ignored SIGINT ignored: give this process a terminal's default for the test.
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with ctrl_c_deferred():
                timer.start()
                validated.append(validate_study(study, catalog))   # 16 values on the FMUs: longer than 0.05 s
                timer.join()   # the signal has arrived inside the block
        assert validated == [["left", "right"]]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler   # restored
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, inherited)


# -- --retry-failed ----------------------------------------------------------------------------------
def test_retry_failed_reruns_the_failed_and_the_missing_cases_only(tmp_path, fmu_dir, client):
    """A study with one failed case: --resume runs nothing; --resume --retry-failed runs that case
    (and a case whose row was removed) and nothing else; the ok rows stay byte for byte, each case
    has exactly one row."""
    study = write(tmp_path / "fail.toml", FAIL)
    out = tmp_path / "out"
    first = run_study(study, out, client=client, fmu_dir=fmu_dir, progress=False)
    assert (first.ran, first.failed) == (4, 1)
    again = run_study(study, out, client=client, fmu_dir=fmu_dir, resume=True, progress=False)
    assert (again.ran, again.skipped) == (0, 4)   # --resume alone never retries

    lines = (out / "results.csv").read_text().splitlines(keepends=True)
    failed_line = next(line for line in lines[1:] if ",failed," in line)
    ok_lines = [line for line in lines[1:] if line != failed_line]
    removed = ok_lines.pop()   # a missing case: its row removed
    (out / "results.csv").write_text("".join([lines[0], *ok_lines, failed_line]))

    retry = run_study(study, out, client=client, fmu_dir=fmu_dir, resume=True, retry_failed=True, progress=False)
    assert (retry.retried, retry.ran, retry.skipped, retry.failed) == (1, 2, 2, 1)
    assert {r["case_id"] for r in retry.rows} == {removed.split(",")[0], failed_line.split(",")[0]}
    after = (out / "results.csv").read_text().splitlines(keepends=True)
    assert after[:3] == [lines[0], *ok_lines]   # the ok rows kept byte for byte, the failed row replaced
    _, rows = read_results(out / "results.csv")
    assert len(rows) == 4 and len({r["case_id"] for r in rows}) == 4
    assert sum(r["status"] == "failed" for r in rows) == 1   # the case fails again: it is deterministic


# -- the output folder -------------------------------------------------------------------------------
def test_output_folder_of_someone_else_is_refused_untouched(tmp_path, fmu_dir, capsys):
    """--out naming a file, or a folder with a file no study wrote: exit 2 before anything runs,
    the file and folder untouched.  A study refused after it claimed a new nested folder leaves
    no folder behind."""
    study = write(tmp_path / "fail.toml", FAIL)
    a_file = write(tmp_path / "notes.txt", "mine\n")
    assert cli_main(["study", str(study), "--out", str(a_file), "--fmu-dir", str(fmu_dir)]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err and a_file.read_text() == "mine\n"

    nested = tmp_path / "new" / "deeper" / "out"   # a study refused after claiming its folder: no debris
    assert cli_main(["study", str(study), "--out", str(nested), "--fmu-dir", str(fmu_dir), "--max-cases", "3"]) == 2
    assert "more than the 3" in capsys.readouterr().err and not (tmp_path / "new").exists()
    assert cli_main(["study", str(study), "--out", str(nested), "--fmu-dir", str(fmu_dir),
                     "--scheduler", "tcp://127.0.0.1:9"]) == 2   # claimed, validated, then no scheduler
    assert "cannot reach the Dask scheduler" in capsys.readouterr().err and not (tmp_path / "new").exists()

    folder = tmp_path / "mine"
    folder.mkdir()
    write(folder / "thesis.tex", "mine\n")
    assert cli_main(["study", str(study), "--out", str(folder), "--fmu-dir", str(fmu_dir)]) == 2
    assert "holds files that no study wrote (thesis.tex)" in capsys.readouterr().err
    assert [p.name for p in folder.iterdir()] == ["thesis.tex"] and (folder / "thesis.tex").read_text() == "mine\n"


def test_a_workers_teardown_never_frees_the_fmus_under_a_running_case(fmu_dir, monkeypatch):
    """A Dask worker tears its plugin down (``CaseRunner.close``) from its event-loop thread while
    a cancelled case may still step the FMUs in its task thread: freeing them then corrupted the
    heap on a study's Ctrl-C.  close waits for the case (here: gives up after its wait and frees
    nothing), and a close after the case frees everything."""
    import threading

    from cosim.apps.study import runner as runner_module

    inside, release = threading.Event(), threading.Event()
    real_simulate = runner_module.simulate

    def held_simulate(system, **options):
        inside.set()                        # the case is stepping its FMUs now
        assert release.wait(30.0)
        return real_simulate(system, **options)

    monkeypatch.setattr(runner_module, "simulate", held_simulate)
    runner = runner_module.CaseRunner(fmu_dir)
    rows = []
    case = threading.Thread(target=lambda: rows.append(runner.run(*_free_vibration_case())))
    case.start()
    try:
        assert inside.wait(60.0)
        assert runner.close(wait_s=0.2) is False      # a case runs: nothing freed
        assert runner.system is not None
    finally:
        release.set()
        case.join(60.0)
    assert rows and rows[0]["status"] == "ok", rows
    assert runner.close(wait_s=0.2) is True
    assert runner.system is None


def _free_vibration_case(tmp_path=None):
    """``(scene_raw, overrides)`` of a small study's scene (the default scene), its first case
    shortened to 0.3 s, read as a study reads it."""
    import tempfile

    folder = Path(tempfile.mkdtemp())
    study = load_study(write(folder / "small.toml", SMALL))
    return study.scene_raw, list(study.fixed) + [Override.of("stop_time", 0.3)]
