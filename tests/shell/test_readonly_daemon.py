"""``stationd run`` as its service user on a database file it may not write (a maintenance
technician's trial: the file replaced by root's copy, root:root 0644, then a reload; or the
daemon started on such a file).  SQLite opens it read-only without a word: the reload was
accepted, every write failed ("attempt to write a readonly database") and within seconds the
journal said "database: back", a flip-flop, the station tracking and offering bolts between;
a chown alone did not end it (a second reload did).  Now: a lasting fault that says what to
do, and the station back on its own once the file is chowned.

Runs the daemon as uid 65534 (root writes any file whatever its mode); skipped where the
tests do not run as root, or where that user cannot reach this clone."""

from __future__ import annotations

import os
import pwd
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.db.test_db_cli import _unreachable_as_nobody
from tests.shell.test_serve import _sim_copy

NOBODY = 65534


class Journal:
    """The daemon's stderr, line by line, as it comes (a thread reads it)."""

    def __init__(self, p: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        self._cv = threading.Condition()
        self._p = p
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self._p.stderr is not None
        for line in self._p.stderr:
            with self._cv:
                self.lines.append(line.rstrip("\n"))
                self._cv.notify_all()
        with self._cv:
            self.lines.append("<stderr closed>")
            self._cv.notify_all()

    def wait(self, done: Callable[[list[str]], bool], what: str,
             timeout: float = 120.0) -> list[str]:
        """The lines so far, once ``done(lines)``; fails after ``timeout`` s (a generous
        bound, never a measure), showing the journal's end."""
        end = time.monotonic() + timeout
        with self._cv:
            while not done(self.lines):
                left = end - time.monotonic()
                if left <= 0 or (self.lines and self.lines[-1] == "<stderr closed>"):
                    tail = "\n".join(self.lines[-40:])
                    raise AssertionError(f"{what}: not seen; the journal's end:\n{tail}")
                self._cv.wait(min(left, 1.0))
            return list(self.lines)


#: the daemon's line as a reload begins
RELOADED = "configuration reloaded"


def _since(lines: list[str], start: int, needle: str) -> list[str]:
    return [x for x in lines[start:] if needle in x]


@pytest.mark.system
@pytest.mark.timeout(420)
@pytest.mark.parametrize("how", ["start", "reload"])
def test_a_database_file_the_daemon_may_not_write_is_a_lasting_fault_until_chowned(how):
    if os.geteuid() != 0:
        pytest.skip("runs the daemon as uid 65534 and chowns its file: needs root")
    why = _unreachable_as_nobody()
    if why is not None:
        pytest.skip(f"uid 65534 cannot run this clone's interpreter (a private folder?): {why}")
    from db.repository import Repository
    from stationd.boltfile import import_bolts

    nobody = pwd.getpwuid(NOBODY).pw_name
    # a folder uid 65534 can reach (pytest's own are root's only), the service user's
    folder = Path(tempfile.mkdtemp(prefix="stationd-rodb-", dir="/tmp"))
    p: subprocess.Popen[str] | None = None
    try:
        station = _sim_copy(folder)
        db = folder / "stationd-sim.db"
        repo = Repository.open(f"sqlite:///{db}")     # as the daemon left it: migrated,
        import_bolts(repo, folder / "bolts.yaml")     # its bolt table imported
        repo.close()
        for f in folder.iterdir():
            os.chown(f, NOBODY, NOBODY)
        os.chown(folder, NOBODY, NOBODY)
        if how == "start":                            # root's copy before the daemon starts
            os.chown(db, 0, 0)
            db.chmod(0o644)
        p = subprocess.Popen(
            [sys.executable, "-m", "stationd", "run", "--config", str(station)],
            cwd=folder, user=NOBODY, group=NOBODY, env={**os.environ, "HOME": "/"},
            stdin=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        journal = Journal(p)
        assert p.stdin is not None
        start = 0
        if how == "reload":
            journal.wait(lambda ls: any("stationd running" in x for x in ls),
                         "the daemon running on the service user's own file")
            # the vehicle at working height first, the station idle (a 'next' that comes
            # while it reloads is ignored, "reloading": CI once), then the file replaced:
            # the reloaded station loads it, a write
            p.stdin.write("next\n")
            p.stdin.flush()
            lines = journal.wait(lambda ls: any("lift at working height" in x for x in ls),
                                 "the simulated lift raised")
            copy = folder / "copy.db"                 # the technician's copy, root's, 0644
            shutil.copyfile(db, copy)
            os.chown(copy, 0, 0)
            copy.chmod(0o644)
            os.replace(copy, db)
            start = len(lines)
            p.send_signal(signal.SIGHUP)
            # the reloaded station waiting for a vehicle (the file opened), or its
            # database's fault: after the reload's own line (the station before it says
            # it waits too)
            lines = journal.wait(lambda ls: bool(_since(ls, start, RELOADED)),
                                 "the reload begun")
            begun = start + next(i for i, x in enumerate(lines[start:]) if RELOADED in x)
            journal.wait(lambda ls: bool(_since(ls, begun, "lift not at working height")
                                         or _since(ls, begun, "fault: database")),
                         "the reload taken")
        else:
            # a new vehicle at working height (the simulated lift reads its standard input):
            # its loading is a write, as a bolt's tool enable is
            p.stdin.write("next\n")
            p.stdin.flush()
        hint = f"chown it to {nobody}"

        def decided(ls: list[str]) -> bool:   # a retry said the fault again, or it flipped
            return len(_since(ls, start, hint)) >= 2 or \
                bool(_since(ls, start, "database: back"))

        lines = journal.wait(decided, f"the fault saying {hint!r} twice")
        said = "\n".join(lines[start:])
        assert not _since(lines, start, "database: back"), said
        assert not _since(lines, start, "tightening:"), said
        fault = _since(lines, start, hint)[0]
        assert f"the database file {db} is not writable by this daemon's user ({nobody}; " \
               "the file is root's, mode 0644)" in fault, fault
        # chowned, and no reload: the station is back on its own, the vehicle loaded
        chowned = len(lines)
        os.chown(db, NOBODY, NOBODY)
        lines = journal.wait(lambda ls: bool(_since(ls, chowned, "database: back")) and any(
            "tracking" in x for x in ls[chowned:]), "the station back after the chown")
        assert not [x for x in lines[chowned:] if "readonly" in x or hint in x], \
            "\n".join(lines[chowned:])
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=60) == 0
        lines = journal.wait(lambda ls: ls[-1:] == ["<stderr closed>"], "the daemon's end")
        assert not [x for x in lines if "Traceback" in x], "\n".join(lines)
    finally:
        if p is not None and p.poll() is None:
            p.kill()
            p.wait(timeout=60)
        shutil.rmtree(folder, ignore_errors=True)
