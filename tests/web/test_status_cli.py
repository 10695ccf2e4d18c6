"""``stationd status``: a running daemon's state over its web server."""

from __future__ import annotations

from pathlib import Path

import pytest

from stationd.cli import main
from tests.web.scenario import fault, fault_state, opened


def test_status_prints_state_vehicle_and_faulty_device(live_server, capsys):
    srv = live_server()
    srv.publish(opened())
    assert main(["status", "--url", srv.url]) == 0        # serving, not in fault
    capsys.readouterr()
    srv.publish(fault())
    srv.call(_settle(srv))
    assert main(["status", "--url", srv.url]) == 1        # in fault: not OK for a monitor
    out = capsys.readouterr().out
    assert "state:    fault (lift: no answer" in out
    assert "vehicle:  WVWZZZ1JZ3W386752 (SEDAN): 0/4 bolts OK, 0 bolts ending NOK" in out
    assert "device:   lift: timed out: no answer" in out and "versions: aiohttp" in out


def test_status_says_what_each_count_counts_and_shows_skipped_bolts():
    """Issue 30: "3/50 done, 1 NOK" counted bolts ending NOK unlabelled (read as NOK results)
    and left the skipped bolts out (the API's counters had "skipped": 1)."""
    from stationd.web.status_cli import format_status

    st = {"state": "idle", "vehicle": {"vin": "VIN1", "model": "SEDAN"},
          "counters": {"total": 50, "done": 3, "nok": 1, "skipped": 1}}
    assert "vehicle:  VIN1 (SEDAN): 3/50 bolts OK, 1 skipped, 1 bolt ending NOK" \
        in format_status(st).splitlines()
    st["counters"] = {"total": 50, "done": 3, "nok": 2, "skipped": 0}
    assert "vehicle:  VIN1 (SEDAN): 3/50 bolts OK, 2 bolts ending NOK" \
        in format_status(st).splitlines()
    # the bolts named, a skipped one said (a supervisor's trial: a bolt skipped after its
    # lock was "1 bolt ending NOK", no bolt named)
    st["bolts"] = [{"bolt": "B07", "state": "nok", "ends_nok": True},
                   {"bolt": "B39", "state": "skipped", "ends_nok": True},
                   {"bolt": "B40", "state": "skipped", "ends_nok": False}]
    assert "vehicle:  VIN1 (SEDAN): 3/50 bolts OK, 2 bolts ending NOK (B07; B39, skipped)" \
        in format_status(st).splitlines()


async def _settle(srv):
    import asyncio
    while srv.server.view.state != "fault":
        await asyncio.sleep(0.02)


def test_status_without_daemon_is_one_line_exit_3(capsys):
    """3, not the 1 of a station in fault: a monitor tells "no status" from "fault"."""
    assert main(["status", "--url", "http://127.0.0.1:9/", "--timeout", "2"]) == 3
    err = capsys.readouterr().err
    assert err.startswith("stationd: status: no daemon answers at") and err.count("\n") == 1


def test_status_json_without_daemon_is_a_json_object_saying_why(capsys):
    """A technician's trial: ``status --json`` of no daemon printed nothing on stdout, so a
    monitoring script had no JSON to read; now an object saying it did not answer, and why
    (the words on stderr as ever)."""
    import json

    assert main(["status", "--url", "http://127.0.0.1:9/", "--timeout", "2", "--json"]) == 3
    out, err = capsys.readouterr()
    doc = json.loads(out)
    assert doc["answered"] is False and doc["exit"] == 3 and doc["url"] == "http://127.0.0.1:9/"
    assert "no daemon answers at" in doc["error"] and doc["error"] in err
    assert err.count("\n") == 1


