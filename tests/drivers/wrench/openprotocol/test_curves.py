"""Tightening curves: the MID 0900 reader against messages written by hand from the
specification, and the driver against the simulated controller over TCP on 127.0.0.1 (MID
0008 subscription, 0900 decoded and acknowledged, 0009 at close; a controller without
curves refuses and nothing else changes; a curve never holds a result back)."""

from __future__ import annotations

import struct
import time
from collections.abc import Sequence

import pytest

from drivers.errors import DeviceError, ProtocolError
from drivers.wrench import open_wrench
from drivers.wrench.openprotocol import client as client_mod
from drivers.wrench.openprotocol.curve import TraceType, parse_curve, subscribe_data
from drivers.wrench.sim.controller import SimController

from ..conftest import FAST, connect, op, read_message, reconnect_within, wait_until


def field(pid: str, value: str, dtype: str = "02", unit: str = "000") -> bytes:
    """A data field as the specification lays it out: PID 5, length 3, type 2, unit 3,
    step 4, value."""
    return f"{pid}{len(value):03d}{dtype}{unit}0000{value}".encode()


def trace_message(samples: list[int], *, trace_type: int = 2, unit: str = "001",
                  pids: Sequence[bytes] = (), params: Sequence[bytes] = (),
                  resolution: list[bytes] | None = None, tid: int = 4711,
                  count: int | None = None, nul: bytes = b"\x00") -> bytes:
    """MID 0900 revision 1 written out by hand (header + data, no framing NUL)."""
    if resolution is None:     # one range: 5 ms between samples
        resolution = [f"00001{len(samples):05d}00103202".encode() + b"5"]
    text = (f"{tid:010d}".encode() + b"2026-11-27:08:15:30"
            + f"{len(pids):03d}".encode() + b"".join(pids)
            + f"{trace_type:02d}".encode() + b"01" + unit.encode()
            + f"{len(params):03d}".encode() + b"".join(params)
            + f"{len(resolution):03d}".encode() + b"".join(resolution)
            + f"{len(samples) if count is None else count:05d}".encode())
    data = text + nul + b"".join(struct.pack(">h", s) for s in samples)
    return f"{20 + len(data):04d}0900001         ".encode() + data


def ready(w) -> None:
    w.select_pset(1)
    w.enable_tool()


# -- the reader -----------------------------------------------------------------------------
def test_a_torque_trace_is_scaled_by_its_coefficient_signed_and_big_endian():
    raw = trace_message([0, 1250, -300, 32767],
                        params=[field("02213", "100", "03")])
    c = parse_curve(raw)
    assert (c.tightening_id, c.trace_type, c.name, c.unit, c.unit_code) == (
        4711, TraceType.TORQUE, "torque", "Nm", 1)
    assert c.values == pytest.approx((0.0, 12.5, -3.0, 327.67))
    assert c.time_step_s == pytest.approx(0.005)
    assert c.times_s == pytest.approx((0.0, 0.005, 0.010, 0.015))
    assert c.timestamp is not None and c.timestamp.isoformat() == "2026-11-27T08:15:30"


def test_a_multiplier_scales_and_units_convert():
    angle = parse_curve(trace_message([10, 20], trace_type=1, unit="050",
                                      pids=[field("02214", "0.5", "03")]))
    assert (angle.name, angle.unit, angle.values) == ("angle", "deg", (5.0, 10.0))
    ftlbf = parse_curve(trace_message([100], unit="002",
                                      params=[field("02213", "10", "03")]))
    assert ftlbf.unit == "Nm" and ftlbf.values == pytest.approx((13.558179483314004,))
    odd = parse_curve(trace_message([7], unit="999"))
    assert (odd.unit, odd.values) == ("unit 999", (7.0,))       # no scaling PID: as sent


