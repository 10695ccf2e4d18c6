"""The station's notices and its state's reasons in words (stationd.words.notice_words,
state_words, state_line; skip_words for a skip, fault_words for the station's own faults,
wait_words for the sequence's rule, unchecked_words for a pair not checked,
unattributed_words for a result no bolt owns, result_type_words, gap_plan_words,
check_asked_words and comment_words):
each kind's line, word for word as the journal wrote it when the core still built the text
(daemon tests and people's log searches wait for these lines), and each notice kind's level."""

from __future__ import annotations

import pytest

from db.kinds import loosening_note, not_taken_note, other_pset_note, unknown_type_note
from drivers.wrench.base import ResultType
from stationd.reasons import (
    CoreFault,
    CoreFaultKind,
    Reason,
    Skip,
    SkipKind,
    Unattributed,
    UnattributedKind,
    Unchecked,
    UncheckedKind,
    Unproved,
    UnprovedKind,
    Wait,
    WaitKind,
    Why,
)
from stationd.station.commands import SignOut
from stationd.station.events import (
    Because,
    BoltSkipped,
    ControllerResultEvent,
    DeviceHealth,
    Notice,
    OperatorChange,
    Said,
    State,
    StateChanged,
    StateReason,
)
from stationd.station.gaps import NoFetch, plan
from stationd.station.trust import Asked, CheckAsked
from stationd.words import (
    check_asked_words,
    comment_words,
    fault_words,
    gap_plan_words,
    notice_words,
    reason_words,
    result_type_words,
    skip_words,
    state_line,
    state_words,
    unattributed_words,
    unchecked_words,
    unproved_words,
    wait_words,
    worded,
)

