"""What a Dask worker needs to run a study's cases, checked on every worker before any case is sent.

A worker runs the cases with this package's master (:class:`~cosim.apps.study.runner.CaseRunner`)
on the FMUs that travel with the study: it needs this package, at the submitter's version (the
master's code makes the rows), and the package's install requirements (``pyproject.toml``'s
``dependencies``: numpy, scipy, fmpy, pythonfmu, dask, ...).  :func:`check_workers` runs
:func:`probe` on every worker with ``client.run`` and refuses the study, naming each worker that
falls short and what it lacks, before anything is submitted.

:func:`probe` runs on workers that may lack everything but Python and Dask, so it is sent by value
(cloudpickle's ``register_pickle_by_value``: a worker without this package can still unpickle it)
and this module imports nothing but the standard library at module level.
"""
from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

DISTRIBUTION = "pounding-cosim"   # the package's distribution name (pyproject.toml [project] name)
CASE_MODULE = "cosim.apps.study.runner"   # what a worker imports to run a case


def worker_requirements() -> list[str]:
    """Distribution names every worker must have installed: the package's install requirements
    (without extras), read from its installed metadata, or from ``pyproject.toml`` in a source
    tree that was never installed."""
    import importlib.metadata

    try:
        requires = importlib.metadata.requires(DISTRIBUTION) or []
    except importlib.metadata.PackageNotFoundError:
        import tomllib

        pyproject = Path(__file__).resolve().parents[3] / "pyproject.toml"
        requires = tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]["dependencies"]
    names = []
    for requirement in requires:
        if re.search(r";.*\bextra\s*==", requirement):   # test and bench extras: not for workers
            continue
        names.append(re.match(r"[A-Za-z0-9._-]+", requirement).group(0))
    return names


def probe(requirements: Sequence[str], module: str = "cosim", case_module: str = CASE_MODULE,
          dask_worker=None) -> dict[str, Any]:
    """Runs ON A WORKER (sent by value): the worker's name and Python, the installed versions of
    ``requirements``, the missing ones, and whether this package and its case runner import."""
    import importlib
    import importlib.metadata
    import os
    import platform
    import socket
    import sys as _sys

    report: dict[str, Any] = dict(name=str(getattr(dask_worker, "name", "")), host=socket.gethostname(), pid=os.getpid(), python=platform.python_version(),
                                  executable=_sys.executable, versions={}, missing=[], package_version=None,
                                  import_error=None)
    for name in requirements:
        try:
            report["versions"][name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            report["missing"].append(name)
    try:
        report["package_version"] = importlib.import_module(module).__version__
        importlib.import_module(case_module)
    except Exception as exc:  # noqa: BLE001 - whatever stops the import is what the user must fix
        report["import_error"] = f"{type(exc).__name__}: {exc}"
    return report


@dataclass
class WorkerEnvironment:
    """One worker's answer to :func:`probe` (or the reason it could not answer)."""

    address: str
    report: dict[str, Any] | None
    failure: str | None = None       # the probe itself failed (e.g. another Python version)

    def problems(self, package_version: str) -> list[str]:
        """What stops this worker from running the submitter's cases (empty: nothing)."""
        if self.report is None:
            return [f"cannot run the environment check ({self.failure})"]
        r = self.report
        out = []
        if r["missing"]:
            out.append("missing " + ", ".join(r["missing"]))
        if r["package_version"] is None:
            out.append(f"{DISTRIBUTION} is not installed ({r['import_error']})")
        elif r["import_error"] is not None:
            if not r["missing"]:   # else the first missing requirement is the reason
                out.append(f"cannot import the case runner {CASE_MODULE} ({r['import_error']})")
        elif r["package_version"] != package_version:
            out.append(f"{DISTRIBUTION} {r['package_version']}, the submitter has {package_version} "
                       f"(the master on the worker computes the rows: install the same version)")
        return out

    def label(self) -> str:
        if self.report is None:
            return self.address
        r = self.report
        return f"{self.address} (name {r['name']}, host {r['host']}, pid {r['pid']}, python {r['executable']})"


def worker_environments(client, workers: Sequence[str] | None = None) -> list[WorkerEnvironment]:
    """Run :func:`probe` on the workers (all by default) and collect their answers."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])   # idempotent
    answers = client.run(probe, worker_requirements(), workers=list(workers) if workers is not None else None,
                         on_error="return")
    out = []
    for address, answer in sorted(answers.items()):
        if isinstance(answer, BaseException):
            out.append(WorkerEnvironment(address, None, f"{type(answer).__name__}: {answer}"))
        else:
            out.append(WorkerEnvironment(address, answer))
    return out


def unfit(environments: Sequence[WorkerEnvironment], package_version: str) -> dict[str, str]:
    """``{worker label: its problems}`` of the workers that cannot run the cases."""
    return {env.label(): "; ".join(p) for env in environments if (p := env.problems(package_version))}


def refusal(bad: Mapping[str, str], total: int) -> str:
    """The one-line message naming every worker that cannot run the cases."""
    return (f"{len(bad)} of {total} Dask workers cannot run this study's cases (nothing was sent to any "
            f"worker): " + " | ".join(f"worker {label}: {problems}" for label, problems in bad.items()))
