"""Where results go: one rule for every output path, folders written complete or not at all, no debris.

**The rule** (:func:`output_target`, for every command that writes a folder: ``run``,
``calibrate``, ``report``, the accuracy study and the study application):

* a path that does not exist, or an empty folder: written;
* a folder this package wrote before (it holds the marker file :data:`MARKER`, and nothing
  but the files that marker lists): replaced only with ``overwrite=True`` (``--overwrite``);
* anything else (a folder with files this package did not write, a regular file, a link, a
  device): refused, whatever ``overwrite`` says.  The program never deletes or replaces
  what it did not create;
* a *default* path (``out/<scene>``: chosen by the program, not by the user) that is taken is
  not refused but numbered: ``out/<scene>-2``, ``out/<scene>-3``, ... (the first one the rule
  allows; the command prints where the results went).  ``--overwrite`` replaces the default
  folder itself when the rule allows it.

A single file (:func:`file_target`, ``--export-ssp FILE.ssp``): a new path, or an existing
regular file with ``overwrite=True``; never a directory, a link or a device.

**Writing** (:func:`written_folder`): the results are written into a hidden sibling,
``.<name>.partial-<pid>-<token>``, created (with the marker, state ``partial``) *before* the
work starts, so that an unwritable path or a full disk is found in a second, not after the
run.  On success the marker is completed (with the list of files) and the sibling renamed to
the final name in one step; on any failure, Ctrl-C included, it is removed.  A process killed
outright (SIGKILL, power loss) leaves its sibling behind: the next write into the same parent
removes every sibling whose marker says it is this package's and whose process, on this host,
no longer runs (:func:`remove_debris`).  A full disk ends with one line (:class:`WriteError`)
and nothing partial.

Names from scenes and studies that become folder names are plain names (:func:`plain_name_problem`).
"""
from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import secrets
import shutil
import socket
import stat
import time
from pathlib import Path
from typing import Iterator

#: the marker file of every folder this package writes (JSON: package, version, kind, state, files)
MARKER = ".pounding-cosim.json"
PACKAGE = "pounding-cosim"
#: hidden siblings this package makes while writing (``.partial``) or replacing (``.old``) a folder
_SIBLING = re.compile(r"^\.(?P<name>.+)\.(?P<what>partial|old)-(?P<pid>\d+)-(?P<token>[0-9a-f]{8})$")
#: default paths are numbered up to this before giving up (a folder with 1000 runs is a mistake)
MAX_NUMBERED = 1000
#: free space kept beyond the estimate (bytes): plots vary, and a filesystem filled to its last
#: block makes every other program on the machine fail too
SPACE_MARGIN = 16 * 2**20
#: longest name a scene or study may give its folder (most filesystems allow 255 bytes; the
#: hidden sibling adds about 30)
MAX_NAME = 100
_NO_SPACE = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


class OutputError(Exception):
    """The output path cannot be used: refused by the rule, not writable, or too little free
    space (bad input: exit 2).  The message is one line naming the path and the remedy."""


class WriteError(OutputError):
    """Writing failed after the work was done (a full disk, an I/O error): nothing partial was
    left (exit 1)."""


# -- names -----------------------------------------------------------------------------------------
def plain_name_problem(name: object) -> str | None:
    """Why ``name`` cannot name an output folder, or None: a plain name is letters, digits,
    ``_ . -``, starts with a letter, digit or ``_`` (so never ``.``, ``..`` or hidden), has no
    path separator and at most :data:`MAX_NAME` characters."""
    if not isinstance(name, str) or not re.fullmatch(r"\w[\w.-]*", name):
        return (f"{name!r} is not a plain name: letters, digits, _ . - only, starting with a letter, digit or _ "
                f"(it names the output folder: no '.', '..', '/' or hidden names)")
    if len(name) > MAX_NAME:
        return f"{name[:20]!r}... has {len(name)} characters; a folder name may have at most {MAX_NAME}"
    return None


# -- markers ---------------------------------------------------------------------------------------
def _version() -> str:
    from . import __version__

    return __version__


