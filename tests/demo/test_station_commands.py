"""People's commands during ``stationd demo``: the demo's screens take them to the demo's
station as the daemon's take them to its own (``stationd skip|reopen|release|loosen``
answered "HTTP 503: the station is not serving yet" for the whole run and the hold).  The demo
runs as a process on one pair of config/sim with an ``access:`` section; the commands go
through the command line, as a person types them."""

from __future__ import annotations

import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import yaml

from stationd.access import hash_password
from stationd.sim.vin import is_valid
from tests.shell.daemons import SIM, free_port
from tests.shell.test_commands_daemon import Client

ROOT = Path(__file__).resolve().parents[2]
PASSWORD = "supervise-it-well"  # noqa: S105 - a test user's


def _station(tmp: Path, port: int) -> Path:
    for f in SIM.glob("*.yaml"):
        (tmp / f.name).write_text(f.read_text())
    doc = yaml.safe_load((tmp / "station.yaml").read_text())
    doc["pairs"] = {"pair1": doc["pairs"]["pair1"]}
    doc["cameras"] = {n: c for n, c in doc["cameras"].items() if n.startswith("pair1_")}
    doc["matching"]["max_age_s"] = 5.0     # a loaded machine renders late: not this test's
    doc["http"] = {"listen": f"127.0.0.1:{port}"}
    doc["access"] = {"users": {"sue": {"role": "supervisor",
                                       "password": hash_password(PASSWORD)},
                               "ed": {"role": "engineer",
                                      "password": hash_password(PASSWORD)}}}
    path = tmp / "station.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.mark.timeout(300)
def test_commands_reach_the_demos_station_during_the_run_and_the_hold(tmp_path):
    port = free_port()
    station = _station(tmp_path, port)
    env = {**os.environ, "STATIOND_PASSWORD": PASSWORD, "PYTHONPATH": str(ROOT)}
    url = f"http://127.0.0.1:{port}/"
    named = f"station DEMO-1 at {url} ({station.resolve()})\n"   # each command's first line
    demo = subprocess.Popen([sys.executable, "-m", "stationd", "demo", "--config",
                             str(station), "--cycles", "1", "--seed", "11", "--hold"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=tmp_path)
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert demo.stdout is not None
        for line in demo.stdout:
            lines.put(line.rstrip("\n"))
    threading.Thread(target=pump, daemon=True).start()

    def expect(start: str, timeout: float = 180) -> str:
        while True:
            line = lines.get(timeout=timeout)
            if line.startswith(start):
                return line

    def expect_re(pattern: str, timeout: float = 60) -> str:
        while True:
            line = lines.get(timeout=timeout)
            if re.fullmatch(pattern, line):
                return line

    def command(*words: str) -> subprocess.CompletedProcess[str]:
        # the demo's station is found by its station file, as a daemon's is
        got = subprocess.run([sys.executable, "-m", "stationd", *words, "--user", "sue",
                              "--config", str(station)], capture_output=True, text=True,
                             env=env, timeout=60, check=False)
        assert got.stdout.startswith(named), got
        return got

    try:
        # the demo's vehicle: its own VIN, the run's id in its serial part (issue 30, item 7)
        said = expect("vehicle: ")
        vin = said.split()[1]
        assert is_valid(vin) and vin[-6:] == said.split("run id ")[1][:6]
        expect("screens: ")
        # during the run: the station answers (whatever it answers), never 503
        during = command("reopen", vin)
        assert during.returncode in (0, 1), during
        assert "503" not in during.stderr and "not serving" not in during.stderr
        assert f"command reopen {vin} by sue (cli " in during.stdout
        expect("run over")
        # the hold: the vehicle left the lift incomplete (closed): a supervisor reopens it
        held = command("reopen", vin)
        assert held.returncode == 0, held
        assert held.stdout.strip().endswith(": accepted: it opens as a rework when it is at "
                                            "the station (its skips before no longer count)")
        # journaled in the demo's output as in the daemon's journal: accepted ones too (issue
        # 30, item 5: a reopen, a teach start and stop left no line), with a time stamp
        stamp = r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}[+-]\d{4} "
        line = expect_re(stamp + rf"command reopen {vin}.* by sue \(cli 127\.0\.0\.1\): "
                         r"accepted: it opens as a rework when it is at the station \(its skips "
                         r"before no longer count\)$")
        # no vehicle on the lift now: the station's no
        skip = command("skip", vin, "B01", "--comment", "no access")
        assert skip.returncode == 1 and "no vehicle at the station" in skip.stdout, skip
        expect_re(stamp + rf"command skip B01 of {vin}.* by sue \(cli 127\.0\.0\.1\): "
                  "refused: no vehicle at the station.*")
        c = Client(url)
        assert c.post("/api/login", {"user": "ed", "password": PASSWORD})[0] == 200
        for body in ({"kind": "teach-start", "model": "SIM-1"}, {"kind": "teach-stop"}):
            nonce = json.loads(c.get("/api/nonce"))["nonce"]
            status, text = c.post("/api/commands", {**body, "nonce": nonce})
            assert status == 200, text
        expect_re(stamp + r"command teach-start SIM-1 by ed \(screen 127\.0\.0\.1\): "
                  "accepted$")
        expect_re(stamp + r"command teach-stop by ed \(screen 127\.0\.0\.1\): accepted$")
        assert line
        # the simulated operator signed in at the demo's station: its rundowns carry it
        status = subprocess.run([sys.executable, "-m", "stationd", "operator", "status",
                                 "--url", url], capture_output=True, text=True, env=env,
                                timeout=60, check=False)
        assert status.stdout == f"{named}operator: operator signed in\n", status
    finally:
        demo.send_signal(signal.SIGINT)
        demo.wait(timeout=60)
    assert demo.returncode == 0
    said = expect("rundowns recorded, by who was signed in at the station: ", timeout=10)
    assert "by user 'operator'" in said, said
