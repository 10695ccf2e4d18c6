"""Faults over the real protocol: each is a typed error with a clear message, the link comes
back with exponential backoff, and a command is either acknowledged or reported failed."""

from __future__ import annotations

import logging
import re
import socket
import threading
import time

import pytest

from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    ConnectTimeoutError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.link import TcpLink
from drivers.wrench import open_wrench
from drivers.wrench.base import UnreadableResult
from drivers.wrench.openprotocol.client import OpenProtocolWrench

from .conftest import FAST, connect, op, read_message, reconnect_within, wait_until

TRANSPORTS = ["tcp", "serial"]


def test_connection_refused():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]                  # nothing listens there once closed
    with pytest.raises(ConnectError, match=rf"openprotocol://127.0.0.1:{port}: open: "
                                           r"connection refused by 127.0.0.1:\d+"):
        open_wrench(f"openprotocol://127.0.0.1:{port}", **FAST)


def test_connect_timeout():
    with socket.socket() as server:                # a full accept queue drops the SYN
        server.bind(("127.0.0.1", 0))
        server.listen(0)
        port = server.getsockname()[1]
        with socket.create_connection(("127.0.0.1", port)):
            t0 = time.monotonic()
            with pytest.raises(ConnectTimeoutError, match="no answer connecting to "
                                                         r"127.0.0.1:\d+ within 0.3 s"):
                open_wrench(f"openprotocol://127.0.0.1:{port}", **{**FAST,
                                                                   "connect_timeout": 0.3})
            assert time.monotonic() - t0 < 1.0


def test_a_controller_that_never_answers(peer):
    p = peer(lambda c: (read_message(c), c.recv(100)))    # read 0001, then wait for close
    with pytest.raises(DeviceTimeoutError, match=re.escape("open: communication start: no "
                                                           "answer to MID 0001 within 0.5 s")):
        open_wrench(f"openprotocol://127.0.0.1:{p.port}", **FAST)


def test_communication_start_refused(peer):
    def script(c):
        assert read_message(c) == op(1, rev="006")     # the highest revision first
        c.sendall(b"00260004001         000196\x00")
        c.recv(100)
    p = peer(script)
    with pytest.raises(RefusedError, match=r"error 96 \(client already connected\)") as e:
        open_wrench(f"openprotocol://127.0.0.1:{p.port}", **FAST)
    assert e.value.code == 96


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize(("fault", "error", "words"), [
    ("silent", DeviceTimeoutError, "no answer to MID 0018 within 0.3 s; not acknowledged"),
    ("partial", DeviceTimeoutError, "no answer to MID 0018"),
    ("garbage", ProtocolError, "not acknowledged"),
    ("truncate", ConnectionLostError, "in the middle of a message"),
    ("close", ConnectionLostError, "not acknowledged"),
])
def test_a_spoiled_answer_fails_the_command_and_the_link_recovers(sim, transport, tmp_path,
                                                                   fault, error, words):
    with connect(sim, transport, tmp_path, timeout=0.3) as w:
        sim.inject(fault, 18)
        with pytest.raises(error, match=f"select pset 2: .*{words}"):
            w.select_pset(2)
        if fault in ("truncate", "close") and transport == "serial":
            sim.power_on()                         # the pty went away with the fault
        assert reconnect_within(w, 3.0)
        w.select_pset(1)                           # acknowledged on the new session
        assert w.status().reconnects == 1 and sim.pset == 1