def test_resolution_fields_with_different_steps_give_each_sample_its_time():
    res = [b"00001" + b"00002" + b"001" + b"01" + b"202" + b"1",       # 1 ms for 2 samples
           b"00003" + b"00004" + b"001" + b"01" + b"202" + b"4"]       # then 4 ms
    c = parse_curve(trace_message([1, 2, 3, 4], resolution=res))
    assert c.time_step_s is None
    assert c.times_s == pytest.approx((0.0, 0.001, 0.002, 0.006))


@pytest.mark.parametrize(("kw", "match"), [
    ({"count": 9}, "says 9 samples"),
    ({"nul": b"X"}, "no NUL"),
    ({"params": [field("02213", "0", "03")]}, "coefficient .* is 0"),
    ({"params": [field("02213", "abc", "03")]}, "not a number"),
])
def test_a_trace_that_does_not_read_is_a_protocol_error(kw, match):
    with pytest.raises(ProtocolError, match=match):
        parse_curve(trace_message([1, 2, 3], **kw))


def test_a_cut_trace_is_a_protocol_error():
    raw = trace_message([1, 2, 3])
    with pytest.raises(ProtocolError, match="ends inside"):
        parse_curve(raw[:40])


def test_the_subscription_asks_for_angle_and_torque():
    data = subscribe_data()
    assert data[:4] == b"0900" and data[4:7] == b"001"
    extra = data[9:]
    assert int(data[7:9]) == len(extra) == 10 + 19 + 3 + 6
    assert extra[29:] == b"002001002"


# -- the driver against the simulated controller ----------------------------------------------
def test_curves_are_subscribed_decoded_and_acknowledged(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        assert not w.curves_on and w.curves_reason == "not asked for"
        assert w.subscribe_curves() and w.curves_on and w.curves_reason is None
        ready(w)
        truth = [sim.pull_trigger() for _ in range(3)]
        results = [w.wait_result(1.0) for _ in truth]
        curves = [w.wait_curve(1.0) for _ in range(6)]
        assert w.wait_curve(0.05) is None
        assert wait_until(lambda: sim.curve_acks == 6)
    for t, r in zip(truth, results, strict=True):
        assert t is not None and r is not None and r.tightening_id == t.tightening_id
        mine = [c for c in curves if c is not None and c.tightening_id == t.tightening_id]
        assert sorted(c.name for c in mine) == ["angle", "torque"]
        angle = next(c for c in mine if c.name == "angle")
        torque = next(c for c in mine if c.name == "torque")
        assert (angle.unit, torque.unit) == ("deg", "Nm")
        assert len(angle.values) == len(torque.values) == 240
        assert angle.time_step_s == torque.time_step_s == pytest.approx(0.002)
        # the rundown ends on the result's final values
        assert angle.values[-1] == pytest.approx(r.angle_deg, abs=0.6)
        assert torque.values[-1] == pytest.approx(r.torque_nm, abs=0.011)
        assert all(b >= a for a, b in zip(angle.values, angle.values[1:], strict=False))
        assert torque.timestamp == r.timestamp
    assert [m.data[:4] for m in sim.received(8)] == [b"0900"]
    assert [m.data[:4] for m in sim.received(9)] == [b"0900"]      # stopped at close
    assert sim.errors == []


def test_the_url_option_subscribes_at_every_session(sim):
    port = sim.listen_tcp()
    with open_wrench(f"openprotocol://127.0.0.1:{port}?curves=1", **FAST) as w:
        assert w.curves_on
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected)
        assert reconnect_within(w)
        assert w.curves_on and len(sim.received(8)) == 2
        ready(w)
        sim.pull_trigger()
        assert w.wait_result(1.0) is not None
        assert w.wait_curve(1.0) is not None and w.wait_curve(1.0) is not None


@pytest.mark.parametrize("code", [78, 99])
def test_a_controller_without_curves_refuses_and_nothing_breaks(code, tmp_path):
    with SimController(seed=1, nok_rate=0.0, curves=False, curves_refusal_code=code) as sim:
        with connect(sim, "tcp", tmp_path, curves=True) as w:
            check_no_curves(sim, w, code)
        assert sim.received(9) == []              # nothing to stop at close


