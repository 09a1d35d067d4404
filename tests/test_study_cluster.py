"""Parameter studies on a real Dask cluster: ``dask scheduler`` and ``dask worker`` processes on 127.0.0.1.

Each process of the cluster is its own process group, each worker runs in its own working
directory with its own temporary folder (:class:`cosim.apps.study.loopback.LoopbackCluster`),
and the study is submitted by ``pounding-cosim study ... --scheduler tcp://127.0.0.1:PORT`` in
another process, as a user would.  What is checked:

* the rows of the cluster are those of the LocalCluster and of each case run alone;
* faults: a worker lost mid-study (its case runs elsewhere, no row lost or duplicated), a
  worker joining mid-study (it takes cases), the scheduler lost (exit 1, clear message, rows
  kept; ``--resume`` on a new scheduler completes them), workers whose environment lacks the
  package, a requirement or the right version (named, and nothing sent to any worker).

Every process started is stopped by its process group in the fixtures' finalizers, also when a
test fails; every wait is bounded.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

import pytest

from cosim.apps.study import case_row, load_study, read_results, run_study
from cosim.apps.study.loopback import LoopbackCluster
from study_helpers import SMALL

ROOT = Path(__file__).resolve().parents[1]
MACHINE_COLUMNS = ("wall_time_s", "case_time_s", "worker")   # the only columns that depend on where a case ran
STUDY_TIMEOUT_S = 120   # a study of these sizes takes seconds; a hang fails the test instead of the session

# 12 cases for the faults: the faults are timed by freezing a worker (SIGSTOP) after 3 rows, so
# that cases remain whatever the machine's speed; each case a few tenths of a second
N_FAULTS = 12
FAULTS = f"""
name = "faults"
scene = "default"
[set]
stop_time = 3.0
[vary]
"pounding.gap" = {{ start = 0.0, stop = 0.03, num = {N_FAULTS} }}
"""


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def study_command(study: Path, out: Path, fmu_dir: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "cosim.cli", "study", str(study), "--out", str(out), "--fmu-dir", str(fmu_dir),
            "--no-progress", *extra]


def submit(study: Path, out: Path, fmu_dir: Path, cwd: Path, *extra: str) -> subprocess.Popen:
    """The study as a user starts it, in its own process group (stopped by the finalizer)."""
    return subprocess.Popen(study_command(study, out, fmu_dir, *extra), cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


@pytest.fixture
def processes():
    """Processes a test starts besides the cluster's: killed (process group) at the end, pass or fail."""
    started: list[subprocess.Popen] = []
    yield started
    for p in started:
        if p.poll() is None:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait(10)


