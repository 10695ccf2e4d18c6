"""A held bolt resolved by the outcome a supervisor read on the controller's screen, through the
daemon as systemd runs it: the simulated controller over Open Protocol sends a result that
does not read (the bolt held), ``stationd enter-outcome`` over the daemon's API is refused for
an operator and for a bolt that is not held, and a supervisor's OK closes the bolt: recorded
as a rundown entered by them (in the feed, linked to the unreadable result), said in the
journal, the bolt never selected again."""

from __future__ import annotations

import json

import pytest

from tests.shell.daemons import db_rows, tool_on, tracking, until
from tests.shell.test_commands_daemon import _cli, _station

pytestmark = pytest.mark.system      # a whole daemon, and the command line's processes

VIN = "ENTEREDVIN0000001"


@pytest.mark.timeout(300)
def test_a_supervisor_enters_the_outcome_of_a_held_bolt_from_the_cli(tmp_path):
    from tests.shell.daemons import free_port

    http_port = free_port()
    url = f"http://127.0.0.1:{http_port}/"

    def edit(text: str) -> str:
        return _station(http_port)(text).replace("    supervisor: [skip, reopen]\n",
                                                 "    supervisor: [skip, reopen, release]\n")

    pose = tmp_path / "pose"
    with tracking(tmp_path, VIN, edit=edit) as (d, _, ctl):
        tool_on(d, ctl, pose, "B05")
        ctl.garble_next_result("layout")       # a body that reads at no revision
        bad = ctl.pull_trigger()
        assert bad is not None
        d.wait_log("B05: the controller's result could not be read")
        until(lambda: not ctl.tool_enabled, 30, "the tool off")
        pose.write_text("")
        outcome = ["--ok", "--torque", "49.6", "--angle", "31", "--comment",
                   "read on the controller's screen", "--url", url]
        got = _cli("enter-outcome", VIN, "B05", *outcome, "--user", "olga")
        assert got.returncode == 1 and "right to release" in got.stdout, got.stderr
        got = _cli("enter-outcome", VIN, "B06", *outcome, "--user", "sam")
        assert got.returncode == 1 and "B06 is not held" in got.stdout, got.stderr
        got = _cli("enter-outcome", VIN, "B05", *outcome, "--user", "sam")
        assert got.returncode == 0 and "accepted" in got.stdout, got.stdout + got.stderr
        d.wait_log("command enter-outcome B05 of ENTEREDVIN0000001: OK 49.6 Nm, 31.0 deg "
                   "(\"read on the controller's screen\") by sam (cli 127.0.0.1): accepted")
        d.wait_log("B05: OK 49.6 Nm, 31.0 deg entered by sam from the controller's screen "
                   "(the result that could not be read: MID 0061 revision 7): B05 done")
        pose.write_text("B05")
        d.wait_log("no bolt: B05 is already done")
        assert d.log().count("tightening bolt B05") == 1
        pose.write_text("")
        feed = _cli("feed", "--url", url)
        assert feed.returncode == 0, feed.stderr
        entries = [json.loads(line) for line in feed.stdout.splitlines()]
        [run] = [e["record"] for e in entries if e["kind"] == "rundown"]
        [unread] = [e["record"] for e in entries if e["kind"] == "unreadable"]
        assert (run["bolt"], run["status"], run["entered_by"], run["unreadable_id"],
                run["tightening_id"]) == ("B05", "ok", "sam", unread["id"],
                                          unread["tightening_id"])
    db = tmp_path / "station.db"
    assert db_rows(db, "SELECT status, torque_nm, angle_deg, entered_by, entered_comment "
                       "FROM tightening_records") == [
        ("ok", 49.6, 31.0, "sam", "read on the controller's screen")]
    assert db_rows(db, "SELECT kind, user, bolt FROM commands WHERE kind != 'refused'") == [
        ("enter-outcome", "sam", "B05")]
    # the two refused (olga's: no right; sam's of a bolt not held) kept as the attempts
    assert db_rows(db, "SELECT user, bolt FROM commands WHERE kind = 'refused' "
                       "ORDER BY id") == [("olga", "B05"), ("sam", "B06")]
