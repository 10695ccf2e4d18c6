"""Revisions and old results against the simulated controller over TCP on 127.0.0.1: the
driver asks for the highest revisions, steps down when refused, reads every revision of MID
0061 and 0065, and keeps the controller's identity typed."""

from __future__ import annotations

import pytest

from drivers.errors import ConnectionLostError, ProtocolError, RefusedError
from drivers.wrench import open_wrench
from drivers.wrench.base import ResultType, Status, TorqueUnit, UnreadableResult
from drivers.wrench.sim.controller import SimController, SimPset

from ..conftest import FAST, connect, op, read_message, reconnect_within, wait_until
from .test_revisions import OLD_APPENDED, OLD_REV2, build


def ready(w) -> None:
    w.select_pset(1)
    w.enable_tool()


def test_the_highest_revisions_are_asked_and_the_identity_is_typed(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        assert w.revisions == {1: 6, 60: 7}
        ident = w.controller_identity
        assert ident is not None and ident.revision == 6
        assert (ident.cell_id, ident.channel_id, ident.controller_name) == (
            1, 1, "SimController")
        assert (ident.supplier_code, ident.open_protocol_version,
                ident.controller_software_version, ident.controller_serial) == (
            "SIM", "2.8.0", "stationd-sim 1.0", "SIM0000001")
        assert (ident.system_type, ident.sequence_number_support) == (0, False)
        assert not w.link_level and "link-level ack no" in w.identity()
        ready(w)
        truth = sim.pull_trigger(result_type=2)
        r = w.wait_result(1.0)
    assert truth is not None and r is not None
    assert (r.revision, r.result_type, r.pset_name, r.torque_unit, r.strategy) == (
        7, ResultType.LOOSENING, "pset 1", TorqueUnit.NM, 2)
    assert (r.tightening_id, r.torque_nm, r.angle_deg) == (1, truth.torque_nm, truth.angle_deg)
    assert r.rundown_angle_status is Status.OK and r.angle_decimal_deg is not None
    assert abs(r.angle_decimal_deg - r.angle_deg) <= 0.5


@pytest.mark.parametrize("code", [97, 76])
def test_refused_revisions_are_stepped_down(code, tmp_path):
    with SimController(seed=1, nok_rate=0.0, revision_refusal_code=code,
                       refused_revisions={1: {6, 5}, 60: {7, 6, 5, 4}}) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        assert [r.revision for r in sim.received(1)] == [6, 5, 4]
        assert [r.revision for r in sim.received(60)] == [7, 6, 5, 4, 3]
        assert w.revisions == {1: 4, 60: 3}
        ident = w.controller_identity
        assert ident is not None and ident.revision == 4 and ident.system_type is None
        ready(w)
        sim.pull_trigger()
        r = w.wait_result(1.0)
        assert r is not None and r.revision == 3 and r.pset_name == "pset 1"
        assert r.identifiers == ()                              # a revision 4 parameter


@pytest.mark.parametrize("revision", range(1, 8))
def test_each_result_revision_over_the_wire(revision, tmp_path):
    higher = set(range(revision + 1, 8))
    with SimController({1: SimPset(25.0, 22.5, 27.5, 90.0, 60.0, 120.0, name="M8")},
                       seed=3, nok_rate=0.0, refused_revisions={60: higher}) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        ready(w)
        truth = [sim.pull_trigger() for _ in range(3)]
        got = [w.wait_result(1.0) for _ in truth]
    for t, r in zip(truth, got, strict=True):
        assert t is not None and r is not None and r.revision == revision
        assert (r.tightening_id, r.ok, r.torque_nm, r.angle_deg, r.timestamp) == (
            t.tightening_id, t.ok, t.torque_nm, t.angle_deg, t.timestamp)
        assert (r.torque_min_nm, r.torque_max_nm, r.angle_target_deg) == (22.5, 27.5, 90.0)
        assert r.pset_name == ("M8" if revision >= 3 else "")
        assert (r.strategy is None) == (revision == 1)


def test_a_refusal_that_is_not_about_the_revision_is_not_retried(tmp_path):
    with SimController(seed=1) as sim:
        sim.refuse_mid(60, 3)
        with pytest.raises(RefusedError, match=r"open: communication start: .*error 03") as e:
            connect(sim, "tcp", tmp_path)
        assert e.value.code == 3 and len(sim.received(60)) == 1


def test_a_revision_1_controller_still_works(tmp_path):
    old = {mid: set(range(2, 8)) for mid in (1, 60, 64)}
    with SimController(seed=1, nok_rate=0.0, refused_revisions=old) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        assert w.revisions == {1: 1, 60: 1}
        assert w.identity() == "SimController (cell 0001, channel 01)"
        ready(w)
        sim.pull_trigger()
        r = w.wait_result(1.0)
        assert r is not None and r.revision == 1 and r.result_type is None
        old_r = w.fetch_result(1)
        assert old_r is not None and old_r.revision == 1 and old_r.torque_nm == r.torque_nm
        assert old_r.torque_min_nm == 0.0                       # MID 0065 rev 1: no limits
        assert w.revisions[64] == 1


# -- old results: MID 0064 -> 0065 ----------------------------------------------------------------
def test_fetch_result_by_id_newest_and_not_found(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        assert w.fetch_result(0) is None                        # nothing tightened yet
        ready(w)
        pushed = []
        for _ in range(3):
            sim.pull_trigger()
            pushed.append(w.wait_result(1.0))
        second = w.fetch_result(2)
        newest = w.fetch_result(0)
        sim.forget_results(1)
        gone = w.fetch_result(1)
        assert w.fetch_result(99) is None
        assert w.revisions[64] == 7
    assert second is not None and newest is not None and gone is None
    assert second.fetched and not pushed[1].fetched
    assert (second.tightening_id, second.torque_nm, second.angle_deg, second.timestamp,
            second.pset, second.result_type) == (
        2, pushed[1].torque_nm, pushed[1].angle_deg, pushed[1].timestamp, pushed[1].pset,
        pushed[1].result_type)
    assert second.torque_max_nm == 0.0            # MID 0065 carries no limits
    assert newest.tightening_id == 3
    assert [r.data for r in sim.received(64)][:3] == [b"0000000000", b"0000000002",
                                                      b"0000000000"]


def test_fetch_result_steps_down_once_and_remembers(tmp_path):
    with SimController(seed=1, refused_revisions={64: {7, 6}}) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.pull_trigger()
        w.wait_result(1.0)
        first, again = w.fetch_result(1), w.fetch_result(1)
        assert first is not None and first.revision == 5 and again == first
        assert [r.revision for r in sim.received(64)] == [7, 6, 5, 5]


def test_an_untyped_old_result_of_a_controller_whose_pushes_are_typed_is_held(tmp_path):
    """A controller that pushes its results at revision 7 (each with its type) but answers
    MID 0064 only at revision 1 (7 to 2 refused): a loosening made while the link was down,
    fetched after the reconnect, comes without its type.  Not handed out as a result (the
    station reads a result without a type as a tightening, and so closed the link cut's bolt
    with a loosening) but as an :class:`UnreadableResult` laid out as revision 1, its id
    known: the bolt it may be is held for a person, as for a push that lost its type."""
    with SimController(seed=1, nok_rate=0.0,
                       refused_revisions={64: {7, 6, 5, 4, 3, 2}}) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.pull_trigger()
        seen = w.wait_result(1.0)
        assert seen is not None and seen.result_type is ResultType.TIGHTENING
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected)
        missed = sim.pull_trigger(2)                 # a loosening, nobody subscribed
        assert missed is not None and reconnect_within(w)
        got = w.fetch_result(missed.tightening_id)
        assert [r.revision for r in sim.received(64)][-1] == 1
    assert isinstance(got, UnreadableResult), got
    assert (got.tightening_id, got.fetched, got.laid_out_as) == (missed.tightening_id, True, 1)
    assert "result type" in got.error


def test_a_result_made_while_the_link_was_down_is_fetched_after_the_reconnect(sim, tmp_path):
    """The gap the tightening ids show is filled with MID 0064 (the station's part is to
    notice it; here the driver's part: the missed result is there to fetch)."""
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.pull_trigger()
        seen = w.wait_result(1.0)
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected)
        missed = sim.pull_trigger()                  # nobody subscribed: not pushed
        assert missed is not None
        assert reconnect_within(w)
        assert w.wait_result(0.2) is None
        newest = w.fetch_result(0)
        assert seen is not None and newest is not None
        assert newest.tightening_id == seen.tightening_id + 1 == missed.tightening_id
        assert (newest.torque_nm, newest.ok, newest.fetched) == (missed.torque_nm,
                                                                 missed.ok, True)


