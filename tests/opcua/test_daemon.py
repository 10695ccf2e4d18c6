"""The OPC UA server with the daemon (``station_proc.py``: the real serve loop, its PLC and
controller on loopback): a bolt tightened at the station is the MES's latest result, read by
a client in its own process (``mes_client.py``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.shell.daemons import free_port, tracking, until

ROOT = Path(__file__).resolve().parents[2]
VIN = "OPCUAVIN000000001"


@pytest.mark.timeout(300)
def test_a_bolt_tightened_at_the_station_is_the_mes_latest_result(tmp_path):
    ua_port = free_port()

    def edit(text: str) -> str:
        return text + (f"\nopcua: {{endpoint: 'opc.tcp://127.0.0.1:{ua_port}', "
                       "station_id: ST-UA, security: [none]}\n")

    pose = tmp_path / "pose"
    with tracking(tmp_path, VIN, seed=12, edit=edit) as (d, _, ctl):
        d.wait_log("OPC UA: serving")
        pose.write_text("B05")
        d.wait_log("tightening bolt B05")
        until(lambda: ctl.tool_enabled, 30, "tool enabled")
        shot = ctl.pull_trigger()
        assert shot is not None
        until(lambda: shot.tightening_id in ctl.acked_ids, 30, "stored")

        def latest() -> dict[str, object] | None:
            got = subprocess.run(
                [sys.executable, str(ROOT / "tests" / "opcua" / "mes_client.py"),
                 f"opc.tcp://127.0.0.1:{ua_port}", "ST-UA"], capture_output=True, text=True,
                timeout=90, env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
            return dict(json.loads(got.stdout)) if got.returncode == 0 else None

        doc: dict[str, object] = {}

        def has_it() -> bool:
            got = latest()
            if got and [20, VIN] in got["entities"]:   # type: ignore[operator]
                doc.update(got)
                return True
            return False

        until(has_it, 90, "the rundown as the latest result")
        assert [23, "B05"] in doc["entities"]
        assert doc["evaluation"] == 1
