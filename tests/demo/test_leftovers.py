"""The demo's temporary folders: a demo killed with SIGKILL left its ``stationd-demo-*``
folder behind; the next demo removes the folders whose process is gone (read from the pid
file in each), never a live demo's, nor a folder without a pid file."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from stationd.demo.leftovers import PID_FILE, PREFIX, mark, owner_gone, sweep


def _dead_pid() -> int:
    """The pid of a process that has ended (and was reaped)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _folder(parent: Path, name: str, pid_text: str | None) -> Path:
    folder = parent / f"{PREFIX}{name}"
    (folder / "1").mkdir(parents=True)
    (folder / "1" / "stationd.db").write_bytes(b"x" * 1000)
    if pid_text is not None:
        (folder / PID_FILE).write_text(pid_text)
    return folder


def test_the_folders_of_demos_that_are_gone_are_removed_and_no_other(tmp_path):
    dead = _folder(tmp_path, "dead", f"{_dead_pid()} -\n")
    live = _folder(tmp_path, "live", None)
    mark(live)                                           # this process: alive
    assert (live / PID_FILE).read_text().split()[0] == str(os.getpid())
    # a pid alive now but started at another time: another process took the pid since
    reused = _folder(tmp_path, "reused", f"{os.getpid()} 1\n")
    unmarked = _folder(tmp_path, "unmarked", None)       # a demo that just made its folder
    garbled = _folder(tmp_path, "garbled", "not a pid\n")
    other = tmp_path / "stationd-other"
    other.mkdir()
    (other / PID_FILE).write_text(f"{_dead_pid()} -\n")  # not a demo's folder

    assert sorted(sweep(tmp_path)) == sorted([dead, reused])
    assert not dead.exists() and not reused.exists()
    assert live.exists() and unmarked.exists() and garbled.exists() and other.exists()
    assert not owner_gone(live) and sweep(tmp_path) == []
