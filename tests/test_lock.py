import subprocess
import sys
import textwrap

import pytest

from stationd.lock import LockHeldError, StationLock, lock_path


def test_lock_path_is_beside_the_database_or_in_the_records(tmp_path):
    assert lock_path(f"sqlite:///{tmp_path}/s.db") == tmp_path / "s.db.lock"
    assert lock_path("sqlite:///:memory:") is None
    assert lock_path("postgresql://h/db", tmp_path) == tmp_path / "stationd.lock"
    assert lock_path("postgresql://h/db") is None


def test_a_second_holder_is_refused_with_the_holders_pid(tmp_path):
    """The holder is another process (flock is per open file: a second open in this process
    would conflict too, but the pid must be the other process's)."""
    path = tmp_path / "s.db.lock"
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, time
            from pathlib import Path
            from stationd.lock import StationLock
            with StationLock(Path({str(path)!r})):
                print("held", flush=True)
                sys.stdin.readline()
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(LockHeldError, match=rf"already run by pid {holder.pid}") as err:
            StationLock(path).acquire()
        assert err.value.pid == holder.pid
    finally:
        assert holder.stdin is not None
        holder.stdin.close()
        holder.wait(10)
    with StationLock(path):  # released when the holder exits
        assert path.read_text().strip().isdigit()


def test_a_killed_holder_leaves_no_stale_lock(tmp_path):
    path = tmp_path / "s.db.lock"
    proc = subprocess.Popen(
        [sys.executable, "-c", f"from pathlib import Path; from stationd.lock import StationLock;"
         f"StationLock(Path({str(path)!r})).acquire(); print('held', flush=True);"
         "import time; time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    proc.kill()
    proc.wait(10)
    lock = StationLock(path)
    lock.acquire()
    lock.release()


def test_a_database_path_through_a_file_names_the_file(tmp_path):
    """``sqlite:////x/notes.txt/s.db``: mkdir said "File exists" (a newcomer's trial); the
    refusal names the file standing where a folder should be."""
    from stationd.errors import InputError

    (tmp_path / "notes.txt").write_text("not a folder\n")
    with pytest.raises(InputError, match=r"notes\.txt is a file, not a folder"):
        StationLock(tmp_path / "notes.txt" / "sub" / "s.db.lock").acquire()


def _hold_devices(folder, devices):
    """Another process holding device locks (as a second daemon would), until its stdin
    closes."""
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys
            from pathlib import Path
            from stationd.lock import StationLocks
            locks = StationLocks(Path({str(folder)!r}))
            locks.hold("sqlite:///:memory:", devices={devices!r})
            print("held", flush=True)
            sys.stdin.readline()
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
    return holder


def _free(folder, what, url):
    """Whether this device's lock can be taken now (by a fresh open: flock conflicts with
    this process's own other descriptors too)."""
    from stationd.devicekey import device_key
    from stationd.lock import DeviceHeldError, DeviceLock

    lock = DeviceLock(device_key(url) or "", what, url, folder)
    try:
        lock.acquire()
    except DeviceHeldError:
        return False
    lock.release()
    return True


def test_a_device_another_daemon_drives_is_refused_naming_its_pid_and_the_device(tmp_path):
    """Another database, the same lift written differently: refused; the database lock this
    call took is given back (nothing held after a refusal)."""
    from stationd.lock import DeviceHeldError, StationLocks

    holder = _hold_devices(tmp_path, [("lift", "modbus-tcp://127.0.0.1:1502?unit=1")])
    try:
        locks = StationLocks(tmp_path)
        with pytest.raises(DeviceHeldError) as err:
            locks.hold(f"sqlite:///{tmp_path}/b.db", devices=[
                ("wrench", "openprotocol://127.0.0.1:4545"),
                ("lift", "modbus-tcp://localhost:1502?timeout=2")])
        assert err.value.pid == holder.pid
        assert str(err.value).startswith(f"lift modbus-tcp://localhost:1502?timeout=2: the "
                                         f"device is already driven by pid {holder.pid}")
        assert locks.where is None and locks.devices == []
        StationLock(tmp_path / "b.db.lock").acquire()    # given back
        assert _free(tmp_path, "wrench", "openprotocol://127.0.0.1:4545")
        # simulated devices are each daemon's own: never locked
        locks.hold(f"sqlite:///{tmp_path}/c.db", devices=[("lift", "sim://lift"),
                                                           ("wrench", "sim://wrench")])
        assert locks.devices == []
        locks.release()
    finally:
        assert holder.stdin is not None
        holder.stdin.close()
        holder.wait(10)


def test_a_reload_takes_the_new_device_first_and_keeps_the_old_when_refused(tmp_path):
    from stationd.lock import DeviceHeldError, StationLocks

    lift1, lift2, lift3 = (f"modbus-tcp://127.0.0.1:{p}" for p in (1502, 1503, 1504))
    wrench = "openprotocol://127.0.0.1:4545"
    locks = StationLocks(tmp_path)
    locks.hold("sqlite:///:memory:", devices=[("lift", lift1), ("wrench", wrench)])
    holder = _hold_devices(tmp_path, [("lift", lift2)])
    try:
        with pytest.raises(DeviceHeldError, match=rf"lift {lift2}: .* pid {holder.pid}"):
            locks.hold("sqlite:///:memory:", devices=[("lift", lift2), ("wrench", wrench)])
        assert not _free(tmp_path, "lift", lift1) and not _free(tmp_path, "wrench", wrench)
    finally:
        assert holder.stdin is not None
        holder.stdin.close()
        holder.wait(10)
    locks.hold("sqlite:///:memory:", devices=[("lift", lift3), ("wrench", wrench)])
    assert _free(tmp_path, "lift", lift1)            # the old lift is let go
    assert not _free(tmp_path, "lift", lift3) and not _free(tmp_path, "wrench", wrench)
    locks.release()
    assert _free(tmp_path, "lift", lift3) and _free(tmp_path, "wrench", wrench)


def test_one_device_named_twice_in_one_station_is_one_lock(tmp_path):
    """A lift and a controller on one Modbus RTU line (two units, one port): one daemon
    drives both."""
    from stationd.lock import StationLocks

    (tmp_path / "ttyUSB0").touch()
    locks = StationLocks(tmp_path / "locks")
    locks.hold("sqlite:///:memory:", devices=[
        ("lift", f"modbus-rtu://{tmp_path}/ttyUSB0?unit=1"),
        ("wrench", f"modbus-rtu://{tmp_path}/ttyUSB0?unit=2")])
    assert locks.devices == [f"serial {tmp_path}/ttyUSB0"]
    assert (tmp_path / "locks").stat().st_mode & 0o1777 == 0o1777   # shared by all users
    locks.release()
