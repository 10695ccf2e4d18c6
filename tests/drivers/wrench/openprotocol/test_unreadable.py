"""Result messages that do not match their label, or do not read at all, between the driver
and the simulated controller over TCP on 127.0.0.1: read at their own header's revision, at
a lower one they are laid out as (said once, the subscription renewed there), or handed out
whole as an UnreadableResult, acknowledged only when the station says so."""

from __future__ import annotations

import logging
from datetime import datetime
from typing import Any

import pytest

from drivers.errors import ProtocolError
from drivers.wrench.base import TighteningResult, UnreadableResult
from drivers.wrench.openprotocol.message import decode
from drivers.wrench.openprotocol.reading import TypeLostError, pick, read_result, receive
from drivers.wrench.openprotocol.result import parse_tightening
from drivers.wrench.sim.controller import SimController
from drivers.wrench.sim.results import mislabelled_data, result_data
from drivers.wrench.sim.server import message

from ..conftest import connect, wait_until


def ready(w) -> None:
    w.send_vin("WVWZZZ1JZXW000001")
    w.select_pset(2)
    w.enable_tool()


def record(sim: SimController, result_type: int = 1):
    t = sim.pull_trigger(result_type)
    assert t is not None and t.record is not None
    return t.record


# -- the reading rules, on bodies the simulator writes ---------------------------------------
@pytest.mark.parametrize("mid", [61, 65])
def test_a_revision_1_body_with_fields_appended_is_held_without_its_type(sim, mid, tmp_path):
    """Labelled 7, laid out as revision 1 (which carries no result type): what it reads as is
    kept, and it is unreadable: read without its type, a loosening would close its bolt."""
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        r = record(sim, 2)                        # a loosening
    text = message(mid, mislabelled_data(mid, 1, r), 7).decode()
    with pytest.raises(ProtocolError):            # not at the revision it is labelled
        parse_tightening(mid, 7, text)
    with pytest.raises(TypeLostError, match="laid out as revision 1, which carries no result type"
                       ) as lost:
        read_result(mid, 7, text)
    got = lost.value.result
    assert (got.revision, got.header_revision, got.tightening_id, got.pset, got.vin) == (
        1, 7, r.tightening_id, 2, "WVWZZZ1JZXW000001")
    assert got.raw == text and got.result_type_code is None   # revision 1 has no type
    held = receive(decode(text.encode()))
    assert isinstance(held, UnreadableResult)
    assert (held.revision, held.laid_out_as, held.tightening_id, held.pset, held.vin,
            held.timestamp) == (7, 1, r.tightening_id, 2, "WVWZZZ1JZXW000001", got.timestamp)
    assert held.raw == text and held.fetched is (mid == 65)


@pytest.mark.parametrize("cut", ["tag", "blank"])
def test_a_result_type_lost_on_the_line_is_no_tightening(sim, cut, tmp_path):
    """One byte of parameter 49's tag lost or garbled (the body then reads as revision 2,
    with fields appended), or the type sent as spaces: unreadable, never a tightening."""
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        r = record(sim, 2)                        # a loosening
    data = result_data(61, 7, r).decode()
    bad = data.replace("4902", "4?02" if cut == "tag" else "49  ", 1)
    assert bad != data
    held = receive(decode(message(61, bad.encode(), 7)))
    assert isinstance(held, UnreadableResult)
    assert (held.tightening_id, held.pset) == (r.tightening_id, 2)
    assert held.laid_out_as == (2 if cut == "tag" else None)


