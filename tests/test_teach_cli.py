"""Teach-in end to end in the simulator, with a scripted engineer: `stationd teach` against the
running daemon (``station_proc.py``: its serve loop, its PLC over Modbus TCP and controller
over Open Protocol on loopback, the simulated cameras).  The engineer holds the tool on each
bolt in turn (the simulated wrench is put there) and presses Enter; the station measures the
bolt end while its normal cycle is off (nothing is sent), and a new bolt table is written with
the taught positions, compared with the CAD table."""

from __future__ import annotations

import functools
import os
import queue
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim.controller import SimController
from stationd.access import hash_password
from stationd.sim.devices_cli import psets_of
from tests.shell.daemons import SIM, Proc, at_height, free_port, taken, until

ROOT = Path(__file__).resolve().parents[1]
PASSWORD = "teach-me-please"  # noqa: S105 - a test user's
VIN = "TEACHVIN000000001"


def _station(port: int, hashed: str):
    def edit(text: str) -> str:
        return text + (f"\nhttp: {{listen: '127.0.0.1:{port}'}}\naccess:\n  users:\n"
                       f"    ed: {{role: engineer, password: '{hashed}'}}\n"
                       f"    olga: {{role: operator, password: '{hashed}'}}\n")
    return edit


@pytest.mark.timeout(300)
def test_an_engineer_teaches_bolts_and_gets_a_new_table_compared_with_cad(tmp_path):
    lift_port, ctl_port, http_port = free_port(), free_port(), free_port()
    plc = SimulatedPlc()
    ctl = SimController(psets_of(SIM / "bolts.yaml"), seed=11, nok_rate=0.0)
    d = Proc(tmp_path, lift_port, ctl_port, edit=_station(http_port, hash_password(PASSWORD)))
    pose, out = tmp_path / "pose", tmp_path / "taught.yaml"
    env = {**os.environ, "STATIOND_PASSWORD": PASSWORD, "PYTHONPATH": str(ROOT)}
    url = f"http://127.0.0.1:{http_port}/"
    try:
        at_height(d, plc, ctl, lift_port, ctl_port, VIN)
        # an operator may not teach
        got = subprocess.run([sys.executable, "-m", "stationd", "teach", "--model", "SIM-1",
                              "--user", "olga", "--bolts", "B01", "--out", str(out),
                              "--url", url], capture_output=True, text=True, env=env,
                             timeout=60, input="\n", check=False)
        assert got.returncode == 1 and "right to teach" in got.stderr and not out.exists()
        p = subprocess.Popen(
            [sys.executable, "-m", "stationd", "teach", "--model", "SIM-1", "--user", "ed",
             "--from", str(tmp_path / "bolts.yaml"), "--bolts", "B01,B02,B03",
             "--out", str(out), "--url", url],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=env)
        lines: queue.Queue[str] = queue.Queue()

        def pump() -> None:
            assert p.stdout is not None
            for line in p.stdout:
                lines.put(line.rstrip("\n"))
        threading.Thread(target=pump, daemon=True).start()

        def expect(start: str) -> str:
            while True:
                line = lines.get(timeout=90)
                if line.startswith(start):
                    return line

        assert p.stdin is not None
        said: dict[str, str] = {}
        for bolt, answer in (("B01", "\n"), ("B02", "\n"), ("B03", "s\n")):
            expect(f"hold the tool on {bolt}")
            held = bolt if answer == "\n" else ""
            pose.write_text(held)
            d.wait_log("teaching SIM-1 (ed)")
            # the engineer settles the tool: the world has it there before Enter
            until(functools.partial(taken, pose, held), 60, f"the tool on {bolt!r}")
            p.stdin.write(answer)
            p.stdin.flush()
            if answer == "\n":
                said[bolt] = expect(f"{bolt}: ")
        pose.write_text("")
        expect("2 bolts taught")
        assert p.wait(timeout=60) == 0
        assert "tightening bolt" not in d.log() and "selected" not in d.log()
        d.wait_log("teach mode ended")
        assert d.stop() == 0
    finally:
        d.kill()
        ctl.close()
        plc.close()
    cad = {b["id"]: b for b in yaml.safe_load((tmp_path / "bolts.yaml").read_text())
           ["models"]["SIM-1"]["bolts"]}
    new = {b["id"]: b for b in yaml.safe_load(out.read_text())["models"]["SIM-1"]["bolts"]}
    for bolt in ("B01", "B02"):
        moved = np.array(new[bolt]["position"]) - np.array(cad[bolt]["position"])
        assert np.hypot(*moved[:2]) < 2.0, (bolt, moved)            # taught near CAD
        assert "dispersion" in said[bolt] and "CAD" in said[bolt]
        assert new[bolt]["pset"] == cad[bolt]["pset"]               # parameters kept
    assert new["B03"]["position"] == cad["B03"]["position"]         # skipped: as it was
    con = sqlite3.connect(tmp_path / "station.db")
    try:
        rows = list(con.execute("SELECT user, kind, bolt FROM commands ORDER BY id"))
    finally:
        con.close()
    assert rows == [("ed", "teach-start", None), ("ed", "teach-point", "B01"),
                    ("ed", "teach-point", "B02"), ("ed", "teach-stop", None)]


