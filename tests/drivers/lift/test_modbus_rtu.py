"""The lift over real Modbus RTU on a pseudo-terminal pair: states, mbpoll, faults."""

from __future__ import annotations

import time

import pytest

from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.lift import open_lift
from drivers.lift.modbus import ModbusLift
from drivers.lift.sim import PtyPair

from .conftest import FAST, VIN, mbpoll


def lift_for(path: str, **kw) -> ModbusLift:
    query = kw.pop("query", "baud=19200&parity=N")
    lift = open_lift(f"modbus-rtu://{path}?{query}", **{**FAST, **kw})
    assert isinstance(lift, ModbusLift)
    return lift


def test_reads_what_the_world_sets(plc):
    path = plc.start_rtu()
    with lift_for(path, query="baud=19200&parity=E&unit=1") as lift:  # parity is not enforced
        assert lift.identity() == f"Modbus RTU {path} 19200 8E1 unit 1"
        assert not lift.read_state().ready
        plc.set_vehicle(31, VIN)
        plc.raise_lift()
        s = lift.read_state(timeout=0.5)
        assert s.ready and (s.height_mm, s.model_code, s.vin) == (1750.0, 31, VIN)
        plc.set_fault()
        assert lift.read_state().fault


def test_mbpoll_reads_the_same_registers(plc):
    path = plc.start_rtu()
    plc.set_vehicle(4711, VIN)
    plc.raise_lift()
    code, regs, err = mbpoll("-m", "rtu", "-b", "19200", "-P", "none", "-a", "1", "-t", "4",
                             "-r", "0", "-c", "4", path)
    assert code == 0, err
    assert regs == {0: 17500, 1: 0b001, 2: 4711, 3: ord("W") << 8 | ord("V")}
    code, _, err = mbpoll("-m", "rtu", "-b", "19200", "-P", "none", "-a", "1", "-t", "4",
                          "-r", "12", path)
    assert code != 0 and "Illegal data address" in err


def test_unknown_unit_is_exception_4(plc):
    path = plc.start_rtu()
    with lift_for(path, query="parity=N&unit=9") as lift, \
            pytest.raises(RefusedError, match=r"exception 4 .* of unit 9") as info:
        lift.read_state()
    assert info.value.code == 4


def test_silent_line_times_out_and_recovers(plc):
    path = plc.start_rtu()
    with lift_for(path) as lift:
        plc.set_silent()
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match=r"no answer within 0\.1"):
            lift.read_state(timeout=0.15)
        assert time.monotonic() - t0 < 0.6
        plc.set_silent(False)
        with pytest.raises(ConnectionLostError, match=r"link down \(no answer"):
            lift.read_state(timeout=0.5)       # the link was dropped: a late answer is no answer
        lift.reconnect()
        assert lift.read_state(timeout=0.5).height_mm == 0.0


def test_plc_stops_and_restarts_on_the_line(plc):
    path = plc.start_rtu()
    with lift_for(path) as lift:
        plc.raise_lift()
        assert lift.read_state().ready
        plc.stop_rtu()  # powered off: the cable stays, nobody answers
        with pytest.raises(DeviceTimeoutError):
            lift.read_state(timeout=0.15)
        assert plc.start_rtu() == path
        deadline = time.monotonic() + 2.0
        while True:
            try:
                lift.reconnect()
                assert lift.read_state(timeout=0.2).ready
                break
            except DeviceError:
                assert time.monotonic() < deadline


def test_missing_port_and_busy_port():
    with pytest.raises(ConnectError, match="no such serial port /dev/ttyNOSUCH0"):
        open_lift("modbus-rtu:///dev/ttyNOSUCH0")
    pty = PtyPair()
    try:
        with lift_for(pty.paths[1]), pytest.raises(ConnectError, match="in use by another"):
            lift_for(pty.paths[1])  # pyserial's exclusive lock
    finally:
        pty.close()
        pty.close()


def test_sim_url_over_rtu():
    with open_lift("sim://lift?transport=rtu", timeout=0.5) as lift:
        assert "Modbus RTU /dev/pts/" in lift.identity()
        lift.plc.set_vehicle(7)
        lift.plc.raise_lift()
        s = lift.read_state()
        assert s.ready and s.model_code == 7 and s.vin is None


def test_garbage_on_the_line_is_a_protocol_error_not_silence():
    """A peer on the line that answers with something else (another protocol, a wrong baud
    rate's noise) is ProtocolError, as over TCP and Open Protocol; silence stays a timeout."""
    import threading

    from drivers.link import pyserial

    pty = PtyPair()
    peer = pyserial().Serial(pty.paths[0], 19200, timeout=0.05)
    stop = threading.Event()

    def answer_garbage() -> None:
        while not stop.is_set():
            if peer.read(64):
                peer.write(b"\xff\x00garbage, not a Modbus reply\r\n")

    thread = threading.Thread(target=answer_garbage, daemon=True)
    thread.start()
    try:
        with lift_for(pty.paths[1]) as lift, pytest.raises(
                ProtocolError, match=r"garbage reading .*: the device answered something that "
                                     r"is not Modbus RTU \(b'"):
            lift.read_state(timeout=0.3)
    finally:
        stop.set()
        thread.join(2.0)
        peer.close()
        pty.close()