def read_marker(folder: Path) -> dict | None:
    """The marker of ``folder`` if it is this package's, else None (absent, unreadable, foreign).
    Keys: ``package``, ``version``, ``kind`` (run, calibration, report, accuracy, study...),
    ``state`` (``partial`` while written, ``complete``), ``pid``, ``host``, ``written`` (UTC), and
    ``files`` (what a complete folder holds)."""
    path = folder / MARKER
    try:
        if not stat.S_ISREG(path.lstat().st_mode) or path.lstat().st_size > 2**20:
            return None
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("package") != PACKAGE:
        return None
    return data


def write_marker(folder: Path, kind: str, state: str, files: list[str] | None = None) -> None:
    """Mark ``folder`` as this package's (atomically).  A writer that fills its folder over time
    (a parameter study) marks it ``complete`` with its ``files`` whenever they are consistent, so
    that the rule lets ``--overwrite`` replace it and nothing else."""
    data = {"package": PACKAGE, "version": _version(), "kind": kind, "state": state, "pid": os.getpid(),
            "host": socket.gethostname(), "written": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if files is not None:
        data["files"] = files
    tmp = folder / f"{MARKER}.tmp"
    tmp.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, folder / MARKER)


def listing(folder: Path) -> list[str]:
    """Every path under ``folder`` relative to it (files and folders, sorted; the marker excluded)."""
    out = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        out += [str(rel / d) for d in dirs] + [str(rel / f) for f in files]
    return sorted(p for p in out if p != MARKER)


def _foreign(folder: Path, marker: dict) -> list[str]:
    """What ``folder`` holds that its marker does not list (files a person added)."""
    listed = set(marker.get("files") or ())
    return [p for p in listing(folder) if p not in listed]


# -- the rule ----------------------------------------------------------------------------------------
def _refusal(path: Path, overwrite: bool) -> str | None:
    """Why the rule refuses to write a folder at ``path``, or None when it may."""
    try:
        st = path.lstat()
    except (FileNotFoundError, NotADirectoryError):   # absent (check_writable says if it can be made)
        return None
    except OSError as exc:
        return f"{path}: cannot be inspected ({exc.strerror})"
    if stat.S_ISLNK(st.st_mode):
        return f"{path} is a symbolic link; give the folder it points to, or another path"
    if not stat.S_ISDIR(st.st_mode):
        kind = "a regular file" if stat.S_ISREG(st.st_mode) else "not a folder"
        return f"{path} is {kind}; results go into a folder: give another path"
    try:
        empty = not any(os.scandir(path))
    except OSError as exc:
        return f"{path}: cannot be read ({exc.strerror})"
    if empty:
        return None
    marker = read_marker(path)
    if marker is None or marker.get("state") != "complete":
        return (f"{path} already exists and holds files this program did not write; it is never replaced: "
                f"give a new or empty folder")
    foreign = _foreign(path, marker)
    if foreign:
        shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
        return (f"{path} holds results of an earlier run and files it did not write ({shown}); it is never "
                f"replaced: give a new or empty folder")
    if not overwrite:
        return (f"{path} holds the results of an earlier run ({marker.get('kind', 'run')}, "
                f"{marker.get('written', 'unknown time')}); add --overwrite to replace them, or give another path")
    return None


def output_target(path: str | Path, *, overwrite: bool = False, default: bool = False) -> Path:
    """Where a folder of results may be written, by the rule of the module docstring.

    ``path``: the requested folder; ``default``: True when the program chose it (then a taken
    path is numbered ``<path>-2``, ``-3``, ... instead of refused).  Returns the absolute path
    to write; raises :class:`OutputError` (one line) when the rule refuses, or when the path
    cannot be created (a parent is a file, a read-only filesystem: :func:`check_writable`).
    """
    path = Path(os.path.abspath(Path(path).expanduser()))   # "." and ".." become the folders they name
    if path == path.parent:
        raise OutputError(f"{path}: the root folder cannot hold results; give a path like out/run1")
    why = _refusal(path, overwrite)
    if why is None:
        check_writable(path)
        return path
    if not default:
        raise OutputError(why)
    for number in range(2, MAX_NUMBERED + 1):
        candidate = path.with_name(f"{path.name}-{number}")
        if _refusal(candidate, overwrite=False) is None:
            check_writable(candidate)
            return candidate
    raise OutputError(f"{path}: {path.name}-2 ... {path.name}-{MAX_NUMBERED} are all taken; clean up "
                      f"{path.parent} or give --out")


