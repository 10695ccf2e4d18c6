"""An outcome a supervisor entered for a held bolt, in the database: the command and its
rundown written together, the rundown marked entered (who, why, the unreadable result it
resolves) in the feed and the exports, the hold over for a restart, and a NOK entered counted
in the bolt's NOK row like a measured one."""

from __future__ import annotations

import csv
import io
import math
from datetime import UTC, datetime, timedelta

import pytest

from db.entered import record_entered
from db.errors import DataError
from db.kinds import (
    LOOSENED,
    LOOSENING,
    NOT_TAKEN,
    TIGHTENING,
    UNKNOWN_TYPE_HELD,
    HeldUnder,
    is_not_taken_note,
    not_taken_note,
    unknown_type_note,
)
from db.ledger import COMMAND, RUNDOWN
from db.repository import Repository
from stationd.web.results import Results, rundowns_csv
from tests.db.conftest import record
from tests.db.test_controller_records import RAW, _unreadable


def _enter(repo, ok: bool = True, bolt: str = "B1", **kw):
    args = {"torque_nm": 49.6, "angle_deg": 31.0, "at": datetime.now(UTC) + timedelta(
        seconds=1), "user": "sam", "source": "cli", "comment": "read on the controller", **kw}
    return record_entered(repo, vin="VIN1", bolt=bolt, ok=ok, **args)


def test_an_entered_ok_is_a_rundown_marked_entered_that_ends_the_hold(sedan):
    repo = sedan
    sel = {"point_mm": [1.0, 2.0, 3.0], "tilt_deg": 2.5, "distance_mm": 0.7,
           "exposure_t": 1.0, "decided_t": 1.1, "loosen": False, "operator": "olga"}
    version = repo.bolts_for_model("SEDAN")[0].parameters_id
    repo.enables.note("VIN1", "B1", 1, version, sel, datetime.now(UTC))
    uid = _unreadable(repo, 12, "B1")
    assert repo.held_bolts("VIN1") == {"B1": "tightening 12"}
    rid = _enter(repo)
    assert repo.held_bolts("VIN1") == {}                 # a restart holds it no more
    [cmd_entry, run_entry] = repo.ledger.since(1)        # after the unreadable's entry
    assert cmd_entry["kind"] == COMMAND and run_entry["kind"] == RUNDOWN
    assert (cmd_entry["record"]["kind"], cmd_entry["record"]["bolt"],
            cmd_entry["record"]["user"]) == ("enter-outcome", "B1", "sam")
    run = run_entry["record"]
    assert run["id"] == rid and run["status"] == "ok" and run["rundown"] == "tightening"
    assert (run["torque_nm"], run["angle_deg"], run["tightening_id"]) == (49.6, 31.0, 12)
    assert (run["entered_by"], run["entered_comment"], run["unreadable_id"]) == (
        "sam", "read on the controller", uid)
    # the enable its unreadable result answered: where the wrench was, who held it
    assert run["position_mm"] == [1.0, 2.0, 3.0] and run["operator"] == "olga"
    assert repo.vehicle_report("VIN1").bolts[0].status == "ok"
    # the export says it was entered, and by whom
    rows = list(csv.DictReader(io.StringIO(rundowns_csv(Results(repo).export("VIN1")))))
    [b1] = [r for r in rows if r["bolt"] == "B1" and r["status"] == "ok"]
    assert (b1["entered_by"], b1["comment"]) == ("sam", "read on the controller")
    [vehicle_b1] = [b for b in Results(repo).vehicle("VIN1")["bolts"] if b["bolt"] == "B1"]
    assert vehicle_b1["rundowns"][0]["entered_by"] == "sam"


def test_a_measured_rundown_says_it_is_not_entered(sedan):
    record(sedan, "VIN1", "B2", tightening_id=3)
    [entry] = sedan.ledger.since(0)
    assert entry["record"]["entered_by"] is None and entry["record"]["unreadable_id"] is None


def test_an_entered_nok_counts_in_the_nok_row(sedan):
    repo = sedan
    record(repo, "VIN1", "B1", ok=False, tightening_id=1)
    _unreadable(repo, 2, "B1")
    _enter(repo, ok=False, torque_nm=56.1)
    assert repo.nok_streaks("VIN1") == {"B1": 2}
    assert repo.held_bolts("VIN1") == {}


