"""Long tightening curves in several messages (the header's number of parts and part
number), and MID 0901/0902: the assembler against parts written by hand, the driver against
the simulated controller over TCP on 127.0.0.1 (a long trace in parts, with and without
link-level acknowledgement; parts that do not add up; a 0901 or 0902 nobody asked for is
acknowledged and changes nothing)."""

from __future__ import annotations

import socket

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import ProtocolError
from drivers.wrench.openprotocol.message import Message, decode
from drivers.wrench.openprotocol.parts import BrokenParts, PartAssembler
from drivers.wrench.openprotocol.tracedata import parse_db_info, parse_plot
from drivers.wrench.sim.controller import SimController
from drivers.wrench.sim.curves import in_parts, mid0900, mid0901, mid0902

from ..conftest import connect, op, read_message, wait_until


def part(mid: int, data: bytes, parts: int, number: int, rev: int = 1) -> Message:
    """One part as the specification lays out its header (bytes 19-20: parts, part)."""
    return decode(f"{20 + len(data):04d}{mid:04d}{rev:03d}"     # no-ack flag, station,
                  f"{' ' * 7}{parts}{number}".encode() + data)    # spindle, sequence: blank


def ready(w) -> None:
    w.select_pset(1)
    w.enable_tool()


# -- the assembler ----------------------------------------------------------------------------
def test_parts_in_order_make_one_message_and_others_pass_between_them():
    a = PartAssembler()
    assert a.feed(part(900, b"abc", 3, 1)) == []
    between = decode(op(61, b"x")[:-1])
    assert a.feed(between) == [between]                 # another MID passes at once
    assert a.feed(part(900, b"def", 3, 2)) == []
    (whole,) = a.feed(part(900, b"\x00\x01", 3, 3))
    assert isinstance(whole, Message)
    assert (whole.mid, whole.data, whole.parts, whole.part) == (900, b"abcdef\x00\x01",
                                                                None, None)
    assert a.pending == 0


@pytest.mark.parametrize(("feed", "why"), [
    ([(2, 2)], "without the parts before it"),
    ([(3, 1), (3, 3)], "part 3 of 3"),
    ([(3, 1), (2, 2)], "part 2 of 2"),
    ([(2, 1), (2, 1)], "new first part"),
    ([(2, 3)], "not a part number"),
])
def test_parts_that_do_not_add_up_are_given_up_and_the_stream_goes_on(feed, why):
    a = PartAssembler()
    out: list[Message | BrokenParts] = []
    for parts, number in feed:
        out += a.feed(part(900, b"data", parts, number))
    broken = [x for x in out if isinstance(x, BrokenParts)]
    assert len(broken) == 1 and why in broken[0].reason and broken[0].mid == 900
    a.reset()
    (ok,) = a.feed(part(900, b"1234", 1, 1))           # "1 part of 1" is a whole message
    assert isinstance(ok, Message) and ok.data == b"1234"


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.sampled_from([900, 901, 61]), st.integers(0, 9),
                          st.integers(0, 9), st.binary(max_size=8)), max_size=30))
def test_any_sequence_of_parts_gives_messages_or_given_up_ones_never_an_exception(seq):
    a = PartAssembler()
    data_in = data_out = 0
    for mid, parts, number, data in seq:
        data_in += len(data)
        for item in a.feed(part(mid, data, parts, number)):
            assert isinstance(item, Message | BrokenParts)
            if isinstance(item, Message):
                data_out += len(item.data)
    assert data_out <= data_in and a.pending <= 3


def test_the_simulators_parts_cut_a_long_trace_at_most_nine_times():
    raw = b"00300900001         " + b"x" * 10
    assert in_parts(raw, 100) == [raw]
    long = raw[:20] + bytes(range(256)) * 4                     # 1024 bytes of data
    pieces = in_parts(long, 300)
    assert [p[18:20] for p in pieces] == [b"41", b"42", b"43", b"44"]
    assert b"".join(p[20:] for p in pieces) == long[20:]
    assert all(int(p[:4]) == len(p) for p in pieces)
    with pytest.raises(ValueError, match="at most 9"):
        in_parts(long, 100)


# -- the driver against the simulated controller ----------------------------------------------
@pytest.mark.parametrize("link_ack", [False, True])
def test_a_long_trace_in_parts_is_put_together_and_acknowledged_once(tmp_path, link_ack):
    with SimController(seed=3, nok_rate=0.0, curve_samples=1500, part_size=1000,
                       link_ack=link_ack) as sim, \
            connect(sim, "tcp", tmp_path, curves=True) as w:
        assert w.link_level is link_ack and w.curves_on
        ready(w)
        truth = sim.pull_trigger()
        r = w.wait_result(1.0)
        curves = [w.wait_curve(2.0) for _ in range(2)]
        assert wait_until(lambda: sim.curve_acks == 2)       # one per curve, not per part
        assert sim.parts_sent == 8 and sim.curves_sent == 2
        # a result after the long curves is not held back by them
        sim.pull_trigger()
        assert (nxt := w.wait_result(1.0)) is not None and nxt.tightening_id == 2
    assert truth is not None and r is not None and r.tightening_id == truth.tightening_id
    by = {c.name: c for c in curves if c is not None}
    assert sorted(by) == ["angle", "torque"]
    assert len(by["angle"].values) == len(by["torque"].values) == 1500
    assert by["torque"].values[-1] == pytest.approx(r.torque_nm, abs=0.011)
    assert by["angle"].values[-1] == pytest.approx(r.angle_deg, abs=0.6)
    assert sim.errors == [] and sim.link_drops == 0