def file_target(path: str | Path, *, overwrite: bool = False) -> Path:
    """Where a single output file (an SSP package) may be written: a new path, or an existing
    regular file with ``overwrite``; never a directory, link or device.  Raises :class:`OutputError`."""
    path = Path(os.path.abspath(Path(path).expanduser()))
    try:
        st = path.lstat()
    except (FileNotFoundError, NotADirectoryError):
        st = None
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{path} is a folder; give a file name, e.g. {path / 'scene.ssp'}")
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{path} is not a regular file (a link or a device); give another path")
        if not overwrite:
            raise OutputError(f"{path} already exists; add --overwrite to replace it, or give another path")
    check_writable(path)
    return path


def check_writable(path: Path) -> None:
    """Raise :class:`OutputError` unless ``path`` could be created: its nearest existing ancestor
    must be a folder this process may write into, on a filesystem mounted writable."""
    ancestor = path.parent
    while not os.path.lexists(ancestor):
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputError(f"{path}: {ancestor} is not a folder, so nothing can be written under it")
    if not os.access(ancestor, os.W_OK | os.X_OK):   # EROFS too: access(2) reports a read-only mount
        why = "is on a read-only filesystem" if _read_only(ancestor) else "is not writable by this user"
        raise OutputError(f"{path}: {ancestor} {why}; give another path")