def test_a_tagged_body_with_a_parameter_of_its_own_reads_at_its_revision(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        r = record(sim, 2)
    text = message(61, mislabelled_data(61, 3, r), 7).decode()
    got = read_result(61, 7, text)
    assert (got.revision, got.header_revision, got.result_type_code) == (3, 7, 2)


def test_a_value_that_does_not_read_is_not_read_at_a_lower_revision(sim, tmp_path):
    """The layout is right, a value is not: reading it as revision 2 would drop its result
    type (what decides whether it may close a bolt): it reads at no revision."""
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        r = record(sim, 3)
    data = result_data(61, 7, r).decode()
    bad = data.replace(f"49{3:02d}", "49X3", 1)
    with pytest.raises(ProtocolError, match="result_type 'X3' is not a number"):
        read_result(61, 7, message(61, bad.encode(), 7).decode())
    picked = pick(61, 7, message(61, bad.encode(), 7).decode())
    assert (picked["tightening_id"], picked["pset"], picked["vin"]) == (
        r.tightening_id, 2, "WVWZZZ1JZXW000001")
    assert picked["timestamp"] == r.timestamp


@pytest.mark.parametrize("byte", [b"\xff", b"\x00", b"\x07"])
def test_a_text_parameter_garbled_on_the_line_does_not_read(byte):
    """Line noise turned a byte of the VIN into a non-ASCII byte or a control character:
    the body reads at no revision (as the same byte in a number does; the module says a
    non-ASCII byte fails its field), kept as unreadable with what can be picked out of it;
    NULs and spaces after the text are padding.  Before: a TighteningResult whose VIN was
    'VIN\ufffd23' (or held the NUL), stored so with an unattributed result or a controller
    event (a NUL then refused by the line database)."""
    good = (b"02310061001         010001020103PF6000                   04VIN123"
            b"                   050006005070004080002091101111120045001300550014005000150050"
            b"121600010170020018000901900095202026-12-02:01:00:00212026-12-01:01:00:002222300"
            b"00000041")
    got = receive(decode(good[:62] + byte + good[63:]))
    assert isinstance(got, UnreadableResult), got
    assert (got.tightening_id, got.pset, got.vin) == (41, 5, "")
    assert "vin" in got.error
    padded = receive(decode(good[:65] + b"\x00" * 19 + good[84:]))
    assert isinstance(padded, TighteningResult) and padded.vin == "VIN123"


def test_another_text_parameter_in_its_own_character_set_still_reads():
    """A guard: a pset name with a byte of the controller's own character set (a Latin-1
    umlaut) or a control character still reads (what is not printable written ``\\xNN``):
    only the VIN, the station's own text echoed, must be printable ASCII."""
    r = parse_tightening(61, 3, message(61, _rev3_named(b"T\xfcr\x07"), 3).decode(
        "ascii", "replace"))
    assert r.pset_name == "T\ufffdr\\x07" and r.result_type_code == 1


def _rev3_named(name: bytes) -> bytes:
    """A MID 0061 revision 3 body (node-open-protocol's layout) whose pset name is ``name``."""
    body = (b"010001020103PF6000                   04VIN123                   05000006005"
            b"070108000000900041000021111221311411511611711811912000000000002100450022005500"
            b"230050002400501225000102600200270009028000952900000300000031000003200033000340"
            b"003500000036000000370000003800000039000000400000004100000000414200000430000044"
            b"T1            452026-12-02:01:00:00462026-12-01:01:00:0047")
    return body + name.ljust(25, b" ") + b"4814901"


def test_what_is_picked_out_of_a_body_cut_short():
    assert pick(61, 7, "0040006100700000001" + "01") == {
        "tightening_id": None, "pset": None, "vin": "", "timestamp": None}


# -- over the wire ---------------------------------------------------------------------------
def test_a_result_labelled_another_revision_than_subscribed_is_read_at_its_own(tmp_path):
    with SimController(seed=3, nok_rate=0.0, send_revision=3) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        assert w.revisions[60] == 7
        ready(w)
        sim.pull_trigger(4)
        got = w.wait_result(1.0)
        assert isinstance(got, TighteningResult)
        assert (got.revision, got.header_revision, got.result_type_code) == (3, None, 4)
        assert w.revisions[60] == 7                    # nothing to renew
        assert sim.received(63) == []


def test_a_result_honestly_labelled_below_a_typed_subscription_is_not_a_tightening(tmp_path):
    """Subscribed at 7, the controller sends revision 2, labelled so: no result type, so a
    loosening would read as a tightening and close its bolt (an independent controller's
    trial).  Held as unreadable (laid out as its own revision 2), and, an honest label being
    no byte lost on the line, the subscription is renewed at 2 at once, where untyped
    results are what the controller has."""
    with SimController(seed=3, nok_rate=0.0, send_revision=2) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        assert w.revisions[60] == 7
        ready(w)
        made = sim.pull_trigger(2)                                # a loosening
        held = w.wait_result(1.0)
        assert isinstance(held, UnreadableResult) and made is not None
        assert (held.tightening_id, held.revision, held.laid_out_as) == (
            made.tightening_id, 2, 2)
        assert "carries no result type" in held.error
        assert wait_until(lambda: w.revisions[60] == 2)
        later = sim.pull_trigger()
        third = w.wait_result(1.0)
        assert isinstance(third, TighteningResult) and later is not None
        assert (third.tightening_id, third.revision) == (later.tightening_id, 2)


@pytest.mark.parametrize("link_ack", [False, True])
def test_a_controller_that_claims_more_than_it_implements(link_ack, tmp_path, caplog):
    """The field case: subscribed at 7, revision 1 bodies with fields appended labelled 7.
    Revision 1 carries no result type: each is held as unreadable (the first here is a
    loosening), and after two in a row (the controller's habit, not a byte lost on the
    line) the subscription is renewed at revision 1 (0063, then 0060 revision 1), said
    once; the next results come labelled 1 and read cleanly.  With link-level
    acknowledgement too: the renewal waits its turn behind the result's 0062 (whose 9997
    the reading thread must read)."""
    caplog.set_level(logging.INFO, logger="drivers.wrench.openprotocol.client")
    with SimController(seed=3, nok_rate=0.0, mislabel=1, link_ack=link_ack) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        assert w.link_level is link_ack
        ready(w)
        first = sim.pull_trigger(2)
        held = w.wait_result(1.0)
        assert isinstance(held, UnreadableResult) and first is not None
        assert (held.tightening_id, held.revision, held.laid_out_as) == (
            first.tightening_id, 7, 1)
        assert w.revisions[60] == 7                     # once may be the line's
        second = sim.pull_trigger()
        again = w.wait_result(1.0)
        assert isinstance(again, UnreadableResult) and second is not None
        assert (again.tightening_id, again.laid_out_as) == (second.tightening_id, 1)
        # (a result made between the 0063 and the 0060 is not pushed: the station's
        # tightening-id gap check fetches it, MID 0064)
        assert wait_until(lambda: w.revisions[60] == 1)
        assert [r.revision for r in sim.received(60)] == [7, 1]
        assert len(sim.received(63)) == 1
        later = sim.pull_trigger()
        third = w.wait_result(1.0)
        assert isinstance(third, TighteningResult) and later is not None
        assert (third.tightening_id, third.revision, third.header_revision) == (
            later.tightening_id, 1, None)
        assert third.torque_nm == later.torque_nm and third.pset == 2
        assert wait_until(lambda: sim.acks == 3) and w.status().reconnects == 0
        # a new session asks for the highest revision again (the controller may be another
        # one: a revision below 3 carries no result type), and lowers again, not losing one
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected)
        w.reconnect()
        assert w.revisions[60] == 7
        made = [sim.pull_trigger(), sim.pull_trigger()]
        got = [w.wait_result(1.0), w.wait_result(1.0)]
        assert [(g.tightening_id, g.laid_out_as) for g in got
                if isinstance(g, UnreadableResult)] == [
            (m.tightening_id, 1) for m in made if m is not None]
        assert wait_until(lambda: w.revisions[60] == 1)
    said = [r for r in caplog.records if "subscribed at that revision from now on"
            in r.getMessage()]
    assert len(said) == 1 and "laid out as revision 1" in said[0].message
    assert len([r for r in caplog.records if "its bolt held" in r.getMessage()]) == 4
    assert sim.errors == []


