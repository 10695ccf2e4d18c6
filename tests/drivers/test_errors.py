"""The same failure is the same error type on every backend (the daemon's fault handling and
the commands' messages key on the type, not on which protocol the controller speaks): one
link layer, ``drivers.link``, opens every socket and serial port."""

from __future__ import annotations

import socket
import threading
from typing import Any

import pytest

from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    ConnectTimeoutError,
    DeviceError,
    DeviceTimeoutError,
)
from drivers.lift import open_lift
from drivers.wrench import open_wrench

OPTS: dict[str, Any] = {"timeout": 0.3, "connect_timeout": 0.2}


def _open(url: str) -> object:
    if url.startswith("lift+"):
        return open_lift(url.removeprefix("lift+"), timeout=0.2)
    return open_wrench(url, **OPTS)


@pytest.mark.parametrize("scheme", ["openprotocol", "modbus-tcp", "lift+modbus-tcp"])
def test_a_connect_timeout_is_one_error_type_over_every_protocol(scheme):
    with socket.socket() as server:                # a full accept queue drops the SYN
        server.bind(("127.0.0.1", 0))
        server.listen(0)
        port = server.getsockname()[1]
        with socket.create_connection(("127.0.0.1", port)):
            with pytest.raises(ConnectTimeoutError) as info:
                _open(f"{scheme}://127.0.0.1:{port}")
    error = info.value
    # one type, caught as a failed connect and as a timeout alike, with one wording
    assert isinstance(error, ConnectError) and isinstance(error, DeviceTimeoutError)
    assert f"no answer connecting to 127.0.0.1:{port} within 0.2 s" in str(error)


@pytest.mark.parametrize("scheme", ["openprotocol", "modbus-tcp", "lift+modbus-tcp"])
def test_a_refused_connect_is_one_error_type_over_every_protocol(scheme):
    with socket.socket() as s:                     # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(ConnectError) as info:
        _open(f"{scheme}://127.0.0.1:{port}")
    assert type(info.value) is ConnectError and isinstance(info.value, DeviceError)
    assert f"connection refused by 127.0.0.1:{port}" in str(info.value)


def _use(url: str) -> None:
    """Open, and for the lift (whose open only connects) read once."""
    device: Any = _open(url)
    try:
        if url.startswith("lift+"):
            device.read_state()
    finally:
        device.close()


@pytest.mark.parametrize("scheme", ["openprotocol", "modbus-tcp", "lift+modbus-tcp"])
def test_a_peer_that_closes_is_one_error_type_over_every_protocol(scheme):
    """The device accepts, reads the first request and hangs up."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]

    def hang_up() -> None:
        conn, _ = server.accept()
        with conn:
            conn.recv(256)

    thread = threading.Thread(target=hang_up)
    thread.start()
    try:
        with pytest.raises(ConnectionLostError) as info:
            _use(f"{scheme}://127.0.0.1:{port}")
    finally:
        thread.join(5.0)
        server.close()
    assert type(info.value) is ConnectionLostError


@pytest.mark.parametrize("scheme", ["openprotocol+serial", "modbus-rtu", "lift+modbus-rtu"])
def test_a_missing_serial_port_is_one_error_type_over_every_protocol(scheme):
    with pytest.raises(ConnectError) as info:
        _use(f"{scheme}:///dev/ttyNOSUCH7")
    assert type(info.value) is ConnectError
    assert "no such serial port /dev/ttyNOSUCH7" in str(info.value)


@pytest.mark.parametrize("scheme", ["openprotocol+serial", "modbus-rtu"])
def test_a_path_that_is_no_serial_port_is_said_so(scheme):
    """A sweep: /dev/null as the port said pyserial's "(25, 'Inappropriate ioctl for
    device')"."""
    with pytest.raises(ConnectError) as info:
        _use(f"{scheme}:///dev/null")
    assert "/dev/null is not a serial port" in str(info.value), info.value


def test_a_socket_connected_to_itself_is_a_refusal_not_a_link(monkeypatch):
    """TCP simultaneous open: a client can be given the very port it dials when nothing
    listens there, and would read its own requests back.  The kernel makes such a socket
    for real here (bound to the port it connects to); the link layer refuses it."""
    import socket

    from drivers import link

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]

    def self_connected(address, timeout=None):
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(address)
        s.settimeout(timeout)
        s.connect(address)
        return s

    monkeypatch.setattr(link.socket, "create_connection", self_connected)
    with pytest.raises(ConnectError, match=f"connection refused by 127.0.0.1:{port}"):
        link.connect_tcp("127.0.0.1", port, 1.0, "nothing listens")
