"""Controller events and unreadable results in the database: each stored once, each a kind of
its own in the results feed, both counted among the tightening ids the station accounted for,
and a bolt held by an unreadable result held until a rundown or a release after it."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from sqlalchemy import update
from sqlalchemy.orm import Session

from db.ledger import CONTROLLER_EVENT, UNREADABLE
from db.models import TighteningRecord, UnreadableRecord
from stationd.boltfile import import_bolts
from tests.db.conftest import record

RAW = "02310061007    " + "0100010200SimController" + "\x00garbage"


def _event(repo, tid: int, code: int = 3, bolt: str | None = "B1"):
    return repo.others.record_controller_event(
        result_type=code, what="batch increment", vin="VIN1", bolt=bolt, controller_vin=None,
        tightening_id=tid, pset=1, ok=True, torque_nm=0.0, angle_deg=0.0,
        result_at=datetime(2026, 11, 29, 8, 0, tzinfo=UTC))


def _unreadable(repo, tid: int | None, bolt: str | None = "B1", raw: str = RAW):
    return repo.others.record_unreadable(
        mid=61, revision=7, raw=raw, error="MID 0061 revision 7: parameter 01 missing",
        vin="VIN1", bolt=bolt, controller_vin=None, tightening_id=tid, pset=1,
        result_at=None)


def test_controller_events_and_unreadable_results_are_stored_once_and_fed(repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    assert _event(repo, 5)
    assert _event(repo, 5) is None                       # sent again: stored once
    assert _event(repo, 5, code=4)                       # another type, same id: its own
    assert _unreadable(repo, 6)
    assert _unreadable(repo, 6) is None                  # the same message again
    feed = repo.ledger.since(0)
    kinds = [e["kind"] for e in feed]
    assert kinds == [CONTROLLER_EVENT, CONTROLLER_EVENT, UNREADABLE]
    event = feed[0]["record"]
    assert (event["result_type"], event["what"], event["bolt"], event["status"]) == \
        (3, "batch increment", "B1", "ok")
    unread = feed[2]["record"]
    assert unread["raw"] == RAW and unread["revision"] == 7 and unread["mid"] == 61
    assert unread["error"].startswith("MID 0061 revision 7") and unread["tightening_id"] == 6
    assert repo.last_tightening_id() == 6


def test_a_held_bolts_note_is_in_its_controller_events_feed_record(repo, bolts_file):
    """The note of a controller event that holds a bolt (which tightening may be its own) is
    in its results-feed record, so the forwarder takes it to the line database: the station's
    own report had it, the line only "result unknown after a lost push" (an MES integrator's
    trial)."""
    from db.kinds import LOST_UNKNOWN

    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    note = "tightening 28 may be its own (its push lost, fetched later; ...)"
    assert repo.others.record_controller_event(
        result_type=0, what=LOST_UNKNOWN, vin="VIN1", bolt="B1", controller_vin=None,
        tightening_id=None, pset=1, ok=None, torque_nm=None, angle_deg=None, result_at=None,
        note=note)
    assert _event(repo, 5)                               # a batch increment: no note
    held, batch = (e["record"] for e in repo.ledger.since(0))
    assert (held["what"], held["bolt"], held["note"]) == (LOST_UNKNOWN, "B1", note)
    assert batch["note"] is None
    assert held["status"] is None and batch["status"] in ("ok", "nok")   # no verdict


def test_an_unreadable_message_sent_again_under_another_header_is_the_stored_one(
        repo, bolts_file):
    """A copy the controller sends again carries another sequence number in its header: the
    same text after the header is the same message, said with where it was stored, and
    stored once; another text is another message."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    assert repo.others.stored_unreadable(mid=61, raw=RAW, header_len=20) is None
    assert repo.others.record_unreadable(
        mid=61, revision=7, raw=RAW, error="x", vin="VIN1", bolt="B1", controller_vin=None,
        tightening_id=None, pset=1, result_at=None, header_len=20)
    resent = RAW[:16] + "07" + RAW[18:]
    assert resent != RAW
    assert repo.others.stored_unreadable(mid=61, raw=resent, header_len=20) == ("VIN1", "B1")
    assert repo.others.stored_unreadable(mid=65, raw=resent, header_len=20) is None
    assert repo.others.stored_unreadable(mid=61, raw=resent[:-1] + "?", header_len=20) is None
    assert repo.others.record_unreadable(
        mid=61, revision=7, raw=resent, error="x", vin="VIN1", bolt="B3", controller_vin=None,
        tightening_id=None, pset=1, result_at=None, header_len=20) is None
    assert [u["bolt"] for u in repo.others.unreadable()] == ["B1"]


