"""A throw-away PostgreSQL server for the tests: Debian's server binaries, a cluster in a temp
folder, on 127.0.0.1 and a free port, as an unprivileged user (``initdb`` and ``pg_ctl`` refuse
to run as root: as root the cluster belongs to ``nobody``).  Where no server can be started
(the package is not installed), the tests that need one are skipped with that reason."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path


def _bin(name: str) -> str | None:
    found = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))
    return found[-1] if found else shutil.which(name)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class PgServer:
    """``PgServer()``: why it cannot start (``missing``), or ``start()`` then ``url(db)``,
    ``create(db)`` and ``stop()``."""

    def __init__(self) -> None:
        self.initdb, self.pg_ctl = _bin("initdb"), _bin("pg_ctl")
        self.missing = None if self.initdb and self.pg_ctl else \
            "PostgreSQL's server is not installed (apt-get install postgresql)"
        self.port = 0
        self.dir: Path | None = None

    def _as_user(self, argv: list[str]) -> list[str]:
        if os.geteuid() != 0:
            return argv
        return ["runuser", "-u", "nobody", "--", *argv]

    def start(self) -> None:
        assert self.initdb and self.pg_ctl, self.missing
        self.dir = Path(tempfile.mkdtemp(prefix="stationd-pg-"))
        if os.geteuid() == 0:
            nobody = pwd.getpwnam("nobody")
            os.chown(self.dir, nobody.pw_uid, nobody.pw_gid)
        os.chmod(self.dir, 0o700)
        data, self.port = self.dir / "data", _free_port()
        subprocess.run(self._as_user([self.initdb, "-D", str(data), "-A", "trust", "-U",
                                      "postgres", "--no-sync", "-E", "UTF8"]),
                       check=True, capture_output=True, cwd=self.dir)
        subprocess.run(self._as_user([
            self.pg_ctl, "-D", str(data), "-l", str(self.dir / "log"), "-w", "-t", "60",
            "-o", f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.dir} "
                  "-c fsync=off -c max_connections=50", "start"]), check=True,
                       capture_output=True, cwd=self.dir)

    def pause(self) -> None:
        """The server goes down (its data kept): the line database is unreachable."""
        assert self.dir is not None and self.pg_ctl
        subprocess.run(self._as_user([self.pg_ctl, "-D", str(self.dir / "data"), "-m", "fast",
                                      "-w", "stop"]), check=True, capture_output=True,
                       cwd=self.dir)

    def resume(self) -> None:
        """The server back on the same port with its data."""
        assert self.dir is not None and self.pg_ctl
        subprocess.run(self._as_user([
            self.pg_ctl, "-D", str(self.dir / "data"), "-l", str(self.dir / "log"), "-w",
            "-t", "60", "-o", f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.dir} "
                              "-c fsync=off -c max_connections=50", "start"]),
                       check=True, capture_output=True, cwd=self.dir)

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
        if self.dir is None or self.pg_ctl is None:
            return
        subprocess.run(self._as_user([self.pg_ctl, "-D", str(self.dir / "data"), "-m",
                                      "immediate", "-w", "stop"]),
                       check=False, capture_output=True, cwd=self.dir)
        shutil.rmtree(self.dir, ignore_errors=True)
        self.dir = None