def test_an_entered_outcome_without_a_stored_unreadable_result_still_records(sedan):
    _enter(sedan, bolt="B2")
    [_, run] = sedan.ledger.since(0)
    assert run["record"]["unreadable_id"] is None and run["record"]["tightening_id"] is None
    assert run["record"]["position_mm"] == [0.0, 0.0, 0.0]


def test_an_entered_outcome_needs_finite_values_and_an_open_vehicle(sedan):
    with pytest.raises(DataError):
        _enter(sedan, torque_nm=math.nan)
    sedan.close_vehicle("VIN1")
    with pytest.raises(DataError, match="closed"):
        _enter(sedan)
    assert sedan.ledger.commands("VIN1") == []     # nothing written, not even the command


def test_opc_ua_says_an_entered_result_was_entered_and_by_whom():
    from stationd.opcua.results import message

    rec = {"vin": "VIN1", "bolt": "B1", "rundown": "tightening", "status": "ok"}
    assert message(rec) == "VIN1 B1: tightening OK"
    assert message({**rec, "entered_by": "sam"}) == \
        "VIN1 B1: tightening OK (entered by sam, not measured)"


def _not_taken(repo, tid: int, bolt: str = "B1", enable_id: int | None = None):
    """An OK result without a type outside the bolt's torque window, as the station stores
    it (a controller event, its bolt held)."""
    return repo.others.record_controller_event(
        result_type=0, what=NOT_TAKEN, vin="VIN1", bolt=bolt, controller_vin=None,
        tightening_id=tid, pset=1, ok=True, torque_nm=0.0, angle_deg=0.0, result_at=None,
        enable_id=enable_id)


def test_an_untyped_ok_outside_the_window_holds_its_bolt_over_a_restart_until_resolved(sedan):
    """Stored as a controller event: the enable it answered settled (nothing owed to it),
    the bolt held (what a restart reads), the hold's note its own; an outcome entered for it
    carries that result's tightening id (no unreadable result), and ends the hold; a
    release ends the next one."""
    repo = sedan
    version = repo.bolts_for_model("SEDAN")[0].parameters_id
    enable = repo.enables.note("VIN1", "B1", 1, version, {"operator": "olga"},
                               datetime.now(UTC))
    assert repo.enables.owed() is not None
    assert _not_taken(repo, 21, enable_id=enable)
    assert repo.enables.owed() is None
    assert repo.held_bolts("VIN1") == {"B1": not_taken_note(0.0, 21)}
    assert is_not_taken_note(repo.held_bolts("VIN1")["B1"])
    _enter(repo)
    assert repo.held_bolts("VIN1") == {}
    run = repo.ledger.since(0)[-1]["record"]
    assert (run["tightening_id"], run["unreadable_id"], run["entered_by"], run["operator"]) \
        == (21, None, "sam", "olga")
    # an unreadable result before it, then such a result: the later one is entered for
    _unreadable(repo, 30, "B2")
    _not_taken(repo, 31, "B2")
    assert repo.held_bolts("VIN1") == {"B2": not_taken_note(0.0, 31)}
    _enter(repo, bolt="B2")
    assert repo.ledger.since(0)[-1]["record"]["tightening_id"] == 31
    # one released by a supervisor: over too
    _not_taken(repo, 32, "B3")
    repo.ledger.record_command(at=datetime.now(UTC) + timedelta(seconds=2), user="sam",
                               source="cli", kind="release", vin="VIN1", bolt="B3",
                               comment="a batch increment on the controller")
    assert repo.held_bolts("VIN1") == {}
    # a controller event of another kind holds nothing
    repo.others.record_controller_event(result_type=3, what="batch increment", vin="VIN1",
                                        bolt="B1", controller_vin=None, tightening_id=33, pset=1,
                                        ok=True, torque_nm=0.0, angle_deg=0.0, result_at=None)
    assert repo.held_bolts("VIN1") == {}


