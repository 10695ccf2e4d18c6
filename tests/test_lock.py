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