def test_fetch_result_checks_its_arguments_and_the_link(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        for bad in (-1, 10**10, 1.0, True):
            with pytest.raises(ValueError, match="tightening_id must be an integer"):
                w.fetch_result(bad)
        sim.refuse_mid(64, 99)
        with pytest.raises(RefusedError, match=r"fetch tightening 5: .*error 99") as e:
            w.fetch_result(5)
        assert e.value.code == 99 and w.status().connected
        sim.clear_refusals()
        # a controller that ignores MID 0064 refuses it by its silence: the link kept (a
        # trial: taken for a dead link, every reconnect's catch-up asked and reset it again)
        sim.ignore_mid(64)
        reconnects = w.status().reconnects
        with pytest.raises(RefusedError, match=r"fetch tightening 5: no answer to MID 0064 "
                                               r"within .* taken as refused"):
            w.fetch_result(5, timeout=0.3)
        assert w.status().connected and w.status().reconnects == reconnects
        # the same for the VIN (an independent simulator answers MID 0050 with MID 0052)
        sim.ignore_mid(50)
        with pytest.raises(RefusedError, match=r"send VIN V1: no answer to MID 0050 within "
                                               r".* taken as refused"):
            w.send_vin("V1", timeout=0.3)
        assert w.status().connected and w.status().reconnects == reconnects
        sim.clear_refusals()
        sim.power_off()
        assert wait_until(lambda: not w.status().connected)
        with pytest.raises(ConnectionLostError, match="fetch tightening 5: link down"):
            w.fetch_result(5)


def _answering_0064(answer: bytes):
    """A controller's script: a session (no clock: an unknown MID), then ``answer`` to the
    first MID 0064."""
    def script(c):
        read_message(c)
        c.sendall(op(2, b"010001020103" + b"Scripted".ljust(25)))
        read_message(c)
        c.sendall(op(5, b"0060"))
        assert read_message(c)[4:8] == b"0080"
        c.sendall(op(4, b"008099"))
        assert read_message(c)[4:8] == b"0064"
        c.sendall(answer + b"\x00")
        c.recv(100)
    return script


def test_an_answer_about_another_tightening_is_refused(peer):
    """A controller that answers MID 0064 with another tightening is wrong: never taken for
    the one asked."""
    p = peer(_answering_0064(build(65, 3, OLD_REV2 + OLD_APPENDED[0])))   # tightening 1235
    with open_wrench(f"openprotocol://127.0.0.1:{p.port}", **FAST) as w:
        with pytest.raises(ProtocolError, match="fetch tightening 7: the controller "
                                                "answered with tightening 1235"):
            w.fetch_result(7)


def test_an_unreadable_answer_whose_id_reads_as_another_is_kept_without_an_id(peer):
    """An answer to MID 0064 that does not read, with another id picked out of it: the id
    may be another field of a body laid out otherwise, and the message is the controller's
    record of a tightening all the same: kept whole, its id unknown, never raised away."""
    garbled = [(t, "00ABCD" if t == "19" else v) for t, v in OLD_REV2]   # the torque

    p = peer(_answering_0064(build(65, 2, garbled)))          # reads as tightening 1235
    with open_wrench(f"openprotocol://127.0.0.1:{p.port}", **FAST) as w:
        got = w.fetch_result(7)
    assert isinstance(got, UnreadableResult) and got.fetched
    assert got.tightening_id is None and got.pset == 5
    assert "asked for tightening 7, its body reads as 1235" in got.error
    assert got.raw.startswith("0226") and "00ABCD" in got.raw


def test_an_untyped_answer_about_another_tightening_is_refused(peer):
    """Asked at revision 7, answered at revision 2 (no result type: held as unreadable,
    ``untyped_below``) about tightening 1235: its id was read, so it is an answer about
    another tightening, refused as a readable one is, not kept as one without an id."""
    p = peer(_answering_0064(build(65, 2, OLD_REV2)))
    with open_wrench(f"openprotocol://127.0.0.1:{p.port}", **FAST) as w:
        with pytest.raises(ProtocolError, match="answered with tightening 1235"):
            w.fetch_result(7)