def wait_rows(csv: Path, n: int, process: subprocess.Popen, timeout: float = STUDY_TIMEOUT_S) -> int:
    """Wait until ``csv`` holds ``n`` rows (bounded); fail if the study ended first."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        rows = csv.read_text().count("\n") - 1 if csv.exists() else 0
        if rows >= n:
            return rows
        if process.poll() is not None:
            pytest.fail(f"the study ended before {n} rows: {process.communicate()}")
        time.sleep(0.02)
    pytest.fail(f"no {n} rows in {csv} within {timeout} s")


def alone(study, fmu_dir) -> dict[str, dict]:
    """Each case of ``study`` run alone (run_scene in this process): {case_id: row columns}."""
    from cosim.master.runner import run_scene
    from cosim.master.system import Catalog

    rows = {}
    with Catalog(fmu_dir) as catalog:
        for case in study.cases():
            run = run_scene(study.scene, study.fixed + case.overrides, catalog=catalog, write=False, progress=False)
            rows[case.id] = case_row(run.summary, study.energy_tolerance)
    return rows


def assert_same_rows(rows: list[dict], expected: dict[str, dict], study) -> None:
    """Every case exactly once, and every column that does not depend on the machine equal to ``expected``."""
    assert sorted(r["case_id"] for r in rows) == sorted(c.id for c in study.cases())
    for r in rows:
        for column, value in expected[r["case_id"]].items():
            if column not in MACHINE_COLUMNS:
                value = None if value == "" else value   # an empty text cell reads back as None
                assert r[column] == value, (r["case_id"], column, r[column], value)


@pytest.fixture(scope="module")
def faults_study(tmp_path_factory, fmu_dir):
    """The faults' study file, and each of its cases run alone ({case_id: row})."""
    path = write(tmp_path_factory.mktemp("faults") / "faults.toml", FAULTS)
    return path, alone(load_study(path), fmu_dir)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two workers, each worker in its own folder; stopped at the end of the module."""
    with LoopbackCluster(tmp_path_factory.mktemp("loopback")) as loopback:
        loopback.add_worker("w1", wait=False)
        loopback.add_worker("w2", wait=False)
        loopback.wait_for_workers(["w1", "w2"])
        yield loopback


def test_cluster_rows_equal_local_cluster_and_alone(tmp_path, fmu_dir, cluster, processes):
    """6 cases through --scheduler on two `dask worker` processes: exit 0, both workers took cases,
    and every row equals the LocalCluster run's and the case run alone (exactly: same FMUs, same
    start values; no column but wall times and the worker's name may differ)."""
    from distributed import Client

    study_file = write(tmp_path / "small.toml", SMALL)
    study = load_study(study_file)
    submitter = tmp_path / "submitter"
    submitter.mkdir()
    p = submit(study_file, tmp_path / "cluster", fmu_dir, submitter, "--scheduler", cluster.address)
    processes.append(p)
    out, err = p.communicate(timeout=STUDY_TIMEOUT_S)
    assert p.returncode == 0, err
    assert "6 run now" in out and "on 2 workers" in out
    _, rows = read_results(tmp_path / "cluster" / "results.csv")

    with Client(cluster.address) as client:   # where the workers are: their own folders, not the submitter's
        places = client.run(lambda dask_worker: (dask_worker.name, f"{os.uname().nodename}:{os.getpid()}",
                                                 os.getcwd(), tempfile.gettempdir(), dask_worker.local_directory))
    pids = {}
    for name, pid, cwd, tmp, local in places.values():
        folder = cluster.workers[name].folder
        assert (Path(cwd), Path(tmp)) == (folder, folder / "tmp") and Path(local).is_relative_to(folder)
        assert any(Path(local).glob("cosim-study-*/pounding.fmu"))   # the FMUs travelled with the study
        pids[pid] = name
    assert {pids[r["worker"]] for r in rows} == {"w1", "w2"}   # both workers took cases
    assert not any(submitter.iterdir())   # nothing written where the study was submitted

    local = run_study(study, tmp_path / "local", workers=2, fmu_dir=fmu_dir, progress=False)
    _, local_rows = read_results(local.csv)
    assert_same_rows(local_rows, {r["case_id"]: r for r in rows}, study)
    expected = alone(study, fmu_dir)
    assert_same_rows(rows, expected, study)
    assert sum(r["impacts"] for r in rows) > 0 and all(r["status"] == "ok" for r in rows)


def test_worker_lost_and_worker_joining(tmp_path, fmu_dir, faults_study, processes):
    """One worker starts the study; after 3 rows it hangs (SIGSTOP) with cases assigned, a second
    worker joins and takes cases, then the first is killed (SIGKILL of its process group, a lost
    machine).  The study ends normally: every case exactly once, equal to the case run alone; the
    case the lost worker held (the scheduler's log shows it released from the lost worker) ran
    on the joiner."""
    from distributed import Client

    study_file, expected = faults_study
    study = load_study(study_file)
    out = tmp_path / "out"
    with LoopbackCluster(tmp_path / "cluster") as loopback:
        loopback.add_worker("first")
        p = submit(study_file, out, fmu_dir, tmp_path, "--scheduler", loopback.address)
        processes.append(p)
        wait_rows(out / "results.csv", 3, p)
        loopback.workers["first"].freeze()
        loopback.add_worker("joiner")       # returns once the scheduler lists it: the study is still running
        assert p.poll() is None
        with Client(loopback.address) as client:
            joiner_pid = next(f"{os.uname().nodename}:{pid}" for pid in
                              client.run(os.getpid, workers=[a for a, w in client.scheduler_info()["workers"].items()
                                                              if w["name"] == "joiner"]).values())
            loopback.kill_worker("first")
            stdout, err = p.communicate(timeout=STUDY_TIMEOUT_S)
            assert p.returncode == 0, err
            released = client.run_on_scheduler(lambda dask_scheduler: [
                t[0] for t in dask_scheduler.transition_log
                if str(t[0]).startswith("cosim-case-") and t[1] == "processing" and t[2] != "memory"])
    _, rows = read_results(out / "results.csv")
    assert_same_rows(rows, expected, study)
    by_worker = {}
    for r in rows:
        by_worker.setdefault(r["worker"], []).append(r["case_id"])
    assert len(by_worker) == 2 and len(by_worker[joiner_pid]) >= 1   # the joiner took cases
    lost = {key.rsplit("-", 1)[1] for key in released}
    assert lost and lost <= set(by_worker[joiner_pid]), (released, by_worker)   # held by the lost worker, rerun


