"""One daemon per station: an advisory lock beside the database.

Two daemons on one database and one set of devices would both poll the PLC, both send
parameters to one controller and both record its results.  The lock is ``flock`` on a file
beside the SQLite database (or in the records folder for a database server), holding the
holder's pid: the kernel releases it when the process dies (even by SIGKILL), so a crash never
leaves a stale lock, and a second daemon is told who holds it.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path
from types import TracebackType

from stationd.errors import InputError

LOCK_NAME = "stationd.lock"


class LockHeldError(InputError):
    """Another process holds the station's lock (its pid in the message)."""

    def __init__(self, path: Path, pid: int | None) -> None:
        who = f"pid {pid}" if pid is not None else "another process"
        super().__init__(f"{path}: the station is already run by {who} (one daemon per "
                         "database and devices; stop it first)")
        self.pid = pid


def lock_path(database_url: str, records_dir: Path | None = None) -> Path | None:
    """Where the lock of a station with this database lives: ``<database>.lock`` for an SQLite
    file, else ``records_dir/stationd.lock``; None for an in-memory database without records
    (nothing to share)."""
    prefix = "sqlite:///"
    if database_url.startswith(prefix):
        name = database_url[len(prefix):]
        if name and name != ":memory:":
            return Path(name).with_name(Path(name).name + ".lock")
    return records_dir / LOCK_NAME if records_dir is not None else None


class StationLock:
    """``with StationLock(path):`` holds the lock for the block (or ``acquire``/``release``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock or raise :class:`LockHeldError` naming the holder; never waits.  A
        folder this user cannot create or write is an :class:`InputError` naming it (an
        installation mistake, not something a restart cures)."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            blocker = next((p for p in self.path.parents if p.exists() and not p.is_dir()),
                           None)
            if blocker is not None:   # mkdir says "File exists", which misleads
                raise InputError(f"{self.path}: cannot create the station's lock: {blocker} "
                                 "is a file, not a folder (check the database URL)") from None
            raise InputError(f"{self.path}: cannot create the station's lock: "
                             f"{exc.strerror or exc} (the daemon's user must be able to write "
                             f"{self.path.parent}: its database lives there)") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = _read_pid(fd)
            os.close(fd)
            raise LockHeldError(self.path, pid) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> StationLock:
        self.acquire()
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.release()


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


class StationLocks:
    """The lock of the station a daemon runs now, moved when a reload names another database:
    the new one is taken before the old one is let go, so a reload onto a database another
    daemon runs is refused (and this daemon keeps its own), and the old one is free after."""

    def __init__(self) -> None:
        self.where: Path | None = None
        self._lock: StationLock | None = None

    def hold(self, database_url: str, records_dir: Path | None = None) -> None:
        """Hold the lock of this database (raises :class:`LockHeldError` and keeps the one
        held if another process has it)."""
        where = lock_path(database_url, records_dir)
        if where == self.where and self._lock is not None:
            return
        new = StationLock(where) if where is not None else None
        if new is not None:
            new.acquire()
        self.release()
        self.where, self._lock = where, new

    def release(self) -> None:
        if self._lock is not None:
            self._lock.release()
        self.where, self._lock = None, None