WORDS = [
    (Notice(Said.NO_REFERENCES),
     "no calibration check configured (no references in the station file): every pair is "
     "trusted"),
    (Notice(Said.PAIR_DISTRUSTED, pair="pair2", bolt="B03"),
     "pair2 no longer trusted while bolt B03 is selected"),
    (Notice(Said.IDS_AGAIN, tightening_id=12),
     "tightening id 12 again with other values: the controller's ids started again (a new "
     "or reset controller?); taken as a new result"),
    (Notice(Said.SENT_AGAIN, tightening_id=7, bolt="B11"),
     "result 7 of B11 sent again by the controller: stored once"),
    (Notice(Said.UNATTRIBUTED, tightening_id=12, pset=3,
            unattributed=Unattributed(UnattributedKind.OUTSIDE, 12, 3)),
     "result 12 (pset 3) outside any tightening: not attributable to a bolt, stored "
     "unattributed"),
    (Notice(Said.CONTROLLER_EVENT, result_type=3),
     "batch increment on the controller: not a tightening"),
    (Notice(Said.CONTROLLER_EVENT, bolt="B1", result_type=6),
     "abort job on the controller: not a tightening, B1 still open"),
    (Notice(Said.UNKNOWN_TYPE, result_type=9),
     "result type 9 (unknown) on the controller: not a tightening; check the controller's "
     "result there"),
    (Notice(Said.UNKNOWN_TYPE, bolt="B1", result_type=9),
     "result type 9 (unknown) on the controller: not a tightening, B1 still open; check the "
     "controller's result there"),
    (Notice(Said.GAP, tightening_id=70061, last_id=70062, note="the controller no longer has it"),
     "tightening 70061-70062 missed while the link was down: a gap (the controller no "
     "longer has it)"),
    (Notice(Said.GAP, tightening_id=5, last_id=5, link_up=True, note="not sent"),
     "tightening 5 missed with the link up: a gap (not sent)"),
    (Notice(Said.NOT_STORED, tightening_id=7, bolt="B03", note="disk I/O error"),
     "tightening 7 of B03 not stored: disk I/O error"),
    (Notice(Said.UNREADABLE, note="MID 0061 revision 7: parameter 01 missing"),
     "a result from the controller could not be read (MID 0061 revision 7: parameter 01 "
     "missing): stored whole; no bolt it could belong to"),
    (Notice(Said.HELD, bolt="B1", note="tightening 7"),
     "B1: the controller's result could not be read (tightening 7): check it on the "
     "controller, then enter its outcome, or release it to tighten it again"),
    (Notice(Said.NOT_TAKEN, bolt="B1", torque_nm=0.04, torque_min=20.0, torque_max=25.0,
            tightening_id=7),
     "B1: an OK result without a result type, 0.0 Nm outside 20.0-25.0 Nm (tightening 7): "
     "not taken as a tightening; check it on the controller, then enter its outcome, or "
     "release it to tighten it again"),
    (Notice(Said.UNKNOWN_TYPE_HELD, bolt="B1", result_type=9, tightening_id=7),
     "B1: result 7 of type 9, a type the station does not know: not taken as a tightening; "
     "check it on the controller, then enter its outcome, or release it to tighten it again"),
    (Notice(Said.CUT_RECORDED, tightening_id=41, bolt="B1"),
     "tightening 41 made during the link cut, fetched after it: recorded to B1 (its pset, "
     "VIN, tightening id and time agree)"),
    (Notice(Said.CUT_NOTHING, bolt="B1"),
     "no tightening made while the link was down (cut, or the station stopped; every result "
     "since fetched): B1 open as before"),
    (Notice(Said.CUT_UNKNOWN, bolt="B1",
            note="its result during the link cut not known: the controller refused MID 0064"),
     "B1: its result during the link cut not known: the controller refused MID 0064: check it "
     "on the controller, then enter its outcome, or release it to tighten it again"),
    (Notice(Said.LATE_RESULT, bolt="B1", tightening_id=12),
     "result 12 came after the tool went off for B1 (within the late-result window): "
     "recorded to B1"),
    (Notice(Said.LATE_RESULT, bolt="B1"),
     "the result came after the tool went off for B1 (within the late-result window): "
     "recorded to B1"),
    (Notice(Said.LATE_RESULT, bolt="B1", vin="VIN1", tightening_id=12),
     "result 12 came after the tool went off for B1 (within the late-result window): "
     "recorded to B1 of VIN1 (gone from the station since)"),
    (Notice(Said.LOST_RECORDED, bolt="B1", tightening_id=41),
     "tightening 41, its push lost, fetched when a later one came: made while the tool was on "
     "for B1 alone, recorded to B1"),
    (Notice(Said.LOST_CHECKED, bolt="B1", tightening_id=41),
     "tightening 41, its push lost, fetched as B1's late-result window ended: made while the "
     "tool was on for B1 alone, recorded to B1"),
    (Notice(Said.LOST_CHECKED, bolt="B9", vin="VIN1", tightening_id=41),
     "tightening 41, its push lost, fetched as B9's late-result window ended: made while the "
     "tool was on for B9 alone, recorded to B9 of VIN1 (gone from the station since)"),
    (Notice(Said.LOST_FOUND_ON, bolt="B1", tightening_id=42),
     "tightening 42, its push not come (lost, or late), fetched by a check of the "
     "controller's newest with the tool on for B1: made while the tool was on for B1 alone, "
     "recorded to B1, the tool off"),
    (Notice(Said.CUT_UNKNOWN, bolt="B1", vin="VIN1", note="tightening 41 may be its own"),
     "B1 of VIN1 (gone from the station): tightening 41 may be its own: check it on the "
     "controller; held when that vehicle is back (stationd reopen), to release or enter its "
     "outcome"),
    (Notice(Said.LOOSEN_PSET_TIGHTENED, bolt="B1", pset=9),
     "B1: the loosen pset 9 reported a tightening: the bolt counts as tightened; check that "
     "pset's program"),
    (Notice(Said.LOOSENED, bolt="B1"), "B1 loosened: its tightening pset goes next"),
    (Notice(Said.LOOSENING_NOK, bolt="B1", count=2), "B1: loosening NOK (2 NOK in a row)"),
    (Notice(Said.LOCKED, bolt="B12", count=3),
     "B12 locked after 3 NOK in a row: a supervisor releases it"),
    (Notice(Said.NOK_AFTER_LOCK, bolt="B12", tightening_id=42, count=4, locked_at=3),
     "B12: tightening 42, a NOK made after B12 had reached 3 NOK in a row (the push of one "
     "of them lost: the station did not know yet), recorded: 4 NOK in a row; B12 stays "
     "locked for a supervisor"),
    (Notice(Said.ENTERED_OK, bolt="B1", torque_nm=49.6, angle_deg=31.0, user="sam"),
     "B1: OK 49.6 Nm, 31.0 deg entered by sam from the controller's screen: B1 done"),
    (Notice(Said.ENTERED_OK, bolt="B1", torque_nm=49.6, angle_deg=31.0, user="sam",
            note="tightening 7"),
     "B1: OK 49.6 Nm, 31.0 deg entered by sam from the controller's screen (the result that "
     "could not be read: tightening 7): B1 done"),
    (Notice(Said.ENTERED_NOK, bolt="B1", torque_nm=12.0, angle_deg=4.5, user="sam",
            note=not_taken_note(0.0, 7)),
     "B1: NOK 12.0 Nm, 4.5 deg entered by sam from the controller's screen (the result not "
     "taken: an OK result without a result type, 0.0 Nm outside the bolt's torque window "
     "(tightening 7)): a NOK of B1, the NOK policy applies"),
    # a held loosening's outcome: said to be a loosening, never the bolt done
    (Notice(Said.ENTERED_LOOSENING_OK, bolt="B1", torque_nm=8.0, angle_deg=400.0, user="sam",
            note=loosening_note("tightening 7", 90), pset=90),
     "B1: loosening OK 8.0 Nm, 400.0 deg entered by sam from the controller's screen (the "
     "result that could not be read: tightening 7, a loosening with loosen pset 90): a "
     "loosening, not a tightening: B1 not done"),
    (Notice(Said.ENTERED_LOOSENING_NOK, bolt="B1", torque_nm=60.0, angle_deg=2.0, user="sam",
            note=loosening_note("tightening 7", 90), pset=90),
     "B1: loosening NOK 60.0 Nm, 2.0 deg entered by sam from the controller's screen (the "
     "result that could not be read: tightening 7, a loosening with loosen pset 90): a "
     "loosening NOK of B1, the NOK policy applies"),
    (Notice(Said.TYPED_COPY, tightening_id=41, bolt="B11"),
     "tightening 41, fetched without its result type and B11 held for it, came pushed with "
     "its type, made while the tool was on for B11: recorded to B11, its hold ended"),
    (Notice(Said.OTHER_VIN, tightening_id=14, bolt="B17", vin="VIN1",
            note="WVWZZZ1JZ3W000001"),
     "tightening 14 of B17 carries the controller's VIN WVWZZZ1JZ3W000001, not VIN1: "
     "recorded to B17 (its tool was on for it); the controller files it under that VIN: its "
     "VIN download (MID 0050) did not take, or another program set it"),
    (Notice(Said.REWORK_REOPENED, vin="VIN1"),
     "VIN VIN1 already closed: reopened as a rework (its records kept)"),
    (Notice(Said.LATE_ACK, bolt="B1"), "late acknowledgement for B1 ignored"),
]


@pytest.mark.parametrize(("notice", "words"), WORDS,
                         ids=[f"{n.said.name}-{i}" for i, (n, _) in enumerate(WORDS)])
def test_each_notice_says_what_the_journal_said(notice: Notice, words: str) -> None:
    assert notice_words(notice) == words


def test_every_kind_has_its_words() -> None:
    assert {n.said for n, _ in WORDS} == set(Said)