def test_garbage_messages_say_what_came(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        sim.inject("garbage", 43)
        with pytest.raises(ProtocolError, match=r"enable tool: garbage where a message "
                                                r"should start: b'\\xffGARBAGE"):
            w.enable_tool()


def test_the_device_disappears_and_stays_down_until_reconnected(sim):
    """No reconnecting behind the caller's back (the station's keeper decides when): every
    call says the link is down at once, and ``reconnect()`` starts a new session."""
    attempts = []

    class Recording(TcpLink):
        def connect(self, timeout):
            attempts.append(time.monotonic())
            super().connect(timeout)

    w = OpenProtocolWrench(Recording("127.0.0.1", sim.listen_tcp()), device="rec", **FAST)
    with w:
        w.select_pset(1)
        w.enable_tool()
        sim.power_off()
        assert wait_until(lambda: not w.status().connected)
        t0 = time.monotonic()
        with pytest.raises(ConnectionLostError, match="select pset 2: link down") as down:
            w.select_pset(2)
        assert "failed reconnect" not in str(down.value)   # none tried yet: not "0 failed"
        with pytest.raises(ConnectionLostError, match="listening for results: link down"):
            w.wait_result(1.0)
        assert time.monotonic() - t0 < 0.1         # fails at once: nothing was sent
        time.sleep(0.3)
        assert len(attempts) == 1                  # nothing retried by itself
        with pytest.raises(ConnectError, match="reconnect: connection refused"):
            w.reconnect()
        status = w.status()
        assert status.attempts == 1 and "refused" in (status.reason or "")
        with pytest.raises(ConnectionLostError, match=r"link down \(.*\); 1 failed reconnect;"):
            w.select_pset(2)
        sim.power_on()
        w.reconnect()
        assert w.status().connected and w.status().reconnects == 1
        restart = [r.mid for r in sim.received()]
        assert restart[-3:] == [1, 60, 80] and restart.count(18) == 1   # nothing leaked
        assert not sim.tool_enabled                # the station must send its state again
        w.select_pset(2)
        w.enable_tool()
        sim.pull_trigger()
        result = w.wait_result(1.0)
        assert result is not None and result.pset == 2


def test_the_serial_device_disappears_and_comes_back(sim, tmp_path):
    with connect(sim, "serial", tmp_path) as w:
        sim.power_off()
        assert wait_until(lambda: not w.status().connected)
        assert "is gone" in (w.status().reason or "")
        with pytest.raises(ConnectError, match="reconnect: no such serial port"):
            w.reconnect()
        sim.power_on()
        assert reconnect_within(w)
        w.select_pset(3)
        assert sim.pset == 3


def test_a_command_in_flight_when_the_link_drops_fails_at_once(sim, tmp_path):
    errors = []
    with connect(sim, "tcp", tmp_path, timeout=5.0) as w:
        sim.inject("silent", 18)

        def select():
            try:
                w.select_pset(2)
            except BaseException as e:
                errors.append(e)
        t = threading.Thread(target=select)
        t0 = time.monotonic()
        t.start()
        assert wait_until(lambda: bool(sim.received(18)))
        sim.drop_connections()
        t.join()
        assert time.monotonic() - t0 < 2.0
        assert isinstance(errors[0], ConnectionLostError)
        assert "select pset 2" in str(errors[0]) and "not acknowledged" in str(errors[0])
        assert reconnect_within(w)


def test_results_received_before_a_loss_are_still_delivered(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        w.select_pset(1)
        w.enable_tool()
        sim.pull_trigger()
        assert wait_until(lambda: bool(w._results))   # received, not yet taken
        sim.power_off()
        assert wait_until(lambda: not w.status().connected)
        result = w.wait_result(0.1)
        assert result is not None and result.tightening_id == 1
        assert sim.acks == 0     # taken after the loss: the controller was never told
        with pytest.raises(ConnectionLostError):
            w.wait_result(0.1)


def test_an_unreadable_result_is_handed_out_and_acknowledged_when_the_station_says(peer):
    """A MID 0061 that reads at no revision is not a link fault and not acknowledged on
    receipt: it is handed out whole (UnreadableResult) and acknowledged once stored."""
    acked = threading.Event()
    clock = threading.Event()

    def script(c):
        read_message(c)
        c.sendall(op(2, b"010001020103" + b"Scripted".ljust(25)))
        read_message(c)
        c.sendall(op(5, b"0060"))
        clock.set() if read_message(c)[4:8] == b"0080" else None
        c.sendall(op(4, b"008099"))                        # no clock: the session goes on
        c.sendall(op(61, b"01" + b"x" * 209))              # right length, wrong content
        acked.set() if read_message(c) == op(62) else None
        c.recv(100)

    p = peer(script)
    with open_wrench(f"openprotocol://127.0.0.1:{p.port}", **FAST) as w:
        assert w.identity() == "Scripted (cell 0001, channel 01)"
        assert clock.is_set() and w.clock_offset_s is None
        got = w.wait_result(1.0, acknowledge=False)
        assert isinstance(got, UnreadableResult)
        assert (got.mid, got.revision, got.tightening_id, got.pset) == (61, 1, None, None)
        assert got.raw == op(61, b"01" + b"x" * 209)[:-1].decode()
        assert "expected tag 02 (channel_id)" in got.error
        assert next(iter(w._unacked.values()))[0] is got and not acked.is_set()
        w.acknowledge_result(got)
        assert acked.wait(1.0) and w.status().connected


def test_a_keepalive_that_is_not_mirrored_resets_the_link(sim, tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="drivers.wrench.openprotocol.client")
    sim.inject("silent", 9999)
    with connect(sim, "tcp", tmp_path, keepalive=0.1, timeout=0.3) as w:
        assert wait_until(lambda: not w.status().connected)
        assert "keep-alive (MID 9999) not mirrored within 0.3 s" in caplog.text


def test_without_keepalive_the_controller_drops_an_idle_link(sim, tmp_path):
    sim.silence_timeout = 0.3
    with connect(sim, "tcp", tmp_path, keepalive=10.0) as w:
        assert wait_until(lambda: not w.status().connected)
        assert sim.drops >= 1


def test_a_bad_wrench_url_names_itself_once():
    """``probe wrench openprotocol://127.0.0.1:99999`` said the URL twice before why (an
    integrator's trial)."""
    from drivers.errors import UrlError
    from drivers.wrench import wrench_class

    url = "openprotocol://127.0.0.1:99999"
    with pytest.raises(UrlError) as err:
        wrench_class(url)
    said = str(err.value)
    assert said.count(url) == 1 and said.startswith(f"{url}: the port is not a number"), said
