"""The lift over real Modbus TCP on 127.0.0.1: states, mbpoll cross-check, faults, reconnect."""

from __future__ import annotations

import re
import socket
import threading
import time

import pytest

from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    ConnectTimeoutError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.lift import RegisterMap, open_lift
from drivers.lift.base import Text
from drivers.lift.modbus import ModbusLift
from drivers.lift.sim import SimulatedPlc

from .conftest import FAST, VIN, mbpoll


def lift_for(port: int, **kw) -> ModbusLift:
    lift = open_lift(f"modbus-tcp://127.0.0.1:{port}?unit={kw.pop('unit', 1)}", **{**FAST, **kw})
    assert isinstance(lift, ModbusLift)
    return lift


def wait_for(fn, seconds=2.0):
    """Poll ``fn`` until it returns a value (DeviceErrors count as not yet)."""
    deadline = time.monotonic() + seconds
    while True:
        try:
            return fn()
        except DeviceError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.01)


def test_reads_what_the_world_sets(plc):
    port = plc.start_tcp()
    with lift_for(port) as lift:
        assert lift.identity() == f"Modbus TCP 127.0.0.1:{port} unit 1"
        s = lift.read_state()
        assert (s.height_mm, s.at_working_height, s.moving, s.fault) == (0.0, False, False, False)
        assert (s.model_code, s.vin) == (0, None)
        assert abs(s.timestamp - time.time()) < 1.0
        plc.set_vehicle(4711, VIN)
        plc.raise_lift()
        s = lift.read_state(timeout=0.5)
        assert s.ready and s.height_mm == pytest.approx(1750.0)
        assert (s.model_code, s.vin) == (4711, VIN)
        plc.set_fault()
        assert lift.read_state().fault and not lift.read_state().ready
        plc.set_fault(False)
        plc.lower_lift()
        assert not lift.read_state().at_working_height


def test_motion_is_seen_while_it_happens():
    clock = [0.0]
    with SimulatedPlc(clock=lambda: clock[0]) as plc, lift_for(plc.start_tcp()) as lift:
        plc.raise_lift(duration=10.0)
        clock[0] = 4.0
        s = lift.read_state()
        assert s.moving and not s.at_working_height and s.height_mm == pytest.approx(700.0)
        plc.set_fault()  # a fault stops the lift where it is
        clock[0] = 20.0
        plc.raise_lift(duration=1.0)  # interlocked while faulted
        s = lift.read_state()
        assert s.fault and not s.moving and s.height_mm == pytest.approx(700.0)


def test_mbpoll_reads_the_same_registers(plc):
    port = plc.start_tcp()
    plc.set_vehicle(65000, VIN)
    plc.set_height(1234.5)
    code, regs, err = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-t", "4", "-r", "0",
                             "-c", "12", "127.0.0.1")
    assert code == 0, err
    assert regs[0] == 12345 and regs[1] == 0 and regs[2] == 65000
    assert bytes(b for a in range(3, 12) for b in regs[a].to_bytes(2, "big")).rstrip(b"\0") \
        == VIN.encode()
    plc.raise_lift()
    code, regs, _ = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-t", "3", "-r", "0",
                           "-c", "2", "127.0.0.1")  # input registers serve the same block
    assert code == 0 and regs == {0: 17500, 1: 0b001}
    with lift_for(port, register_map=RegisterMap(table="input")) as lift:
        assert lift.read_state().ready


def test_mbpoll_sees_the_same_exception_codes(plc):
    port = plc.start_tcp()
    code, _, err = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-t", "4", "-r", "12",
                          "127.0.0.1")
    assert code != 0 and "Illegal data address" in err
    code, _, err = mbpoll("-m", "tcp", "-p", str(port), "-a", "7", "-t", "4", "-r", "0",
                          "127.0.0.1")
    assert code != 0 and "Slave device or server failure" in err  # exception 4


def test_illegal_address_is_a_refusal_and_keeps_the_link(plc):
    port = plc.start_tcp()
    with lift_for(port, register_map=RegisterMap(vin=Text(40, 17))) as lift:
        for _ in range(2):
            with pytest.raises(RefusedError, match=r"Modbus exception 2 \(illegal data address\)"
                               r" reading holding registers 40-48 of unit 1: the register map")\
                    as info:
                lift.read_state()
            assert info.value.code == 2
        assert not [t for t in threading.enumerate() if t.name.startswith("lift-reconnect")]


def test_unknown_unit_is_exception_4_with_a_hint(plc):
    port = plc.start_tcp()
    with lift_for(port, unit=7) as lift:
        with pytest.raises(RefusedError, match=r"exception 4 \(server device failure\).*unit=\?")\
                as info:
            lift.read_state()
        assert info.value.code == 4