def test_a_result_of_an_unknown_type_holds_its_bolt_over_a_restart_until_entered(sedan):
    """A result of a type the station does not know under B1's enable (an MES integrator's
    trial: type 9, a rundown of 49 Nm, left B1 open): stored as a controller event under the
    station's own kind, the enable settled, B1 held (what a restart reads, its note naming
    the type and the result), may hold the vehicle, and an outcome entered for it carries
    that result's id."""
    repo = sedan
    version = repo.bolts_for_model("SEDAN")[0].parameters_id
    enable = repo.enables.note("VIN1", "B1", 1, version, {"operator": "olga"},
                               datetime.now(UTC))
    assert repo.others.record_controller_event(
        result_type=9, what=UNKNOWN_TYPE_HELD, vin="VIN1", bolt="B1", controller_vin=None,
        tightening_id=41, pset=1, ok=True, torque_nm=49.4, angle_deg=30.0, result_at=None,
        enable_id=enable)
    assert repo.enables.owed() is None
    assert repo.held_bolts("VIN1") == {"B1": unknown_type_note(9, 41)}
    assert unknown_type_note(9, 41) == ("a result of a type the station does not know "
                                        "(type 9, tightening 41)")
    assert is_not_taken_note(repo.held_bolts("VIN1")["B1"])
    assert repo.holds("VIN1")["B1"][1] == HeldUnder(False, 1)
    assert repo.may_hold(["VIN1", "VIN2"]) == {"VIN1"}
    _enter(repo)
    assert repo.held_bolts("VIN1") == {}
    assert repo.ledger.since(0)[-1]["record"]["tightening_id"] == 41
    # one under B2's loosen pset comes back after a restart as a loosening's hold (a review:
    # taken for a tightening's, an OK entered closed a bolt only loosened)
    repo.enables.note("VIN1", "B2", 90, version, {"loosen": True}, datetime.now(UTC))
    repo.others.record_controller_event(
        result_type=9, what=UNKNOWN_TYPE_HELD, vin="VIN1", bolt="B2", controller_vin=None,
        tightening_id=42, pset=90, ok=True, torque_nm=8.0, angle_deg=400.0, result_at=None)
    assert repo.holds("VIN1")["B2"][1] == HeldUnder(True, 90)


# -- an outcome entered for a held loosening: a loosening in the records --------------------------
LOOSEN_SEL = {"point_mm": [1.0, 2.0, 3.0], "tilt_deg": 2.5, "distance_mm": 0.7,
              "exposure_t": 1.0, "decided_t": 1.1, "loosen": True, "operator": "olga"}


def _held_loosening(repo: Repository, tid: int = 2) -> int | None:
    """B1 NOK, then its loosen pset 90 enabled and that result unreadable (as the station
    notes and stores them): the unreadable record's id."""
    record(repo, "VIN1", "B1", ok=False, tightening_id=tid - 1)
    version = repo.bolts_for_model("SEDAN")[0].parameters_id
    repo.enables.note("VIN1", "B1", 90, version, LOOSEN_SEL, datetime.now(UTC))
    return repo.others.record_unreadable(
        mid=61, revision=7, raw=f"unreadable loosening {tid}", error="parameter 01 missing",
        vin="VIN1", bolt="B1", controller_vin=None, tightening_id=tid, pset=90,
        result_at=None)


def test_an_ok_entered_for_a_held_loosening_is_stored_and_reported_as_a_loosening(
        sedan, tmp_path, capsys):
    """The reviewer's case in the records: the held loosening's OK, entered, is a loosening
    OK (the bolt loosened, to be tightened again) in the report, the export, the feed the
    line database takes and ``db report``; never an OK tightening."""
    from stationd import cli

    repo = sedan
    uid = _held_loosening(repo)
    # what a restart reads: held, under the loosen pset (the enable it answered)
    assert repo.holds("VIN1") == {"B1": ("tightening 2", HeldUnder(True, 90))}
    _enter(repo, torque_nm=8.0, angle_deg=400.0, kind=LOOSENING, pset=90)
    assert repo.held_bolts("VIN1") == {}
    [b1] = [b for b in repo.vehicle_report("VIN1").bolts if b.bolt_id == "B1"]
    assert (b1.status, b1.kind, b1.attempts) == (LOOSENED, LOOSENING, 2)
    assert "B1" not in repo.vehicle_report("VIN1").ok and "B1" in repo.vehicle_report(
        "VIN1").loosen
    # an OK loosening neither counts nor ends the NOK row (as a measured one)
    assert repo.nok_streaks("VIN1") == {"B1": 1}
    run = repo.ledger.since(0)[-1]["record"]            # what the line database gets
    assert (run["rundown"], run["status"], run["entered_by"], run["unreadable_id"]) == (
        LOOSENING, "ok", "sam", uid)
    assert run["params_sent"] == {"pset": 90, "torque": None, "angle": None, "loosen": True}
    assert (run["parameters"]["pset"], run["parameters"]["torque"]) == (90, None)
    [last] = [r for r in Results(repo).rundowns("VIN1") if r["bolt"] == "B1"][-1:]
    assert (last["rundown"], last["pset"], last["entered_by"]) == (LOOSENING, 90, "sam")
    capsys.readouterr()
    code = cli.main(["db", "report", "VIN1", "--db", f"sqlite:///{tmp_path / 'station.db'}"])
    out = capsys.readouterr().out
    assert code == 1                                  # not complete: B1 only loosened
    [line] = [ln for ln in out.splitlines() if ln.strip().startswith("B1 ")]
    assert "LOOSENED" in line and "entered by sam" in line
    assert "2. loosening OK pset 90, 8.0 Nm, 400.0 deg" in out


