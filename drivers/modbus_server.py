"""Simulated Modbus devices: a real pymodbus server on loopback or a pty, and a null-modem pty
pair; the only module that uses pymodbus's server API (its client: ``modbus_link.py``).

Tests and ``stationd demo`` must exercise the same bytes a plant does, so a simulated device is
not a mock: :class:`SimServer` serves it over Modbus TCP on 127.0.0.1 (a free port) and over
Modbus RTU on a pair of pseudo-terminals joined back to back, from an asyncio event loop in
its own thread.  A subclass says what it serves (``unit``, :meth:`SimServer._blocks`), how
each request changes it (:meth:`SimServer._action`) and which answers are lost
(:meth:`SimServer._trace`); the lift's simulated PLC (``drivers.lift.sim``) and the wrench's
simulated register controller (``drivers.wrench.modbus_sim``) are two.

The pymodbus server API used here: ModbusTcpServer / ModbusSerialServer with a SimDevice whose
``action`` is called before every request is served.
"""

from __future__ import annotations

import asyncio
import os
import select
import threading
import tty
from abc import ABC, abstractmethod
from collections.abc import Coroutine
from types import TracebackType
from typing import Any, Self, TypeVar, cast

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

T = TypeVar("T")


class PtyPair:
    """Two pseudo-terminals joined by a thread that copies bytes both ways: a null-modem cable
    between ``paths[0]`` and ``paths[1]``, in-process (no socat needed).  We keep both slave
    ends open ourselves, so either side can open and close its end without EIO on ours."""

    def __init__(self, name: str = "sim-pty") -> None:
        self._fds: list[int] = []
        masters, paths = [], []
        for _ in range(2):
            master, slave = os.openpty()
            tty.setraw(slave)  # no echo, no line discipline, before anyone opens it
            os.set_blocking(master, False)
            self._fds += [master, slave]
            masters.append(master)
            paths.append(os.ttyname(slave))
        self.paths = (paths[0], paths[1])
        self._masters = (masters[0], masters[1])
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        a, b = self._masters
        while True:
            ready, _, _ = select.select([a, b, self._wake_r], [], [])
            if self._wake_r in ready:
                return
            for src, dst in ((a, b), (b, a)):
                if src in ready:
                    try:
                        os.write(dst, os.read(src, 4096))
                    except (BlockingIOError, InterruptedError):
                        pass  # nobody draining the other end: the bytes are lost, as on a wire
                    except OSError:
                        return  # an end is gone: the line goes dead (timeouts), no busy loop

    def close(self) -> None:
        """Stop the copier and close every end; safe to call twice."""
        if self._thread.is_alive():
            os.write(self._wake_w, b"x")
            self._thread.join()
        for fd in (*self._fds, self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self._fds = []
        self._wake_r = self._wake_w = -1


class SimServer(ABC):
    """One simulated Modbus device (unit ``unit``) served over TCP and/or RTU: ``start_tcp()``
    / ``start_rtu()``, ``stop_tcp()`` / ``stop_rtu()`` (the device disappears from that line),
    ``close()`` (everything, safe to call twice), or use it as a context manager.  The event
    loop thread is named ``thread_name``, the pty copier ``pty_name``."""

    unit: int

    def __init__(self, *, thread_name: str, pty_name: str) -> None:
        self._thread_name = thread_name
        self._pty_name = pty_name
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._tcp: ModbusTcpServer | None = None
        self._rtu: ModbusSerialServer | None = None
        self._pty: PtyPair | None = None
        self.tcp_port: int | None = None
        self.rtu_port: str | None = None  # the pty a master opens

    # -- what a subclass serves ---------------------------------------------------------------
    @abstractmethod
    def _blocks(self) -> list[tuple[int, int, bool]]:
        """The register blocks served: (first address, count, read-only on the wire)."""

    @abstractmethod
    def _action(self, function_code: int, start: int, address: int, count: int,
                registers: list[int], values: list[int] | list[bool] | None) -> int | None:
        """Called (in the event loop thread) before each request is served: ``registers`` is
        the block from address ``start`` (modify in place), ``values`` what a write request
        carries (None for a read; modify in place to change what is stored).  Returns a
        Modbus exception code to answer with, or None to serve the request."""

    def _trace(self, sending: bool, packet: bytes) -> bytes:
        """Every packet received and sent; returning b"" for a sent one drops the answer."""
        return packet

    def _device(self) -> SimDevice:
        async def action(function_code: int, start: int, address: int, count: int,
                         registers: list[int], values: list[int] | list[bool] | None
                         ) -> ExcCodes | None:
            code = self._action(function_code, start, address, count, registers, values)
            return None if code is None else ExcCodes(code)

        blocks = [SimData(a, count=n, datatype=DataType.REGISTERS, readonly=readonly)
                  for a, n, readonly in self._blocks()]
        return SimDevice(id=self.unit, simdata=blocks, action=action)

    # -- the servers ----------------------------------------------------------------------------
    def _run(self, coro: Coroutine[Any, Any, T]) -> T:
        if self._loop is None:
            loop = asyncio.new_event_loop()
            self._thread = threading.Thread(target=loop.run_forever, name=self._thread_name,
                                            daemon=True)
            self._thread.start()
            self._loop = loop
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(10.0)

    def start_tcp(self, port: int = 0) -> int:
        """Serve Modbus TCP on 127.0.0.1:``port`` (0: a free port); returns the port."""
        if self._tcp is not None:
            raise RuntimeError("the TCP server is already running")

        async def start() -> tuple[ModbusTcpServer, int]:
            server = ModbusTcpServer(self._device(), address=("127.0.0.1", port),
                                     trace_packet=self._trace)
            await server.serve_forever(background=True)
            listener = cast(asyncio.Server, server.transport)  # listen() stores the Server
            return server, int(listener.sockets[0].getsockname()[1])

        self._tcp, self.tcp_port = self._run(start())
        return self.tcp_port

    def start_rtu(self) -> str:
        """Serve Modbus RTU (19200 8N1: ptys refuse parity bits) on one end of a pty pair;
        returns the other end's path."""
        if self._rtu is not None:
            raise RuntimeError("the RTU server is already running")
        if self._pty is None:
            self._pty = PtyPair(self._pty_name)
        path = self._pty.paths[0]

        async def start() -> ModbusSerialServer:
            server = ModbusSerialServer(self._device(), framer=FramerType.RTU, port=path,
                                        baudrate=19200, parity="N", trace_packet=self._trace)
            await server.serve_forever(background=True)
            return server

        self._rtu = self._run(start())
        self.rtu_port = self._pty.paths[1]
        return self.rtu_port

    def _stop(self, server: ModbusTcpServer | ModbusSerialServer | None) -> None:
        async def stop(server: ModbusTcpServer | ModbusSerialServer) -> None:
            # let connections already accepted finish connection_made(): pymodbus closes only
            # those, and one caught half-way would live on, orphaned and silent
            await asyncio.sleep(0.01)
            await server.shutdown()  # type: ignore[no-untyped-call]

        if server is not None and self._loop is not None:
            self._run(stop(server))

    def stop_tcp(self) -> None:
        """Stop listening and drop the connections: masters see the device disappear."""
        server, self._tcp = self._tcp, None
        self._stop(server)

    def stop_rtu(self) -> None:
        """Stop answering on the serial line (the pty stays: the cable is still plugged)."""
        server, self._rtu = self._rtu, None
        self._stop(server)

    def close(self) -> None:
        """Stop both servers, the event loop thread and the pty copier; safe to call twice."""
        self.stop_tcp()
        self.stop_rtu()
        loop, self._loop = self._loop, None
        if loop is not None and self._thread is not None:
            asyncio.run_coroutine_threadsafe(cancel_all(), loop).result(10.0)
            loop.call_soon_threadsafe(loop.stop)
            self._thread.join()
            loop.close()
        self._thread = None
        if self._pty is not None:
            self._pty.close()
            self._pty = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


async def cancel_all() -> None:
    """Cancel what pymodbus leaves running (request handlers, relisten tasks)."""
    tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