@pytest.mark.parametrize("how", ["value", "layout"])
def test_a_result_that_reads_at_no_revision_is_kept_and_acknowledged_when_stored(
        sim, how, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.garble_next_result(how)
        bad = sim.pull_trigger()
        good = sim.pull_trigger()
        first = w.wait_result(1.0, acknowledge=False)
        assert isinstance(first, UnreadableResult) and bad is not None
        assert (first.mid, first.revision, first.fetched) == (61, 7, False)
        assert first.raw.startswith(f"{len(first.raw):04d}0061007")
        if how == "value":
            assert "torque 'TORQUE' is not a number" in first.error
            assert (first.tightening_id, first.pset, first.vin, first.timestamp) == (
                bad.tightening_id, 2, "WVWZZZ1JZXW000001", bad.timestamp)
        else:
            assert "cut short" in first.error or "missing" in first.error
        assert w.status().connected and sim.acks == 0      # not a fault, not acknowledged
        # 0062 names no result: the controller takes acknowledgements in order
        w.acknowledge_result(first)
        second = w.wait_result(1.0)
        assert isinstance(second, TighteningResult) and good is not None
        assert second.tightening_id == good.tightening_id
        assert wait_until(lambda: sim.acked_ids == [bad.tightening_id, good.tightening_id])
        assert w.revisions[60] == 7 and w.status().reconnects == 0


def test_fetching_a_result_that_does_not_read(sim, tmp_path):
    """MID 0065 that reads at no revision: an UnreadableResult (fetched), not an error;
    one laid out as a lower revision without a result type is held so too, and after two
    such answers later fetches ask for that revision; their answers, at a revision without a
    type while the pushed results carry one, are held as well (a loosening made during a
    link cut would read as a tightening)."""
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        t = sim.pull_trigger()
        assert t is not None and w.wait_result(1.0) is not None
        sim.garble_next_result("value")
        got = w.fetch_result(t.tightening_id)
        assert isinstance(got, UnreadableResult) and got.fetched and got.mid == 65
        assert (got.tightening_id, got.pset) == (t.tightening_id, 2)
        sim.mislabel = 1
        old = [w.fetch_result(t.tightening_id), w.fetch_result(t.tightening_id)]
        assert all(isinstance(o, UnreadableResult) and o.fetched and o.laid_out_as == 1
                   and o.tightening_id == t.tightening_id for o in old)
        assert w.revisions[64] == 1
        again = w.fetch_result(t.tightening_id)
        assert isinstance(again, UnreadableResult) and again.laid_out_as == 1
        assert (again.revision, again.tightening_id) == (1, t.tightening_id)
        assert "its pushed results, at revision 7, do" in again.error
        assert [r.revision for r in sim.received(64)] == [7, 7, 7, 1]


class TightensDuringTheRenewal(SimController):
    """The operator tightens in the moment between the driver's 0063 and its 0060: that
    result is never pushed (nobody is subscribed when it is made)."""

    def handle(self, s, msg) -> None:
        super().handle(s, msg)
        if msg.mid == 63:
            self.during = self._tighten(1)


def test_a_result_made_while_the_subscription_is_renewed_is_fetched(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="drivers.wrench.openprotocol.client")
    with TightensDuringTheRenewal(seed=3, nok_rate=0.0, mislabel=1) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        ready(w)
        made = [sim.pull_trigger(), sim.pull_trigger()]     # held twice: renewed at 1
        got = [w.wait_result(1.0), w.wait_result(1.0), w.wait_result(1.0)]
        assert wait_until(lambda: w.revisions[60] == 1)
        after = sim.pull_trigger()
        fourth = w.wait_result(1.0)
        assert w.wait_result(0.2) is None                        # nothing twice
    assert all(m is not None for m in made) and after is not None
    assert [g.tightening_id for g in got if g is not None] == [1, 2, 3]
    # the third, made while the subscription was renewed and fetched, does not read (laid
    # out without a type): handed out as pushed, not as fetched after a link cut (the
    # station holds the bolt enabled now with it; a reviewer: held against none)
    assert isinstance(got[2], UnreadableResult) and got[2].laid_out_as == 1
    assert [getattr(g, "fetched", None) for g in got] == [False, False, False]
    assert sim.during is not None and sim.during.tightening_id == 3
    assert fourth is not None and (fourth.tightening_id, fourth.fetched) == (4, False)
    assert sim.acked_ids == [1, 2, 4] and sim.errors == []      # no 0062 for a fetched one
    assert "tightening 3 made while the result subscription was renewed" in caplog.text


def test_a_controller_without_mid_0064_keeps_the_renewed_subscription_and_the_link(
        tmp_path, caplog):
    """A controller that mislabels its results and answers MID 0064 with error 99 (unknown
    MID), as an independent emulator does: the renewal at revision 1 stands, its catch-up
    is said impossible, and the link stays up (a link dropped there renewed the subscription
    at every session, two held bolts each time); the next result reads cleanly."""
    caplog.set_level(logging.WARNING, logger="drivers.wrench.openprotocol.client")
    with SimController(seed=3, nok_rate=0.0, mislabel=1) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        sim.refuse_mid(64, 99)
        ready(w)
        made = [sim.pull_trigger(), sim.pull_trigger()]     # held twice: renewed at 1
        got = [w.wait_result(1.0), w.wait_result(1.0)]
        assert all(isinstance(g, UnreadableResult) for g in got) and None not in made
        assert wait_until(lambda: w.revisions[60] == 1)
        assert wait_until(lambda: "cannot be fetched (MID 0064" in caplog.text)
        later = sim.pull_trigger()
        third = w.wait_result(1.0)
        assert isinstance(third, TighteningResult) and later is not None
        assert third.tightening_id == later.tightening_id
        assert w.status().connected and w.status().reconnects == 0
    assert "error 99" in caplog.text and "link lost" not in caplog.text


def test_a_revision_beyond_those_read_gives_the_ones_it_starts_with(sim, tmp_path):
    """MID 0061 revision 998 is revision 6 plus the stages (PROTOCOLS.md): it starts with a
    whole revision 6 body (here a revision 7 one), read so; not taken for a revision it
    is not."""
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        r = record(sim, 5)
    stages = "5401" + "0" * 30                      # a stage count and one stage, roughly
    text = message(61, result_data(61, 7, r) + stages.encode(), 998).decode()
    got = read_result(61, 998, text)
    assert (got.revision, got.header_revision, got.result_type_code) == (7, 998, 5)


def test_results_subscribed_below_revision_3_are_said_to_carry_no_type(tmp_path, caplog):
    """A controller that takes MID 0060 only at revisions 1-2: its results carry no result
    type, so the station cannot tell a batch increment from a tightening: said at every
    session, as a warning."""
    caplog.set_level(logging.INFO, logger="drivers.wrench.openprotocol.client")
    with SimController(seed=3, nok_rate=0.0, refused_revisions={60: range(3, 8)}) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        ready(w)
        assert w.revisions[60] == 2
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected)
        w.reconnect()
    said = [r for r in caplog.records if "carries no result type" in r.getMessage()]
    assert len(said) == 2 and all(r.levelno == logging.WARNING for r in said)


