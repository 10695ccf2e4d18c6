"""The demo's temporary folders: each names the process that owns it, and a demo starting
removes the folders of demos whose process is gone.

Why: a demo's folder (its station databases, images; hundreds of KB) is removed when the demo
ends, but a demo killed with SIGKILL (or a machine that lost power) never gets to it, and
``/tmp`` filled up with ``stationd-demo-*`` folders nobody owned.  Why a pid file and not the
folder's age: a demo held with ``--hold`` may serve its folder for days, and a live demo's
folder must never go.  The pid file holds the process's start time too (Linux: the 22nd field
of ``/proc/PID/stat``), so a pid reused by another process since does not keep a dead demo's
folder forever.  A folder without a pid file is left alone: a demo that has just made its
folder and not written the file yet, or a folder someone else made.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

PREFIX = "stationd-demo-"
PID_FILE = "demo.pid"


def _start_time(pid: int) -> str | None:
    """The process's start time in clock ticks since boot (None: not known here)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # the command name (field 2) is in parentheses and may hold spaces: split after it
    fields = stat[stat.rfind(")") + 2:].split()
    return fields[19] if len(fields) > 19 else None


def mark(folder: Path) -> None:
    """Write this process's pid file into its demo ``folder``."""
    pid = os.getpid()
    (folder / PID_FILE).write_text(f"{pid} {_start_time(pid) or '-'}\n")


def _alive(pid: int, start: str) -> bool:
    """Whether the process that wrote a pid file (``pid``, its ``start`` time or ``-``)
    still runs."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # another user's process: it exists
        pass
    now = _start_time(pid)
    return start == "-" or now is None or now == start


def owner_gone(folder: Path) -> bool:
    """Whether ``folder``'s pid file names a process that is gone (False without one, or
    with one that does not read as a pid file: nothing is removed on a guess)."""
    try:
        words = (folder / PID_FILE).read_text().split()
        pid, start = int(words[0]), words[1]
    except (OSError, ValueError, IndexError):
        return False
    return not _alive(pid, start)


def sweep(parent: Path | None = None) -> list[Path]:
    """Remove the demo folders in ``parent`` (the temporary directory) whose demo process
    is gone; the folders removed."""
    root = Path(parent) if parent is not None else Path(tempfile.gettempdir())
    removed = []
    try:
        found = sorted(root.glob(f"{PREFIX}*"))
    except OSError:
        return []
    for folder in found:
        if folder.is_dir() and not folder.is_symlink() and owner_gone(folder):
            shutil.rmtree(folder, ignore_errors=True)
            if not folder.exists():
                removed.append(folder)
    return removed


__all__ = ["PID_FILE", "PREFIX", "mark", "owner_gone", "sweep"]
