"""A throw-away PostgreSQL server: the distribution's server binaries, a cluster in a temp
folder, on 127.0.0.1 and a free port, as an unprivileged user.

Why here and not only in the tests: ``stationd bench line`` (and a demo of a line) needs a
line database where nobody gave one, and it must be the same engine the plant runs, started
the way the tests start it.  ``initdb`` and ``pg_ctl`` refuse to run as root, so as root the
cluster belongs to ``nobody``.  Where the server package is not installed, ``missing`` says
so and nothing is started (the tests skip with that reason, the benchmark asks for ``--pg``).

A throw-away server must not outlive whoever started it: a test run or a demo killed with -9
never reaches ``stop()``, and its server would go on holding a port, memory and a temp folder.
So each start also starts a small watcher in its own session that outlives a killed owner: when
the owner's pid is gone, it stops the server at once and removes its folder.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MISSING = "PostgreSQL's server is not installed (apt-get install postgresql)"


class PgServerError(Exception):
    """The server did not start or stop: its own words (the first lines of its output)."""


def _bin(name: str) -> str | None:
    found = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))
    return found[-1] if found else shutil.which(name)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def watch(owner: int, folder: str, stop_argv: list[str]) -> None:
    """Wait while ``owner`` lives, then stop the server and remove ``folder`` (the watcher's
    body, run as ``python -c`` in its own session so that killing the owner spares it)."""
    while True:
        try:
            os.kill(owner, 0)
        except ProcessLookupError:
            break
        except PermissionError:
            pass                                   # alive, owned by another user
        time.sleep(1.0)
    if Path(folder).exists():
        _down(stop_argv, folder)


def _down(stop_argv: list[str], folder: str | Path) -> None:
    """The server stopped at once (``pg_ctl stop -m immediate``) and its folder removed."""
    subprocess.run(stop_argv, check=False, capture_output=True, cwd=folder)  # noqa: S603
    shutil.rmtree(folder, ignore_errors=True)


_WATCH = ("import sys, json; from stationd.pgserver import watch; "
          "watch(int(sys.argv[1]), sys.argv[2], json.loads(sys.argv[3]))")


class PgServer:
    """``PgServer()``: why it cannot start (``missing``), or ``start()`` then ``url(db)``,
    ``create(db)``, ``pause()``/``resume()`` (down and back with its data) and ``stop()``
    (everything removed).  Also a context manager (started on entry, stopped on exit)."""

    def __init__(self, max_connections: int = 50, *, durable: bool = False) -> None:
        self.initdb, self.pg_ctl = _bin("initdb"), _bin("pg_ctl")
        self.missing = None if self.initdb and self.pg_ctl else MISSING
        self.max_connections = max_connections
        #: commits on disk, as a plant's server (a benchmark's figures); the tests' is faster
        self.durable = durable
        self.port = 0
        self.dir: Path | None = None
        self._watcher: subprocess.Popen[bytes] | None = None

    def __enter__(self) -> PgServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _as_user(self, argv: list[str]) -> list[str]:
        if os.geteuid() != 0:
            return argv
        return ["runuser", "-u", "nobody", "--", *argv]

    def _run(self, argv: list[str], what: str) -> None:
        done = subprocess.run(self._as_user(argv),  # noqa: S603 - the server's own binaries
                              capture_output=True, cwd=self.dir, check=False)
        if done.returncode != 0:
            words = (done.stderr or done.stdout).decode(errors="replace").strip()
            first = words.splitlines()[0] if words else f"exit {done.returncode}"
            raise PgServerError(f"PostgreSQL {what}: {first}")

    def _data(self) -> tuple[str, str]:
        """``pg_ctl`` and the cluster's data folder (``PgServerError``: not started)."""
        if self.dir is None or self.pg_ctl is None:
            raise PgServerError("PostgreSQL: the server was not started")
        return self.pg_ctl, str(self.dir / "data")

    def _pg_start(self) -> None:
        pg_ctl, data = self._data()
        self._run([pg_ctl, "-D", data, "-l", str(Path(data).parent / "log"),
                   "-w", "-t", "60", "-o",
                   f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.dir} "
                   f"{'' if self.durable else '-c fsync=off '}"
                   f"-c max_connections={self.max_connections}", "start"],
                  "did not start")

    def start(self) -> None:
        """A new cluster, started (``PgServerError`` when it does not start)."""
        if self.missing or not self.initdb:
            raise PgServerError(self.missing or MISSING)
        self.dir = Path(tempfile.mkdtemp(prefix="stationd-pg-"))
        if os.geteuid() == 0:
            nobody = pwd.getpwnam("nobody")
            os.chown(self.dir, nobody.pw_uid, nobody.pw_gid)
        os.chmod(self.dir, 0o700)
        self.port = _free_port()
        try:
            self._run([self.initdb, "-D", str(self.dir / "data"), "-A", "trust", "-U",
                       "postgres", "--no-sync", "-E", "UTF8"], "cluster not made")
            self._pg_start()
        except PgServerError:
            shutil.rmtree(self.dir, ignore_errors=True)
            self.dir = None
            raise
        self._watch()

    def _stop_argv(self) -> list[str]:
        pg_ctl, data = self._data()
        return self._as_user([pg_ctl, "-D", data, "-m", "immediate", "-w", "stop"])

    def _watch(self) -> None:
        """The watcher that stops this server when its owner dies without ``stop()``."""
        import json

        self._watcher = subprocess.Popen(  # noqa: S603 - our own interpreter and module
            [sys.executable, "-c", _WATCH, str(os.getpid()), str(self.dir),
             json.dumps(self._stop_argv())],
            start_new_session=True, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, cwd="/",
            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)})

    def pause(self) -> None:
        """The server goes down (its data kept): the line database is unreachable."""
        pg_ctl, data = self._data()
        self._run([pg_ctl, "-D", data, "-m", "fast", "-w", "stop"], "did not stop")

    def resume(self) -> None:
        """The server back on the same port with its data."""
        self._pg_start()

    def url(self, db: str = "postgres") -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{db}"

    def create(self, db: str) -> str:
        """A new empty database; its URL."""
        import psycopg

        with psycopg.connect(f"host=127.0.0.1 port={self.port} user=postgres dbname=postgres",
                             autocommit=True) as c:
            c.execute(f'CREATE DATABASE "{db}"')
        return self.url(db)

    def stop(self) -> None:
        """Down at once and removed; safe to call twice."""
        if self.dir is None or self.pg_ctl is None:
            return
        _down(self._stop_argv(), self.dir)
        self.dir = None
        if self._watcher is not None:
            self._watcher.kill()
            self._watcher.wait()
            self._watcher = None


__all__ = ["MISSING", "PgServer", "PgServerError"]