def test_a_notice_s_level_is_its_kind_s() -> None:
    errors = {s for s in Said if Notice(s).level == "error"}
    warnings = {s for s in Said if Notice(s).level == "warning"}
    assert errors == {Said.NOT_STORED}
    assert warnings == {
        Said.PAIR_DISTRUSTED, Said.IDS_AGAIN, Said.UNATTRIBUTED, Said.UNKNOWN_TYPE, Said.GAP,
        Said.UNREADABLE, Said.HELD, Said.CUT_UNKNOWN, Said.NOT_TAKEN, Said.UNKNOWN_TYPE_HELD,
        Said.LOOSEN_PSET_TIGHTENED, Said.LOOSENING_NOK, Said.LOCKED, Said.NOK_AFTER_LOCK,
        Said.ENTERED_NOK, Said.ENTERED_LOOSENING_NOK, Said.OTHER_VIN}
    # a controller event is a warning only while a bolt is still open
    assert Notice(Said.CONTROLLER_EVENT, bolt="B1").level == "warning"


def test_a_locked_or_held_bolt_is_said_alike_as_a_notice_and_as_a_refusal() -> None:
    """One bolt, one wording: the journal's notice and the operator's refusal."""
    assert notice_words(Notice(Said.LOCKED, bolt="B2", count=3)) == \
        reason_words(Reason(Why.LOCKED, bolt="B2", count=3))
    assert notice_words(Notice(Said.HELD, bolt="B2", note="tightening 9")) == \
        reason_words(Reason(Why.HELD, bolt="B2", note="tightening 9"))


@pytest.mark.parametrize("note", [unknown_type_note(9, 2002), other_pset_note(5005, 3, 1)])
def test_a_bolt_held_for_a_result_read_and_not_taken_is_not_said_unreadable(note: str) -> None:
    """An integrator's trial with an independent controller: a bolt held for a result of
    another pset, or of a type the station does not know, was said "the controller's result
    could not be read (...)" where that result was read.  Said as its note, alike as a notice
    and as a refusal; a result that did not read still says so."""
    said = notice_words(Notice(Said.HELD, bolt="B2", note=note))
    assert said.startswith(f"B2: {note}: not taken as a tightening; check it on the "
                           "controller") and \
        "could not be read" not in said
    assert said == reason_words(Reason(Why.HELD, bolt="B2", note=note))
    assert "could not be read (tightening 9)" in notice_words(
        Notice(Said.HELD, bolt="B2", note="tightening 9"))


def test_a_notice_goes_on_the_wire_as_its_kind_and_fields() -> None:
    """The event's JSON carries the kind and the fields, never words to parse back."""
    doc = Notice(Said.LOCKED, bolt="B2", count=3, t=1.0).to_json()
    assert (doc["kind"], doc["said"], doc["bolt"], doc["count"]) == ("notice", "locked", "B2", 3)
    assert "message" not in doc


STATE_WORDS = [
    (StateReason(Because.OPENING), "opening the devices"),
    (StateReason(Because.FAULT, faults=(("lift", "no answer from 10.0.0.7:502 for 2.0 s"),
                                         ("pair1", "no frame within 1 s"))),
     "lift: no answer from 10.0.0.7:502 for 2.0 s; pair1: no frame within 1 s"),
    (StateReason(Because.RECOVERED), "recovered; waiting for the lift"),
    (StateReason(Because.STARTED),
     "station started: the tool stays off until a bolt is confirmed"),
    (StateReason(Because.CONTROLLER_BACK),
     "controller back: the tool stays off until a bolt is confirmed"),
    (StateReason(Because.WAITING_LIFT), "waiting for the lift"),
    (StateReason(Because.LIFT_NOT_READY, note="lift moving"), "lift moving"),
    (StateReason(Because.LOADING, vin="VIN1"), "loading vehicle VIN1"),
    (StateReason(Because.TRACKING), "tracking the wrench"),
    (StateReason(Because.SELECTED, bolt="B11", pset=3), "bolt B11 selected"),
    (StateReason(Because.SELECTED, bolt="B11", pset=90, loosen=True),
     "bolt B11 selected: loosen first (pset 90)"),
    (StateReason(Because.ACKNOWLEDGED, bolt="B11"),
     "bolt B11 acknowledged; confirming the wrench is on it"),
    (StateReason(Because.RESULT_OWED, bolt="B08", owed="B05"),
     "bolt B08: the tool stays off until bolt B05's result is in, or can no longer come"),
    (StateReason(Because.CUT_OWED, bolt="B08", owed="B05"),
     "bolt B08: the tool stays off until the controller's results made during the link cut "
     "are fetched (bolt B05 was enabled)"),
    (StateReason(Because.TIGHTENING, bolt="B11"), "tightening bolt B11"),
    (StateReason(Because.TIGHTENING, bolt="B11", loosen=True), "loosening bolt B11"),
    (StateReason(Because.NOT_CONFIRMED, bolt="B11"), "wrench not confirmed on bolt B11"),
    (StateReason(Because.SELECTED_UNCONFIRMED, bolt="B11"),
     "bolt B11 selected; wrench not confirmed"),
    (StateReason(Because.WRENCH_LEFT, bolt="B11"), "wrench left bolt B11"),
    (StateReason(Because.LATE_ACK, bolt="B11"), "late acknowledgement for B11 ignored"),
    (StateReason(Because.RUNDOWN, bolt="B11"), "bolt B11 tightened"),
    (StateReason(Because.RUNDOWN, bolt="B11", loosen=True), "bolt B11 loosened"),
    (StateReason(Because.RUNDOWN, bolt="B11", ok=False), "bolt B11 NOK"),
    (StateReason(Because.RUNDOWN, bolt="B11", loosen=True, ok=False), "bolt B11 loosening NOK"),
    (StateReason(Because.PUSH_AFTER_LOST, bolt="B11"),
     "bolt B11: a rundown's result came after others the controller did not push: those "
     "first"),
    (StateReason(Because.RESULT, bolt="B11", ok=True), "bolt B11 OK; tracking"),
    (StateReason(Because.RESULT, bolt="B11", ok=False, loosen=True),
     "bolt B11 loosening NOK; tracking"),
    (StateReason(Because.UNREADABLE, bolt="B11"), "bolt B11: its result could not be read"),
    (StateReason(Because.UNREADABLE_HELD, bolt="B11"),
     "bolt B11: its result could not be read; held for a supervisor"),
    # under its loosen pset: the outcome to enter is a loosening's
    (StateReason(Because.UNREADABLE, bolt="B11", loosen=True),
     "bolt B11: its loosening's result could not be read"),
    (StateReason(Because.UNREADABLE_HELD, bolt="B11", loosen=True),
     "bolt B11: its loosening's result could not be read; held for a supervisor"),
    (StateReason(Because.NOT_TAKEN, bolt="B11"),
     "bolt B11: an OK result without a result type outside its torque window"),
    (StateReason(Because.NOT_TAKEN_HELD, bolt="B11"),
     "bolt B11: an OK result without a result type outside its torque window; held for a "
     "supervisor"),
    (StateReason(Because.NOT_TAKEN_HELD, bolt="B11",
                 note="a result of a type the station does not know (type 9, tightening 7)"),
     "bolt B11: a result of a type the station does not know (type 9, tightening 7); held for "
     "a supervisor"),
    (StateReason(Because.UNKNOWN_HELD, bolt="B11"),
     "bolt B11: its result not known; held for a supervisor"),
    (StateReason(Because.SKIPPED, bolt="B11",
                 skip=Skip(SkipKind.COMMAND, user="sam", comment="no access")),
     "bolt B11 sam's command (no access)"),
    (StateReason(Because.LOOSEN_ORDERED, bolt="B11"), "bolt B11: loosen first"),
    (StateReason(Because.OPERATOR, how=OperatorChange.SIGNED_OUT), "operator signed out"),
    (StateReason(Because.OPERATOR, how=OperatorChange.IDLE), "operator idle"),
    (StateReason(Because.TEACH_MODE), "teach mode"),
    (StateReason(Because.TEACHING, model="M1", user="ed"),
     "teaching M1 (ed): hold the tool on a bolt"),
    (StateReason(Because.TEACHING, model="M1", user="ed", bolt="B7"),
     "teaching M1 (ed): measuring B7"),
    (StateReason(Because.TEACH_ENDED), "teach mode ended; waiting for the lift"),
    (StateReason(Because.TEACH_ENDED_TRACKING), "teach mode ended; tracking the wrench"),
]


