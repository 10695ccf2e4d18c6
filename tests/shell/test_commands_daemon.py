"""People's commands through the running daemon (``station_proc.py``: the real serve loop,
its lift PLC over Modbus TCP and its controller over Open Protocol on loopback): ``stationd
skip`` and ``reopen`` log in over the daemon's API with a user's password and are accepted or
refused with the station's reason; a wrong password, a role without the right, a replayed or
stale request change nothing; an accepted skip is recorded with its user, is in the results
feed, and outlives a reload."""

from __future__ import annotations

import http.cookiejar
import json
import os
import sqlite3
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path

import pytest

from db.repository import Repository
from stationd.access import hash_password
from tests.shell.daemons import controller, free_port, tracking, until

ROOT = Path(__file__).resolve().parents[2]
VIN = "COMMANDVIN0000001"
PASSWORD = "line-7-password"  # noqa: S105 - a test user's
HASH = hash_password(PASSWORD)


def _station(port: int) -> Callable[[str], str]:
    def edit(text: str) -> str:
        return text + (f"\nhttp: {{listen: '127.0.0.1:{port}'}}\naccess:\n  roles:\n"
                       "    operator: [skip]\n    supervisor: [skip, reopen]\n    viewer: []\n"
                       f"  users:\n    olga: {{role: operator, password: '{HASH}'}}\n"
                       f"    sam: {{role: supervisor, password: '{HASH}'}}\n"
                       f"    nina: {{role: viewer, password: '{HASH}'}}\n")
    return edit


def _cli(*args: str, password: str = PASSWORD) -> subprocess.CompletedProcess[str]:
    """A command to the daemon as a person types it, waiting for its answer as long as a busy
    machine needs (the daemon renders eight 20 MP cameras beside it): these tests check the
    answer, not how fast it comes (15 s, the default, ran out on a loaded machine)."""
    env = {**os.environ, "STATIOND_PASSWORD": password, "PYTHONPATH": str(ROOT)}
    wait = () if "--timeout" in args else ("--timeout", "120")   # unless it is the test
    return subprocess.run([sys.executable, "-m", "stationd", *args, *wait],
                          capture_output=True, text=True, env=env, timeout=180, check=False)


class Client:
    """A logged-in HTTP client (as a script would be), to send requests by hand."""

    def __init__(self, url: str) -> None:
        self.url = url.rstrip("/")
        self.opener = urllib.request.build_opener(
            urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))

    def get(self, path: str) -> str:
        with self.opener.open(self.url + path, timeout=30) as r:
            return str(r.read().decode())

    def post(self, path: str, body: dict[str, object]) -> tuple[int, str]:
        req = urllib.request.Request(  # noqa: S310 - http on loopback
            self.url + path, data=json.dumps(body).encode(),
            headers={"Content-Type": "application/json"})
        try:
            with self.opener.open(req, timeout=30) as r:
                return r.status, r.read().decode()
        except urllib.error.HTTPError as exc:
            return exc.code, exc.read().decode()


