"""A study's result files: ``results.csv`` (appended as cases finish), ``results.parquet``,
``study.json`` (what the rows depend on), and the columns of a row.

The CSV is flushed and synced after every row, so that a killed study loses nothing written;
``--resume`` reopens it (a torn last line is dropped) and skips the cases already in it.
"""
from __future__ import annotations

import csv
import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .lock import LOCK_FILE, StudyLock
from .spec import Study, StudyError

STATUSES = ("ok", "failed", "unstable")
STRING_COLUMNS = ("case_id", "status", "error", "worker")  # never read back as numbers

# Summary columns of every row, in order (per-building columns are inserted after them).
CASE_COLUMNS = ("case_id", "case")
SUMMARY_COLUMNS = ("status", "error", "peak_force_N", "impacts", "dissipated_energy_J", "max_penetration_m",
                   "peak_impact_velocity_m_s", "first_impact_s")
BUILDING_COLUMNS = ("peak_displacement_m", "peak_drift_m", "peak_base_shear_N", "peak_ductility", "residual_drift_m",
                    "hysteretic_energy_J")
TAIL_COLUMNS = ("energy_input_J", "energy_residual_relative", "stop_time_s", "communication_steps", "rollbacks",
                "wall_time_s", "case_time_s", "worker")


def columns_for(study: Study, buildings: Sequence[str]) -> list[str]:
    """The CSV header: identity, varied variables, summary, per-building peaks, costs."""
    return (list(CASE_COLUMNS) + study.variables + list(SUMMARY_COLUMNS)
            + [f"{b}.{c}" for b in buildings for c in BUILDING_COLUMNS] + list(TAIL_COLUMNS))


def one_line(text: str) -> str:
    return " | ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _infer(values: list[str], text: bool = False):
    """Typed column from CSV text: int, float, bool or str (empty = missing)."""
    present = [v for v in values if v != ""]
    for convert in () if text else (int, float):
        try:
            [convert(v) for v in present]   # every present value converts, or try the next type
        except ValueError:
            continue
        return [None if v == "" else convert(v) for v in values]
    if present and all(v in ("True", "False") for v in present):
        return [None if v == "" else v == "True" for v in values]
    return [None if v == "" else v for v in values]


def read_results(csv_path: str | Path) -> tuple[list[str], list[dict[str, Any]]]:
    """``(header, rows)`` of a study's CSV, typed (int, float, bool, str, None), in file order.

    A last line without its newline (the study was killed while writing it)
    is ignored.
    """
    text = Path(csv_path).read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
    lines = list(csv.reader(text.splitlines()))
    if not lines:
        return [], []
    header, body = lines[0], lines[1:]
    for number, line in enumerate(body, 2):
        if len(line) != len(header):
            raise StudyError(f"{csv_path}, line {number}: {len(line)} fields, the header has {len(header)}")
    columns = {name: _infer([line[j] for line in body], name in STRING_COLUMNS) for j, name in enumerate(header)}
    rows = [{name: columns[name][i] for name in header} for i in range(len(body))]
    return header, rows


