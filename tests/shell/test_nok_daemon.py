"""The NOK policy's loosen strategy through the running daemon (``station_proc.py``: the real
serve loop, its lift PLC over Modbus TCP and its controller over Open Protocol on loopback):
after a NOK the next parameters sent for the bolt are its loosen pset, after a loosening its
tightening pset again; a third NOK (a loosening that fails counts) locks it: nothing is sent
and the tool stays off, with the typed reason; an operator's release through the API is
refused, a supervisor's accepted; then loosened and tightened OK.  Every rundown (its kind and
time) and every command (its user and time) is in the records, ``db report`` and the export."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from pathlib import Path

import pytest

from drivers.wrench.sim.controller import SimController, SimPset, SimTightening
from stationd.sim.devices_cli import psets_of
from tests.shell.daemons import SIM, Proc, free_port, tracking, until
from tests.shell.test_commands_daemon import PASSWORD, Client, _station

ROOT = Path(__file__).resolve().parents[2]
VIN = "LOOSENVIN00000001"
LOOSEN_PSET = 90
#: the controller's loosening program: wide limits (a joint that comes loose is OK)
LOOSEN = SimPset(40.0, 5.0, 150.0, 360.0, 90.0, 720.0, name="loosen")
#: B05 (pset 2) is loosened before it is tightened again; every other bolt repeats
TOOL_ON = "tightening: tightening bolt B05"   # the state in which the tool is on for it
LOOSENING_ON = "tightening: loosening bolt B05"  # ... for its loosen pset
POLICY = (f"nok:\n  max_nok: 3\n  bolts:\n    B05: {{strategy: loosen, loosen_pset: "
          f"{LOOSEN_PSET}}}\n")


def nok_station(http_port: int) -> object:
    """config/sim with the screens on ``http_port``, users olga (operator: skip) and sam
    (supervisor: skip, reopen, release, loosen), and :data:`POLICY`."""
    def edit(text: str) -> str:
        return str(_station(http_port)(text)).replace(
            "    supervisor: [skip, reopen]\n",
            "    supervisor: [skip, reopen, release, loosen]\n") + POLICY
    return edit


def controller(seed: int) -> SimController:
    """The simulated controller with the table's psets and the loosen program; every
    tightening NOK until the test says otherwise."""
    return SimController({**psets_of(SIM / "bolts.yaml"), LOOSEN_PSET: LOOSEN}, seed=seed,
                         nok_rate=1.0)


def rundown(d: Proc, ctl: SimController, pose: Path, n: int, *, pset: int,
            loosening: bool = False) -> SimTightening:
    """The wrench onto B05 until the tool is on for it the ``n``-th time, with ``pset``
    selected on the controller; the trigger pulled; the result stored (acknowledged)."""
    pose.write_text("B05")
    # the tool on for B05 the n-th time: for its tightening pset or (said so) its loosen pset
    until(lambda: d.log().count(TOOL_ON) + d.log().count(LOOSENING_ON) >= n, 90,
          f"the tool on for B05 {n} time(s)")
    log = d.log()     # the journal says which: "loosening bolt" for the loosen pset
    assert (log.rfind(LOOSENING_ON) > log.rfind(TOOL_ON)) == loosening, log[-2000:]
    until(lambda: ctl.tool_enabled, 30, "tool enabled")
    assert ctl.pset == pset
    shot = ctl.pull_trigger(result_type=2 if loosening else 1)
    assert shot is not None
    until(lambda: shot.tightening_id in ctl.acked_ids, 30, "result stored")
    pose.write_text("")
    return shot


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "stationd", *args], capture_output=True,
                          text=True, timeout=60, check=False,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


def command(c: Client, kind: str, comment: str = "") -> tuple[int, dict[str, object]]:
    nonce = json.loads(c.get("/api/nonce"))["nonce"]
    status, text = c.post("/api/commands", {"kind": kind, "vin": VIN, "bolt": "B05",
                                            "comment": comment, "nonce": nonce})
    return status, json.loads(text)


@pytest.mark.timeout(300)
def test_loosen_strategy_lock_and_release_through_the_daemon(tmp_path):
    http_port = free_port()
    url = f"http://127.0.0.1:{http_port}/"
    pose = tmp_path / "pose"
    with tracking(tmp_path, VIN, edit=nok_station(http_port), ctl=controller(seed=11)
                  ) as (d, _, ctl):
        # a NOK -> the loosen pset goes next; a loosening OK -> the tightening pset again
        assert not rundown(d, ctl, pose, 1, pset=2).ok
        d.wait_log(f"B05: loosen first (loosen pset {LOOSEN_PSET}), then tighten")
        assert "B05: B05:" not in d.log()      # the bolt named once
        ctl.nok_rate = 0.0
        assert rundown(d, ctl, pose, 2, pset=LOOSEN_PSET, loosening=True).ok
        d.wait_log(f"bolt selected: B05: loosen first (pset {LOOSEN_PSET})")
        d.wait_log("B05 loosened: its tightening pset goes next")
        ctl.nok_rate = 1.0
        assert not rundown(d, ctl, pose, 3, pset=2).ok   # NOK 2
        # a loosening that fails counts: the third NOK in a row locks the bolt
        assert not rundown(d, ctl, pose, 4, pset=LOOSEN_PSET, loosening=True).ok
        d.wait_log("B05 locked after 3 NOK in a row: a supervisor releases it")

        # locked: the wrench on it sends nothing and the tool stays off, with the reason
        sent = ctl.pset
        pose.write_text("B05")
        d.wait_log("no bolt: B05 locked after 3 NOK in a row")
        c = Client(url)
        view = json.loads(c.get("/api/view"))
        [b05] = [b for b in view["bolts"] if b["bolt"] == "B05"]
        assert b05["locked"] and b05["state"] == "locked", b05
        assert not ctl.tool_enabled and ctl.pset == sent
        assert d.log().count(TOOL_ON) + d.log().count(LOOSENING_ON) == 4   # no fifth

        # the operator may not release it (API: 409 with the typed reason), sam may
        assert c.post("/api/login", {"user": "olga", "password": PASSWORD})[0] == 200
        status, answer = command(c, "release", "try again")
        assert status == 409 and answer["reason"] == {
            "kind": "no right", "right": "release",
            "words": "your role does not have the right to release"}, answer
        assert c.post("/api/login", {"user": "sam", "password": PASSWORD})[0] == 200
        status, answer = command(c, "loosen", "rework")
        # ordered already (its kind says so: "loosen first" read as an instruction)
        assert status == 409 and answer["reason"]["kind"] == "loosen ordered", answer
        status, answer = command(c, "release", "thread checked")
        assert status == 200 and answer["accepted"], answer
        status, answer = command(c, "release", "again")   # released already: nothing changes
        assert status == 409 and answer["reason"]["kind"] == "not locked", answer

        # released, still to be loosened first: the loosen pset, then the tightening one
        pose.write_text("")
        ctl.nok_rate = 0.0
        assert rundown(d, ctl, pose, 5, pset=LOOSEN_PSET, loosening=True).ok
        assert rundown(d, ctl, pose, 6, pset=2).ok
        d.wait_log("tracking: bolt B05 OK; tracking")
        export = c.get(f"/api/vehicles/{VIN}/export.csv")

    # the records: every rundown with its kind, time and pset; the commands with their user
    runs = [r for r in csv.DictReader(io.StringIO(export)) if r["bolt"] == "B05"]
    # the release a row of its own, where it was given (after the NOK that locked it)
    assert [(r["rundown"], r["status"], r["pset"]) for r in runs] == [
        ("tightening", "nok", "2"), ("loosening", "ok", "90"), ("tightening", "nok", "2"),
        ("loosening", "nok", "90"), ("", "locked", ""), ("", "released", ""),
        ("loosening", "ok", "90"), ("tightening", "ok", "2")]
    runs = [r for r in runs if r["status"] not in ("locked", "released")]
    assert all(r["recorded_at"] for r in runs)
    got = cli("db", "report", VIN, "--db", f"sqlite:///{tmp_path}/station.db", "--json")
    assert got.returncode == 1, got.stderr   # 1: the vehicle is incomplete (49 missing)
    report = json.loads(got.stdout)
    [b05] = [b for b in report["bolts"] if b["bolt"] == "B05"]
    assert (b05["status"], b05["kind"], b05["attempts"]) == ("ok", "tightening", 6)
    assert [(c["user"], c["kind"], c["bolt"], c["comment"]) for c in report["commands"]
            if c["kind"] != "refused"] == [
        ("station", "lock", "B05", "3 NOK in a row"),     # the NOK policy's, recorded
        ("sam", "release", "B05", "thread checked")]
    # the refused ones kept as attempts: olga's release, sam's loosen and second release
    assert [(c["user"], c["bolt"], c["comment"].split(" ", 1)[0]) for c in report["commands"]
            if c["kind"] == "refused"] == [("olga", "B05", "release"), ("sam", "B05", "loosen"),
                                           ("sam", "B05", "release")]
    assert report["commands"][0]["at"]
    assert [(r["rundown"], r["status"], r["pset"]) for r in report["rundowns"]] == [
        (r["rundown"], r["status"], int(r["pset"])) for r in runs]
    text = cli("db", "report", VIN, "--db", f"sqlite:///{tmp_path}/station.db").stdout
    assert "release B05 by sam (screen 127.0.0.1) at " in text and ": thread checked" in text
    assert "    4. loosening NOK pset 90, " in text and "    6. tightening OK pset 2, " in text
