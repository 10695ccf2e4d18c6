"""The Open Protocol codec: header, framings, MID 0061 revision 1, and the simulator's own
server-side parsers; byte layouts written out by hand from PROTOCOLS.md, and hypothesis for
"arbitrary bytes never crash or hang a parser"."""

from __future__ import annotations

import re
from datetime import datetime

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.errors import ProtocolError
from drivers.wrench.base import Status
from drivers.wrench.openprotocol.message import (
    Message,
    SerialFramer,
    TcpFramer,
    decode,
    frame_serial,
    frame_tcp,
    identity,
    parse_result,
    refusal,
)
from drivers.wrench.sim.server import parse_message, split_serial, split_tcp

FAST = settings(max_examples=300, deadline=200,
                suppress_health_check=[HealthCheck.too_slow])

# MID 0061 revision 1 written field by field from PROTOCOLS.md (tag, then value)
GOLDEN = "".join((
    "0231", "0061", "001", "         ",               # header: length 231, MID 61, rev 1
    "01", "0007", "02", "03", "03", "PF6000 Line 3".ljust(25),
    "04", "WVWZZZ1JZ3W386752".ljust(25), "05", "00", "06", "005", "07", "0004", "08", "0002",
    "09", "1", "10", "1", "11", "1",
    "12", "002250", "13", "002750", "14", "002500", "15", "002512",
    "16", "00060", "17", "00120", "18", "00090", "19", "00097",
    "20", "2025-03-14:08:15:42", "21", "2025-03-14:07:00:00", "22", "0", "23", "0000001234",
)).encode()


def at(first: int, last: int) -> bytes:
    """GOLDEN's bytes first..last, 1-based inclusive, as PROTOCOLS.md numbers them."""
    return GOLDEN[first - 1:last]


def test_the_header_is_exactly_the_documented_example():
    assert frame_tcp(Message(1, revision=3)) == b"00200001003         \x00"
    msg = decode(b"00200001003         ")
    assert (msg.mid, msg.revision, msg.data, msg.no_ack) == (1, 3, b"", False)
    assert msg.station is msg.spindle is msg.sequence is msg.parts is msg.part is None


@pytest.mark.parametrize("rev", [b"   ", b"000", b"001"])
def test_spaces_000_and_001_are_revision_1(rev):
    assert decode(b"00200018" + rev + b"         ").revision == 1


def test_header_fields_round_trip():
    msg = Message(18, revision=2, data=b"005", no_ack=True, station=1, spindle=2, sequence=3,
                  parts=1, part=1)
    assert msg.encode() == b"00230018002101020311005"
    assert decode(msg.encode()) == msg


def test_serial_framing_integrator_side():
    assert frame_serial(Message(18, data=b"005")) == (
        b"\x07\x09\x07\x09\x02" + b"00230018001         005" + b"\x00\x03")


def test_golden_result_sits_at_the_documented_byte_positions():
    assert len(GOLDEN) == 231
    assert at(23, 26) == b"0007" and at(33, 57).rstrip() == b"PF6000 Line 3"
    assert at(91, 93) == b"005" and at(108, 108) == b"1" and at(141, 146) == b"002512"
    assert at(170, 174) == b"00097" and at(177, 195) == b"2025-03-14:08:15:42"
    assert at(222, 231) == b"0000001234"


def test_parse_result_reads_every_field():
    r = parse_result(GOLDEN)
    assert r.ok and r.torque_status is Status.OK and r.angle_status is Status.OK
    assert (r.torque_nm, r.torque_min_nm, r.torque_max_nm, r.torque_target_nm) == (
        25.12, 22.5, 27.5, 25.0)
    assert (r.angle_deg, r.angle_min_deg, r.angle_max_deg, r.angle_target_deg) == (
        97.0, 60.0, 120.0, 90.0)
    assert (r.cell_id, r.channel_id, r.controller_name, r.vin) == (
        7, 3, "PF6000 Line 3", "WVWZZZ1JZ3W386752")
    assert (r.job, r.pset, r.batch_size, r.batch_counter, r.batch_status) == (0, 5, 4, 2, 0)
    assert r.timestamp == datetime(2025, 3, 14, 8, 15, 42)
    assert r.pset_changed == datetime(2025, 3, 14, 7, 0, 0)
    assert r.tightening_id == 1234 and r.raw == GOLDEN.decode()


@pytest.mark.parametrize(("pos", "byte", "words"), [
    (108, b"0", None),                               # NOK is a value, not an error
    (111, b"7", "torque_status 7 is out of range"),
    (141, b"x", "torque"),
    (139, b"99", "expected tag 15 (torque) at byte 139"),
    (177, b"X", "timestamp"),
])
def test_parse_result_names_the_bad_field(pos, byte, words):
    bad = GOLDEN[:pos - 1] + byte + GOLDEN[pos - 1 + len(byte):]
    if words is None:
        assert parse_result(bad).ok is False
        return
    with pytest.raises(ProtocolError, match=re.escape(words)):
        parse_result(bad)