@pytest.mark.timeout(300)
def test_commands_through_the_daemon_are_authenticated_recorded_and_outlive_a_reload(
        tmp_path):
    http_port = free_port()
    url = f"http://127.0.0.1:{http_port}/"
    with tracking(tmp_path, VIN, seed=6, edit=_station(http_port)) as (d, _, _):
        # an operator skips B05 from the command line: accepted, journaled with the user
        got = _cli("skip", VIN, "B05", "--user", "olga", "--comment", "no access",
                   "--url", url)
        assert got.returncode == 0, got.stderr
        assert "accepted" in got.stdout and "olga" in got.stdout
        d.wait_log("command skip B05 of COMMANDVIN0000001 ('no access') by olga (cli "
                   "127.0.0.1): accepted")
        (tmp_path / "pose").write_text("B05")
        d.wait_log("no bolt: B05 skipped: olga's command (no access)")
        assert "tightening bolt B05" not in d.log()
        (tmp_path / "pose").write_text("")

        # refused: a role without the right, a bolt already skipped, a wrong password
        got = _cli("skip", VIN, "B06", "--user", "nina", "--comment", "no access", "--url", url)
        assert got.returncode == 1 and "does not have the right to skip" in got.stdout
        got = _cli("reopen", "OLDVIN", "--user", "olga", "--url", url)
        assert got.returncode == 1 and "right to reopen" in got.stdout
        got = _cli("skip", VIN, "B05", "--user", "sam", "--comment", "no access", "--url", url)
        assert got.returncode == 1 and "B05 skipped: olga's command" in got.stdout
        got = _cli("skip", VIN, "B07", "--user", "sam", "--comment", "no access", "--url", url,
                   password="guess1234")  # noqa: S106
        assert got.returncode == 3 and "login refused" in got.stderr
        d.wait_log("login refused for user 'sam'")
        got = _cli("reopen", VIN, "--user", "sam", "--url", url)   # open at the station
        assert got.returncode == 1 and f"vehicle {VIN} is open at the station" in got.stdout
        # a VIN mistyped, which the database does not know: said so, not "reopen it" (the
        # daemon looks the VIN up for the core: a supervisor's trial)
        got = _cli("skip", "COMMANDVIN0000009", "B07", "--user", "sam", "--comment", "no",
                   "--url", url)
        assert got.returncode == 1 and "vehicle COMMANDVIN0000009 is not in the database" \
            in got.stdout and "reopen" not in got.stdout, got.stdout
        for bad in (("--url", "not a url"), ("--timeout", "-1"), ("--timeout", "nan"),
                    ("--comment", "x" * 501)):
            got = _cli("skip", VIN, "B07", "--user", "olga", "--comment", "no access", "--url",
                       url, *bad)
            assert got.returncode == 2 and "Traceback" not in got.stderr, (bad, got.stderr)
        got = _cli("skip", VIN, " ", "--user", "olga", "--comment", "no access", "--url", url)
        assert got.returncode == 2 and "bolt ' '" in got.stderr

        # by hand: without a session, with a nonce the server never issued, replayed
        c = Client(url)
        body = {"kind": "skip", "vin": VIN, "bolt": "B08", "comment": "no access"}
        assert c.post("/api/commands", {**body, "nonce": "a" * 24})[0] == 401
        assert c.post("/api/login", {"user": "sam", "password": PASSWORD})[0] == 200
        status, text = c.post("/api/commands", {**body, "nonce": "a" * 24})
        assert status == 400 and "unknown nonce" in text
        nonce = json.loads(c.get("/api/nonce"))["nonce"]
        assert c.post("/api/commands", {**body, "nonce": nonce})[0] == 200
        status, text = c.post("/api/commands", {**body, "bolt": "B09", "nonce": nonce})
        assert status == 400 and "replayed" in text
        req = urllib.request.Request(url + "api/commands", data=b"kind=skip")  # noqa: S310
        with pytest.raises(urllib.error.HTTPError) as err:
            c.opener.open(req, timeout=30)
        assert err.value.code == 415
        # wrong passwords: the user is locked out for a while, the right one too
        for _ in range(5):
            assert c.post("/api/login", {"user": "nina", "password": "nope-nope"})[0] == 401
        status, text = c.post("/api/login", {"user": "nina", "password": PASSWORD})
        assert status == 429 and "too many wrong passwords" in text

        # the record: the two accepted skips, with their users, in the feed in order; the
        # refused ones that would have changed a bolt or a vehicle kept as refusals, with why
        con = sqlite3.connect(tmp_path / "station.db")
        try:
            rows = list(con.execute("SELECT user, source, kind, vin, bolt, comment "
                                    "FROM commands ORDER BY id"))
        finally:
            con.close()
        assert [r for r in rows if r[2] != "refused"] == [
            ("olga", "cli 127.0.0.1", "skip", VIN, "B05", "no access"),
            ("sam", "screen 127.0.0.1", "skip", VIN, "B08", "no access")]
        refused = [(r[0], r[4], r[5].split(": refused: ")[1]) for r in rows
                   if r[2] == "refused"]
        assert ("nina", "B06", "your role does not have the right to skip") in refused
        assert ("olga", None, "your role does not have the right to reopen") in refused
        assert any(user == "sam" and bolt == "B05" and "skipped" in why
                   for user, bolt, why in refused), refused
        got = _cli("feed", "--url", url)
        assert got.returncode == 0, got.stderr
        feed = [json.loads(line) for line in got.stdout.splitlines()]
        feed = [e for e in feed if e["record"]["kind"] != "refused"]
        assert [(e["kind"], e["record"]["bolt"]) for e in feed] == [("command", "B05"),
                                                                    ("command", "B08")]
        assert feed[0]["seq"] < feed[1]["seq"] and len({e["db_id"] for e in feed}) == 1
        assert _cli("feed", "--url", url, "--since", str(feed[-1]["seq"])).stdout == ""
        # a page shorter than the records says the rest is there (100 lines stopped silently)
        page = _cli("feed", "--url", url, "--limit", "1")
        assert page.returncode == 0 and len(page.stdout.splitlines()) == 1
        assert f"stationd: feed: 1 record up to seq {feed[0]['seq']}; more up to seq " \
            f"{feed[-1]['seq']}: give --since {feed[0]['seq']}" in page.stderr

        # a reload that removes sam: his open session ends, his commands are refused
        assert json.loads(c.get("/api/me"))["user"] == "sam"
        station = tmp_path / "station.yaml"
        station.write_text("\n".join(line for line in station.read_text().splitlines()
                                     if not line.strip().startswith("sam:")) + "\n")
        d.p.send_signal(1)   # SIGHUP
        d.wait_log("configuration reloaded")
        d.wait_log("tracking: tracking the wrench", count=2)
        (tmp_path / "pose").write_text("B08")
        d.wait_log("no bolt: B08 skipped: sam's command")
        assert json.loads(c.get("/api/me"))["user"] is None
        status, _ = c.post("/api/commands", {**body, "bolt": "B10", "nonce": "b" * 24})
        assert status == 401
        until(lambda: d.p.poll() is None, 1, "running")