@pytest.mark.parametrize(("reason", "words"), STATE_WORDS,
                         ids=[f"{r.kind.name}-{i}" for i, (r, _) in enumerate(STATE_WORDS)])
def test_each_state_reason_says_what_the_core_said(reason: StateReason, words: str) -> None:
    assert state_words(reason) == words


def test_every_state_reason_kind_has_its_words() -> None:
    assert {r.kind for r, _ in STATE_WORDS} == set(Because)


def test_the_journal_line_names_a_selected_bolt_once() -> None:
    """``bolt selected: bolt B11 selected`` said the state twice; the reason alone (the
    screens, OPC UA) keeps its words."""
    assert state_line(State.BOLT_SELECTED, StateReason(Because.SELECTED, bolt="B11", pset=3)) \
        == "bolt selected: B11"
    assert state_line(State.BOLT_SELECTED, StateReason(Because.SELECTED, bolt="B05", pset=90,
                                                       loosen=True)) == \
        "bolt selected: B05: loosen first (pset 90)"
    assert state_line(State.BOLT_SELECTED,
                      StateReason(Because.SELECTED_UNCONFIRMED, bolt="B11")) == \
        "bolt selected: B11; wrench not confirmed"
    # every other line is the state and its reason's words, as the daemon's tests wait for
    assert state_line(State.BOLT_SELECTED, StateReason(Because.ACKNOWLEDGED, bolt="B11")) == \
        "bolt selected: bolt B11 acknowledged; confirming the wrench is on it"
    assert state_line(State.TIGHTENING, StateReason(Because.TIGHTENING, bolt="B05")) == \
        "tightening: tightening bolt B05"
    assert state_line(State.TRACKING, StateReason(Because.TRACKING)) == \
        "tracking: tracking the wrench"


def test_teach_mode_and_faults_are_said_alike_as_the_state_and_as_a_refusal() -> None:
    """A command refused while teaching or in fault names the same as the state's reason."""
    teaching = state_words(StateReason(Because.TEACHING, model="M1", user="ed", bolt="B7"))
    assert reason_words(Reason(Why.TEACHING, note="M1", user="ed", bolt="B7")) == \
        f"teach mode is on ({teaching})"
    faults = (("lift", "no answer"), ("pair1", "no frame"))
    assert reason_words(Reason(Why.DEVICE_FAULT, faults=faults)) == \
        f"a device is in fault: {state_words(StateReason(Because.FAULT, faults=faults))}"


def test_a_state_change_goes_on_the_wire_as_its_kind_and_fields() -> None:
    """The event's JSON carries the reason's kind and fields (the screens' JSON has its words
    beside the kind: stationd.web.view)."""
    doc = StateChanged(State.BOLT_SELECTED, StateReason(Because.SELECTED, bolt="B2", pset=4),
                       t=1.0).to_json()
    assert (doc["kind"], doc["state"]) == ("state_changed", "bolt selected")
    assert (doc["reason"]["kind"], doc["reason"]["bolt"], doc["reason"]["pset"]) == (
        "selected", "B2", 4)


