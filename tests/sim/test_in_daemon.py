"""``stationd run`` on the simulated station, as a process: the simulated world runs inside the
daemon (the ``sim://`` cameras render it), with the scripted operator (``--sim-operator``: a
vehicle arrives, bolts are tightened and recorded) or idle (the lift down, said once in the
journal, raised from standard input; no pair fault).  One pair of config/sim (fewer 20 MP
cameras to render: a faster test), its database in the test's folder, no screens."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest
import yaml

from stationd.cli import main

ROOT = Path(__file__).resolve().parents[2]
SIM = ROOT / "config" / "sim"


def _station(tmp: Path, **extra: object) -> Path:
    """config/sim with pair1 only, its database in ``tmp``, no screens."""
    for f in SIM.glob("*.yaml"):
        (tmp / f.name).write_text(f.read_text())
    doc = yaml.safe_load((tmp / "station.yaml").read_text())
    doc["pairs"] = {"pair1": doc["pairs"]["pair1"]}
    doc["cameras"] = {n: c for n, c in doc["cameras"].items() if n.startswith("pair1_")}
    doc["database"] = {"url": f"sqlite:///{tmp / 'station.db'}"}
    doc.pop("http", None)
    doc.update(extra)
    path = tmp / "station.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


class Daemon:
    """``stationd run`` as systemd would start it; its journal (stderr) goes to a file."""

    def __init__(self, tmp: Path, *args: str) -> None:
        self.log_path = tmp / "daemon.log"
        self._err = self.log_path.open("w")
        self.p = subprocess.Popen(
            [sys.executable, "-m", "stationd", "run", "--config", str(tmp / "station.yaml"),
             *args], cwd=tmp, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
            stderr=self._err, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})

    def log(self) -> str:
        return self.log_path.read_text()

    def wait(self, pattern: str, timeout: float) -> re.Match[str]:
        end = time.monotonic() + timeout
        while time.monotonic() < end and self.p.poll() is None:
            found = re.search(pattern, self.log())
            if found is not None:
                return found
            time.sleep(0.1)
        raise AssertionError(f"{pattern!r} not in the journal within {timeout} s (exit "
                             f"{self.p.poll()}): {self.log()[-3000:]}")

    def say(self, line: str) -> None:
        assert self.p.stdin is not None
        self.p.stdin.write(line + "\n")
        self.p.stdin.flush()

    def stop(self) -> int:
        """SIGTERM, then the daemon's exit code; one that does not stop within two minutes
        (a busy machine) is killed and its journal's end told."""
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
        try:
            code = self.p.wait(timeout=120)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()
            raise AssertionError("the daemon did not stop within 120 s of SIGTERM: "
                                 f"{self.log()[-3000:]}") from None
        finally:
            self._err.close()
        return code


