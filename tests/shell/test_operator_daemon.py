"""The operator signed in at the station, through the running daemon (``station_proc.py``: the
real serve loop, its lift PLC over Modbus TCP and its controller over Open Protocol on
loopback), with ``access.operator_required``: nobody signed in, nothing is sent (the typed
reason in the journal, ``stationd operator status`` says so); ``stationd operator sign-in``
with a wrong password or an unknown user is one line and exit 3, bad input exit 2; signed in,
the bolt is tightened and its rundown recorded with the operator, who is still signed in
after a reload; the sign-in and sign-out are audit entries."""

from __future__ import annotations

import json
import sqlite3

import pytest

from tests.shell.daemons import free_port, tracking, until
from tests.shell.test_commands_daemon import _cli, _station

VIN = "OPERATORVIN000001"


@pytest.mark.timeout(300)
def test_a_signed_in_operators_rundown_is_recorded_with_them_and_nobody_tightens_without(
        tmp_path):
    http_port = free_port()
    url = f"http://127.0.0.1:{http_port}/"

    def edit(text: str) -> str:   # users olga, sam, nina; an operator required to tighten
        return str(_station(http_port)(text)) + "  operator_required: true\n"

    pose = tmp_path / "pose"
    with tracking(tmp_path, VIN, seed=11, edit=edit) as (d, _, ctl):
        d.wait_log("operator: nobody signed in: sign in to tighten")
        got = _cli("operator", "status", "--url", url)
        assert got.returncode == 0 and "nobody signed in" in got.stdout, got.stderr
        assert "sign in to tighten" in got.stdout

        # nobody signed in: the wrench on B05 is refused with the reason, nothing is sent
        pose.write_text("B05")
        d.wait_log("no bolt: sign in to tighten")
        assert "bolt B05 selected" not in d.log() and not ctl.tool_enabled

        # bad input: one line, exit 2; a wrong password or an unknown user: exit 3
        got = _cli("operator", "sign-in", " ", "--url", url)
        assert got.returncode == 2 and len(got.stderr.strip().splitlines()) == 1
        got = _cli("operator", "sign-in", "olga", "--url", url, password="guess1234")  # noqa: S106
        assert got.returncode == 3 and "login refused" in got.stderr
        assert len(got.stderr.strip().splitlines()) == 1 and "Traceback" not in got.stderr
        got = _cli("operator", "sign-in", "nobody", "--url", url)
        assert got.returncode == 3 and "login refused" in got.stderr
        got = _cli("operator", "sign-out", "--user", "sam", "--url", url)
        assert got.returncode == 1 and "nobody is signed in" in got.stdout

        # olga signs in (an operator: no right needed): B05 is selected and tightened
        got = _cli("operator", "sign-in", "olga", "--comment", "shift 2", "--url", url)
        assert got.returncode == 0 and "accepted" in got.stdout, got.stdout + got.stderr
        d.wait_log("operator: olga signed in")
        assert "olga signed in" in _cli("operator", "status", "--url", url).stdout
        got = _cli("operator", "status", "--url", url, "--json")   # for a script
        assert json.loads(got.stdout) == {"user": "olga", "required": True}, got.stderr
        assert got.stderr.startswith("station at ")
        d.wait_log("tightening: tightening bolt B05")
        until(lambda: ctl.tool_enabled, 30, "tool enabled")
        shot = ctl.pull_trigger()
        assert shot is not None and shot.ok
        until(lambda: shot.tightening_id in ctl.acked_ids, 30, "result stored")
        pose.write_text("")

        # a reload: still signed in
        d.p.send_signal(1)   # SIGHUP
        d.wait_log("configuration reloaded")
        d.wait_log("operator: olga signed in (still, from before this start or reload)")
        got = _cli("operator", "sign-out", "--user", "sam", "--url", url)
        assert got.returncode == 0 and "accepted" in got.stdout, got.stdout + got.stderr
        d.wait_log("operator: olga signed out by sam")
    con = sqlite3.connect(tmp_path / "station.db")
    try:
        runs = list(con.execute("SELECT tightening_id, status, operator "
                                "FROM tightening_records"))
        audit = list(con.execute("SELECT user, kind, comment FROM commands ORDER BY id"))
    finally:
        con.close()
    assert runs == [(shot.tightening_id, "ok", "olga")]
    assert audit == [("olga", "sign-in", "shift 2"), ("sam", "sign-out", "olga signed out")]
