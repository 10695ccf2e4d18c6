"""The forwarder with the daemon (``station_proc.py``: the real serve loop, its PLC and
controller on loopback) and a real PostgreSQL server for the line: every result reaches the
line database; while the line database is down the station goes on tightening, the status
API shows the backlog and the journal says so; when it is back the backlog is forwarded."""

from __future__ import annotations

import json
import urllib.request
from typing import Any

import pytest

from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim.controller import SimController
from stationd.sim.devices_cli import psets_of
from tests.pgserver import PgServer
from tests.shell.daemons import SIM, Proc, at_height, free_port, until
from tests.test_forward import _line_rows

VIN = "LINEVIN0000000001"


def _get(port: int, path: str) -> dict[str, Any]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as r:
        return dict(json.loads(r.read()))


def _status(port: int) -> dict[str, Any]:
    return _get(port, "/api/status")


@pytest.mark.timeout(300)
def test_results_reach_the_line_database_and_wait_while_it_is_down(tmp_path):
    pg = PgServer()
    if pg.missing:
        pytest.skip(pg.missing)
    pg.start()
    lift_port, ctl_port, http_port = free_port(), free_port(), free_port()
    url = pg.create("line")
    plc = SimulatedPlc()
    ctl = SimController(psets_of(SIM / "bolts.yaml"), seed=10, nok_rate=0.0)

    def edit(text: str) -> str:
        return text + (f"\nhttp: {{listen: '127.0.0.1:{http_port}'}}\n"
                       f"line: {{url: '{url}', station_id: ST-T1}}\n")

    d = Proc(tmp_path, lift_port, ctl_port, edit=edit)
    pose = tmp_path / "pose"
    try:
        at_height(d, plc, ctl, lift_port, ctl_port, VIN)

        def tighten(bolt: str) -> int:
            pose.write_text(bolt)
            d.wait_log(f"tightening bolt {bolt}")
            until(lambda: ctl.tool_enabled, 30, "tool enabled")
            shot = ctl.pull_trigger()
            assert shot is not None
            until(lambda: shot.tightening_id in ctl.acked_ids, 30, "stored")
            pose.write_text("")
            return int(shot.tightening_id)

        # what the controller said it is (MID 0002) reaches the devices panel through the
        # station's core, as every report of the station's state does
        until(lambda: "identity" in _get(http_port, "/api/view")["devices"]["wrench"], 30,
              "the controller's identity on the devices panel")
        first = tighten("B05")
        until(lambda: any(r.record.get("tightening_id") == first
                          for r in _line_rows(url, "ST-T1")), 30, "on the line")
        # the row is visible at the line's commit, the forwarder's status a moment after
        until(lambda: (_status(http_port)["line"] or {}).get("up") is True, 10,
              "the status says it is up")
        pg.pause()                                  # the line database goes away
        second = tighten("B06")                  # the station goes on tightening
        until(lambda: (_status(http_port)["line"] or {}).get("up") is False, 60,
              "the status says it is down")
        st = _status(http_port)["line"]
        assert st["backlog"] >= 1 and st["last_error"]
        assert st["backlog_bytes"] >= 300 and st["alarm"] is None   # sized, under its bound
        # the screens' snapshot carries it too (the operator's devices panel), within a
        # heartbeat
        until(lambda: (_get(http_port, "/api/view").get("line") or {}).get("up") is False,
              30, "the screens' snapshot says the line database is down")
        d.wait_log("line database: down")
        pg.resume()
        until(lambda: {first, second} <= {r.record.get("tightening_id")
                                          for r in _line_rows(url, "ST-T1")}, 120,
              "the backlog forwarded")
        until(lambda: _status(http_port)["line"]["backlog"] == 0, 30, "caught up")
        seqs = [r.seq for r in _line_rows(url, "ST-T1")]
        assert sorted(seqs) == sorted(set(seqs))                  # none twice
        assert d.stop() == 0
    finally:
        d.kill()
        ctl.close()
        plc.close()
        pg.stop()
    assert "Traceback" not in d.log()