def test_scheduler_lost_then_resume_on_a_new_scheduler(tmp_path, fmu_dir, faults_study, processes):
    """The scheduler is killed mid-study (its worker hangs first, so that cases remain): the study
    ends at once with exit 1, one line naming the scheduler and --resume, no traceback, and the
    rows written are kept.  `--resume` on a new scheduler and worker completes the study: every
    case once, the earlier rows byte for byte, all equal to the cases run alone."""
    study_file, expected = faults_study
    study = load_study(study_file)
    out = tmp_path / "out"
    with LoopbackCluster(tmp_path / "cluster") as loopback:
        loopback.add_worker("a")
        first_address = loopback.address
        p = submit(study_file, out, fmu_dir, tmp_path, "--scheduler", first_address)
        processes.append(p)
        wait_rows(out / "results.csv", 3, p)
        loopback.workers["a"].freeze()
        loopback.kill_scheduler()
        start = time.monotonic()
        stdout, err = p.communicate(timeout=STUDY_TIMEOUT_S)
        ended_s = time.monotonic() - start
        assert p.returncode == 1, err
        assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
        assert f"lost the Dask scheduler at {first_address}" in err and "--resume" in err
        assert ended_s < 30   # at once (a few seconds for the client to give up and close), not a hang
        before = (out / "results.csv").read_text()
        n_before = before.count("\n") - 1
        assert 3 <= n_before < N_FAULTS and not (out / "study.lock").exists()

        loopback.start_scheduler()
        loopback.add_worker("b")
        done = subprocess.run(study_command(study_file, out, fmu_dir, "--resume", "--scheduler", loopback.address),
                              cwd=tmp_path, capture_output=True, text=True, timeout=STUDY_TIMEOUT_S)
        assert done.returncode == 0, done.stderr
        assert f"{n_before} already done, {N_FAULTS - n_before} run now" in done.stdout
    after = (out / "results.csv").read_text()
    assert after.startswith(before)
    _, rows = read_results(out / "results.csv")
    assert_same_rows(rows, expected, study)


def site_packages_without(folder: Path, exclude: tuple[str, ...], fake_version: str | None = None,
                          with_sources: bool = False) -> str:
    """A PYTHONPATH for ``python -S``: this environment's site-packages without the entries whose
    names start with ``exclude`` (symbolic links to the rest).  ``fake_version``: this package's
    metadata at another version (the sources then come from the checkout); ``with_sources``: the
    checkout on the path (the editable install's finder is a .pth file, which ``-S`` skips)."""
    folder.mkdir(parents=True)
    site = Path(sysconfig.get_paths()["purelib"])
    for entry in site.iterdir():
        if not entry.name.startswith(exclude):
            (folder / entry.name).symlink_to(entry)
    if fake_version:
        meta = folder / f"pounding_cosim-{fake_version}.dist-info"
        meta.mkdir()
        (meta / "METADATA").write_text(f"Metadata-Version: 2.1\nName: pounding-cosim\nVersion: {fake_version}\n")
    # the checkout after the folder: its egg-info must not hide the faked metadata
    return os.pathsep.join([str(folder)] + ([str(ROOT)] if fake_version or with_sources else []))


