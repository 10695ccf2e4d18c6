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


def _exposed_station(folder: Path, *, careful: bool) -> Path:
    """config/sim with screens holding a token, an images folder and an OPC UA server:
    ``careful`` as the README says to install them, else as a security review found them."""
    from stationd.access import hash_password

    for f in SIM.iterdir():
        shutil.copy(f, folder)
    station = folder / "station.yaml"
    images = folder / "images" if careful else folder
    opcua = ("{endpoint: 'opc.tcp://0.0.0.0:4840', security: [none], anonymous: false, "
             f"users: {{mes: '{hash_password('mes-password', salt=b'a-test-salt-16b.')}'}}}}"
             if careful else "{endpoint: 'opc.tcp://0.0.0.0:4840', security: [none]}")
    text = station.read_text().replace("sqlite:///stationd-sim.db",
                                       f"sqlite:///{folder / 'station.db'}")
    text = "\n".join(line for line in text.splitlines() if not line.startswith("http:"))
    station.write_text(text + "\nhttp: {listen: '127.0.0.1:8080', token: "
                       "'a-token-long-enough-1'}\n"
                       f"records: {{images_dir: '{images}'}}\nopcua: {opcua}\n")
    station.chmod(0o640 if careful else 0o644)
    return station


def test_what_the_station_gives_away_is_warned_of(tmp_path: Path) -> None:
    """A security review: a token in a file every user reads, an images folder (served to
    the token's holders) that holds the database, an OPC UA server anonymous clients read
    from the network; none of it an error (the daemon runs as written)."""
    from stationd.stationcheck import check_station

    (tmp_path / "given").mkdir()
    found = check_station(_exposed_station(tmp_path / "given", careful=False))
    assert not found.errors
    said = [str(w) for w in found.warnings]
    assert any("http: the token is in a file every user of this machine may read" in w
               for w in said), said
    assert any("holds the station's database" in w and "images only" in w for w in said)
    assert any("anonymous clients may browse, read and subscribe" in w for w in said)
    (tmp_path / "kept").mkdir()
    found = check_station(_exposed_station(tmp_path / "kept", careful=True))
    assert not found.errors
    assert not [w for w in map(str, found.warnings)
                if "may read" in w or "holds the" in w or "anonymous" in w]