def test_an_id_holds_a_read_result_only_where_one_the_controller_sent_is_stored(
        repo, bolts_file):
    """What a reconnect compares the controller's result under the last id with: a rundown
    measured, one unattributed or a controller event; not an unreadable message or a gap's
    end (a reviewer: those took a controller's ids for restarted, and the results made
    before the cut was noticed were not fetched)."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    record(repo, "VIN1", "B2", tightening_id=3)
    _event(repo, 4)
    repo.others.record_unattributed(vin="VIN1", controller_vin=None, tightening_id=5, pset=1,
                                    ok=True, torque_nm=1.0, angle_deg=2.0, result_at=None,
                                    reason="outside")
    _unreadable(repo, 7)
    repo.others.record_gap(8, 9, "VIN1", "the controller no longer has it")
    assert [repo.read_result_stored(t) for t in (3, 4, 5, 6, 7, 8, 9)] == [
        True, True, True, False, False, False, False]
    assert repo.last_tightening_id() == 9


def test_a_readable_copy_of_an_unreadable_message_finds_it(repo, bolts_file):
    """After a reload the database is asked: a result that reads, whose first copy did not,
    is found by its id, and by its pset and time where they were picked out."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    at = datetime(2026, 11, 29, 8, 0, tzinfo=UTC)
    repo.others.record_unreadable(mid=61, revision=7, raw=RAW, error="x", vin="VIN1", bolt="B1",
                                  controller_vin=None, tightening_id=7, pset=1, result_at=at)
    assert repo.others.unreadable_of(tightening_id=7, pset=1, at=at) == ("VIN1", "B1")
    assert repo.others.unreadable_of(tightening_id=7, pset=None, at=None) == ("VIN1", "B1")
    assert repo.others.unreadable_of(tightening_id=7, pset=2, at=at) is None      # another pset
    assert repo.others.unreadable_of(tightening_id=7, pset=1,
                                     at=datetime(2026, 11, 29, 9, 0, tzinfo=UTC)) is None
    assert repo.others.unreadable_of(tightening_id=8, pset=1, at=at) is None


def test_a_result_made_after_a_timeless_unreadable_one_under_its_id_is_not_its_copy(repo):
    """A controller whose ids started again: tightening 7 again, made (on the station's
    clock) after the unreadable 7 without a time was stored, is another result."""
    repo.others.record_unreadable(mid=61, revision=7, raw=RAW, error="x", vin="VIN1", bolt="B1",
                                  controller_vin=None, tightening_id=7, pset=1, result_at=None)
    stored = datetime.now(UTC)
    at = datetime(2026, 11, 29, 8, 0, tzinfo=UTC)
    assert repo.others.unreadable_of(tightening_id=7, pset=1, at=at) == ("VIN1", "B1")
    assert repo.others.unreadable_of(tightening_id=7, pset=1, at=at,
                                     made=stored - timedelta(minutes=5)) == ("VIN1", "B1")
    assert repo.others.unreadable_of(tightening_id=7, pset=1, at=at,
                                     made=stored + timedelta(minutes=5)) is None


