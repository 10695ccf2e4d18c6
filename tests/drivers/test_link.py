"""The serial link's writes over a real pty: a stalled host loses no command it sent, and a
port that takes nothing times out."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator

import pytest
import serial  # type: ignore[import-untyped]

from drivers.errors import ConnectionLostError
from drivers.link import SerialLink


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    """A pty pair: the test reads the master, the link opens the slave as a serial port."""
    master, slave = os.openpty()
    name = os.ttyname(slave)
    try:
        yield master, name
    finally:
        os.close(master)
        os.close(slave)


def read_for(fd: int, n: int, timeout: float = 10.0) -> bytes:
    os.set_blocking(fd, False)
    got = b""
    deadline = time.monotonic() + timeout
    while len(got) < n and time.monotonic() < deadline:
        try:
            got += os.read(fd, n - len(got))
        except BlockingIOError:
            time.sleep(0.01)
    return got


def test_a_host_stalled_past_the_write_timeout_loses_nothing_it_sent(
        pty: tuple[int, str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Every look at the clock (the link's and pyserial's) sees 10 s more, a host stalled
    between each step: the bytes went out, so the send succeeds (pyserial's own write calls
    this a timeout)."""
    master, name = pty
    link = SerialLink(name)
    link.connect(0.5)
    try:
        real: Callable[[], float] = time.monotonic
        looks = [0]

        def stalled() -> float:
            looks[0] += 1
            return real() + 10.0 * looks[0]

        monkeypatch.setattr(time, "monotonic", stalled)
        monkeypatch.setattr(serial.serialutil.Timeout, "TIME", staticmethod(stalled))
        link.send(b"00200018001         \x00")
        monkeypatch.undo()
        assert read_for(master, 21) == b"00200018001         \x00"
    finally:
        link.close()


def test_a_port_that_takes_nothing_times_out(pty):
    """Nobody reads the other end: the pty's buffer fills and the write gives up after its
    timeout, saying so, instead of blocking the station."""
    _, name = pty
    link = SerialLink(name)
    link.connect(0.3)
    try:
        started = time.monotonic()
        with pytest.raises(ConnectionLostError, match=r"timed out \(the port took nothing "
                                                      r"within 0.3 s\)"):
            link.send(b"x" * 1_000_000)
        assert time.monotonic() - started < 20
    finally:
        link.close()


def test_a_pyserial_url_writes_through_pyserial() -> None:
    """``loop://`` (any pyserial URL without a device file) is written by pyserial itself:
    the link's own write is for ports with a file number."""
    link = SerialLink("loop://")
    link.connect(0.5)
    try:
        link.send(b"00200018001         \x00")
        got = b""
        deadline = time.monotonic() + 10
        while len(got) < 21 and time.monotonic() < deadline:
            got += link.recv(0.1)
        assert got == b"00200018001         \x00"
    finally:
        link.close()