def write_parquet(csv_path: Path, parquet_path: Path) -> Path:
    """Regenerate the Parquet table from the CSV (sorted by case number), written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    header, rows = read_results(csv_path)
    rows.sort(key=lambda r: r.get("case") if r.get("case") is not None else -1)
    table = pa.table({name: pa.array([r[name] for r in rows]) for name in header}) if header else pa.table({})
    tmp = parquet_path.with_name(parquet_path.name + ".partial")
    pq.write_table(table, tmp)
    os.replace(tmp, parquet_path)
    return parquet_path


def _cell(value: Any) -> str:
    """CSV text of one value: floats exactly (repr round-trips), one line per row."""
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return one_line(value)


class _RowWriter:
    """Appends one CSV row per finished case, flushed and synced, so a kill loses nothing written."""

    def __init__(self, path: Path, header: list[str]):
        self.header = header
        new = not path.exists() or path.stat().st_size == 0
        self.file = open(path, "a", newline="", encoding="utf-8")
        self.writer = csv.DictWriter(self.file, fieldnames=header, extrasaction="ignore", lineterminator="\n")
        if new:
            self.writer.writeheader()
            self._sync()

    def write(self, row: Mapping[str, Any]) -> None:
        self.writer.writerow({k: _cell(v) for k, v in row.items()})
        self._sync()

    def _sync(self) -> None:
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self) -> None:
        self.file.close()


class FolderClaim:
    """A study folder claimed by :func:`claim_folder`: locked while the study writes.  ``written``:
    set once the study wrote into it (until then a folder the claim created is removed again)."""

    def __init__(self, folder: Path, created: list[Path], lock: StudyLock):
        self.folder, self.created, self.lock, self.written = folder, created, lock, False

    def __enter__(self) -> "FolderClaim":
        return self

    def __exit__(self, *exc) -> None:
        self.lock.release()
        if not self.written:
            for path in self.created:   # deepest first: the folder, then the parents it needed
                try:
                    path.rmdir()   # only if still empty: nothing of anyone's is removed
                except OSError:
                    break


def claim_folder(folder: Path) -> FolderClaim:
    """Check that ``folder`` may hold a study's results, create it if new, and lock it.

    Allowed: a new path, an empty folder, or a study's own folder (it holds ``study.json`` or the
    lock file); a regular file or a folder with anything else is refused, so that nothing the
    study did not write is mixed with its results.  A second study writing to the folder is
    refused naming the holder (:class:`~cosim.apps.study.lock.StudyLock`).
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise StudyError(f"--out {folder} is a file, not a folder: choose a new folder for the study's results")
    if folder.exists():
        entries = sorted(p.name for p in folder.iterdir())
        if entries and "study.json" not in entries and LOCK_FILE not in entries:
            raise StudyError(f"--out {folder} holds files that no study wrote ({', '.join(entries[:3])}"
                             f"{', ...' if len(entries) > 3 else ''}): choose a new or empty folder")
    created = []   # the folders this claim makes, deepest first
    path = folder
    while not os.path.lexists(path):
        created.append(path)
        path = path.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StudyError(f"--out {folder}: cannot create the folder ({exc.strerror})") from None
    lock = StudyLock(folder)
    try:
        lock.acquire()
    except BaseException:
        FolderClaim(folder, created, lock).__exit__(None, None, None)
        raise
    return FolderClaim(folder, created, lock)


def recorded_rows(folder: Path, fingerprint: dict, header: list[str], resume: bool) -> list[dict[str, Any]]:
    """The rows already in a claimed folder (none in a new one), after the checks of ``--resume``:
    without it a results file is refused; with it the study must be the same (``study.json``)
    and have the same columns.  A last line torn by a kill is dropped."""
    csv_path, meta_path = folder / "results.csv", folder / "study.json"
    if not (csv_path.exists() and csv_path.stat().st_size > 0):
        return []
    if not resume:
        raise StudyError(f"{csv_path} already holds results: use --resume to complete it, "
                         f"or --out for a new folder")
    fingerprint = json.loads(json.dumps(fingerprint))  # compare as stored (tuples -> lists)
    if meta_path.exists():
        saved = json.loads(meta_path.read_text())
        changed = [k for k in fingerprint if saved.get(k) != fingerprint[k]]
        if changed:
            raise StudyError(f"--resume {folder}: the study changed since its rows were computed "
                             f"({', '.join(changed)} differ; new values of the varied variables are fine); "
                             f"use --out for a new folder")
    text = csv_path.read_text(encoding="utf-8")
    if not text.endswith("\n"):  # killed while writing a row: drop the torn line
        with open(csv_path, "r+", encoding="utf-8") as f:
            f.truncate(len(text[:text.rfind("\n") + 1].encode("utf-8")))
    saved_header, rows = read_results(csv_path)
    if saved_header != header:
        raise StudyError(f"--resume {csv_path}: its columns differ from this study's; use --out for a new folder")
    return rows


def start_results(folder: Path, fingerprint: dict, rows: Sequence[Mapping[str, Any]], retry_failed: bool) -> int:
    """Write ``study.json`` into a folder without rows; with ``retry_failed``, drop the failed and
    unstable rows (their cases run again).  Returns the number of rows dropped."""
    if rows:
        return _drop_failed_rows(folder / "results.csv", rows) if retry_failed else 0
    meta_path = folder / "study.json"
    tmp = meta_path.with_name("study.json.partial")
    tmp.write_text(json.dumps(fingerprint, indent=2) + "\n")
    os.replace(tmp, meta_path)
    return 0


def _drop_failed_rows(csv_path: Path, rows: Sequence[Mapping[str, Any]]) -> int:
    """Rewrite the CSV without its failed and unstable rows (each row is one line: :func:`_cell`);
    the ok rows' lines are kept byte for byte.  Atomic: a kill leaves the old file or the new."""
    lines = csv_path.read_text(encoding="utf-8").splitlines(keepends=True)
    keep = [lines[0]] + [line for line, row in zip(lines[1:], rows) if row["status"] == "ok"]
    dropped = len(lines) - len(keep)
    if dropped:
        tmp = csv_path.with_name(csv_path.name + ".partial")
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.writelines(keep)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, csv_path)
    return dropped
