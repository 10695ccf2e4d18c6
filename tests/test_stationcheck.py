"""What the station's checks do beside a running daemon's database, with SQLite's own locks
and a second process (tests/test_config.py holds the checks' findings)."""

from __future__ import annotations

import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from stationd.stationcheck import more_errors

SIM = Path(__file__).resolve().parents[1] / "config" / "sim"
ROWS = "import sqlite3, sys; print(sqlite3.connect(sys.argv[1]).execute(" \
       "'SELECT count(*) FROM t').fetchone()[0])"


@pytest.mark.system
def test_a_refused_reload_keeps_the_daemon_s_locks_and_its_wal(tmp_path: Path) -> None:
    """The daemon's connection (WAL, as the station's) stays open while a refused reload
    counts the file's further errors in its process; another program then opens and closes
    the database (a backup, a `db import`): it must see the daemon's connection, keep the WAL,
    and every row written after is read by a third (a newcomer's trial lost them)."""
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    sim_copy = tmp_path
    db = sim_copy / "station.db"
    station = sim_copy / "station.yaml"
    station.write_text(station.read_text().replace("sqlite:///stationd-sim.db",
                                                   f"sqlite:///{db}"))
    daemon = sqlite3.connect(db, isolation_level=None)
    try:
        assert daemon.execute("PRAGMA journal_mode=WAL").fetchone()[0] == "wal"
        daemon.execute("CREATE TABLE t (x)")
        daemon.execute("INSERT INTO t VALUES (1)")
        more_errors(station)
        subprocess.run([sys.executable, "-c", ROWS, str(db)], check=True,
                       capture_output=True)
        assert (sim_copy / "station.db-wal").exists()
        daemon.execute("INSERT INTO t VALUES (2)")
        read = subprocess.run([sys.executable, "-c", ROWS, str(db)], check=True,
                              capture_output=True, text=True)
        assert read.stdout.strip() == "2"
    finally:
        daemon.close()
