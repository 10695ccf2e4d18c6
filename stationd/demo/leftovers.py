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
#: the station file the demo runs, resolved: ``stationd db report VIN --config FILE`` finds a
#: running demo's database by it (:func:`demo_databases`)
STATION_FILE = "station"
#: each station's database in the demo's folder: ``k/stationd.db`` for DEMO-k
DATABASE = "stationd.db"


def _start_time(pid: int) -> str | None:
    """The process's start time in clock ticks since boot (None: not known here)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # the command name (field 2) is in parentheses and may hold spaces: split after it
    fields = stat[stat.rfind(")") + 2:].split()
    return fields[19] if len(fields) > 19 else None


def mark(folder: Path, station: Path | None = None) -> None:
    """Write this process's pid file into its demo ``folder``, and the ``station`` file it
    runs (resolved)."""
    pid = os.getpid()
    (folder / PID_FILE).write_text(f"{pid} {_start_time(pid) or '-'}\n")
    if station is not None:
        (folder / STATION_FILE).write_text(f"{Path(station).resolve()}\n")


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


def owner_alive(folder: Path) -> bool:
    """Whether ``folder``'s pid file names a process that still runs (False without one)."""
    try:
        words = (folder / PID_FILE).read_text().split()
        pid, start = int(words[0]), words[1]
    except (OSError, ValueError, IndexError):
        return False
    return _alive(pid, start)


def demo_databases(station: Path, parent: Path | None = None) -> list[tuple[str, Path]]:
    """The station databases of the running demos of ``station`` (a station file): (station
    id, database file), the first station's first.  Why: a demo keeps its records in its
    temporary folder, not in the station file's database, and ``stationd db report VIN
    --config STATION.yaml`` during a demo said "no database at .../stationd-sim.db"."""
    root = Path(parent) if parent is not None else Path(tempfile.gettempdir())
    try:
        mine = str(Path(station).resolve())
        found = sorted(root.glob(f"{PREFIX}*"))
    except (OSError, RuntimeError):
        return []
    out: list[tuple[str, Path]] = []
    for folder in found:
        try:
            runs = (folder / STATION_FILE).read_text().strip()
            if runs != mine or not owner_alive(folder):
                continue
            ks = sorted(int(d.name) for d in folder.iterdir() if d.name.isdigit())
        except (OSError, ValueError):
            continue
        out += [(f"DEMO-{k}", folder / str(k) / DATABASE) for k in ks
                if (folder / str(k) / DATABASE).is_file()]
    return out


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


__all__ = ["DATABASE", "PID_FILE", "PREFIX", "STATION_FILE", "demo_databases", "mark",
           "owner_alive", "owner_gone", "sweep"]