def test_parse_result_refuses_other_lengths_and_revisions():
    with pytest.raises(ProtocolError, match="231 bytes"):
        parse_result(b"0232" + GOLDEN[4:] + b" ")
    with pytest.raises(ProtocolError, match="revision 2"):
        parse_result(GOLDEN[:8] + b"002" + GOLDEN[11:])


def test_replies():
    assert refusal(decode(b"00260004001         001802")) == (18, 2)
    ident = decode(b"00570002001         010001020103" + b"PF6000".ljust(25))
    assert identity(ident) == "PF6000 (cell 0001, channel 01)"


def test_tcp_framer_splits_a_stream_at_any_boundary():
    stream = frame_tcp(Message(5, data=b"0018")) + GOLDEN + b"\x00" + frame_tcp(Message(9999))
    for cut in range(len(stream) + 1):
        f = TcpFramer()
        items = f.feed(stream[:cut]) + f.feed(stream[cut:])
        assert [m.mid for m in items if isinstance(m, Message)] == [5, 61, 9999]
        assert f.pending == 0


@pytest.mark.parametrize(("data", "words"), [
    (b"HELLO there", "garbage where a message should start"),
    (b"0010", "shorter than the header"),
    (b"00200005001         X", "not followed by NUL"),
    (b"002000x5001         \x00", "MID field"),
])
def test_tcp_framer_reports_garbage_then_ignores_the_stream(data, words):
    f = TcpFramer()
    items = f.feed(frame_tcp(Message(5, data=b"0018")) + data)
    assert isinstance(items[0], Message)
    assert isinstance(items[-1], ProtocolError) and words in str(items[-1])
    assert f.feed(frame_tcp(Message(5))) == []          # no resynchronising on TCP


def test_serial_framer_resynchronises():
    good = b"\x02" + frame_tcp(Message(5, data=b"0018")) + b"\x03"
    no_nul = b"\x02" + Message(9999).encode() + b"\x03"
    f = SerialFramer()
    items = f.feed(b"noise" + good + b"\x02half a fr" + good + b"\x02GARBAGE\x03" + no_nul)
    kinds = [type(i).__name__ for i in items]
    assert kinds == ["Message", "ProtocolError", "Message", "ProtocolError", "Message"]
    assert "cut short by a new STX" in str(items[1]) and f.noise == 5


def test_serial_framer_drops_an_endless_frame():
    f = SerialFramer()
    items = f.feed(b"\x02" + b"0" * 10_050)
    assert len(items) == 1 and "without ETX" in str(items[0]) and f.pending < 100


# -- properties -----------------------------------------------------------------------------
chunks = st.lists(st.binary(max_size=300), max_size=8)
messages = st.builds(
    Message, mid=st.integers(0, 9999), revision=st.integers(1, 999),
    data=st.binary(max_size=60).map(lambda b: bytes(0x20 + x % 95 for x in b)),
    no_ack=st.booleans(), station=st.none() | st.integers(0, 99),
    spindle=st.none() | st.integers(0, 99), sequence=st.none() | st.integers(0, 99),
    parts=st.none() | st.integers(0, 9), part=st.none() | st.integers(0, 9))


@FAST
@given(st.binary(max_size=300))
def test_decode_never_crashes(data):
    try:
        decode(data)
    except ProtocolError:
        pass


@FAST
@given(chunks)
def test_tcp_framer_never_crashes_and_stops_at_the_first_error(parts):
    f = TcpFramer()
    items = [i for p in parts for i in f.feed(p)]
    errors = [i for i in items if isinstance(i, ProtocolError)]
    assert len(errors) <= 1 and (not errors or items[-1] is errors[0])
    assert f.pending <= 10_000


@FAST
@given(chunks)
def test_serial_framer_is_chunking_invariant(parts):
    whole, split = SerialFramer(), SerialFramer()
    at_once = [str(i) for i in whole.feed(b"".join(parts))]
    piecewise = [str(i) for p in parts for i in split.feed(p)]
    assert at_once == piecewise and whole.pending == split.pending <= 10_001


@FAST
@given(st.lists(messages, max_size=4), st.lists(st.binary(max_size=20), max_size=4))
def test_framed_messages_survive_line_noise(msgs, noise):
    clean = [bytes(b for b in n if b not in (2, 3)) for n in noise]   # no STX or ETX in it
    stream = b"".join(c + frame_serial(m)[4:] for c, m in zip(clean + [b""] * 4, msgs,
                                                                strict=False))
    assert SerialFramer().feed(stream) == msgs
    assert [i for m in msgs for i in TcpFramer().feed(frame_tcp(m))] == msgs


@FAST
@given(st.binary(max_size=300), st.integers(0, 230), st.binary(min_size=1, max_size=4))
def test_parse_result_never_crashes(data, pos, splice):
    for raw in (data, GOLDEN[:pos] + splice + GOLDEN[pos + len(splice):]):
        try:
            parse_result(raw)
        except ProtocolError:
            pass


@FAST
@given(chunks)
def test_simulator_parsers_never_crash(parts):
    tcp, ser = bytearray(), bytearray()
    for p in parts:
        tcp += p
        ser += p
        for raw in split_tcp(tcp)[0] + split_serial(ser)[0]:
            try:
                parse_message(raw)
            except ValueError:
                pass
    assert len(ser) <= 10_010