def test_connection_refused(plc):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    with pytest.raises(ConnectError, match=f"connection refused by 127.0.0.1:{port}"):
        lift_for(port)


def test_connect_timeout_when_the_backlog_is_full():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(0)
    port = server.getsockname()[1]
    filler = socket.create_connection(("127.0.0.1", port), timeout=0.5)  # fills the queue
    try:
        t0 = time.monotonic()
        with pytest.raises(ConnectTimeoutError, match=r"no answer connecting to .* within 0.2 s"):
            lift_for(port, timeout=0.2)
        assert time.monotonic() - t0 < 1.0
    finally:
        filler.close()
        server.close()


def test_silent_plc_times_out_then_recovers(plc):
    port = plc.start_tcp()
    with lift_for(port) as lift:
        plc.set_silent()
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match=r"no answer within 0.1\d s to a read of "
                                                     r"holding registers 0-11 of unit 1"):
            lift.read_state(timeout=0.15)
        assert 0.12 < time.monotonic() - t0 < 0.6
        plc.set_silent(False)
        lift.reconnect()                   # the link was dropped: a late answer is no answer
        assert lift.read_state().height_mm == 0.0


@pytest.mark.parametrize("hang_up", [False, True])
def test_garbage_answers_are_a_protocol_error_not_silence(hang_up):
    """pymodbus drops frames it cannot parse; the link tells a peer that answered something
    else from a silent one, as Open Protocol does (ProtocolError, the keeper's "garbage"),
    showing what it said.  An HTTP server on the port answers and hangs up: that was "link
    lost ...: _HeardTcp ... unbounded read" (a newcomer's trial), garbage too."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def serve() -> None:
        conn, _ = server.accept()
        with conn:
            while conn.recv(256):
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")
                if hang_up:
                    return

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        with lift_for(server.getsockname()[1]) as lift, pytest.raises(
                ProtocolError, match=re.escape(
                    "garbage reading holding registers 0-11 of unit 1: the device answered "
                    "something that is not Modbus TCP (b'HTTP/1.1 400 Bad Request\\r\\n\\r\\n')")):
            lift.read_state(timeout=0.2)
    finally:
        thread.join(2.0)
        server.close()


def test_plc_disappears_and_comes_back_on_reconnect(plc):
    """No reconnecting behind the caller's back: the link stays down, each read says why at
    once, and ``reconnect()`` (the station's keeper calls it with backoff) brings it back."""
    port = plc.start_tcp()
    threads = set(threading.enumerate())
    with lift_for(port) as lift:
        lift.read_state()
        plc.stop_tcp()
        with pytest.raises(ConnectionLostError, match="link lost reading holding registers"
                           ) as lost:
            lift.read_state()
        # it answered on this link before: gone, not another device's port (a technician's
        # trial: a PLC switched off was said with that hint)
        assert "switched off, restarted, or its network dropped" in str(lost.value)
        assert "another device's port" not in str(lost.value)
        t0 = time.monotonic()
        with pytest.raises(ConnectionLostError, match=r"link down \(link lost reading"):
            lift.read_state(timeout=5.0)
        assert time.monotonic() - t0 < 1.0          # said at once, not after the timeout
        with pytest.raises(ConnectError, match=r"connection refused by 127\.0\.0\.1"):
            lift.reconnect()
        with pytest.raises(ConnectionLostError, match=r"link down \(connection refused"):
            lift.read_state()
        assert set(threading.enumerate()) <= threads  # nothing retries in the background
        plc.start_tcp(port)
        lift.reconnect()
        assert lift.read_state().height_mm == 0.0


def test_close_while_the_link_is_down_is_immediate(plc):
    port = plc.start_tcp()
    lift = lift_for(port)
    try:
        plc.stop_tcp()
        with pytest.raises(ConnectionLostError):
            lift.read_state()
    finally:
        t0 = time.monotonic()
        lift.close()
        lift.close()
    assert time.monotonic() - t0 < 0.5
    with pytest.raises(DeviceError, match="not open"):
        lift.read_state()


def test_sim_url_drives_the_same_path():
    with open_lift("sim://lift", timeout=0.5) as lift:
        assert re.fullmatch(r"simulated lift PLC \(Modbus TCP 127\.0\.0\.1:\d+ unit 1\)",
                            lift.identity())
        lift.plc.set_vehicle(12, "VIN12345")
        lift.plc.raise_lift()
        s = lift.read_state()
        assert s.ready and (s.model_code, s.vin) == (12, "VIN12345")
        lift.close()
        assert not lift.is_open