def test_a_nok_entered_for_a_held_loosening_is_a_loosening_nok_counted_in_the_row(sedan):
    repo = sedan
    _held_loosening(repo)
    _enter(repo, ok=False, torque_nm=60.0, angle_deg=2.0, kind=LOOSENING, pset=90)
    [b1] = [b for b in repo.vehicle_report("VIN1").bolts if b.bolt_id == "B1"]
    assert (b1.status, b1.kind) == ("nok", LOOSENING)
    assert repo.nok_streaks("VIN1") == {"B1": 2}
    assert repo.ledger.since(0)[-1]["record"]["rundown"] == LOOSENING


def test_a_held_tightening_is_entered_as_one_and_a_kind_must_be_a_rundown_s(sedan):
    repo = sedan
    _unreadable(repo, 12, "B1")
    with pytest.raises(DataError, match="kind"):
        _enter(repo, kind="rundown")
    assert repo.held_bolts("VIN1") == {"B1": "tightening 12"}   # nothing written
    _enter(repo)
    run = repo.ledger.since(0)[-1]["record"]
    assert run["rundown"] == TIGHTENING and run["params_sent"]["pset"] == 1


def test_what_a_held_result_came_under_is_read_from_the_enable_it_answered(sedan):
    """A restart rebuilds each hold with what its result came under: the latest enable of
    its bolt before it (the selection's loosen flag, its pset); none found: the result's own
    pset and ``loosen`` not known (the station decides); an untyped OK outside the window:
    a tightening's."""
    repo = sedan
    version = repo.bolts_for_model("SEDAN")[1].parameters_id
    # B2: no enable at all; its unreadable result's own pset as far as read
    repo.others.record_unreadable(mid=61, revision=7, raw="no enable", error="x", vin="VIN1",
                                  bolt="B2", controller_vin=None, tightening_id=None, pset=77,
                                  result_at=None)
    # B3: a loosening enabled first, then a tightening: the latest before the result decides
    sel = {**LOOSEN_SEL}
    repo.enables.note("VIN1", "B3", 90, None, sel, datetime.now(UTC) - timedelta(seconds=5))
    repo.enables.note("VIN1", "B3", 21, None, {**sel, "loosen": False},
                      datetime.now(UTC) - timedelta(seconds=1))
    repo.others.record_unreadable(mid=61, revision=7, raw="b3", error="x", vin="VIN1", bolt="B3",
                                  controller_vin=None, tightening_id=40, pset=None, result_at=None)
    # B1: an enable from before loosen psets existed (no flag): a tightening's
    repo.enables.note("VIN1", "B1", 1, version, {"point_mm": [0, 0, 0]}, datetime.now(UTC))
    _not_taken(repo, 41, "B1")
    assert repo.holds("VIN1") == {
        "B2": ("MID 0061 revision 7", HeldUnder(None, 77)),
        "B3": ("tightening 40", HeldUnder(False, 21)),
        "B1": (not_taken_note(0.0, 41), HeldUnder(False, 1))}
    assert repo.held_bolts("VIN1") == {b: note for b, (note, _) in repo.holds("VIN1").items()}