def test_a_trace_longer_than_one_message_comes_in_two_parts(tmp_path):
    """6000 samples (12 000 bytes of them): past a message's 9999 bytes at the default
    part size, the most one part holds."""
    with SimController(seed=4, nok_rate=0.0, curve_samples=6000) as sim, \
            connect(sim, "tcp", tmp_path, curves=True) as w:
        ready(w)
        sim.pull_trigger()
        assert w.wait_result(1.0) is not None
        got = [w.wait_curve(2.0) for _ in range(2)]
        assert [len(c.values) for c in got if c is not None] == [6000, 6000]
        assert sim.parts_sent == 4


def test_parts_that_do_not_add_up_cost_that_curve_only(sim, tmp_path):
    with connect(sim, "tcp", tmp_path, curves=True) as w:
        ready(w)
        record = sim.pull_trigger()
        assert record is not None and record.record is not None
        assert w.wait_result(1.0) is not None
        assert [w.wait_curve(1.0) is not None for _ in range(2)] == [True, True]
        pieces = in_parts(mid0900(record.record, 2, 600), 400)
        assert len(pieces) == 4

        def send_some() -> None:
            for s in sim.sessions():
                for p in (pieces[0], pieces[2]):             # part 2 lost on the way
                    sim.post(s, p)
        sim.call(send_some)
        assert wait_until(lambda: sim.curve_acks == 3)       # given up, acknowledged
        assert w.wait_curve(0.2) is None and w.status().connected
        sim.pull_trigger()
        assert (r := w.wait_result(1.0)) is not None and r.tightening_id == 2
        assert w.wait_curve(1.0) is not None


def test_plot_parameters_and_db_info_nobody_asked_for_are_acknowledged_and_ignored(
        sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        first = sim.pull_trigger()
        assert first is not None and first.record is not None
        assert w.wait_result(1.0) is not None

        def push() -> None:
            assert first.record is not None
            for s in sim.sessions():
                sim.post(s, mid0901(first.record))
                sim.post(s, mid0902(1000, [first.record]))
        sim.call(push)
        assert wait_until(lambda: sim.data_acks.get(901) == 1 and sim.data_acks.get(902) == 1)
        info = w.result_db_info
        assert info is not None and (info.capacity, info.oldest_id, info.newest_id) == (
            1000, 1, 1)
        sim.pull_trigger()
        assert (r := w.wait_result(1.0)) is not None and r.tightening_id == 2
        assert w.status().connected and w.wait_curve(0.05) is None
    assert sim.errors == []


def test_plot_parameters_read_in_revisions_1_to_3():
    fields = b"90001" + b"004" + b"02" + b"000" + b"0000" + b"2250"
    head = b"0000004711" + b"2026-11-27:08:15:30" + b"001"
    one = parse_plot(1, head + fields)
    two = parse_plot(2, head + b"0008" + fields)
    three = parse_plot(3, head + b"0008" + b"0001" + b"2" + b"0000" + b"02" + fields)
    for p in (one, two, three):
        assert p.tightening_id == 4711 and p.fields == {"90001": "2250"}
    assert (one.request_mid, two.request_mid, three.trace_type) == (None, 8, 2)
    with pytest.raises(ProtocolError, match=r"4 bytes after its 1 PID$"):
        parse_plot(1, head + fields + b"junk")
    db = parse_db_info(1, b"0000001000" + b"0000000005" + b"2026-11-27:08:00:00"
                       + b"0000000042" + b"2026-11-27:09:00:00" + b"000")
    assert (db.capacity, db.oldest_id, db.newest_id) == (1000, 5, 42)
    assert db.oldest_at is not None and db.oldest_at.hour == 8


def test_the_simulator_serves_0901_by_subscription_and_0902_on_request(sim):
    """As an integrator's client would ask, written by hand: MID 0008 for 0901, then a
    result brings its 0901; MID 0006 for 0902 brings the store's extent."""
    port = sim.listen_tcp()
    with socket.create_connection(("127.0.0.1", port), timeout=5) as c:
        def ask(msg: bytes) -> bytes:
            c.sendall(msg)
            return read_message(c)
        assert ask(op(1))[4:8] == b"0002"
        assert ask(op(8, b"090100100"))[4:8] == b"0005"
        assert ask(op(18, b"001"))[4:8] == b"0005"
        assert ask(op(43))[4:8] == b"0005"
        sim.pull_trigger()
        plot = read_message(c)
        assert plot[4:8] == b"0901"
        p = parse_plot(1, plot[20:-1])
        assert p.tightening_id == 1 and len(p.fields) == 4
        c.sendall(op(5, b"0901"))
        info = ask(op(6, b"090200100"))
        assert info[4:8] == b"0902"
        assert parse_db_info(1, info[20:-1]).newest_id == 1
        c.sendall(op(5, b"0902"))
        assert ask(op(9, b"090100100"))[4:8] == b"0005"
    assert wait_until(lambda: sim.data_acks == {901: 1, 902: 1})
