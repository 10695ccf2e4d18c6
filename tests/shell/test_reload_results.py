"""A reload (SIGHUP) while the station owes a result loses nothing: the daemon as systemd runs
it (``station_proc.py``), its lift PLC (Modbus TCP) and controller (Open Protocol TCP) served
from this process on loopback.

Three moments, each on its own bolt of one vehicle: the reload right at the enable (the
trigger pulled as it begins), during a rundown (the result comes on the reloaded station's
link), and with a result in flight (pushed as the reload begins); then a restart after a
kill -9 during a rundown.  Each result must be in the
database once, attributed to the bolt the tool was enabled for, and acknowledged.  The
controller sends results nobody acknowledged again to its next subscriber, as the
independent controller that found the loss did."""

from __future__ import annotations

import signal
import time

import pytest

from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim.controller import SimController
from stationd.boltfile import load_bolts
from stationd.sim.devices_cli import psets_of
from tests.shell.daemons import SIM, Proc, at_height, free_port, until
from tests.shell.daemons import db_rows as _rows

VIN = "RELOADVIN00000001"


def _subscribed(ctl: SimController) -> bool:
    return any(s.started and s.subscribed for s in ctl.call(ctl.sessions))


@pytest.mark.timeout(420)
def test_a_reload_at_the_enable_during_a_rundown_and_in_flight_records_each_result_once(
        tmp_path):
    lift_port, ctl_port = free_port(), free_port()
    plc = SimulatedPlc()
    ctl = SimController(psets_of(SIM / "bolts.yaml"), seed=3, nok_rate=0.0,
                        resend_unacked=True)
    bolts = [b.bolt_id for b in load_bolts(SIM / "bolts.yaml").models[0].bolts]
    d = Proc(tmp_path, lift_port, ctl_port)
    pose = tmp_path / "pose"
    reloads = 0
    logs: list[str] = []
    try:
        at_height(d, plc, ctl, lift_port, ctl_port, VIN)

        def enabled_on(bolt: str) -> None:
            pose.write_text(bolt)
            d.wait_log(f"tightening bolt {bolt}")
            until(lambda: ctl.tool_enabled, 30, "tool enabled")

        def reload_begins() -> None:
            nonlocal reloads
            reloads += 1
            d.p.send_signal(signal.SIGHUP)

        def reloaded() -> None:
            d.wait_log("configuration reloaded", count=reloads)
            until(lambda: _subscribed(ctl), 60, "the reloaded station subscribed")

        got: dict[str, int] = {}
        # 1. at the enable: the trigger pulled as the reload begins, the rundown ends while
        # the station is reloading (its tool disabled, its link closing or closed)
        enabled_on(bolts[0])
        reload_begins()
        assert ctl.start_rundown()
        pose.write_text("")
        time.sleep(0.3)
        got[bolts[0]] = ctl.finish_rundown().tightening_id
        reloaded()
        # 2. during a rundown: its result comes on the reloaded station's link
        d.wait_log("tracking: tracking the wrench", count=reloads + 1)
        enabled_on(bolts[1])
        assert ctl.start_rundown()
        reload_begins()
        pose.write_text("")
        reloaded()
        got[bolts[1]] = ctl.finish_rundown().tightening_id
        # 3. a result in flight: pushed as the reload begins
        d.wait_log("tracking: tracking the wrench", count=reloads + 1)
        enabled_on(bolts[2])
        shot = ctl.pull_trigger()
        reload_begins()
        assert shot is not None
        got[bolts[2]] = shot.tightening_id
        pose.write_text("")
        reloaded()
        until(lambda: set(got.values()) <= set(ctl.acked_ids), 60,
              f"results {sorted(got.values())} acknowledged (acked: {ctl.acked_ids})")
        assert d.p.poll() is None
        # 4. a restart: killed (-9) during a rundown, its tool left on; the restarted
        # station turns the tool off and records the result to the bolt it was enabled for
        d.wait_log("tracking: tracking the wrench", count=reloads + 1)
        enabled_on(bolts[3])
        assert ctl.start_rundown()
        d.kill()
        d.sock.close()
        (tmp_path / "notify").unlink()
        pose.write_text("")
        logs.append(d.log())
        d = Proc(tmp_path, lift_port, ctl_port)
        until(lambda: _subscribed(ctl), 60, "the restarted station subscribed")
        got[bolts[3]] = ctl.finish_rundown().tightening_id
        until(lambda: got[bolts[3]] in ctl.acked_ids, 60, "the result acknowledged")
        assert not ctl.tool_enabled
        assert d.stop() == 0
    finally:
        d.kill()
        ctl.close()
        plc.close()
    db = str(tmp_path / "station.db")
    stored = _rows(db, "SELECT r.tightening_id, b.code FROM tightening_records r "
                       "JOIN bolts b ON b.id = r.bolt_id ORDER BY r.tightening_id")
    logs.append(d.log())
    assert stored == sorted((tid, bolt) for bolt, tid in got.items()), logs[-1][-3000:]
    assert _rows(db, "SELECT tightening_id FROM unattributed_results") == []
    assert not any("Traceback" in text for text in logs)
    assert f"the tool was enabled for bolt {bolts[3]} of {VIN}" in logs[-1]   # resumed
    assert f"the tool was enabled for bolt {bolts[1]} of {VIN}" in logs[0]