def test_records_waiting_agree_their_verb():
    from stationd.words import records_waiting

    assert [records_waiting(n) for n in (0, 1, 13)] == [
        "no record waits yet", "1 record waits", "13 records wait"]


#: why a bolt is skipped, word for word as the core wrote it (the screens, the refusals and
#: the state's reason say it; a daemon test waits for "B05 skipped: olga's command (...)")
SKIP_WORDS = [
    (Skip(SkipKind.NOK_POLICY), "NOK, skipped by the NOK policy"),
    (Skip(SkipKind.NO_LOOSEN_PSET),
     "to be loosened, and the NOK policy gives it no loosen_pset"),
    (Skip(SkipKind.REFUSED, reason="pset 2 unknown"),
     "controller refused its parameters (pset 2 unknown)"),
    (Skip(SkipKind.COMMAND, user="olga", comment="no access"), "olga's command (no access)"),
    (Skip(SkipKind.COMMAND, user="sam", comment=""), "sam's command"),
]


@pytest.mark.parametrize(("skip", "words"), SKIP_WORDS,
                         ids=[f"{s.kind.name}-{i}" for i, (s, _) in enumerate(SKIP_WORDS)])
def test_each_skip_says_what_the_core_said(skip: Skip, words: str) -> None:
    assert skip_words(skip) == words


def test_every_skip_kind_has_its_words() -> None:
    assert {s.kind for s, _ in SKIP_WORDS} == set(SkipKind)


#: the station's own faults, word for word as the core wrote them (the state's reason, the
#: device's health, the journal's fault line)
FAULT_WORDS = [
    (CoreFault(CoreFaultKind.VIN_CHANGED, vin="VINA", plc_vin="VINOTHER"),
     "the PLC reports VIN VINOTHER at height, the station has VINA loaded: lower the lift"),
    (CoreFault(CoreFaultKind.MODEL_CHANGED, vin="VINA", code=7, plc_code=9),
     "the PLC reports model code 9 at height, VINA was loaded as 7: lower the lift"),
    (CoreFault(CoreFaultKind.CLOSED, vin="VINR", note="vehicle VINR is closed"),
     "VIN VINR already closed: rework needs the vehicle reopened (vehicle VINR is closed); "
     "lower the lift to clear"),
    (CoreFault(CoreFaultKind.PARAMS_REFUSED, bolt="B1", note="pset 2 unknown"),
     "controller refused the parameters for B1: pset 2 unknown"),
    (CoreFault(CoreFaultKind.LIFT_REPORTS_FAULT),
     "the lift PLC reports a fault of the lift (its fault bit): nothing is tightened until it "
     "is cleared at the lift"),
]


@pytest.mark.parametrize(("fault", "words"), FAULT_WORDS,
                         ids=[f"{f.kind.name}-{i}" for i, (f, _) in enumerate(FAULT_WORDS)])
def test_each_fault_of_the_station_says_what_the_core_said(fault: CoreFault, words: str) -> None:
    assert fault_words(fault) == words


def test_every_fault_kind_has_its_words() -> None:
    assert {f.kind for f, _ in FAULT_WORDS} == set(CoreFaultKind)


def test_a_device_s_own_fault_is_said_as_it_came() -> None:
    assert fault_words("no answer from 10.0.0.7:502 for 2.0 s") == \
        "no answer from 10.0.0.7:502 for 2.0 s"


def test_a_skip_is_said_alike_by_a_refusal_a_wait_and_the_state() -> None:
    """One skip, one wording: the refusal on the bolt, a bolt waiting for it, the state's
    reason (as the core wrote them when it kept the skip as text)."""
    by_olga = Skip(SkipKind.COMMAND, user="olga", comment="no access")
    refused = Skip(SkipKind.REFUSED, reason="pset 2 unknown")
    assert reason_words(Reason(Why.SKIPPED, bolt="B05", skip=by_olga)) == \
        "B05 skipped: olga's command (no access)"
    assert reason_words(Reason(Why.MUST_WAIT, bolt="A3", blocking=("A1", "A2"),
                               wait=Wait(WaitKind.ORDER, order=2, batch="subframe",
                                         bolts=("A1", "A2")),
                               skips=(("A1", refused),))) == (
        "A3 must wait: order 2 in batch subframe needs A1, A2 done first; A1 was skipped: "
        "controller refused its parameters (pset 2 unknown)")
    assert reason_words(Reason(Why.MUST_WAIT, bolt="B2",
                               wait=Wait(WaitKind.ORDER, order=2, bolts=("B1",)))) \
        == "B2 must wait: order 2 needs B1 done first"
    assert state_words(StateReason(Because.SKIPPED, bolt="B05", skip=by_olga)) == \
        "bolt B05 olga's command (no access)"


def test_a_loosen_command_says_whose_it_was() -> None:
    """A loosen command's reason carries who gave it and their comment, said as a skip's
    command is; the NOK policy's loosen names nobody."""
    first = Reason(Why.LOOSEN_FIRST, bolt="B1", pset=90, user="sam", note="cross-threaded")
    assert reason_words(first) == \
        "B1: loosen first (loosen pset 90), then tighten: sam's command (cross-threaded)"
    assert reason_words(Reason(Why.LOOSEN_FIRST, bolt="B1", pset=90, user="sam", note="")) \
        == "B1: loosen first (loosen pset 90), then tighten: sam's command"
    assert reason_words(Reason(Why.LOOSEN_FIRST, bolt="B1", pset=90)) == \
        "B1: loosen first (loosen pset 90), then tighten"


def test_the_station_s_own_fault_is_said_beside_a_device_s_own() -> None:
    faults = (("wrench", FAULT_WORDS[3][0]), ("lift", "no answer"))
    said = "wrench: controller refused the parameters for B1: pset 2 unknown; lift: no answer"
    assert state_words(StateReason(Because.FAULT, faults=faults)) == said
    assert reason_words(Reason(Why.DEVICE_FAULT, faults=faults)) == \
        f"a device is in fault: {said}"