@pytest.mark.timeout(300)
def test_a_bolt_locked_after_three_noks_is_released_by_a_supervisor_from_the_cli(tmp_path):
    """The NOK policy through the daemon: three NOKs in a row on B05 lock it (the tool is
    refused there with the reason), an operator cannot release it, a supervisor can; then it
    is tightened OK."""
    http_port = free_port()
    url = f"http://127.0.0.1:{http_port}/"

    def edit(text: str) -> str:
        return str(_station(http_port)(text)).replace("    supervisor: [skip, reopen]\n",
                                                 "    supervisor: [skip, reopen, release]\n")

    with tracking(tmp_path, VIN, edit=edit, ctl=controller(seed=8, nok_rate=1.0)
                  ) as (d, _, ctl):
        pose = tmp_path / "pose"
        for n in range(1, 4):
            pose.write_text("B05")
            d.wait_log("tightening bolt B05", count=n)
            until(lambda: ctl.tool_enabled, 30, "tool enabled")
            shot = ctl.pull_trigger()
            assert shot is not None and not shot.ok
            until(lambda s=shot: s.tightening_id in ctl.acked_ids, 30, "NOK recorded")
            pose.write_text("")
            d.wait_log("bolt B05 NOK; tracking", count=n)
        d.wait_log("B05 locked after 3 NOK in a row: a supervisor releases it")
        pose.write_text("B05")
        d.wait_log("no bolt: B05 locked after 3 NOK in a row")
        assert d.log().count("tightening bolt B05") == 3
        got = _cli("release", VIN, "B05", "--user", "olga", "--comment", "looks fine",
                   "--url", url)
        assert got.returncode == 1 and "right to release" in got.stdout
        got = _cli("release", VIN, "B05", "--user", "sam", "--comment", "thread checked",
                   "--url", url)
        assert got.returncode == 0 and "accepted" in got.stdout, got.stdout + got.stderr
        ctl.nok_rate = 0.0
        d.wait_log("tightening bolt B05", count=4)
        until(lambda: ctl.tool_enabled, 30, "tool enabled")
        shot = ctl.pull_trigger()
        assert shot is not None and shot.ok
        until(lambda: shot.tightening_id in ctl.acked_ids, 30, "OK recorded")
    repo = Repository.open(f"sqlite:///{tmp_path}/station.db")
    try:
        report = repo.vehicle_report(VIN)
        commands = repo.ledger.commands(VIN)
    finally:
        repo.close()
    [b05] = [b for b in report.bolts if b.bolt_id == "B05"]
    assert b05.status == "ok" and b05.attempts == 4
    assert [(c.user, c.kind, c.bolt, c.comment) for c in commands if c.kind != "refused"] == [
        ("station", "lock", "B05", "3 NOK in a row"),     # the NOK policy's, recorded
        ("sam", "release", "B05", "thread checked")]
    # olga's release, refused (no right), kept as the attempt it was
    assert [(c.user, c.bolt) for c in commands if c.kind == "refused"] == [("olga", "B05")]