def _feed(queued: list[object]) -> Any:
    import threading
    from types import SimpleNamespace

    from drivers.wrench.openprotocol.resultfeed import ResultFeed

    channel = SimpleNamespace(cond=threading.Condition(), log=logging.getLogger("t"),
                              device="wrench", epoch=1, route=lambda mid, fn: None)
    return ResultFeed(channel, lambda item, token: queued.append(item))  # type: ignore[arg-type]


def _record(tid: int) -> Any:
    from drivers.wrench.sim.results import SimRecord

    return SimRecord(
        tightening_id=tid, cell=1, channel=1, name="Sim", vin="VIN11", pset=1,
        pset_name="P", batch_size=1, batch_counter=1, batch_status=1, ok=True,
        torque_status=1, angle_status=1, torque_min=100, torque_max=300, torque_target=200,
        torque=210, angle_min=10, angle_max=90, angle_target=45, angle=44, angle_exact=44.0,
        timestamp=datetime(2026, 11, 30, 9, 0, 0), pset_changed=datetime(2026, 11, 30, 8),
        result_type=2)


def test_a_new_session_judges_pushes_against_what_it_asks_not_the_last_one_s_revision():
    """The last session lowered its subscription to revision 2; a new one asks for 7 again,
    and the controller pushes a loosening again at revision 2 during the negotiation: not a
    tightening that may close its bolt (a reviewer: judged against the stale 2)."""
    queued: list[object] = []
    feed = _feed(queued)
    feed.subscribed = 2
    feed.reset()
    feed.received(decode(message(61, result_data(61, 2, _record(12)), 2)))
    [held] = queued
    assert isinstance(held, UnreadableResult) and held.laid_out_as == 2


def test_a_fetched_result_without_its_id_does_not_swallow_the_push_of_that_id():
    """The renewal's catch-up fetched tightening 11 and got a body that does not read, its
    id unknown (picked as another): when the real tightening 11 is then pushed, it is
    handed out, not acknowledged and dropped as "fetched already" (a reviewer: lost)."""
    queued: list[object] = []
    feed = _feed(queued)
    garbled = UnreadableResult(raw="x" * 60, mid=65, revision=2, error="torque 'AB'",
                               tightening_id=None, pset=1, fetched=True)
    assert feed.caught(11, garbled)
    record = _record(11)
    feed.received(decode(message(61, result_data(61, 3, record), 3)))
    assert [getattr(q, "tightening_id", None) for q in queued] == [None, 11]