def test_an_unreadable_result_without_an_id_still_counts_nothing_it_cannot(repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    record(repo, "VIN1", "B2", tightening_id=3)
    assert _unreadable(repo, None)
    assert repo.last_tightening_id() == 3


def test_a_bolt_is_held_until_a_rundown_or_a_release_after_its_unreadable_result(
        repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    record(repo, "VIN1", "B1", tightening_id=1)
    _unreadable(repo, 2, "B1")
    _unreadable(repo, None, "B2", raw=RAW + "2")
    _unreadable(repo, 4, None, raw=RAW + "3")            # no bolt: holds nothing
    assert repo.held_bolts("VIN1") == {"B1": "tightening 2", "B2": "MID 0061 revision 7"}
    # the vehicle's report says so too (a quality trial: "B47 MISSING", its hold unsaid)
    assert repo.vehicle_report("VIN1").held == ()      # asked for where shown
    report = repo.vehicle_report("VIN1", held=True)
    assert report.held == (("B1", "tightening 2"), ("B2", "MID 0061 revision 7"))
    assert ", 2 held (B1, B2)" in report.counts()
    assert report.to_json()["held"] == {"B1": "tightening 2", "B2": "MID 0061 revision 7"}
    later = datetime.now(UTC) + timedelta(seconds=1)
    repo.ledger.record_command(at=later, user="sam", source="cli", kind="release",
                               vin="VIN1", bolt="B1", comment="checked on the controller")
    record(repo, "VIN1", "B2", tightening_id=5)
    assert repo.held_bolts("VIN1") == {}
    assert repo.vehicle_report("VIN1", held=True).held == () and "held" not in \
        repo.vehicle_report("VIN1", held=True).counts()
    # a skip ends a hold as a release does
    _unreadable(repo, 6, "B3", raw=RAW + "6")
    assert repo.held_bolts("VIN1") == {"B3": "tightening 6"}
    repo.ledger.record_command(at=datetime.now(UTC) + timedelta(seconds=2), user="sam",
                               source="cli", kind="skip", vin="VIN1", bolt="B3", comment="")
    assert repo.held_bolts("VIN1") == {}
    # only since the vehicle's last opening
    assert repo.held_bolts("VIN1", since=datetime.now(UTC) + timedelta(hours=1)) == {}
    # the journal's close line counts a bolt still held (a review: it did not)
    _unreadable(repo, 7, "B2", raw=RAW + "7")
    assert ", 1 held (B2)" in repo.close_vehicle("VIN1").counts()
    # ... and the hold outlives the vehicle's reopening for rework: its result is still not
    # known (a supervisor's trial: gone at the reopening the journal asked for)
    repo.reopen_vehicle("VIN1", at=datetime.now(UTC) + timedelta(seconds=3), user="sam",
                        source="cli", comment="rework")
    repo.start_vehicle("VIN1", "SEDAN")
    assert repo.vehicle_report("VIN1", held=True).held == (("B2", "tightening 7"),)
    assert set(repo.holds("VIN1")) == {"B2"}


def test_a_released_hold_is_read_back_until_its_bolt_is_run_down(repo, bolts_file):
    """A hold a person released leaves the bolt open but perhaps tightened already: read
    back (a restart keeps the operator's "check first") until a rundown of the bolt after
    the release; a skip, or a hold stored after the release, is no released hold."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    _unreadable(repo, 2, "B1")
    _unreadable(repo, 3, "B2", raw=RAW + "3")
    _unreadable(repo, 4, "B3", raw=RAW + "4")
    assert repo.released_holds("VIN1") == frozenset()       # held, not released

    def command(kind: str, bolt: str, s: int) -> None:
        repo.ledger.record_command(at=datetime.now(UTC) + timedelta(seconds=s), user="sam",
                                   source="cli", kind=kind, vin="VIN1", bolt=bolt, comment="")

    command("release", "B1", 1)
    command("release", "B2", 1)
    command("skip", "B3", 1)
    assert repo.released_holds("VIN1") == {"B1", "B2"}
    assert repo.held_bolts("VIN1") == {}
    # B1 run down after its release (the record's time later than the command's)
    record(repo, "VIN1", "B1", tightening_id=5)
    _later(repo, TighteningRecord, 5)
    assert repo.released_holds("VIN1") == {"B2"}
    # B2 held again after its release: held, not released
    _unreadable(repo, 6, "B2", raw=RAW + "6")
    _later(repo, UnreadableRecord, 6)
    assert repo.released_holds("VIN1") == frozenset()
    assert set(repo.held_bolts("VIN1")) == {"B2"}


def _later(repo, table, tid: int) -> None:
    """The record of tightening ``tid`` in ``table`` stored 10 s from now (after the
    commands a test placed a second or two ahead)."""
    with Session(repo.engine) as s, s.begin():
        s.execute(update(table).where(table.tightening_id == tid)
                  .values(recorded_at=datetime.now(UTC) + timedelta(seconds=10)))