def test_the_words_are_written_into_the_event_at_publication() -> None:
    """The core publishes a skip and its own fault typed, with no words; ``worded`` (the
    shell's publication) writes them where every reader read them, and the event's JSON is
    what it was when the core wrote the text."""
    skipped = worded(BoltSkipped("B3", skip=Skip(SkipKind.NOK_POLICY), t=1.0))
    assert isinstance(skipped, BoltSkipped)
    assert (skipped.reason, skipped.skip) == ("NOK, skipped by the NOK policy",
                                              Skip(SkipKind.NOK_POLICY))
    assert skipped.to_json() == {"kind": "bolt_skipped", "t": 1.0, "bolt": "B3",
                                 "reason": "NOK, skipped by the NOK policy"}
    fault = FAULT_WORDS[3][0]
    health = worded(DeviceHealth("wrench", False, "refused", fault=fault, t=2.0))
    assert isinstance(health, DeviceHealth) and health.fault == fault
    assert health.to_json() == {"kind": "refused", "t": 2.0, "device": "wrench", "ok": False,
                                "reason": FAULT_WORDS[3][1]}
    # a device's own words, and any other event, are published as they are
    own = DeviceHealth("lift", False, "down", "no answer", t=3.0)
    assert worded(own) is own
    notice = Notice(Said.LOOSENED, bolt="B1")
    assert worded(notice) is notice


#: the sequence's rule a bolt waits for, word for word as the matcher wrote it (the refusal's
#: words after "must wait: ")
WAIT_WORDS = [
    (Wait(WaitKind.ORDER, order=2, bolts=("U1", "U2")), "order 2 needs U1, U2 done first"),
    (Wait(WaitKind.ORDER, order=2, batch="subframe", bolts=("A1", "A2")),
     "order 2 in batch subframe needs A1, A2 done first"),
    (Wait(WaitKind.BATCH, batches=(("subframe", ("A2", "A3")),)),
     "finish batch subframe first: A2, A3 remaining"),
    (Wait(WaitKind.BATCH, batches=(("subframe", ("A3",)), ("x", ("F",)))),
     "finish batch subframe first: A3 remaining; finish batch x first: F remaining"),
]


@pytest.mark.parametrize(("wait", "words"), WAIT_WORDS,
                         ids=[f"{w.kind.name}-{i}" for i, (w, _) in enumerate(WAIT_WORDS)])
def test_each_wait_says_what_the_matcher_said(wait: Wait, words: str) -> None:
    assert wait_words(wait) == words
    assert reason_words(Reason(Why.MUST_WAIT, bolt="Z9", wait=wait)) == f"Z9 must wait: {words}"


def test_every_wait_kind_has_its_words() -> None:
    assert {w.kind for w, _ in WAIT_WORDS} == set(WaitKind)


#: why a pair is not checked, word for word as the trust rules wrote it (the screens'
#: calibration panel, the refusal of a bolt end only such a pair saw)
UNCHECKED_WORDS = [
    (Unchecked(UncheckedKind.SINCE_START), "not checked since the start"),
    (Unchecked(UncheckedKind.ARRIVAL, vin="VIN1"), "checking for vehicle VIN1"),
    (Unchecked(UncheckedKind.PAIRS_UNKNOWN), "which pairs saw the wrench is not known"),
    (Unchecked(UncheckedKind.NO_MARKER), "it sees no reference marker"),
    (Unchecked(UncheckedKind.NOT_MEASURED, reference="R1", measure="not found"),
     "reference R1 not found"),
    (Unchecked(UncheckedKind.NOT_MEASURED, reference="R2", measure="no frames",
               note="grab timed out"), "reference R2 no frames (grab timed out)"),
    (Unchecked(UncheckedKind.NOT_MEASURED), "nothing measured"),
    (Unchecked(UncheckedKind.NOT_MEASURED, note="the pair is down"),
     "nothing measured (the pair is down)"),
]


@pytest.mark.parametrize(("unchecked", "words"), UNCHECKED_WORDS,
                         ids=[f"{u.kind.name}-{i}" for i, (u, _) in enumerate(UNCHECKED_WORDS)])
def test_each_unchecked_pair_says_what_the_trust_rules_said(unchecked: Unchecked,
                                                            words: str) -> None:
    assert unchecked_words(unchecked) == words
    assert reason_words(Reason(Why.PAIR_UNCHECKED, pair="pair1", unchecked=unchecked)) == \
        f"pair1 not checked against the references: {words}"
    assert reason_words(Reason(Why.PAIR_UNCHECKED, unchecked=unchecked)) == \
        f"not checked against the references: {words}"


def test_every_unchecked_kind_has_its_words() -> None:
    assert {u.kind for u, _ in UNCHECKED_WORDS} == set(UncheckedKind)


#: why a calibration check is measured, word for word as the core wrote it
ASKED_WORDS = [
    (CheckAsked(Asked.STARTED), "station started"),
    (CheckAsked(Asked.ARRIVED, vin="VIN1"), "vehicle VIN1 arrived"),
    (CheckAsked(Asked.PERIODIC), "periodic check"),
    (CheckAsked(Asked.COMMAND, user="eve"), "asked by eve"),
]


@pytest.mark.parametrize(("asked", "words"), ASKED_WORDS,
                         ids=[a.kind.name for a, _ in ASKED_WORDS])
def test_each_check_asked_says_what_the_core_said(asked: CheckAsked, words: str) -> None:
    assert check_asked_words(asked) == words


def test_every_asked_kind_has_its_words() -> None:
    assert {a.kind for a, _ in ASKED_WORDS} == set(Asked)


