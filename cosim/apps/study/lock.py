"""One writer per study folder: the lock a study holds while it writes its rows.

Two studies appending to one ``results.csv`` (say two ``--resume`` started at once) would run
the same cases twice and write duplicate rows.  A study therefore holds ``study.lock`` in its
folder from before it reads the rows already there until its last row and ``results.parquet``
are written.  The lock is an ``flock`` on that file, so the kernel releases it when the holder
dies, however it dies: a lock file left by a dead process (SIGKILL, a lost machine) is stale
and the next study takes it over.  The file names the holder (pid, host, start time, command),
so that a second writer is refused at once with a message naming the first one.

``flock`` on NFS: Linux maps it to NFS byte-range locks (NFSv4 and NFSv3 with lockd), which
other clients see; on a file system without locks the study refuses to start (``OSError``).
"""
from __future__ import annotations

import datetime
import errno
import fcntl
import json
import os
import socket
import sys
from pathlib import Path
from typing import Any

from .spec import StudyError

LOCK_FILE = "study.lock"


class StudyLock:
    """The lock of one study folder.  :meth:`acquire` returns what it took over (the record of a
    dead holder, or None); :meth:`release` removes the file.  Also a context manager."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self.fd: int | None = None
        self.stale: dict[str, Any] | None = None   # the record of a dead holder taken over

    @staticmethod
    def record() -> dict[str, Any]:
        """What the lock file says about its holder (this process)."""
        return dict(pid=os.getpid(), host=socket.gethostname(),
                    started=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                    command=" ".join(sys.argv)[:300])

    def acquire(self) -> dict[str, Any] | None:
        """Take the lock or raise :class:`StudyError` naming its holder.  The folder must exist."""
        for _ in range(10):   # the holder may remove the file between our open and our flock: retry
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise
                raise StudyError(f"{self.folder}: another study is writing here ({describe(read(self.path))}); "
                                 f"wait for it to end, or use --out for another folder") from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:   # we locked a file its holder has just removed: try the new one
                os.close(fd)
                continue
            previous = _parse(os.pread(fd, 65536, 0))
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(self.record()) + "\n").encode(), 0)
            os.fsync(fd)
            self.fd = fd
            self.stale = previous or None   # a record in an unlocked file: its holder died
            return self.stale
        raise StudyError(f"{self.path}: the lock file keeps changing; is another study starting here?")

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass
        os.close(self.fd)   # closing releases the flock
        self.fd = None

    def __enter__(self) -> "StudyLock":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def _parse(data: bytes) -> dict[str, Any]:
    try:
        record = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def read(path: Path) -> dict[str, Any]:
    """The holder's record in a lock file ({} if unreadable)."""
    try:
        return _parse(path.read_bytes())
    except OSError:
        return {}


def describe(record: dict[str, Any]) -> str:
    """``pid 123 on host h since 2026-...: pounding-cosim study ...``, or what is known of it."""
    if not record:
        return "holder unknown: the lock file is empty"
    text = f"pid {record.get('pid')} on host {record.get('host')} since {record.get('started')}"
    return text + (f": {record['command']}" if record.get("command") else "")