def test_workers_that_cannot_run_the_cases_are_named_before_anything_is_sent(tmp_path, fmu_dir, faults_study,
                                                                            processes):
    """Three workers started from environments (python -S and a PYTHONPATH of this venv's
    site-packages with entries left out) that lack: this package; fmpy and pythonfmu; the
    submitter's package version (0.0.1 installed).  One good worker.  The study is refused with
    exit 2 naming each bad worker and what it lacks (not the good one), before any case or the
    study's plugin reached any worker, and nothing is written.

    Then a worker of the old version joins a running study (the good worker frozen, so that it
    joins mid-study and is offered cases): the study's plugin finds it unfit, the cases offered
    to it go back to the good worker, the study ends with every row from the good worker, and
    the joiner is named in a note."""
    from distributed import Client

    import cosim

    package = ("__editable__", "pounding_cosim")
    with LoopbackCluster(tmp_path / "cluster") as loopback:
        loopback.add_worker("good", wait=False)
        loopback.add_worker("no-package", wait=False, python_flags=["-S"],
                            env={"PYTHONPATH": site_packages_without(tmp_path / "sp1", package)})
        loopback.add_worker("no-fmpy", wait=False, python_flags=["-S"],
                            env={"PYTHONPATH": site_packages_without(tmp_path / "sp2", package + ("fmpy", "pythonfmu"),
                                                                     with_sources=True)})
        loopback.add_worker("old-version", wait=False, python_flags=["-S"],
                            env={"PYTHONPATH": site_packages_without(tmp_path / "sp3", package, fake_version="0.0.1")})
        loopback.wait_for_workers(["good", "no-package", "no-fmpy", "old-version"])
        study_file = write(tmp_path / "small.toml", SMALL)
        p = submit(study_file, tmp_path / "out", fmu_dir, tmp_path, "--scheduler", loopback.address)
        processes.append(p)
        _, err = p.communicate(timeout=STUDY_TIMEOUT_S)
        assert p.returncode == 2, err
        assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
        assert "3 of 4 Dask workers cannot run this study's cases (nothing was sent to any worker)" in err
        parts = {part.split("(name ")[1].split(",")[0]: part for part in err.split(" | ")}
        assert set(parts) == {"no-package", "no-fmpy", "old-version"}
        assert "pounding-cosim is not installed (ModuleNotFoundError: No module named 'cosim')" in parts["no-package"]
        assert "missing fmpy, pythonfmu" in parts["no-fmpy"]
        assert f"pounding-cosim 0.0.1, the submitter has {cosim.__version__}" in parts["old-version"]
        assert not (tmp_path / "out").exists()
        with Client(loopback.address) as client:
            plugins = client.run(lambda dask_worker: [n for n in dask_worker.plugins if n.startswith("cosim-study")])
            assert plugins and not any(plugins.values())   # the study's plugin reached no worker
            tasks = client.run_on_scheduler(lambda dask_scheduler: [str(k) for k in dask_scheduler.tasks])
            assert not [k for k in tasks if k.startswith("cosim-case-")]   # no case was submitted

        for name in ("no-package", "no-fmpy", "old-version"):
            loopback.workers[name].stop()
        study_file, expected = faults_study
        out = tmp_path / "joined"
        p = submit(study_file, out, fmu_dir, tmp_path, "--scheduler", loopback.address)
        processes.append(p)
        wait_rows(out / "results.csv", 3, p)
        loopback.workers["good"].freeze()
        loopback.add_worker("old-joiner", python_flags=["-S"],
                            env={"PYTHONPATH": site_packages_without(tmp_path / "sp4", package, fake_version="0.0.1")})
        with Client(loopback.address) as client:
            deadline = time.monotonic() + STUDY_TIMEOUT_S
            while not client.run_on_scheduler(
                    lambda dask_scheduler: any("-rerouted-" in str(k) for k in dask_scheduler.tasks)):
                assert time.monotonic() < deadline, "no case offered to the joiner came back"
                time.sleep(0.05)
            loopback.workers["good"].thaw()
            stdout, err = p.communicate(timeout=STUDY_TIMEOUT_S)
            assert p.returncode == 0, err
            good = client.run(lambda: f"{os.uname().nodename}:{os.getpid()}",
                              workers=[a for a, w in client.scheduler_info()["workers"].items() if w["name"] == "good"])
        assert "note: a worker that joined cannot run the cases, its cases ran on the others: " in stdout
        assert "(name old-joiner," in stdout and f"pounding-cosim 0.0.1, the submitter has {cosim.__version__}" in stdout
        _, rows = read_results(out / "results.csv")
        assert_same_rows(rows, expected, load_study(study_file))
        assert {r["worker"] for r in rows} == set(good.values())
