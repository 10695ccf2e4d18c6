"""The daemon with curves on (``?curves=1``): a rundown's angle and torque traces are stored
with it, by tightening id, and the results page's JSON carries them."""

from __future__ import annotations

import re
import sqlite3
from pathlib import Path

import pytest

from db.repository import Repository
from stationd.web.results import Results
from tests.shell.daemons import tracking, until


@pytest.mark.timeout(300)
def test_the_daemon_stores_each_rundown_with_its_curves(tmp_path):
    pose = tmp_path / "pose"
    vin = "CURVEVIN000000001"
    with tracking(tmp_path, vin, edit=_curves_on) as (d, _, ctl):
        pose.write_text("B05")
        d.wait_log("tightening bolt B05")
        until(lambda: ctl.tool_enabled, 30, "tool enabled")
        first = ctl.pull_trigger()
        assert first is not None
        until(lambda: first.tightening_id in ctl.acked_ids, 30, "the result stored")
        until(lambda: ctl.curve_acks == 2, 30, "both curves acknowledged")
        d.wait_log("tightening curves subscribed")
        until(lambda: _count(tmp_path) == 2, 30, "both curves stored")
    con = sqlite3.connect(tmp_path / "station.db")
    try:
        rows = list(con.execute("SELECT tightening_id, trace_type, unit, record_id FROM curves"
                                " ORDER BY trace_type"))
        rec = con.execute("SELECT id FROM tightening_records WHERE tightening_id = ?",
                          (first.tightening_id,)).fetchone()[0]
    finally:
        con.close()
    assert [r[:3] for r in rows] == [(first.tightening_id, 1, "deg"),
                                     (first.tightening_id, 2, "Nm")]
    assert {r[3] for r in rows} == {rec}                  # linked to their rundown
    repo = Repository.open(f"sqlite:///{tmp_path / 'station.db'}")
    try:
        doc = Results(repo).vehicle(vin)
    finally:
        repo.close()
    (b05,) = [b for b in doc["bolts"] if b["bolt"] == "B05"]
    curve = b05["rundowns"][0]["curve"]
    assert curve is not None and len(curve["torque_nm"]) == 240
    assert abs(curve["torque_nm"][-1] - first.torque_nm) < 0.02


def _curves_on(text: str) -> str:
    """The station file with ``?curves=1`` on its controller's URL."""
    on, n = re.subn(r"(openprotocol://127\.0\.0\.1:\d+)'", r"\1?curves=1'", text)
    assert n == 1
    return on


def _count(tmp: Path) -> int:
    con = sqlite3.connect(tmp / "station.db")
    try:
        return int(con.execute("SELECT count(*) FROM curves").fetchone()[0])
    except sqlite3.OperationalError:
        return 0
    finally:
        con.close()