def _read_only(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def check_space(folder: Path, needed: int, what: str) -> None:
    """Raise :class:`OutputError` if the filesystem of ``folder`` has less than ``needed`` bytes
    (plus :data:`SPACE_MARGIN`) free."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return   # no figure to judge by: writing will tell
    if free < needed + SPACE_MARGIN:
        raise OutputError(f"{what} needs about {_size(needed)} but {folder} has {_size(free)} free "
                          f"(keeping {_size(SPACE_MARGIN)} spare); free some space or give another path")


def _size(n: float) -> str:
    for unit in ("bytes", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} PB"


# -- debris ----------------------------------------------------------------------------------------
def _process_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):   # another user's process, or no way to tell: alive
        return True
    return True


def remove_debris(parent: Path) -> list[Path]:
    """Remove what killed runs of this package left in ``parent``: hidden ``.<name>.partial-...``
    and ``.<name>.old-...`` folders whose marker is this package's and whose process, on this
    host, no longer runs.  Nothing else is touched.  Returns the folders removed."""
    removed = []
    host = socket.gethostname()
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return removed
    for entry in entries:
        match = _SIBLING.match(entry.name)
        if not match or not entry.is_dir(follow_symlinks=False):
            continue
        folder = Path(entry.path)
        marker = read_marker(folder)
        if marker is None or marker.get("host") != host:
            continue
        if _process_alive(int(match["pid"])):
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed


# -- writing ---------------------------------------------------------------------------------------
def _make_parents(folder: Path) -> list[Path]:
    """mkdir -p ``folder``; returns the folders it created, deepest first (to undo)."""
    created = []
    current = folder
    while not os.path.lexists(current):
        created.append(current)
        current = current.parent
    for path in reversed(created):
        path.mkdir()
    return created


def _undo_parents(created: list[Path]) -> None:
    for path in created:   # deepest first; only if still empty (someone may have written meanwhile)
        try:
            path.rmdir()
        except OSError:
            break


def _no_space(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno in _NO_SPACE


class PendingFolder:
    """A folder being written: write into :attr:`path` (the hidden sibling); after the ``with``
    block, :attr:`target` is where the results are."""

    def __init__(self, path: Path, target: Path):
        self.path = path
        self.target = target


@contextlib.contextmanager
def written_folder(target: str | Path, kind: str = "run", *, overwrite: bool = False, default: bool = False,
                   expected_bytes: int = 0) -> Iterator[PendingFolder]:
    """Write a folder of results complete or not at all: yields a :class:`PendingFolder` whose
    ``path`` (a hidden sibling of ``target``) becomes ``target`` on success.

    ``target`` comes from :func:`output_target` (with the same ``overwrite`` and ``default``);
    the rule is applied again when the folder is renamed, in case the path was taken meanwhile
    (a default path is then numbered further).  Before yielding: the parents are created,
    debris of killed runs removed (:func:`remove_debris`), ``expected_bytes`` checked against
    the free space, and the sibling created with the marker (state ``partial``).  If the block
    raises (Ctrl-C included), the sibling and any parents created here are removed and the
    exception propagates; a full disk or an I/O error becomes :class:`WriteError`.
    """
    target = Path(os.path.abspath(target))
    parent = target.parent
    try:
        created = _make_parents(parent)
    except OSError as exc:
        raise OutputError(f"{target}: cannot create {parent} ({exc.strerror})") from None
    tmp = parent / f".{target.name}.partial-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        remove_debris(parent)
        check_space(parent, expected_bytes, f"{target}")
        try:
            tmp.mkdir()
            write_marker(tmp, kind, "partial")
        except OSError as exc:
            if _no_space(exc):
                raise OutputError(f"{target}: no space left on {parent}; free some space or give another path") \
                    from None
            raise OutputError(f"{target}: cannot write into {parent} ({exc.strerror})") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        _undo_parents(created)
        raise
    pending = PendingFolder(tmp, target)
    try:
        yield pending
        write_marker(tmp, kind, "complete", listing(tmp))
        pending.target = _commit(tmp, target, overwrite, default)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        _undo_parents(created)
        if _no_space(exc):
            raise WriteError(f"{target}: the disk filled up while writing the results ({exc.strerror}); "
                             f"nothing was written: free some space and run again") from None
        if isinstance(exc, OSError):
            raise WriteError(f"{target}: writing the results failed ({exc.strerror or exc}); nothing was written") \
                from None
        raise


def _commit(tmp: Path, target: Path, overwrite: bool, default: bool) -> Path:
    """Put the complete folder ``tmp`` in place of ``target`` (the rule checked again); returns
    where it went."""
    if _refusal(target, overwrite) is not None:
        target = output_target(target, overwrite=overwrite, default=default)   # numbered, or OutputError
    if os.path.lexists(target) and any(os.scandir(target)):
        # an earlier run's folder, allowed by --overwrite: set it aside (its marker makes it
        # debris if this process dies now), put the new one in place, then remove the old one
        old = target.parent / f".{target.name}.old-{os.getpid()}-{secrets.token_hex(4)}"
        os.rename(target, old)
        try:
            os.rename(tmp, target)
        except BaseException:
            os.rename(old, target)
            raise
        shutil.rmtree(old, ignore_errors=True)
        return target
    try:
        os.rename(tmp, target)   # onto a missing path or an empty folder: one atomic step
    except OSError as exc:
        if exc.errno in (errno.ENOTEMPTY, errno.EEXIST):
            raise OutputError(f"{target} was filled by another program while this one was writing; "
                              f"the new results were not written") from None
        raise
    return target


@contextlib.contextmanager
def written_file(target: str | Path) -> Iterator[Path]:
    """Yield a hidden temporary path next to ``target`` (from :func:`file_target`); on success it
    replaces ``target`` in one step, on failure it is removed (a full disk: :class:`WriteError`)."""
    target = Path(os.path.abspath(target))
    try:
        created = _make_parents(target.parent)
    except OSError as exc:
        raise OutputError(f"{target}: cannot create {target.parent} ({exc.strerror})") from None
    tmp = target.parent / f".{target.name}.partial-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        _undo_parents(created)
        if _no_space(exc):
            raise WriteError(f"{target}: the disk filled up while writing ({exc.strerror}); nothing was written") \
                from None
        raise


# -- estimates -------------------------------------------------------------------------------------
#: bytes per number in history.csv: "%.10g" gives up to 16 characters plus the comma
CSV_BYTES_PER_VALUE = 17
#: the four PNG plots at 110 dpi, each with up to every recorded point (measured: 0.2-0.6 MB each
#: on the bundled scenes; a plot of many points is larger)
PLOT_BYTES = 4 * 2**20


def history_bytes(rows: int, columns: int) -> int:
    """Upper estimate of ``history.csv``'s size (bytes): ``rows`` x (``columns`` + time)."""
    return int(rows) * (int(columns) + 1) * CSV_BYTES_PER_VALUE
