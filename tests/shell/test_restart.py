"""A vehicle across daemon restarts: SIGTERM mid-tightening disables the tool and loses
nothing; SIGKILL leaves a database that opens and holds every result the controller was told
is stored; the restarted daemon resumes the vehicle without sending a done bolt again.

The lift PLC and the controller run in this process, on loopback, as separate machines would;
the daemon is a real ``stationd run`` process (``station_proc.py`` adds the simulated world
its ``sim://`` cameras need)."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from db.repository import Repository
from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim.controller import SimController
from stationd.boltfile import load_bolts
from stationd.sim.devices_cli import psets_of
from tests.shell.daemons import PROC, SIM, sim_station, until

VIN = "RESTARTVIN0000001"


def _all_ids(tmp: Path, bolts: bool = False) -> list[int]:
    """Every tightening id in the database: recorded to a bolt, and (unless ``bolts``)
    unattributed."""
    con = sqlite3.connect(tmp / "station.db")
    try:
        ids = [r[0] for r in con.execute("SELECT tightening_id FROM tightening_records")]
        if not bolts:
            ids += [r[0] for r in con.execute("SELECT tightening_id FROM unattributed_results")]
        return ids
    finally:
        con.close()


class Daemon:
    """One ``stationd run`` process; its journal (stderr) goes to a file."""

    def __init__(self, tmp: Path, n: int) -> None:
        self.log_path = tmp / f"daemon{n}.log"
        self._err = self.log_path.open("w")
        self.p = subprocess.Popen([sys.executable, str(PROC), str(tmp / "station.yaml"),
                                   str(tmp / "pose")], cwd=tmp, stderr=self._err,
                                  env={**os.environ, "PYTHONUNBUFFERED": "1"})

    def log(self) -> str:
        return self.log_path.read_text()

    def wait_log(self, needle: str, timeout: float = 90) -> None:
        until(lambda: needle in self.log() or self.p.poll() is not None, timeout,
              f"{needle!r} in the journal")
        assert needle in self.log(), f"exited {self.p.returncode}: {self.log()[-2000:]}"

    def stop(self, sig: int) -> int:
        self.p.send_signal(sig)
        code = self.p.wait(timeout=60)
        self._err.close()
        return code


@pytest.mark.timeout(420)
def test_sigterm_and_sigkill_mid_vehicle_lose_nothing(tmp_path):
    psets = psets_of(SIM / "bolts.yaml")
    bolts = [b.bolt_id for b in load_bolts(SIM / "bolts.yaml").models[0].bolts]
    a, b, c = bolts[0], bolts[17], bolts[33]
    plc = SimulatedPlc()
    ctl = SimController(psets, seed=4, nok_rate=0.0)
    ctl.start()
    pose = tmp_path / "pose"
    pose.write_text("")
    daemons: list[Daemon] = []
    try:
        lift_port, ctl_port = plc.start_tcp(), ctl.listen_tcp()
        sim_station(tmp_path, f"modbus-tcp://127.0.0.1:{lift_port}", ctl_port)
        plc.set_vehicle(1, VIN)
        plc.raise_lift()

        def start() -> Daemon:
            d = Daemon(tmp_path, len(daemons))
            daemons.append(d)
            return d

        def tool_on_for(d: Daemon, bolt: str) -> None:
            pose.write_text(bolt)
            d.wait_log(f"tightening bolt {bolt}")
            until(lambda: ctl.tool_enabled, 30, "tool enabled")

        def tighten(d: Daemon, bolt: str) -> int:
            tool_on_for(d, bolt)
            shot = ctl.pull_trigger()
            assert shot is not None
            until(lambda: shot.tightening_id in ctl.acked_ids, 30, "result acknowledged")
            pose.write_text("")
            until(lambda: not ctl.tool_enabled, 30, "tool disabled after the result")
            return int(shot.tightening_id)

        # 1. a bolt tightened, then SIGTERM in the middle of the next one
        d = start()
        first = tighten(d, a)
        tool_on_for(d, b)
        assert d.stop(signal.SIGTERM) == 0
        assert not ctl.tool_enabled                  # the cycle in progress aborted safely
        assert "stationd stopped" in d.log() and "Traceback" not in d.log()

        # 2. restarted: the vehicle resumes; the done bolt is refused, the aborted one redone
        d = start()
        second = tighten(d, b)
        pose.write_text(a)
        d.wait_log(f"{a} is already done")
        # 3. SIGKILL right after the trigger: the result may or may not be stored, but every
        # result the controller was told is stored must be in the database
        tool_on_for(d, c)
        shot = ctl.pull_trigger()
        assert shot is not None
        assert d.stop(signal.SIGKILL) == -signal.SIGKILL
        acked = list(ctl.acked_ids)
        assert {first, second} <= set(acked)
        con = sqlite3.connect(tmp_path / "station.db")
        try:
            assert con.execute("PRAGMA integrity_check").fetchone() == ("ok",)
            stored = [r[0] for r in con.execute("SELECT tightening_id FROM tightening_records")]
        finally:
            con.close()
        assert set(acked) <= set(stored)
        assert len(stored) == len(set(stored))       # none recorded twice

        # 4. restarted after the kill: the result the killed daemon may not have stored is
        # recorded now (the enable it owed, the results it missed fetched), then the vehicle
        # is closed consistently when the lift lowers
        pose.write_text("")
        d = start()
        d.wait_log("tracking the wrench")
        until(lambda: shot.tightening_id in _all_ids(tmp_path), 60, "the last result stored")
        plc.lower_lift()
        d.wait_log(f"vehicle {VIN} (SIM-1) closed: bolts:")
        assert d.stop(signal.SIGTERM) == 0
    finally:
        for d in daemons:
            if d.p.poll() is None:
                d.p.kill()
                d.p.wait()
        ctl.close()
        plc.close()
    repo = Repository.open(f"sqlite:///{tmp_path}/station.db")
    try:
        report = repo.vehicle_report(VIN)
    finally:
        repo.close()
    status = {r.bolt_id: r.status for r in report.bolts}
    assert status[a] == status[b] == "ok"
    ids = _all_ids(tmp_path)
    assert sorted(ids) == sorted(set(ids)) and shot.tightening_id in ids   # once, not lost
    assert status[c] == ("ok" if shot.tightening_id in _all_ids(tmp_path, bolts=True)
                         else "missing")
    assert report.vehicle.ended_at is not None
    assert sorted(report.missing) == sorted(k for k in bolts if status[k] == "missing")
    assert len(report.missing) == len(bolts) - 2 - (status[c] == "ok")
