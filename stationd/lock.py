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
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType

from drivers.devices import Kind
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
        held = _take(fd, f"{os.getpid()}\n")
        if held is not None:
            raise LockHeldError(self.path, held[0])
        self._fd = fd

    def release(self) -> None:
        _let_go(self._fd)
        self._fd = None

    def __enter__(self) -> StationLock:
        self.acquire()
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.release()


def _take(fd: int, stamp: str | None) -> tuple[int | None, str] | None:
    """Lock the open lock file ``fd`` without waiting and write ``stamp`` (the pid first,
    then what holds it) into it; None when taken, else ``fd`` is closed and the holder's pid
    and its second line (what it holds the lock as) are returned.  One rule for the
    station's lock and each device's: ``flock`` is per open file, released by the kernel
    when the holder dies, so the file's text only names the holder."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _read_holder(fd)
        os.close(fd)
        return holder
    if stamp is not None:
        os.ftruncate(fd, 0)
        os.pwrite(fd, stamp.encode(), 0)
    return None


def _let_go(fd: int | None) -> None:
    """Release a lock :func:`_take` took (nothing when none is held)."""
    if fd is not None:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def _read_holder(fd: int) -> tuple[int | None, str]:
    """The holder's pid (the lock file's first line) and what it holds the lock as (its
    second line, empty when there is none)."""
    try:
        text = os.pread(fd, 512, 0).decode("utf-8", "replace")
    except OSError:
        return None, ""
    first, _, rest = text.partition("\n")
    first = first.strip()
    return (int(first) if first.isdigit() else None), rest.partition("\n")[0].strip()


class DeviceHeldError(LockHeldError):
    """Another process drives this device (its pid and the device in the message)."""

    def __init__(self, what: str, url: str, path: Path, pid: int | None,
                 holder: str = "") -> None:
        who = f"pid {pid}" if pid is not None else "another process"
        InputError.__init__(self, f"{what} {url}: the device is already driven by {who} (one "
                            "daemon per device: stop that daemon, or name another device; "
                            f"its lock: {path})")
        self.pid = pid
        self.device = url
        #: what the holder took the lock as ("lift modbus-tcp://...", "probe lift ...")
        self.holder = holder


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
        held = _take(fd, f"{os.getpid()}\n{self.what} {self.url}\n" if writable else None)
        if held is not None:
            raise DeviceHeldError(self.what, self.url, self.path, *held)
        self._fd = fd

    def release(self) -> None:
        _let_go(self._fd)
        self._fd = None


#: what a probe writes in a device's lock (its second line begins with it)
PROBE = "probe"


@contextlib.contextmanager
def probing(kind: str, url: str, folder: Path | None = None) -> Iterator[None]:
    """Hold the lock of the device ``url`` while ``stationd probe`` talks to it: a probe
    beside the daemon driving that device would take the controller's one Open Protocol
    session, or poll the PLC between the daemon's reads, or trigger a camera out of turn.
    Never waits: the device a daemon (or another probe) holds is refused, naming its pid, as
    an :class:`InputError` (one line, exit 2).  Simulated devices and URLs that do not parse
    take no lock (the probe says what is wrong with the URL itself)."""
    key = device_key(url, _kind(kind))
    if key is None or key.startswith("url "):
        yield
        return
    lock = DeviceLock(key, f"{PROBE} {kind}", url, folder or lock_dir())
    try:
        lock.acquire()
    except DeviceHeldError as held:
        who = f"pid {held.pid}" if held.pid is not None else "its pid unknown"
        if held.holder.startswith(f"{PROBE} "):
            raise InputError(f"{kind} {url}: another stationd probe ({who}) is using this "
                             "device; wait for it to end") from None
        raise InputError(f"{kind} {url}: the station daemon ({who}) is driving this device; "
                         "stop it or use its screens") from None
    try:
        yield
    finally:
        lock.release()


def _kind(what: str) -> Kind | None:
    """The kind of device ``what`` names ("lift", "wrench", "camera NAME": its first word),
    whose backend says what the URL drives; None for another name (the URL's scheme then
    finds its backend in any kind: ``device_key``)."""
    try:
        return Kind(what.partition(" ")[0])
    except ValueError:
        return None


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
                key = device_key(url, _kind(what))
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