def test_a_station_file_without_an_http_section_is_said_to_serve_no_api(tmp_path, capsys):
    """A daemon runs on a station file without ``http:``: ``status --config`` said "no daemon
    answers ...: is stationd running?" of a daemon that runs (it serves no API).  The file
    is named, and what to do."""
    import argparse
    import shutil
    from pathlib import Path

    from stationd.command_cli import _unreachable, find_station

    for f in (Path(__file__).parents[2] / "config" / "sim").iterdir():
        shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    text = station.read_text()
    assert "http: {listen: '127.0.0.1:8080'}\n" in text
    station.write_text(text.replace("http: {listen: '127.0.0.1:8080'}\n", ""))
    target = find_station(argparse.Namespace(config=str(station), url=None, token=None))
    assert target.no_api
    assert _unreachable(target, ConnectionRefusedError(), "status") == 3
    err = capsys.readouterr().err
    assert err == (f"stationd: status: no daemon answers at {target.url} (connection "
                   f"refused): {station} has no http: section, so its daemon serves no API "
                   "for stationd status and the commands: add one (http: {listen: "
                   "'127.0.0.1:8080'}) and reload, or give --url\n")
    given = find_station(argparse.Namespace(config=str(station), url="http://127.0.0.1:9/",
                                            token=None))
    assert not given.no_api     # the daemon's address given: said as before
    with_http = find_station(argparse.Namespace(
        config=str(Path(__file__).parents[2] / "config" / "sim" / "station.yaml"), url=None,
        token=None))
    assert not with_http.no_api
    # its http.listen asked and nothing there: a daemon whose reload was refused may serve
    # the address it read before (a technician's trial: "is stationd running?" alone)
    assert _unreachable(with_http, ConnectionRefusedError(), "status") == 3
    err = capsys.readouterr().err
    assert "is stationd running? (a daemon whose reload of this file was refused serves " \
        "the address it read before: its journal says which; --url to ask it there)" in err
    assert _unreachable(given, ConnectionRefusedError(), "status") == 3
    assert "reload" not in capsys.readouterr().err     # --url given: said as before


@pytest.mark.parametrize("url", ["ftp://x/", "localhost:8080", "http://[::1",
                                 "http://127.0.0.1:99999/"])
def test_status_bad_url_is_one_line_exit_2(url, capsys):
    assert main(["status", "--url", url]) == 2
    err = capsys.readouterr().err
    assert "expected http://host:port/" in err and err.count("\n") == 1


@pytest.mark.parametrize("timeout", ["0", "-1", "nan"])
def test_status_bad_timeout_is_one_line_exit_2_not_no_daemon(timeout, capsys):
    assert main(["status", "--timeout", timeout]) == 2
    err = capsys.readouterr().err
    assert "--timeout" in err and "no daemon" not in err and err.count("\n") == 1


def test_status_says_not_opened_yet_while_the_database_keeps_the_devices_closed(live_server,
                                                                                capsys):
    from stationd.station.events import DeviceHealth

    srv = live_server(devices=("lift", "wrench"))
    srv.publish([DeviceHealth(device="database", ok=False, kind="down", reason="disk I/O error"),
                 fault_state(("database", "disk I/O error"))])
    srv.call(_settle(srv))
    assert main(["status", "--url", srv.url]) == 1
    out = capsys.readouterr().out
    assert "device:   lift: not opened yet" in out and "device:   wrench: not opened yet" in out
    assert "device:   database: down: disk I/O error" in out


def test_status_refused_for_its_token_is_exit_3_with_the_hint(live_server, capsys):
    """A wrong or missing token is "no status" (3), not "in fault" (1); the line says what
    to give; the right token gets the status."""
    srv = live_server(token="s3cret-token")  # noqa: S106 - a test token
    srv.publish(opened())
    for extra in ([], ["--token", "wrong-token"]):
        assert main(["status", "--url", srv.url, *extra]) == 3
        err = capsys.readouterr().err
        assert "HTTP 401" in err and "--token" in err and err.count("\n") == 1
    assert main(["status", "--url", srv.url, "--token", "s3cret-token"]) == 0


