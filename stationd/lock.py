"""One daemon per station: an advisory lock beside the database.

Two daemons on one database and one set of devices would both poll the PLC, both send
parameters to one controller and both record its results.  The lock is ``flock`` on a file
beside the SQLite database (or in the records folder for a database server), holding the
holder's pid: the kernel releases it when the process dies (even by SIGKILL), so a crash never
leaves a stale lock, and a second daemon is told who holds it.

The database is not all two daemons can share: each device endpoint a daemon drives (the lift,
the controller, every camera) has a lock too, keyed by the endpoint (``stationd.devicekey``),
in one folder every daemon on the machine shares (``/run/lock/stationd``, else the temp
folder: :func:`stationd.devicekey.lock_dir`).  :class:`StationLocks` holds both for the
daemon's life and moves them on a reload: a second daemon with another database but the same
lift URL is refused at its start, naming the holder's pid and the device.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType

from stationd.devicekey import device_key, key_file, lock_dir
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
    """The holder's pid: the lock file's first line."""
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    first = text.split("\n", 1)[0].strip()
    return int(first) if first.isdigit() else None


class DeviceHeldError(LockHeldError):
    """Another process drives this device (its pid and the device in the message)."""

    def __init__(self, what: str, url: str, path: Path, pid: int | None) -> None:
        who = f"pid {pid}" if pid is not None else "another process"
        InputError.__init__(self, f"{what} {url}: the device is already driven by {who} (one "
                            "daemon per device: stop that daemon, or name another device; "
                            f"its lock: {path})")
        self.pid = pid
        self.device = url


class DeviceLock:
    """The lock of one device endpoint (``key``, see :mod:`stationd.devicekey`) in the
    machine's shared ``folder``; ``what`` and ``url`` name it in a refusal (the lift, the
    wrench, camera NAME)."""

    def __init__(self, key: str, what: str, url: str, folder: Path) -> None:
        self.key, self.what, self.url = key, what, url
        self.path = folder / key_file(key)
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock or raise :class:`DeviceHeldError`; never waits.  The folder is made
        sticky and world-writable (as /run/lock itself), the file readable and writable by
        all, so that a daemon run as root and the service's user share them; a file another
        user made read-only is locked all the same (flock needs no write access)."""
        folder = self.path.parent
        try:
            if not folder.is_dir():
                folder.mkdir(parents=True, exist_ok=True)
                with contextlib.suppress(OSError):
                    folder.chmod(0o1777)
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
                with contextlib.suppress(OSError):
                    os.fchmod(fd, 0o666)
                writable = True
            except PermissionError:
                fd = os.open(self.path, os.O_RDONLY)
                writable = False
        except OSError as exc:
            raise InputError(f"{self.path}: cannot create the lock of {self.what} {self.url}: "
                             f"{exc.strerror or exc} (the daemon's user must be able to write "
                             f"{folder})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = _read_pid(fd)
            os.close(fd)
            raise DeviceHeldError(self.what, self.url, self.path, pid) from None
        if writable:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n{self.what} {self.url}\n".encode(), 0)
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None


class StationLocks:
    """The locks of the station a daemon runs now: its database's and its devices', moved
    when a reload names another database or another device.  The new ones are taken before
    the old ones are let go, so a reload onto a database or a device another daemon holds is
    refused (and this daemon keeps its own), and the old ones are free after.  ``folder``:
    where device locks live (None: :func:`stationd.devicekey.lock_dir`)."""

    def __init__(self, folder: Path | None = None) -> None:
        self.where: Path | None = None
        self._lock: StationLock | None = None
        self._folder = folder
        self._devices: dict[str, DeviceLock] = {}   # key -> its lock

    @property
    def devices(self) -> list[str]:
        """The keys of the devices held."""
        return list(self._devices)

    def hold(self, database_url: str, records_dir: Path | None = None,
             devices: Iterable[tuple[str, str]] = ()) -> None:
        """Hold the lock of this database and of each device (``(what, url)``: "lift",
        "modbus-tcp://..."; simulated ones need none).  Raises :class:`LockHeldError` (or
        :class:`DeviceHeldError`) and keeps what was held if another process has any."""
        where = lock_path(database_url, records_dir)
        keep_db = where == self.where and self._lock is not None
        taken: list[StationLock | DeviceLock] = []
        wanted: dict[str, DeviceLock] = {}
        try:
            new = StationLock(where) if where is not None and not keep_db else None
            if new is not None:
                new.acquire()
                taken.append(new)
            folder: Path | None = None
            for what, url in devices:
                key = device_key(url)
                if key is None or key in wanted:   # one device named twice: one lock
                    continue
                lock = self._devices.get(key)
                if lock is None:
                    folder = folder or self._folder or lock_dir()
                    lock = DeviceLock(key, what, url, folder)
                    lock.acquire()
                    taken.append(lock)
                wanted[key] = lock
        except BaseException:
            for lock_ in taken:
                lock_.release()
            raise
        if not keep_db:
            if self._lock is not None:
                self._lock.release()
            self.where, self._lock = where, new
        for key, old in self._devices.items():
            if key not in wanted:
                old.release()
        self._devices = wanted

    def release(self) -> None:
        if self._lock is not None:
            self._lock.release()
        self.where, self._lock = None, None
        for lock in self._devices.values():
            lock.release()
        self._devices = {}