#: what did not prove a fetched result the cut enable's, word for word as the core wrote it
#: (stored in the unattributed result's reason, between parentheses)
UNPROVED_WORDS = [
    (Unproved(UnprovedKind.PSET, bolt="B1", pset=9, sent_pset=1), "pset 9, not 1 sent for B1"),
    (Unproved(UnprovedKind.VIN, vin="OTHER", sent_vin="VIN1"), "VIN OTHER, not VIN1"),
    (Unproved(UnprovedKind.NOT_FIRST, follows=40), "not the first tightening after 40"),
    (Unproved(UnprovedKind.FOLLOWS_UNKNOWN), "the last tightening id accounted for unknown"),
    (Unproved(UnprovedKind.CLOCK_UNKNOWN), "the controller's clock is not known"),
    (Unproved(UnprovedKind.OUTSIDE_CUT, bolt="B1"),
     "made outside the enable of B1 and the link cut"),
    (Unproved(UnprovedKind.NO_CUT), "no tool enable left without its result by the link cut"),
    (Unproved(UnprovedKind.RAN_AGAIN, bolt="B1", follows=41),
     "made during the link cut after B1's rundown 41: the tool ran again, on B1 or another "
     "bolt; B1 held"),
]


@pytest.mark.parametrize(("unproved", "words"), UNPROVED_WORDS,
                         ids=[u.kind.name for u, _ in UNPROVED_WORDS])
def test_each_unproved_result_says_what_the_core_said(unproved: Unproved, words: str) -> None:
    assert unproved_words(unproved) == words


def test_every_unproved_kind_has_its_words() -> None:
    assert {u.kind for u, _ in UNPROVED_WORDS} == set(UnprovedKind)


#: why a result is stored unattributed: the record's reason, byte for byte as the core wrote
#: it (the database keeps it; quality reads it)
UNATTRIBUTED_WORDS = [
    (Unattributed(UnattributedKind.OUTSIDE, 12, 3), "result 12 (pset 3) outside any tightening"),
    (Unattributed(UnattributedKind.FETCHED_LIVE, 13, 3),
     "result 13 (pset 3) fetched after a later one came, the link up"),
    (Unattributed(UnattributedKind.FETCHED_CHECKED, 13, 3),
     "result 13 (pset 3) fetched as an enable's late-result window ended, the link up"),
    (Unattributed(UnattributedKind.FETCHED, 41, 9, UNPROVED_WORDS[0][0]),
     "result 41 (pset 9) fetched after a reconnect (pset 9, not 1 sent for B1)"),
    (Unattributed(UnattributedKind.FETCHED, 42, 1),
     "result 42 (pset 1) fetched after a reconnect"),
    (Unattributed(UnattributedKind.UNREAD_READ, 6, 2, bolt="B47", between=(5, 7)),
     "result 6 (pset 2) fetched after a later one came, the link up: the result of B47 that "
     "could not be read (the one id between tightenings 5 and 7), now read; B47 stays held "
     "until its outcome is entered"),
    (Unattributed(UnattributedKind.OTHER_PSET, 12, 9, bolt="B1"),
     "result 12 (pset 9) pushed while the tool was on for B1 with another pset: run with "
     "another program (one selected on the controller?), or none of B1's: B1 held"),
]


@pytest.mark.parametrize(("why", "words"), UNATTRIBUTED_WORDS,
                         ids=[f"{u.kind.name}-{i}" for i, (u, _) in enumerate(UNATTRIBUTED_WORDS)])
def test_each_unattributed_result_says_what_the_core_stored(why: Unattributed,
                                                             words: str) -> None:
    assert unattributed_words(why) == words
    stored = "stored apart with its values" if why.kind in (
        UnattributedKind.UNREAD_READ, UnattributedKind.OTHER_PSET) \
        else "not attributable to a bolt, stored unattributed"
    assert notice_words(Notice(Said.UNATTRIBUTED, unattributed=why)) == f"{words}: {stored}"


def test_every_unattributed_kind_has_its_words() -> None:
    assert {u.kind for u, _ in UNATTRIBUTED_WORDS} == set(UnattributedKind)


def test_each_result_type_is_named_as_the_controller_names_it() -> None:
    """Stored as the controller event's ``what``, published and said: as the core named it."""
    names = {ResultType.TIGHTENING: "tightening", ResultType.LOOSENING: "loosening",
             ResultType.BATCH_INCREMENT: "batch increment",
             ResultType.BATCH_DECREMENT: "batch decrement",
             ResultType.BYPASS_PSET: "bypass parameter set", ResultType.ABORT_JOB: "abort job",
             ResultType.SYNC_TIGHTENING: "synchronized tightening",
             ResultType.REFERENCE_SETUP: "reference setup"}
    assert set(names) == set(ResultType)
    assert {t: result_type_words(int(t)) for t in ResultType} == names
    assert result_type_words(9) == "result type 9 (unknown)"
    assert result_type_words(None) == "result"


def test_a_controller_event_is_named_at_publication() -> None:
    """The core publishes the type code and no name; the shell's publication writes the name
    where the event carried it, and the event's JSON is what it was."""
    ev = worded(ControllerResultEvent(3, "", 7, 1, True, "B1", t=1.0))
    assert isinstance(ev, ControllerResultEvent) and ev.what == "batch increment"
    assert ev.to_json() == {"kind": "controller_result_event", "t": 1.0, "result_type": 3,
                            "what": "batch increment", "tightening_id": 7, "pset": 1,
                            "ok": True, "bolt": "B1"}
    own = ControllerResultEvent(0, "not taken", 8, 1, True, "B1", t=2.0)
    assert worded(own) is own       # the station's own kind, as it is


#: why nothing is fetched after a reconnect, word for word as the journal wrote it
NO_FETCH_WORDS = [
    (plan(None, 500), "no tightening recorded yet: counting from the controller's newest, 500"),
    (plan(800, 12), "the controller's newest tightening (12) is older than the last recorded "
                    "(800): its ids restarted"),
]