def test_an_outcome_entered_for_a_bolt_held_after_a_link_cut_names_no_older_result(sedan):
    """A bolt held once for an unreadable result (released since), then held after a link
    cut left its result unknown: the outcome entered is for the cut's (no tightening id read),
    not the older unreadable one's (a reviewer)."""
    from db.kinds import CUT_UNKNOWN, cut_unknown_note

    repo = sedan
    _unreadable(repo, 12, "B1")
    repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli", kind="release",
                               vin="VIN1", bolt="B1", comment="checked")
    note = cut_unknown_note("the controller refused to give them")
    repo.others.record_controller_event(result_type=0, what=CUT_UNKNOWN, vin="VIN1", bolt="B1",
                                        controller_vin=None, tightening_id=None, pset=1, ok=False,
                                        torque_nm=None, angle_deg=None, result_at=None, note=note)
    assert repo.held_bolts("VIN1") == {"B1": note}
    rid = _enter(repo)
    run = next(e["record"] for e in repo.ledger.since(0) if e["kind"] == RUNDOWN
               and e["record"]["id"] == rid)
    assert (run["tightening_id"], run["unreadable_id"]) == (None, None)
    assert repo.held_bolts("VIN1") == {}


def _lost_41_holds_b1_and_b2(repo: Repository) -> None:
    """Tightening 41, its push lost, fetched later and stored unattributed under VIN1, holds
    B1 and B2 (it may be either's)."""
    from db.kinds import LOST_UNKNOWN, lost_unknown_note

    repo.others.record_unattributed(vin="VIN1", controller_vin=None, tightening_id=41, pset=1,
                                    ok=True, torque_nm=49.6, angle_deg=31.0,
                                    result_at=datetime(2026, 12, 1, 8, 0, 0, tzinfo=UTC),
                                    reason="fetched later")
    for bolt in ("B1", "B2"):
        repo.others.record_controller_event(
            result_type=0, what=LOST_UNKNOWN, vin="VIN1", bolt=bolt, controller_vin=None,
            tightening_id=41, pset=1, ok=False, torque_nm=None, angle_deg=None,
            result_at=None, note=lost_unknown_note(41, 1, 1_764_576_000.0))


def test_an_outcome_entered_for_a_lost_push_hold_is_the_result_stored_unattributed(sedan):
    """Tightening 41, its push lost, fetched later and stored unattributed, may be B1's or
    B2's (both held for it, each stored: one result, two holds, not a copy).  The outcome a
    supervisor enters for B1 is that result: its rundown carries id 41, and the unattributed
    one says whose outcome it became, in the report's rows and the export (a supervisor's
    trial: retyped, the one tightening read as two in the export)."""
    repo = sedan
    _lost_41_holds_b1_and_b2(repo)
    assert sorted(repo.held_bolts("VIN1")) == ["B1", "B2"]
    [loose] = repo.others.unattributed("VIN1")
    assert loose["entered_as"] is None
    rid = _enter(repo, bolt="B1")
    run = next(e["record"] for e in repo.ledger.since(0) if e["kind"] == RUNDOWN
               and e["record"]["id"] == rid)
    assert (run["tightening_id"], run["entered_by"]) == (41, "sam")
    [loose] = repo.others.unattributed("VIN1")
    assert loose["entered_as"] == {"bolt": "B1", "by": "sam"}
    assert list(repo.held_bolts("VIN1")) == ["B2"]
    rows = list(csv.DictReader(io.StringIO(rundowns_csv(Results(repo).export("VIN1")))))
    [row] = [r for r in rows if r["status"] == "unattributed"]
    assert row["tightening_id"] == "41"
    assert row["comment"].endswith("; the outcome entered for B1 by sam")
    [mine] = [r for r in rows if r["bolt"] == "B1" and r["entered_by"] == "sam"]
    assert mine["tightening_id"] == "41"


def test_one_lost_result_entered_for_two_held_bolts_is_one_bolt_s(sedan):
    """41, its push lost, may be B1's or B2's: both held.  The supervisor finds 41 was B1's
    and enters it; B2, tightened by hand, gets its own entered outcome: 41 is carried by B1's
    rundown alone, and the unattributed one says it became B1's (a reviewer: both rundowns
    carried 41, one controller result on two bolts)."""
    repo = sedan
    _lost_41_holds_b1_and_b2(repo)
    r1 = _enter(repo, bolt="B1")
    r2 = _enter(repo, bolt="B2", comment="tightened by hand")
    runs = {e["record"]["id"]: e["record"] for e in repo.ledger.since(0) if e["kind"] == RUNDOWN}
    assert (runs[r1]["tightening_id"], runs[r2]["tightening_id"]) == (41, None)
    [loose] = repo.others.unattributed("VIN1")
    assert loose["entered_as"] == {"bolt": "B1", "by": "sam"}


