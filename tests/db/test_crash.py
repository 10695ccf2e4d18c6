"""A writer killed with SIGKILL loses nothing that ``record_tightening`` had returned."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time

from db.repository import Repository
from stationd.boltfile import import_bolts
from tests.db.conftest import ROOT, record, url_of

WRITER = """
import sys
from db.repository import Repository
repo = Repository.open(sys.argv[1])
for i in range(100000):
    repo.record_tightening("VIN1", "B1", ok=i % 2 == 0, position_mm=(1, 2, 3),
                           match_distance_mm=0.5, tilt_deg=1.0, torque_nm=50.0,
                           angle_deg=30.0, tightening_id=i)
    print(i, flush=True)  # after the commit: this id is on disk
"""


def test_sigkilled_writer_leaves_every_committed_record(tmp_path, bolts_file):
    url = url_of(tmp_path / "station.db")
    with Repository.open(url) as repo:
        import_bolts(repo, bolts_file)
        repo.start_vehicle("VIN1", "SEDAN")
        record(repo, "VIN1", "B2")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", WRITER, url], stdout=subprocess.PIPE,
                            text=True, env=env, cwd=tmp_path)
    assert proc.stdout is not None
    printed = []
    deadline = time.monotonic() + 20
    while len(printed) < 40 and time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        printed.append(int(line))
    os.kill(proc.pid, signal.SIGKILL)  # mid-stream: most likely inside the next transaction
    proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL and len(printed) >= 40
    raw = sqlite3.connect(tmp_path / "station.db")
    assert raw.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    raw.close()
    with Repository.open(url) as repo:  # opens (and recovers the WAL) like any other start
        report = repo.vehicle_report("VIN1")
        with repo.engine.connect() as c:
            ids = {r[0] for r in c.exec_driver_sql(
                "SELECT tightening_id FROM tightening_records WHERE tightening_id IS NOT NULL")}
        assert set(printed) <= ids  # every printed (committed) record is there
        assert len(ids) <= len(printed) + 1  # at most the one being committed at the kill
        b1 = report.bolts[0]
        assert b1.attempts == len(ids) and b1.tightening_id == max(ids)
        record(repo, "VIN1", "B3")  # and the database takes writes again