def test_each_reason_not_to_fetch_says_what_the_journal_said() -> None:
    assert [gap_plan_words(p) for p, _ in NO_FETCH_WORDS] == [w for _, w in NO_FETCH_WORDS]
    assert {p.why for p, _ in NO_FETCH_WORDS} == set(NoFetch)


def test_the_station_s_idle_sign_out_is_recorded_with_its_comment() -> None:
    assert comment_words(SignOut(user="olga", idle_s=600.0)) == "idle for 600 s"
    assert comment_words(SignOut(user="olga", idle_s=90.5)) == "idle for 90.5 s"
    assert comment_words(SignOut("end of shift", "olga")) == "end of shift"


def test_a_hold_without_a_result_is_not_said_as_a_result_not_read():
    """A link cut's and a lost push's holds: their result was never in hand (a supervisor's
    trial: "the controller's result could not be read (tightening 26 may be its own ...)")."""
    from db.kinds import cut_unknown_note, lost_unknown_note

    for note in (cut_unknown_note("the controller refused MID 0064", 1, 1000.0),
                 lost_unknown_note(26, 1, 1000.0)):
        said = reason_words(Reason(Why.HELD, bolt="B14", note=note))
        assert said == (f"B14: {note}: check it on the controller, then enter its "
                        "outcome, or release it to tighten it again")
        assert "could not be read" not in said
    assert "could not be read (tightening 7)" in reason_words(
        Reason(Why.HELD, bolt="B1", note="tightening 7"))


def test_a_lost_push_s_hold_names_the_result_that_may_be_its_own():
    """Its release's words (and the vehicle's page) name the result stored unattributed that
    may be the bolt's own; the notes of other holds name none."""
    from db.kinds import cut_unknown_note, loosening_note, lost_unknown_id, lost_unknown_note

    note = lost_unknown_note(26, 1, 1000.0)
    assert lost_unknown_id(note) == 26 == lost_unknown_id(loosening_note(note, 90))
    assert lost_unknown_id(cut_unknown_note("tightening 26 may be its own", 1, 1000.0)) is None
    assert lost_unknown_id("tightening 7") is lost_unknown_id(None) is None


def test_releasing_a_gap_s_hold_warns_the_bolt_may_be_tightened_already():
    """A gap's hold (its result may be among tightenings the controller did not give) is
    released with the warning a lost push's gets (a reviewer: 'its hold ended' alone, the
    joint perhaps torqued already); a link cut's and an unreadable result's warn too, with
    no result to name (a supervisor's trial: released, the bolt was tightened twice)."""
    from db.kinds import cut_unknown_note, is_unknown_note, lost_gap_note
    from stationd.words import _reopened

    gap = lost_gap_note("41-42", 1, 1000.0)
    assert gap.startswith("its result may be among tightenings 41-42 (their pushes lost, "
                          "not given by the controller); the tool was enabled for pset 1 at ")
    assert lost_gap_note("41", None, 1000.0).startswith(
        "its result may be tightening 41 (its push lost, not given by the controller); ")
    assert is_unknown_note(gap)
    assert _reopened("B1", gap) == (
        ": B1 is open to be tightened again, but it may be tightened already (a result the "
        "controller did not give): check the controller before tightening it again")
    for note in (cut_unknown_note("no answer"), "tightening 7"):
        assert _reopened("B1", note) == (
            ": B1 is open to be tightened again, but it may be tightened already: check the "
            "controller before tightening it again")
    assert _reopened("B1", None) == ""


def test_a_check_s_hold_says_why_and_its_release_warns_the_bolt_may_be_tightened():
    """A bolt held because the controller's newest result could not be read as its window
    ended: the note says why, the pset and when; its release warns as a lost push's."""
    from db.kinds import check_unknown_note, is_unknown_note, lost_unknown_id
    from stationd.words import _reopened

    note = check_unknown_note("refused by the controller: error 99", 3, 1000.0)
    assert note.startswith("its result not known: the controller's newest result not read as "
                           "its late-result window ended (refused by the controller: error "
                           "99): a rundown whose push was lost may be its own; the tool was "
                           "enabled for pset 3 at 1970-01-01 00:16:40 UTC")
    assert is_unknown_note(note) and lost_unknown_id(note) is None
    assert _reopened("B2", note) == (
        ": B2 is open to be tightened again, but it may be tightened already (a push lost, "
        "the controller's newest result not read): check the controller before tightening "
        "it again")


@pytest.mark.parametrize("note", [None, "tightening 21", not_taken_note(3.0, 7),
                                  unknown_type_note(11, 8)])
@pytest.mark.parametrize("count", [None, 3])
def test_a_stopped_bolt_is_said_with_what_to_do_or_without_for_the_panel(count, note):
    """A lock and a hold said together, each as its reason says it alone; for the screens'
    panel of locks the same words without what to do after each (said once below them)."""
    from stationd.reasons import Reason, Why
    from stationd.words import CHECK_ON_CONTROLLER, LOCK_RELEASE, reason_words, stopped_words

    whole = stopped_words("B2", count, note)
    parts = ([] if count is None else [reason_words(Reason(Why.LOCKED, bolt="B2", count=count))]) \
        + ([] if note is None else [reason_words(Reason(Why.HELD, bolt="B2", note=note))])
    assert whole == "; ".join(parts)
    short = stopped_words("B2", count, note, instruct=False)
    assert CHECK_ON_CONTROLLER not in short and LOCK_RELEASE not in short
    assert short == whole.replace(f": {CHECK_ON_CONTROLLER}", "").replace(
        f"; {CHECK_ON_CONTROLLER}", "").replace(f": {LOCK_RELEASE}", "")
    assert (note is None or note in short) and (count is None or "3 NOK in a row" in short)