def test_status_says_a_pair_that_is_up_but_not_trusted_and_why():
    from stationd.web.status_cli import format_status
    moved = {"trusted": False, "verdict": "moved",
             "words": "pair2 moved: reference R2 off by 5.5 mm (> 2 mm)"}
    text = format_status({"state": "tracking", "devices": {
        "pair1": {"ok": True, "check": {"trusted": True, "verdict": "ok", "words": "x"}},
        "pair2": {"ok": True, "check": moved}}})
    assert "device:   pair1: ok\n" in text
    assert "device:   pair2: ok; pair2 moved: reference R2 off by 5.5 mm (> 2 mm)" in text


def test_status_names_a_locked_bolt_and_who_releases_it_how(live_server, capsys):
    """Issue 30: with ``run --sim-operator --no-sim-supervisor`` the journal said "B11 ...
    locked: the operator waits ... for a person's release", and ``stationd status`` showed
    "1 bolt ending NOK" and "Bring the wrench to a bolt": not the bolt the station waited on,
    nor what to do.  Now a line per lock, then the command and who may give it."""
    from stationd.access import AccessConfig, User
    from tests.web.scenario import VIN, locked

    srv = live_server()
    srv.server.commands.access = AccessConfig(        # the default roles: supervisor
        users={"sue": User("sue", "supervisor", "x")})  # releases, and sue is one
    srv.publish([*opened(), *locked("B2", 3)])

    async def locked():
        import asyncio
        while not srv.server.view.locks():
            await asyncio.sleep(0.02)
    srv.call(locked())
    assert main(["status", "--url", srv.url]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "locked:   B2 locked after 3 NOK in a row: a supervisor releases it" in lines
    # the one locked bolt named in the command (a newcomer read BOLT for it), and the
    # station as this status reached it: run as printed, the command reaches it too
    assert f"release:  stationd release {VIN} B2 --url {srv.url} --comment TEXT --user NAME, " \
        "or the operator screen's Release form (a user with the release right: supervisor)" \
        in lines


def test_status_without_a_lock_has_no_lock_lines_and_says_when_nobody_may_release():
    from stationd.web.status_cli import format_status

    st = {"state": "tracking", "vehicle": {"vin": "VIN1", "model": "SEDAN"}, "locks": []}
    assert "locked:" not in format_status(st) and "release:" not in format_status(st)
    st.update(locks=["B1 locked after 3 NOK in a row: a supervisor releases it"],
              release_by=[])
    assert format_status(st).splitlines()[2:4] == [
        "locked:   B1 locked after 3 NOK in a row: a supervisor releases it",
        "release:  stationd release VIN1 BOLT --comment TEXT --user NAME, or the operator "
        "screen's Release "
        "form (no user of this station has the release right: access.users and "
        "access.roles)"]
    assert "release:  stationd release VIN1 BOLT --config /srv/line/station.yaml --comment " \
        "TEXT --user NAME" in format_status(st, " --config /srv/line/station.yaml")


def test_the_status_says_the_line_database_s_forwarding_in_the_screen_s_words():
    """`stationd status` said nothing while the line database was down and records waited
    (the screens and /api/status did): it says it now, never as the station's fault."""
    from stationd.web.status_cli import format_status

    base = {"state": "tracking", "devices": {}, "versions": {}}
    down = format_status({**base, "line": {"up": False, "backlog": 13,
                                           "last_error": "connection refused"}})
    assert ("line:     line database down (connection refused): 13 records wait (the station "
            "goes on; they are forwarded when it answers)") in down.splitlines()
    one = format_status({**base, "line": {"up": False, "backlog": 1, "last_error": "x"}})
    assert "line database down (x): 1 record waits (" in one
    assert "line:     line database: 0 behind" in format_status(
        {**base, "line": {"up": True, "backlog": 0}}).splitlines()
    alarm = format_status({**base, "line": {"up": True, "backlog": 12000,
                                            "alarm": "12000 records not forwarded"}})
    assert "line:     line database: 12000 records not forwarded" in alarm.splitlines()
    assert not any(x.startswith("line:") for x in format_status(base).splitlines())


#: a camera's reason as a real pair gives it: longer than the headline's 110 characters
LONG = ("no frames for 3.0 s from gige://192.168.10.21/?exposure_us=800&gain_db=0.0&trigger="
        "software&packet_size=9000 (the camera answers ping; its stream stopped)")


def test_status_prints_the_now_line_whole_not_the_screen_s_cut_headline(live_server, capsys):
    """A trial's ``stationd status`` printed ``now:`` cut with "…" (the operator screen's
    headline, cut for large type) under a state line that had the reason whole: whole now,
    in a pipe as in a terminal; and not at all where it would only say the state line again
    (one device in fault: "FAULT: " and the state's reason)."""
    from stationd.station.events import DeviceHealth

    srv = live_server()
    srv.publish([*opened(), DeviceHealth("front", False, "down", LONG),
                 DeviceHealth("wrench", False, "refused", "connection refused"),
                 fault_state(("front", LONG), ("wrench", "connection refused"))])
    srv.call(_settle(srv))
    assert main(["status", "--url", srv.url]) == 1
    lines = capsys.readouterr().out.splitlines()
    [now] = [ln for ln in lines if ln.startswith("now:")]
    assert now == f"now:      FAULT: front: {LONG} (and wrench: see Devices)", now
    assert not any("\u2026" in ln for ln in lines), lines


def test_the_now_line_is_left_out_where_it_repeats_the_state_line():
    from stationd.web.status_cli import format_status

    st = {"state": "fault", "reason": f"front: {LONG}", "headline": f"FAULT: front: {LONG[:90]}…",
          "headline_title": f"FAULT: front: {LONG}"}
    assert not any(ln.startswith("now:") for ln in format_status(st).splitlines())
    # a daemon of an earlier version gives the cut headline only: shown, as before
    st = {"state": "idle", "reason": "waiting for a vehicle", "headline": "Raise the vehicle"}
    assert "now:      Raise the vehicle" in format_status(st).splitlines()


def test_a_refused_reload_is_said_until_a_station_runs_on_a_file_that_reads():
    """After a refused reload, ``stationd status`` and /api/status said nothing of it: the
    station runs on the configuration it loaded before, and the file on disk does not read."""
    from stationd.bus import EventBus
    from stationd.web.server import WebServer
    from stationd.web.status_cli import format_status

    srv = WebServer(EventBus(), None, None)
    assert srv.status()["reload_refused"] is None
    srv.reload_refused = "station.yaml:3: vision.centre_methd: unknown key"
    st = srv.status()
    assert "config:   reload refused (station.yaml:3: vision.centre_methd: unknown key): the " \
        "station runs on the configuration it loaded before" in format_status(st).splitlines()
    assert not any(ln.startswith("config:") for ln in format_status(
        {**st, "reload_refused": None}).splitlines())


def test_status_exits_4_while_the_last_reload_stands_refused(live_server, capsys):
    """A monitor running ``stationd status`` saw 0 after a refused reload, and the file on
    disk would not start the station at the next reboot: exit 4 until a reload reads (a
    fault still says 1)."""
    from stationd.cli import main

    srv = live_server()
    srv.publish(opened())
    assert main(["status", "--url", srv.url]) == 0
    srv.server.reload_refused = "station.yaml:3: vision.centre_methd: unknown key"
    assert main(["status", "--url", srv.url]) == 4
    assert "config:   reload refused (station.yaml:3" in capsys.readouterr().out
    srv.server.reload_refused = None
    assert main(["status", "--url", srv.url]) == 0


def test_status_exits_1_while_a_device_reports_its_own_fault(live_server, capsys):
    """A device reporting its own fault (the lift PLC's fault bit) before the station's state
    says fault: the monitor's exit says it as /healthz's 503 does (it said 0: a maintenance
    trial)."""
    from stationd.cli import main
    from stationd.station.events import (
        Because,
        DeviceHealth,
        State,
        StateChanged,
        StateReason,
    )

    srv = live_server()
    srv.publish(opened())
    srv.publish([DeviceHealth(device="lift", ok=False, kind="reported",
                              reason="the lift PLC reports a fault of the lift (its fault bit)"),
                 StateChanged(state=State.WAITING_VEHICLE, reason=StateReason(
                     Because.LIFT_NOT_READY, note="the lift PLC reports a fault"))])
    srv.call(_until(lambda: srv.server.view.state == State.WAITING_VEHICLE))
    assert main(["status", "--url", srv.url]) == 1
    out = capsys.readouterr().out
    assert "device:   lift: in fault: the lift PLC reports a fault" in out
    assert out.splitlines()[1].startswith("state:    waiting for vehicle")
    srv.publish([DeviceHealth(device="lift", ok=True)])
    srv.call(_until(lambda: srv.server.view.device_health()["lift"]["ok"]))
    assert main(["status", "--url", srv.url]) == 0


async def _until(held):
    import asyncio
    while not held():
        await asyncio.sleep(0.02)


def test_status_with_a_station_file_that_no_longer_reads_still_asks_its_daemon(
        live_server, capsys, tmp_path):
    """A reload of a mistyped file was refused and the daemon runs on: ``status --config``
    of that file said only the file's error (exit 2), and the commands with it.  The file's
    http section still says where the daemon answers: asked there, the error said first."""
    from stationd.cli import main

    srv = live_server()
    srv.publish(opened())
    listen = srv.url.removeprefix("http://").rstrip("/")
    bad = tmp_path / "station.yaml"
    bad.write_text(f"http:\n  listen: '{listen}'\nvision:\n  tolerance_mn: 3\n")
    assert main(["status", "--config", str(bad)]) == 0
    out, err = capsys.readouterr()
    assert err.startswith(f"stationd: {bad} does not read (") and "tolerance_mn" in err
    assert "asking the daemon at its http section's address" in err
    assert out.splitlines()[1].startswith("state:    ")
    # the commonest bad edit: a bracket left open after the http section, so the file is no
    # YAML at all (a new user's lock-out: no release without --url); its http section
    # alone still says where the daemon answers
    bad.write_text(f"http:\n  listen: '{listen}'\naccess:\n  users:\n"
                   f"    bob: {{role: operator, password: \"x\"\n")
    assert main(["status", "--config", str(bad)]) == 0
    out, err = capsys.readouterr()
    assert "malformed YAML" in err and "asking the daemon at its http section" in err
    assert out.splitlines()[1].startswith("state:    ")
    # a file whose http section does not parse either: its error, and how to reach the
    # daemon all the same; given that way, it is asked
    bad.write_text("http: [\n")
    assert main(["status", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "malformed YAML" in err and "give --url http://HOST:PORT/" in err
    assert len(err.strip().splitlines()) == 1
    assert main(["status", "--config", str(bad), "--url", srv.url]) == 0
    out, err = capsys.readouterr()
    assert out.splitlines()[1].startswith("state:    ") and "asking the daemon at --url" in err
    # the http section after others, with Windows line ends: found alike
    bad.write_bytes(f"vision:\r\n  tolerance_mn: [3\r\nhttp:\r\n  listen: '{listen}'\r\n"
                    .encode())
    assert main(["status", "--config", str(bad)]) == 0, capsys.readouterr().err
    capsys.readouterr()
    # a path that names no file is a typo, most likely: said alone, no daemon hint
    assert main(["status", "--config", str(tmp_path / "nothere.yaml")]) == 2
    err = capsys.readouterr().err
    assert "not found" in err and "--url" not in err and len(err.strip().splitlines()) == 1


def test_a_pair_not_registered_into_the_vehicle_frame_is_said_beside_its_health():
    """A pair without ``to_vehicle`` is up and grabs, but localizes nothing: ``config check``
    warned of it, and the daemon then said nothing, its status "rear: ok" (a line engineer's
    trial).  The running station's unregistered pairs are in /api/status (set when the
    station attaches: :func:`stationd.shell.serve.unregistered`) and on the pair's line."""
    from dataclasses import replace

    from stationd.bus import EventBus
    from stationd.config import load_station_config
    from stationd.demo.station import SIM_CONFIG
    from stationd.shell.serve import unregistered
    from stationd.web.server import WebServer
    from stationd.web.status_cli import format_status

    cfg = load_station_config(SIM_CONFIG)
    assert unregistered(cfg) == ()
    pairs = {**cfg.pairs, "pair2": replace(cfg.pairs["pair2"], to_vehicle=None)}
    assert unregistered(replace(cfg, pairs=pairs)) == ("pair2",)
    srv = WebServer(EventBus(), None, None, devices=("pair1", "pair2"))
    srv.unregistered = ("pair2",)
    st = srv.status()
    assert st["unregistered"] == ["pair2"]
    lines = format_status({**st, "devices": {"pair1": {"ok": True}, "pair2": {"ok": True}}})
    assert "device:   pair1: ok\n" in lines
    assert "device:   pair2: ok; not registered into the vehicle frame: its frames localize " \
        "nothing (stationd calibrate vehicle --pair pair2)" in lines


def test_a_closed_vehicle_is_not_said_to_be_at_the_station():
    """The next vehicle raised and rejected (an unknown model code): ``status`` said the
    vehicle closed before it as the one at the station (a line engineer's trial).  A closed
    vehicle is the last one, closed; the fault names the VIN refused
    (``stationd.shell.records``)."""
    from stationd.station.events import VehicleClosed, VehicleReopened
    from stationd.web.status_cli import format_status
    from stationd.web.view import fold
    from tests.web.scenario import VIN, opened

    st = fold(opened()).to_json()
    assert st["vehicle"]["at_station"] is True
    assert f"vehicle:  {VIN} (SEDAN): 0/4 bolts OK" in format_status(st)
    st = fold([*opened(), VehicleClosed(VIN, ("B1", "B2", "B3", "B4"), ())]).to_json()
    assert st["vehicle"]["at_station"] is False
    assert f"vehicle:  none loaded (the last: {VIN} (SEDAN): 0/4 bolts OK" in format_status(st)
    assert ", closed)" in format_status(st)
    st = fold([*opened(), VehicleClosed(VIN, ("B1", "B2", "B3", "B4"), ()),
               VehicleReopened(VIN, "sam")]).to_json()
    assert st["vehicle"]["reopened_by"] == "sam"
    assert any(line.startswith("vehicle:  none loaded") and line.endswith(
        ", reopened by sam: not at the station yet)") for line in format_status(st).splitlines())


def test_status_of_a_bolt_table_says_what_it_is_and_how_to_reach_a_daemon(capsys, tmp_path):
    """A maintenance trial gave the bolt table by mistake: it was told a daemon "running on
    this file before it broke" keeps its configuration; nothing broke, it was the wrong
    file."""
    from stationd.cli import main

    bolts = tmp_path / "bolts.yaml"
    bolts.write_text((Path(__file__).resolve().parents[2] / "config" / "sim" / "bolts.yaml")
                     .read_text())
    assert main(["status", "--config", str(bolts)]) == 2
    err = capsys.readouterr().err
    assert "bolt table" in err and "broke" not in err, err
    assert "if a daemon runs on this file" in err and err.count("\n") == 1


def test_status_of_a_held_bolt_names_entering_its_outcome_before_a_release(live_server,
                                                                            capsys):
    """A bolt held because its result could not be read may have been tightened: the
    status named only "release" (which tightens it again), never entering the outcome the
    controller shows (a supervisor trial)."""
    from tests.web.scenario import VIN, held

    srv = live_server()
    srv.publish([*opened(), *held("B2", "tightening 7")])

    async def held():
        import asyncio
        while not srv.server.view.locks():
            await asyncio.sleep(0.02)
    srv.call(held())
    assert main(["status", "--url", srv.url]) == 0
    out = capsys.readouterr().out
    assert ("check it on the controller, then enter its outcome, or release it to tighten "
            "it again") in out
    [line] = [x for x in out.splitlines() if x.startswith("outcome:")]
    assert line.startswith(f"outcome:  stationd enter-outcome {VIN} B2 --url {srv.url} "
                           "--ok|--nok --torque NM --angle DEG --comment TEXT --user NAME")
    assert out.index("outcome:") < out.index("release:")


def test_status_says_a_held_bolt_as_held_with_why_and_a_lock_as_locked(live_server, capsys):
    """A supervisor's trial: ``stationd status`` listed a held bolt (its result not known:
    unreadable, a link cut's, a lost push's) under ``locked:``, as if its NOKs had locked
    it.  A hold is its own ``held:`` line, with why; a lock stays under ``locked:``."""
    from tests.web.scenario import held, locked

    srv = live_server()
    srv.publish([*opened(), *locked("B1", 3), *held("B2", "tightening 7")])

    async def both():
        import asyncio
        while len(srv.server.view.locks()) < 2:
            await asyncio.sleep(0.02)
    srv.call(both())
    assert main(["status", "--url", srv.url]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [x for x in lines if x.startswith(("locked:", "held:"))] == [
        "locked:   B1 locked after 3 NOK in a row: a supervisor releases it",
        "held:     B2: the controller's result could not be read (tightening 7): check it "
        "on the controller, then enter its outcome, or release it to tighten it again"]
    # the vehicle's line counts it (a supervisor's trial: "0/50 bolts OK, 1 bolt ending NOK"
    # with 3 bolts held)
    [vehicle] = [x for x in lines if x.startswith("vehicle:")]
    assert vehicle.endswith("1 bolt ending NOK, 1 held"), vehicle   # B1's NOKs, B2


def test_status_of_a_daemon_that_gives_no_holds_says_its_locks_as_before():
    """A daemon of an earlier version gives ``locks`` only: they stay ``locked:``."""
    from stationd.web.status_cli import format_status

    st = {"state": "tracking", "vehicle": {"vin": "VIN1", "model": "SEDAN"},
          "locks": ["B1 locked after 3 NOK in a row: a supervisor releases it"]}
    assert "locked:   B1 locked after 3 NOK in a row: a supervisor releases it" in \
        format_status(st).splitlines()
    assert "held:" not in format_status(st)


def test_status_names_a_bolt_to_be_loosened_first(live_server, capsys):
    """After ``stationd loosen VIN B2`` the status said only the state's last rundown ("bolt
    B2 OK; tracking"), nothing of the bolt waiting for its loosening (a newcomer's trial):
    a line names it with its loosen pset, and the API lists it."""
    import json

    from db.kinds import TO_LOOSEN
    from tests.web.scenario import bolt, changed

    srv = live_server()
    srv.publish([*opened(), changed(bolt("B2", TO_LOOSEN, ran=True, loosen_pset=90))])

    async def shown():
        import asyncio
        while not any(b.loosen for b in srv.server.view.bolts.values()):
            await asyncio.sleep(0.02)
    srv.call(shown())
    assert main(["status", "--url", srv.url]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "loosen:   B2 (loosen pset 90): to be loosened first, then tightened" in lines
    assert main(["status", "--url", srv.url, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["to_loosen"] == [
        {"bolt": "B2", "loosen_pset": 90}]


def test_status_in_teach_mode_says_the_cycle_is_off_and_how_teach_mode_ends():
    """A commissioning trial: teach mode left on by a ``stationd teach`` that was cut off;
    ``status`` said ``state: teaching (...)`` and nothing of what that means for the line
    (nothing is tightened) or how it ends."""
    from stationd.web.status_cli import format_status

    st = {"state": "teaching", "reason": "teaching SIM-1 (ed): hold the tool on a bolt",
          "vehicle": {"vin": "VIN1", "model": "SIM-1"}, "counters": {"total": 50}}
    lines = format_status(st, " --config /etc/x.yaml").splitlines()
    assert "teach:    teach mode is on: nothing is tightened until it ends (stationd teach "\
           "--stop --user NAME --config /etc/x.yaml, or the commissioning screen's Stop " \
           "teach mode)" in lines, lines
    st["state"] = "tracking"
    assert not any(line.startswith("teach:") for line in format_status(st).splitlines())