@pytest.mark.timeout(240)
def test_the_scripted_operator_brings_a_vehicle_and_its_bolt_is_tightened_and_recorded(
        tmp_path, capsys):
    station = _station(tmp_path)
    d = Daemon(tmp_path, "--sim-operator")
    try:
        vin = d.wait(r"simulated operator: vehicle (\w{17}) \(lift code 1\) arrives", 60)[1]
        bolt = d.wait(r"simulated operator: (B\d\d): pset \d, (OK|NOK) ", 150)[1]
    finally:
        code = d.stop()
    journal = d.log()
    assert code == 0 and "stationd stopped" in journal
    # the stop is said as it begins (seconds under load before "stopped": read as a hang)
    assert -1 < journal.find("stopping: the station's last cycle") < journal.index(
        "stationd stopped")
    assert "no simulated world" not in journal and "Traceback" not in journal
    assert re.search(r"tightening: tightening bolt B\d\d", journal)
    # the result is in the station's database: stationd db report shows it
    capsys.readouterr()
    main(["db", "report", vin, "--config", str(station), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert report["vin"] == vin and bolt in report["ok"] + report["nok"], report


@pytest.mark.timeout(180)
def test_without_the_operator_the_lift_waits_says_so_once_and_no_pair_faults(tmp_path):
    _station(tmp_path)
    d = Daemon(tmp_path)
    try:
        d.wait(r"simulated lift: down, no vehicle; raise it with 'next'", 60)
        d.say("next")      # the simulated PLC's commands on standard input
        d.wait(r"vehicle \w{17} \(SIM-1\) opened", 60)
        d.wait(r"tracking: tracking the wrench", 30)
        # the cameras render the world: the vision answers (no wrench in view), no fault
        d.wait(r"no bolt: pair1: .*no purple region", 90)
        d.say("lower")
        d.wait(r"simulated lift: lift not at height", 30)
        # a reload that moves the pair's registration: a new world, the new station's PLC
        # takes the typed commands
        vehicle = tmp_path / "pair1.vehicle.yaml"
        doc = yaml.safe_load(vehicle.read_text())
        doc["t"][0] += 20.0
        vehicle.write_text(yaml.safe_dump(doc))
        d.p.send_signal(signal.SIGHUP)
        d.wait(r"configuration reloaded[\s\S]*simulated world: ", 60)
        d.say("next")
        d.wait(r"opened: 50 bolts[\s\S]*opened: 50 bolts", 60)
    finally:
        code = d.stop()
    journal = d.log()
    assert code == 0
    assert journal.count("simulated lift: down, no vehicle") == 1    # said once a daemon
    assert journal.count("simulated world: the sim:// cameras of 1 pair render") == 2
    assert "fault: pair1" not in journal and "no simulated world" not in journal


@pytest.mark.timeout(180)
def test_a_line_database_that_does_not_answer_is_said_at_the_start_and_the_station_runs(
        tmp_path):
    """Issue 30: with nothing recorded yet the forwarder did not try the line database, so an
    unreachable ``line.url`` was said only with the first record.  Now the journal says it
    at the start, in one line, and the station runs: a vehicle is opened."""
    _station(tmp_path, line={"url": "postgresql+psycopg://line@127.0.0.1:1/line",
                             "station_id": "ST-L"})
    d = Daemon(tmp_path)
    try:
        d.wait(r"line database: down \(connection failed: connection to server at "
               r"\"127\.0\.0\.1\", port 1 failed: Connection refused\); no record waits yet "
               r"\(the station goes on; its records are forwarded when it answers\)", 60)
        d.wait(r"simulated lift: down, no vehicle; raise it with 'next'", 60)
        d.say("next")
        d.wait(r"vehicle \w{17} \(SIM-1\) opened", 60)
    finally:
        code = d.stop()
    journal = d.log()
    assert code == 0 and "Traceback" not in journal
    assert journal.count("line database: down") == 1          # said once, not at each retry


def test_the_scripted_operator_is_refused_for_a_station_with_real_devices(tmp_path, capsys):
    station = _station(tmp_path, lift={"url": "modbus-tcp://127.0.0.1:1502"})
    code = main(["run", "--config", str(station), "--sim-operator"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err
    assert "--sim-operator drives simulated devices only" in err and "lift modbus-tcp" in err


def test_the_scripted_operator_is_refused_for_a_register_driven_simulated_controller(
        tmp_path, capsys):
    """A maintenance technician's trial: ``sim+modbus://wrench`` with ``--sim-operator``
    started, then the operator failed every 3 s for good ("needs the simulated lift and
    controller"): it cannot pull that controller's trigger.  Refused at the start now."""
    station = _station(tmp_path, wrench={"url": "sim+modbus://wrench"})
    code = main(["run", "--config", str(station), "--sim-operator"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err
    assert "--sim-operator drives the simulated lift and Open Protocol controller" in err
    assert "wrench sim+modbus://wrench" in err


def test_no_sim_supervisor_without_a_user_who_may_release_is_refused_at_the_start(
        tmp_path, capsys):
    """Issue 30: ``run --sim-operator --no-sim-supervisor`` on a station whose users cannot
    release (here an operator only) waited for good for a release nobody could give; refused
    now at the start, in one line, by the demo's check; no world built, no daemon started."""
    from tests.shell.test_commands_daemon import HASH

    station = _station(tmp_path, access={"users": {"olga": {"role": "operator",
                                                            "password": HASH}}})
    code = main(["run", "--config", str(station), "--sim-operator", "--no-sim-supervisor"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"stationd: error: --no-sim-supervisor needs access.users in {station} "
                          "with a user holding the release right (a supervisor)"), err
    assert not (tmp_path / "station.db").exists()


@pytest.mark.timeout(300)
def test_a_reload_that_leaves_nobody_who_may_release_is_said_in_the_journal(tmp_path):
    """With a supervisor at the start, then a reload whose users cannot release: the daemon
    goes on (a reload is not refused for it), and the journal says in one line that a lock
    now waits until the file gives someone the right."""
    from tests.shell.test_commands_daemon import HASH

    access = {"users": {"olga": {"role": "operator", "password": HASH},
                        "sam": {"role": "supervisor", "password": HASH}}}
    station = _station(tmp_path, access=access)
    d = Daemon(tmp_path, "--sim-operator", "--no-sim-supervisor")
    try:
        d.wait(r"operator: scripted, no simulated supervisor", 120)
        assert "holds the release right" not in d.log()
        doc = yaml.safe_load(station.read_text())
        del doc["access"]["users"]["sam"]
        station.write_text(yaml.safe_dump(doc, sort_keys=False))
        d.p.send_signal(signal.SIGHUP)
        path = re.escape(str(station))
        d.wait(rf"configuration reloaded[\s\S]*simulated operator: no user of {path} holds "
               r"the release right: a lock waits until the station file gives one a role with "
               r"it \(and the station is reloaded\)", 120)
    finally:
        code = d.stop()
    assert code == 0, d.log()[-3000:]


def test_the_world_follows_the_stations_geometry_across_reloads(tmp_path):
    """A reload with the same geometry keeps the world (its rendered backgrounds); one that
    moves a pair gets a new one; a station without sim:// cameras has none."""
    from drivers.camera.sim import registered_worlds
    from stationd.config import load_station_config
    from stationd.sim.in_daemon import SimulatedStation

    station = _station(tmp_path)
    sim = SimulatedStation(load_station_config(station))
    try:
        first = sim.world
        assert first is not None and registered_worlds() == ["pair1"]
        sim.follow(load_station_config(station))              # the same file again
        assert sim.world is first
        vehicle = tmp_path / "pair1.vehicle.yaml"
        doc = yaml.safe_load(vehicle.read_text())
        doc["t"][0] += 50.0                                    # the pair registered elsewhere
        vehicle.write_text(yaml.safe_dump(doc))
        sim.follow(load_station_config(station))
        assert sim.world is not None and sim.world is not first
        assert registered_worlds() == ["pair1"]
        doc = yaml.safe_load(station.read_text())
        doc["cameras"] = {n: {"url": f"aravis://Basler-{k}"}
                          for k, n in enumerate(doc["cameras"])}
        station.write_text(yaml.safe_dump(doc))
        sim.follow(load_station_config(station))
        assert sim.world is None and registered_worlds() == []
    finally:
        sim.close()
    assert registered_worlds() == []


@pytest.mark.timeout(120)
def test_calibrate_check_on_a_simulated_station_measures_its_world(tmp_path, capsys):
    """``stationd calibrate check`` with no daemon running grabs the sim:// cameras here: the
    command gives them the world (it printed 'no simulated world' for every pair)."""
    from tests.shell.refstation import station_dir

    station = station_dir(tmp_path, pairs=("pair1",))
    code = main(["calibrate", "check", "--config", str(station)])
    out = capsys.readouterr()
    assert "no simulated world" not in out.out + out.err
    assert code == 0 and out.out.startswith("pair1 in place: reference R1"), out


@pytest.mark.timeout(420)
def test_the_lift_goes_down_only_when_no_bolt_of_the_vehicle_is_locked_or_held(tmp_path):
    """A supervisor's trial: the scripted operator lowered the lift while a bolt was still
    held, though README says the vehicle waits on the lift for a supervisor's release.  Every
    fifth push lost (one is the scenario; every third lost three, each costing the operator's
    wait for its result and the late-result window: 15 s more), and the controller keeps no
    results to fetch (``old_results=0``: else the check as the bolt's window ends finds it,
    and records it to its bolt): the station holds a bolt whose result it never got (a gap
    when the next result skipped its id), after the operator had gone on.  The bolt is
    released (here by the simulated supervisor) and tightened again before the lift goes
    down: the vehicle closes with no bolt held."""
    _station(tmp_path, wrench={"url": "sim://wrench?lose_push_every=5&old_results=0"})
    d = Daemon(tmp_path, "--sim-operator")
    try:
        closed = d.wait(r"vehicle (\w{17}) \(SIM-1\) closed: (.*)", 360)
    finally:
        d.stop()
    journal = d.log()
    vin, counts = closed[1], closed[2]
    first = journal.split(f"vehicle {vin} (SIM-1) closed", 1)[0]
    # a bolt was held after its visit (the scenario happened) ...
    held = re.findall(r"WARNING (B\d\d): its result may be (?:among tightenings|tightening) "
                      r"[\d-]+ \((?:its push|their pushes) lost, not given by the controller\)",
                      first)
    assert held, first[-3000:]
    # ... and the operator came back to it: released, tightened again, its line said whole
    for bolt in held:
        assert re.search(rf"simulated operator: {bolt}: pset \d, .*\(first: .*held after its "
                         r"visit; released by the supervisor", first), first[-3000:]
    assert " held (" not in counts, counts


@pytest.mark.timeout(420)
def test_a_restarted_daemon_s_simulated_controller_has_its_results_for_the_catch_up(tmp_path):
    """A supervisor's trial: after a restart the simulated controller had no results (its
    memory went with the last process), so the catch-up for the bolt whose enable the last
    daemon left owed said "the controller has no results, though tightening N was
    recorded" and held it, where a real controller keeps its results.  The first daemon's
    operator tightens a bolt; the database then owes an enable made after it (the daemon
    stopped with the tool on: its kill's trail, written here so that no race decides it);
    the restarted daemon's controller has its results (a file of its own beside the
    database), so its catch-up finds none made since and the bolt stays open."""
    from sqlalchemy import select

    from db.models import ToolEnable
    from db.repository import Repository

    _station(tmp_path)
    first = Daemon(tmp_path, "--sim-operator")
    try:
        first.wait(r"simulated operator: B\d\d: pset \d, (OK|NOK) ", 200)
    finally:
        assert first.stop() == 0
    memory = tmp_path / "station.db.sim-wrench.jsonl"
    assert memory.read_text().strip(), "the controller's results not kept"
    with Repository.open(f"sqlite:///{tmp_path / 'station.db'}") as repo:
        with repo.engine.connect() as c:
            last = c.execute(select(ToolEnable).order_by(ToolEnable.id.desc())).first()
        assert last is not None
        repo.enables.note(last.vin, last.bolt, last.pset, last.parameters_id,
                          dict(last.selection), datetime.now(UTC))
    second = Daemon(tmp_path)
    try:
        said = second.wait(r"(no tightening made while the link was down[^\n]*|[^\n]*its result "
                           r"during the link cut not known[^\n]*)", 200)[1]
    finally:
        second.stop()
    assert said.startswith(f"no tightening made while the link was down (cut, or the station "
                           f"stopped; every result since fetched): {last.bolt} open as before"), \
        said
    assert "the controller has no results" not in second.log()


@pytest.mark.timeout(300)
def test_an_outcome_entered_for_the_held_bolt_the_operator_waits_on_ends_the_wait_as_done(
        tmp_path):
    """A supervisor's trial: the scripted operator waiting on a held bolt took the outcome a
    person entered for a release ("released: the operator tightens it again"), said its line
    "held, released", and tried the done bolt for 30 s.  Its outcome entered OK: the bolt is
    done, the operator leaves it, nobody tightens it again."""
    from tests.shell.daemons import free_port
    from tests.shell.test_commands_daemon import HASH, _cli

    port = free_port()
    access = {"users": {"sam": {"role": "supervisor", "password": HASH}}}
    _station(tmp_path, access=access, http={"listen": f"127.0.0.1:{port}"},
             wrench={"url": "sim://wrench?garble_every=2&nok_rate=0"})
    d = Daemon(tmp_path, "--sim-operator", "--no-sim-supervisor")
    try:
        found = d.wait(r"simulated operator: (B\d\d) of (\w{17}) held: the operator waits", 180)
        bolt, vin = found[1], found[2]
        got = _cli("enter-outcome", vin, bolt, "--ok", "--torque", "25", "--angle", "30",
                   "--comment", "read on the controller", "--user", "sam", "--url",
                   f"http://127.0.0.1:{port}/")
        assert got.returncode == 0 and "accepted" in got.stdout, got.stdout + got.stderr
        d.wait(rf"simulated operator: {bolt} of {vin}: its outcome entered by sam \(OK\): "
               r"done, the operator leaves it", 60)
    finally:
        code = d.stop()
    journal = d.log()
    assert code == 0, journal[-3000:]
    assert f"{bolt} of {vin} released: the operator tightens it again" not in journal
    assert f"no bolt: {bolt} is already done" not in journal, journal[-3000:]