def test_an_outcome_is_entered_for_a_held_bolt_a_table_imported_by_hand_retired(
        sedan, bolts_file, tmp_path):
    """``db import`` by hand under the running station took B1 out of the table while the
    station (on the table it loaded) held B1 for its unreadable result: the result of a
    bolt the station sent parameters for is stored to it (:meth:`record_tightening`), but
    the outcome a supervisor read on the controller and entered for it was refused ("bolt
    'B1' is not a bolt of model SEDAN"): the hold could only be released, the result lost."""
    from stationd.boltfile import import_bolts
    from tests.db.conftest import BASE

    repo = sedan
    b1 = repo.bolts_for_model("SEDAN")[0]
    repo.enables.note("VIN1", "B1", 1, b1.parameters_id, {}, datetime.now(UTC))
    _unreadable(repo, 12, "B1")
    assert repo.held_bolts("VIN1") == {"B1": "tightening 12"}
    cut = tmp_path / "cut.yaml"
    cut.write_text(BASE.replace("      - id: B1\n        name: one\n        position: [0, 0, 0]"
                                "\n        pset: 1\n      - id: B2", "      - id: B2", 1))
    url = repo.engine.url.render_as_string(hide_password=False)
    with Repository.open(url) as by_hand:
        assert import_bolts(by_hand, cut).removed == ["SEDAN/B1"]
    _enter(repo)
    assert repo.held_bolts("VIN1") == {}
    assert repo.vehicle_report("VIN1").ok == ["B1"]


def test_an_entered_outcome_carries_the_controller_s_time_of_the_result_it_is(sedan):
    """A quality auditor's trial: an entered outcome's row said only when it was typed in
    (``result_at``); when the controller made that result was on the unreadable one's row
    alone.  Its ``controller_at`` is the controller's time of the result it resolves."""
    repo = sedan
    version = repo.bolts_for_model("SEDAN")[0].parameters_id
    repo.enables.note("VIN1", "B1", 1, version, {}, datetime.now(UTC))
    made = datetime(2026, 12, 1, 6, 30, 5, tzinfo=UTC)
    repo.others.record_unreadable(mid=61, revision=7, raw=RAW, error="MID 0061 revision 7: short",
                                  vin="VIN1", bolt="B1", controller_vin=None, tightening_id=12,
                                  pset=1, result_at=made)
    _enter(repo)
    [b1] = [r for r in Results(repo).export("VIN1") if r["bolt"] == "B1" and r["status"] == "ok"]
    assert b1["entered_by"] == "sam" and b1["controller_at"] == made.isoformat()


def test_an_outcome_entered_for_a_link_cut_hold_naming_a_result_is_that_result(sedan):
    """A supervisor's trial: a retry made during a link cut (tightening 42), stored
    unattributed, held B1 (a link cut's hold, naming it); the OK they entered for B1 and 42
    were counted as two tightenings.  The hold stored with 42's id: the entered rundown
    carries 42 and the unattributed one says whose outcome it became."""
    from db.kinds import CUT_UNKNOWN, cut_unknown_note

    repo = sedan
    repo.others.record_unattributed(vin="VIN1", controller_vin=None, tightening_id=42, pset=1,
                                    ok=True, torque_nm=51.2, angle_deg=26.0,
                                    result_at=datetime(2026, 12, 1, 8, 0, 0, tzinfo=UTC),
                                    reason="fetched after a reconnect")
    repo.others.record_controller_event(
        result_type=0, what=CUT_UNKNOWN, vin="VIN1", bolt="B1", controller_vin=None,
        tightening_id=42, pset=1, ok=None, torque_nm=None, angle_deg=None, result_at=None,
        note=cut_unknown_note("tightening 42, a rundown of its pset made during the link cut "
                              "after its rundown 41, may be its own again or another bolt's",
                              1, 1_764_576_000.0))
    rid = _enter(repo, bolt="B1")
    run = next(e["record"] for e in repo.ledger.since(0) if e["kind"] == RUNDOWN
               and e["record"]["id"] == rid)
    assert run["tightening_id"] == 42
    [loose] = repo.others.unattributed("VIN1")
    assert loose["entered_as"] == {"bolt": "B1", "by": "sam"}
