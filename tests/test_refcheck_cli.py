"""``stationd calibrate check``: the pairs checked with the cameras opened here (simulated ones,
with the reference markers in their world), each check recorded; while the daemon holds the
station, asked of the running daemon through its API (``--user`` with the calibrate right,
the daemon's verdicts printed and recorded by it); refused without references."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml

from db.checks import checks
from db.repository import Repository
from stationd.access import hash_password
from stationd.cli import main
from stationd.config import load_station_config
from stationd.lock import StationLock, lock_path
from stationd.sim.render import Scene
from stationd.sim.world import World
from tests.localize.refscene import PAIR, R1_PAIR, R2_PAIR, TV, vehicle
from tests.shell.daemons import taken, until
from tests.shell.refstation import station_dir


def _station(tmp_path, references: bool = True):
    (tmp_path / "pair1.yaml").write_text(yaml.safe_dump(PAIR.to_dict()))
    (tmp_path / "pair1.vehicle.yaml").write_text(yaml.safe_dump(TV.to_dict()))
    doc = {"cameras": {"l": {"url": "sim://pair1/left"}, "r": {"url": "sim://pair1/right"}},
           "pairs": {"pair1": {"calibration": "pair1.yaml", "to_vehicle": "pair1.vehicle.yaml",
                               "left": "l", "right": "r"}},
           "lift": {"url": "sim://lift"}, "wrench": {"url": "sim://wrench"},
           "database": {"url": f"sqlite:///{tmp_path / 's.db'}"}}
    if references:
        doc["references"] = {"markers": {"R1": list(vehicle(R1_PAIR)),
                                         "R2": list(vehicle(R2_PAIR))}}
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_check_prints_each_pair_and_records_it(tmp_path, capsys):
    path = _station(tmp_path)
    cfg = load_station_config(path, station=True)
    world = World(SimpleNamespace(pairs=cfg.pairs, marker=cfg.marker, references=cfg.references),
                  seed=2, scene=Scene(texture=0.1, blur_sigma=0.8, noise_sigma=2.0))
    try:
        assert main(["calibrate", "check", "--config", str(path)]) == 0
        out = capsys.readouterr().out
        assert out.startswith("pair1 in place: reference R")
        world.move_pair("pair1", rotation_deg=(0.0, 0.3, 0.0))
        assert main(["calibrate", "check", "--config", str(path), "--json"]) == 1
        got = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    finally:
        world.close()
    assert got["pair1"]["verdict"] == "moved" and got["pair1"]["offset_mm"] > 2.0
    repo = Repository.open(cfg.database_url)
    try:
        assert [c["verdict"] for c in checks(repo, "pair1")] == ["moved", "ok"]
    finally:
        repo.close()


def test_refused_while_the_daemon_holds_the_station_and_without_references(tmp_path, capsys):
    path = _station(tmp_path)
    cfg = load_station_config(path, station=True)
    with StationLock(lock_path(cfg.database_url)):
        assert main(["calibrate", "check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "daemon is running" in err and "calibration-check" in err and "--user" in err
    assert len(err.strip().splitlines()) == 1
    (tmp_path / "bare").mkdir()
    bare = _station(tmp_path / "bare", references=False)
    assert main(["calibrate", "check", "--config", str(bare)]) == 2
    assert "no calibration check configured" in capsys.readouterr().err


@pytest.mark.parametrize("extra", ["references: {markers: {R1: [0, 0, -5000]}}\n"])
def test_a_reference_no_pair_sees_is_bad_input_with_its_line(tmp_path, capsys, extra):
    path = _station(tmp_path, references=False)
    path.write_text(path.read_text() + extra)
    assert main(["calibrate", "check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "station.yaml" in err and "seen by no pair" in err


# -- while the daemon runs: the command goes to it ---------------------------------------------
PASSWORD = "cell-4-password"  # noqa: S105 - a test user's
PROC = Path(__file__).parent / "shell" / "station_proc.py"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_log(log: Path, needle: str, proc: subprocess.Popen[bytes], timeout: float = 90) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end and needle not in log.read_text() and proc.poll() is None:
        time.sleep(0.1)
    assert needle in log.read_text(), f"{needle!r} not in the journal: {log.read_text()[-3000:]}"


@pytest.mark.timeout(180)
def test_while_the_daemon_runs_the_check_is_asked_of_it_through_its_api(
        tmp_path, capsys, monkeypatch):
    port = _free_port()
    hashed = hash_password(PASSWORD)
    path = station_dir(tmp_path, ("pair1", "pair2"), http={"listen": f"127.0.0.1:{port}"},
                       access={"roles": {"engineer": ["calibrate"], "operator": ["skip"]},
                               "users": {"erik": {"role": "engineer", "password": hashed},
                                         "olga": {"role": "operator", "password": hashed}}})
    (tmp_path / "pose").write_text("")
    log = tmp_path / "daemon.log"
    with log.open("w") as err:
        daemon = subprocess.Popen([sys.executable, str(PROC), str(path), str(tmp_path / "pose"),
                                   "plain", "lock"], cwd=tmp_path, stderr=err,
                                  env={**os.environ, "PYTHONUNBUFFERED": "1"})
    monkeypatch.setenv("STATIOND_PASSWORD", PASSWORD)
    try:
        _wait_log(log, "pair2 checked: reference R2", daemon)   # the start's own check
        check = ["calibrate", "check", "--config", str(path)]
        assert main([*check, "--user", "erik", "--comment", "after the shift"]) == 0
        named, *out = capsys.readouterr().out.splitlines()
        # the first line names the station that answered: the station file's own daemon
        assert named.startswith("station at http://") and named.endswith(
            f": {path.resolve()}")     # how to give it an id: said by status only
        assert [line.split(":")[0] for line in out] == ["pair1 in place", "pair2 in place"]
        _wait_log(log, "command calibration-check ('after the shift') by erik (cli 127.0.0.1): "
                  "accepted", daemon)

        # pair2 knocked: the daemon finds it moved (and refuses its bolts from now on)
        (tmp_path / "knock").write_text("pair2 0.3\n")
        until(lambda: taken(tmp_path / "knock", "pair2 0.3"), 60, "the world knocked pair2")
        assert main([*check, "--user", "erik", "--json"]) == 1
        got = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert got["pair1"]["verdict"] == "ok"
        assert got["pair2"]["verdict"] == "moved" and got["pair2"]["offset_mm"] > 2.0
        _wait_log(log, "pair2 moved: reference R2 off by", daemon)

        # refused: a user without the right; no --user (the daemon's pid named); bad input
        assert main([*check, "--user", "olga"]) == 1
        assert "right to calibrate" in capsys.readouterr().out
        assert main(check) == 2
        err = capsys.readouterr().err
        assert f"pid {daemon.pid}" in err and "--user" in err and "Traceback" not in err
        assert main([*check, "--user", "erik", "--timeout", "nan"]) == 2
        capsys.readouterr()
    finally:
        daemon.send_signal(signal.SIGTERM)
        daemon.wait(timeout=60)
    repo = Repository.open(f"sqlite:///{tmp_path / 'station.db'}")
    try:   # recorded by the daemon: the start's check, the engineer's two
        assert [c["verdict"] for c in checks(repo, "pair2")][:2] == ["moved", "ok"]
    finally:
        repo.close()
