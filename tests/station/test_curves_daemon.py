"""The daemon with curves on (``?curves=1``): a rundown's angle and torque traces are stored
with it, by tightening id, and the results page's JSON carries them."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from db.repository import Repository
from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim import SimController
from stationd.sim.devices_cli import psets_of
from stationd.web.results import Results
from tests.station.test_daemon_faults import SIM, Proc, _free_port, at_height
from tests.station.test_restart import _until


@pytest.mark.timeout(300)
def test_the_daemon_stores_each_rundown_with_its_curves(tmp_path):
    lift_port, ctl_port = _free_port(), _free_port()
    plc = SimulatedPlc()
    ctl = SimController(psets_of(SIM / "bolts.yaml"), seed=9, nok_rate=0.0)
    url = f"openprotocol://127.0.0.1:{ctl_port}"
    d = Proc(tmp_path, lift_port, ctl_port, edit=lambda t: t.replace(url, url + "?curves=1"))
    pose = tmp_path / "pose"
    vin = "CURVEVIN000000001"
    try:
        at_height(d, plc, ctl, lift_port, ctl_port, vin)
        pose.write_text("B05")
        d.wait_log("tightening bolt B05")
        _until(lambda: ctl.tool_enabled, 30, "tool enabled")
        first = ctl.pull_trigger()
        assert first is not None
        _until(lambda: first.tightening_id in ctl.acked_ids, 30, "the result stored")
        _until(lambda: ctl.curve_acks == 2, 30, "both curves acknowledged")
        d.wait_log("tightening curves subscribed")
        _until(lambda: _count(tmp_path) == 2, 30, "both curves stored")
        assert d.stop() == 0
    finally:
        d.kill()
        ctl.close()
        plc.close()
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
    assert "Traceback" not in d.log()


def _count(tmp: Path) -> int:
    con = sqlite3.connect(tmp / "station.db")
    try:
        return int(con.execute("SELECT count(*) FROM curves").fetchone()[0])
    except sqlite3.OperationalError:
        return 0
    finally:
        con.close()