def check_no_curves(sim: SimController, w, code: int) -> None:
    assert not w.curves_on
    assert f"error {code:02d}" in (w.curves_reason or "")
    assert w.status().connected
    assert not w.subscribe_curves()           # asked again: refused again, no error
    ready(w)
    sim.pull_trigger()
    r = w.wait_result(1.0)
    assert r is not None and r.tightening_id == 1
    assert w.wait_curve(0.1) is None and sim.curves_sent == 0
    sim.drop_connections()
    assert wait_until(lambda: not w.status().connected)
    assert reconnect_within(w)
    assert len(sim.received(8)) == 2          # not asked again after the refusals


def test_a_controller_that_never_answers_the_subscription_still_works(peer):
    """A controller that hangs on MID 0008: the session starts without curves, and they
    are not asked for again (PROTOCOLS.md: keep it optional)."""
    def script(c):
        read_message(c)
        c.sendall(op(2, b"010001020103" + b"Scripted".ljust(25)))
        assert read_message(c)[4:8] == b"0060"
        c.sendall(op(5, b"0060"))
        assert read_message(c)[4:8] == b"0008"    # no answer
        assert read_message(c)[4:8] == b"0080"    # nor to the clock: the session goes on
        assert read_message(c)[4:8] == b"0018"
        c.sendall(op(5, b"0018"))
        c.recv(100)

    p = peer(script)
    with open_wrench(f"openprotocol://127.0.0.1:{p.port}?curves=1", **FAST) as w:
        assert not w.curves_on and "no answer" in (w.curves_reason or "")
        w.select_pset(1)
    assert p.error is None


def test_curves_with_link_level_acknowledgement(tmp_path):
    with SimController(seed=2, nok_rate=0.0, link_ack=True) as sim, \
            connect(sim, "tcp", tmp_path, curves=True) as w:
        assert w.link_level and w.curves_on
        ready(w)
        for _ in range(3):
            sim.pull_trigger()
        got = [w.wait_result(1.0) for _ in range(3)]
        assert [r.tightening_id for r in got if r is not None] == [1, 2, 3]
        names = [c.name for c in (w.wait_curve(1.0) for _ in range(6)) if c is not None]
        assert sorted(names) == ["angle"] * 3 + ["torque"] * 3
        assert wait_until(lambda: sim.curve_acks == 6 and sim.acks == 3)
        assert sim.errors == [] and sim.link_drops == 0


def test_curves_nobody_reads_never_hold_results_back(sim, tmp_path, monkeypatch):
    """Curves are queued apart and bounded: results keep coming, in order, promptly, with
    no one reading the curves."""
    monkeypatch.setattr(client_mod, "CURVE_QUEUE", 4)
    with connect(sim, "tcp", tmp_path, curves=True) as w:
        ready(w)
        waits = []
        for i in range(1, 11):
            sim.pull_trigger()
            t0 = time.monotonic()
            r = w.wait_result(1.0)
            waits.append(time.monotonic() - t0)
            assert r is not None and r.tightening_id == i
        assert max(waits) < 0.5
        assert wait_until(lambda: sim.curve_acks == 20)      # every one acknowledged
        kept = [w.wait_curve(0.2) for _ in range(5)]
        assert [c.tightening_id for c in kept if c is not None] == [9, 9, 10, 10]


def test_unsubscribe_stops_the_curves(sim, tmp_path):
    with connect(sim, "tcp", tmp_path, curves=True) as w:
        w.unsubscribe_curves()
        assert not w.curves_on and w.curves_reason == "unsubscribed"
        ready(w)
        sim.pull_trigger()
        assert w.wait_result(1.0) is not None
        assert w.wait_curve(0.1) is None
    assert len(sim.received(9)) == 1


def test_a_register_driven_controller_sends_no_curves():
    w = open_wrench("sim+modbus://wrench", connect=False)
    try:
        assert not w.can_curves and not w.curves_on and not w.subscribe_curves()
        with pytest.raises(DeviceError, match="sends no curves"):
            w.wait_curve(0.1)
    finally:
        w.close()