def test_teach_checks_its_output_first_and_says_when_no_daemon_answers(tmp_path):
    env = {**os.environ, "STATIOND_PASSWORD": PASSWORD, "PYTHONPATH": str(ROOT)}

    def teach(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "stationd", "teach", "--model", "SIM-1",
                               "--user", "ed", "--url", f"http://127.0.0.1:{free_port()}/",
                               *args], capture_output=True, text=True, env=env, timeout=60,
                              input="\n", check=False)

    got = teach("--bolts", "B01", "--out", str(tmp_path / "no" / "such" / "t.yaml"))
    assert got.returncode == 2 and "does not exist" in got.stderr
    got = teach("--bolts", "B01,,B02", "--out", str(tmp_path / "t.yaml"))
    assert got.returncode == 2 and "separated by commas" in got.stderr
    got = teach("--bolts", "B01", "--out", str(tmp_path / "t.yaml"))
    assert got.returncode == 3 and "no daemon answers" in got.stderr
    assert "Traceback" not in got.stderr and not (tmp_path / "t.yaml").exists()
    # a sweep: the wrong kind of file as the CAD table is named as such
    (tmp_path / "pic.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    for given, words in ((ROOT / "config" / "sim" / "station.yaml",
                          "this is a station file, not a bolt table"),
                         (tmp_path / "pic.png", "not a text file: it looks like a PNG")):
        got = teach("--from", str(given), "--out", str(tmp_path / "t.yaml"))
        assert got.returncode == 2 and words in got.stderr, got


#: the daemon's runtime alone (stationd.shell.serve), without the command line's simulated world:
#: its sim:// cameras have none, every pair faults at its first grab (a station whose cameras
#: give nothing)
WITHOUT_WORLD = ("import argparse, sys; from stationd.shell.serve import run_daemon; "
                 "sys.exit(run_daemon(argparse.Namespace(config=sys.argv[1])))")


@pytest.mark.timeout(120)
def test_teach_with_every_pair_in_fault_says_so_not_that_no_daemon_answers(tmp_path):
    """The daemon answers but its pairs give no frames: the teach point is answered with the
    station's reason (it said 'no daemon answers at URL: timed out')."""
    http_port = free_port()
    for f in SIM.glob("*.yaml"):
        (tmp_path / f.name).write_text(f.read_text())
    doc = yaml.safe_load((tmp_path / "station.yaml").read_text())
    doc["pairs"] = {"pair1": doc["pairs"]["pair1"]}
    doc["cameras"] = {n: c for n, c in doc["cameras"].items() if n.startswith("pair1_")}
    doc["database"] = {"url": f"sqlite:///{tmp_path / 'station.db'}"}
    doc["http"] = {"listen": f"127.0.0.1:{http_port}"}
    doc["access"] = {"users": {"ed": {"role": "engineer", "password": hash_password(PASSWORD)}}}
    station = tmp_path / "station.yaml"
    station.write_text(yaml.safe_dump(doc, sort_keys=False))
    env = {**os.environ, "STATIOND_PASSWORD": PASSWORD, "PYTHONPATH": str(ROOT)}
    journal = tmp_path / "daemon.log"
    with journal.open("w") as err:
        d = subprocess.Popen([sys.executable, "-c", WITHOUT_WORLD, str(station)], cwd=tmp_path,
                             stderr=err, env=env)
    try:
        end = time.monotonic() + 60
        while "stationd running" not in journal.read_text() and time.monotonic() < end:
            assert d.poll() is None, journal.read_text()
            time.sleep(0.1)
        got = subprocess.run([sys.executable, "-m", "stationd", "teach", "--model", "SIM-1",
                              "--user", "ed", "--bolts", "B01", "--out",
                              str(tmp_path / "t.yaml"), "--url",
                              f"http://127.0.0.1:{http_port}/"], capture_output=True,
                             text=True, env=env, timeout=60, input="\n", check=False)
    finally:
        d.terminate()
        d.wait(timeout=60)
    assert "no daemon answers" not in got.stderr and "Traceback" not in got.stderr
    assert "B01: not taught: a device is in fault: pair1: " in got.stdout, got
    assert "no simulated world for pair 'pair1'" in got.stdout
    assert got.returncode == 1 and not (tmp_path / "t.yaml").exists()
