"""Faults over the real Modbus path: an ack that never comes, a late ack, a silent or vanished
controller (typed errors, reconnect with backoff), a fault at each write of the handshake
(never half-done), and a lost result acknowledgement (no loss, no duplicate)."""

from __future__ import annotations

import socket
import time

import pytest

from drivers.errors import (
    ConnectionLostError,
    ConnectTimeoutError,
    DeviceError,
    DeviceTimeoutError,
)
from drivers.wrench import open_wrench
from drivers.wrench.modbus_sim import SimParameters

from .conftest import reconnect_within, wait_until
from .modbus_helpers import FAST, P1, P2, TRANSPORTS, connect, controller


@pytest.fixture
def ctl():
    yield from controller()


@pytest.fixture(params=TRANSPORTS)
def transport(request):
    return request.param


def test_an_ack_that_never_comes_times_out_and_keeps_the_link(ctl):
    with connect(ctl) as w:
        w.select_pset(1)
        ctl.hang()
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match=r"select pset 2: request 2 not "
                           r"acknowledged within 0.2 s \(ack register holds 1\); request 2 "
                           "may have reached the controller: treat it as not done"):
            w.select_pset(2, timeout=0.2)
        assert 0.2 <= time.monotonic() - t0 < 0.6
        with pytest.raises(DeviceTimeoutError, match="tool_enabled bit did not follow"):
            w.enable_tool(timeout=0.1)
        assert w.status().connected and ctl.active == P1
        ctl.hang(False)                  # the late request 2 is acted on now
        assert wait_until(lambda: ctl.active == SimParameters(2, 0.0, 0.0))
        w.enable_tool()
        w.select_pset(3)
        assert ctl.active == SimParameters(3, 0.0, 0.0)


def test_a_late_ack_is_never_taken_for_the_next_request(ctl):
    with connect(ctl) as w:
        ctl.set_ack_delay(0.15)
        with pytest.raises(DeviceTimeoutError, match="request 1 not acknowledged"):
            w.select_pset(1, timeout=0.05)
        assert wait_until(lambda: ctl.active == P1)       # acked late: ack register = 1
        ctl.set_ack_delay(0.25)
        t0 = time.monotonic()
        w.select_pset(2, timeout=1.0)                   # request 2 waits for ack 2
        assert time.monotonic() - t0 >= 0.2
        assert ctl.active == SimParameters(2, 0.0, 0.0)
        regs = ctl.registers()
        assert ctl.map.integer("ack", regs) == ctl.map.integer("request", regs) == 2


def test_a_silent_controller_times_out_then_the_link_comes_back(ctl, transport):
    # the poller held back (a poll every 30 s, not every 20 ms): the command must be what
    # meets the silence.  With FAST's poll, on a loaded machine a poll in flight met it
    # first and dropped the link, and the command was told "the link was reset" (also a
    # typed error with nothing sent, but not the timeout this test is about); the same race
    # after the reconnect failed it once in CI.  The timeout of 1 s: a busy machine's pty.
    with connect(ctl, transport, timeout=1.0, poll=30.0) as w:
        w.select_pset(1)
        ctl.set_silent()
        with pytest.raises(DeviceTimeoutError, match=r"select pset 2: no answer within 1 s "
                           r"writing registers 0-2 of unit 1; not sent"):
            w.select_pset(2)
        assert not w.status().connected
        with pytest.raises(ConnectionLostError, match=r"link down .*nothing was sent"):
            w.select_pset(2)
        ctl.set_silent(False)
        assert reconnect_within(w)
        assert w.status().reconnects == 1
        w.select_pset(2)
        assert ctl.active == SimParameters(2, 0.0, 0.0)


def test_the_controller_disappears_and_comes_back(ctl, transport):
    with connect(ctl, transport) as w:
        w.select_pset(1)
        w.enable_tool()
        ctl.power_off()
        assert wait_until(lambda: not w.status().connected)
        time.sleep(0.3)
        assert w.status().attempts == 0           # nothing retried by itself
        with pytest.raises(DeviceError, match="reconnect: "):
            w.reconnect()
        s = w.status()
        assert s.attempts == 1, s
        gone = "connection refused" if transport == "tcp" else "no answer within"
        assert gone in (s.reason or ""), s
        with pytest.raises(ConnectionLostError, match=r"select pset 2: link down .*; 1 failed "
                                                      r"reconnect"):
            w.select_pset(2)
        with pytest.raises(ConnectionLostError, match="listening for results"):
            w.wait_result(0.1)
        ctl.power_on()
        assert reconnect_within(w)
        assert w.status().reconnects == 1 and w.status().attempts == 0
        assert ctl.active is None                          # the controller lost its RAM
        assert wait_until(lambda: w.controller_status() == (False, False))
        w.select_pset(2)
        w.enable_tool()
        t = ctl.pull_trigger()
        r = w.wait_result(1.0)
        assert t is not None and r is not None and r.tightening_id == t.tightening_id


FAULTS = [("exception", "pset"), ("drop", "pset"), ("lost_answer", "pset"),
          ("exception", "request"), ("drop", "request"), ("lost_answer", "request")]


@pytest.mark.parametrize(("fault", "where"), FAULTS)
def test_the_handshake_is_never_half_done(ctl, fault, where):
    """A fault at each write of the handshake: the call raises, the controller runs either
    its old parameters or the complete new set, and the message says which is possible."""
    with connect(ctl) as w:
        w.select_pset(1)
        ctl.inject(fault, getattr(ctl.map, where).address)
        with pytest.raises(DeviceError) as info:
            w.set_parameters(2, 44.0, 100.0)
        msg = str(info.value)
        if "not sent, the previous parameters stay in effect" in msg:
            assert ctl.active == P1
        else:
            assert "may have reached the controller: treat it as not done" in msg
            assert where == "request" and fault != "exception"
            assert ctl.active in (P1, P2)
        assert all(p in (P1, P2) for p in ctl.history)
        if not w.status().connected:
            assert reconnect_within(w)
        w.set_parameters(2, 44.0, 100.0)
        assert ctl.active == P2 and ctl.history[-1] == P2


@pytest.mark.parametrize("fault", ["drop", "lost_answer"])
def test_a_lost_result_ack_neither_loses_nor_duplicates(ctl, fault):
    with connect(ctl) as w:
        w.select_pset(1)
        w.enable_tool()
        ctl.inject(fault, ctl.map.result_ack.address)
        first, second = ctl.pull_trigger(), ctl.pull_trigger()
        assert first is not None and second is not None
        r = w.wait_result(1.0)           # queued before its ack write
        assert r is not None and r.tightening_id == 1
        # the ack write times out, the link is reset, and after the reconnect the same result
        # is seen again (dropped ack) or not (lost answer): acknowledged, not queued twice
        assert wait_until(lambda: not w.status().connected) and reconnect_within(w)
        r = w.wait_result(1.0)
        assert r is not None and r.tightening_id == 2
        assert w.wait_result(0.2) is None


def test_connect_timeout_when_the_backlog_is_full():
    with socket.socket() as server:                # a full accept queue drops the SYN
        server.bind(("127.0.0.1", 0))
        server.listen(0)
        port = server.getsockname()[1]
        with socket.create_connection(("127.0.0.1", port)):
            t0 = time.monotonic()
            with pytest.raises(ConnectTimeoutError, match=r"open: no answer connecting to "
                                                          r"127.0.0.1:\d+ within 0.2 s"):
                open_wrench(f"modbus-tcp://127.0.0.1:{port}", **{**FAST,
                                                                 "connect_timeout": 0.2})
            assert time.monotonic() - t0 < 1.0
