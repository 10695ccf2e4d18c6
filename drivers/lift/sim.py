"""The simulated lift PLC: a real pymodbus server on loopback, driven by the simulated world.

Tests and ``stationd demo`` must exercise the same bytes a plant does, so the twin is not a
mock: :class:`SimulatedPlc` serves the register map over Modbus TCP on 127.0.0.1 (a free port)
and over Modbus RTU on a pair of pseudo-terminals joined back to back, and the world changes
what it serves (``raise_lift()``, ``set_fault()``, ``set_vehicle()``...).  ``sim://lift``
(:class:`SimLift`) starts one and reads it through the real :class:`ModbusLift`, so the
station's polling, timeouts and reconnects run over the real protocol path.

    sim://lift                 Modbus TCP on 127.0.0.1
    sim://lift?transport=rtu   Modbus RTU over a pty pair (parity N: ptys refuse parity bits)

The pymodbus server API used here (ModbusTcpServer / ModbusSerialServer with a SimDevice whose
``action`` refreshes the registers on every request) is the only pymodbus surface besides
``modbus.py``'s client.
"""

from __future__ import annotations

import asyncio
import os
import select
import threading
import time
import tty
from collections.abc import Callable, Coroutine
from types import TracebackType
from typing import Any, Self, TypeVar, cast

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.errors import DeviceError
from drivers.lift.base import Lift, LiftState, RegisterMap
from drivers.lift.modbus import ModbusLift
from drivers.url import parse_url

SIM_FORM = "sim://lift?transport=tcp|rtu&unit=1&timeout=1.0"
T = TypeVar("T")


class PtyPair:
    """Two pseudo-terminals joined by a thread that copies bytes both ways: a null-modem cable
    between ``paths[0]`` and ``paths[1]``, in-process (no socat needed).  We keep both slave
    ends open ourselves, so either side can open and close its end without EIO on ours."""

    def __init__(self) -> None:
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
        self._thread = threading.Thread(target=self._run, name="lift-sim-pty", daemon=True)
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


class SimulatedPlc:
    """A lift PLC serving ``register_map`` as Modbus unit ``unit``.

    The world moves the lift with :meth:`raise_lift` / :meth:`lower_lift` (instantly, or over
    ``duration`` seconds of ``clock`` with the moving bit set), sets faults and the vehicle;
    each request sees the state of that moment.  ``clock`` lets a simulation use its own time.
    """

    def __init__(self, register_map: RegisterMap | None = None, *, unit: int = 1,
                 low_mm: float = 0.0, working_mm: float = 1750.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.register_map = register_map if register_map is not None else RegisterMap()
        self.unit = unit
        self.low_mm = low_mm
        self.working_mm = working_mm
        self._clock = clock
        self._lock = threading.Lock()
        self._height = low_mm
        self._motion: tuple[float, float, float, float] | None = None  # from, to, t0, duration
        self._fault = False
        self._model = 0
        self._vin: str | None = None
        self._silent = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._tcp: ModbusTcpServer | None = None
        self._rtu: ModbusSerialServer | None = None
        self._pty: PtyPair | None = None
        self.tcp_port: int | None = None
        self.rtu_port: str | None = None  # the pty a master opens

    # -- the world's side ------------------------------------------------------------------
    def _now_height(self, now: float) -> tuple[float, bool]:
        if self._motion is None:
            return self._height, False
        start, target, t0, duration = self._motion
        if duration <= 0 or now >= t0 + duration:
            self._height, self._motion = target, None
            return target, False
        return start + (target - start) * max(0.0, now - t0) / duration, True

    def _move(self, target: float, duration: float) -> None:
        with self._lock:
            now = self._clock()
            height, _ = self._now_height(now)
            self._height = height
            self._motion = None if self._fault else (height, target, now, duration)

    def raise_lift(self, duration: float = 0.0) -> None:
        """Go to working height (ignored while faulted, like a PLC interlock)."""
        self._move(self.working_mm, duration)

    def lower_lift(self, duration: float = 0.0) -> None:
        self._move(self.low_mm, duration)

    def set_height(self, mm: float) -> None:
        """Put the lift at ``mm`` at once (e.g. stopped short of working height)."""
        self.register_map.encode(self._state(mm, False))  # ValueError if it does not fit
        with self._lock:
            self._height, self._motion = mm, None

    def set_fault(self, fault: bool = True) -> None:
        """Set or clear the fault bit; a fault stops the lift where it is."""
        with self._lock:
            self._height, _ = self._now_height(self._clock())
            self._fault = fault
            if fault:
                self._motion = None

    def set_vehicle(self, model_code: int, vin: str | None = None) -> None:
        """The vehicle on the lift; ValueError if the registers cannot hold it."""
        with self._lock:
            probe = LiftState(self._height, False, False, False, model_code, vin, 0.0)
        self.register_map.encode(probe)
        with self._lock:
            self._model, self._vin = model_code, vin

    def set_silent(self, silent: bool = True) -> None:
        """Receive requests but answer none (a hung PLC): the master times out."""
        self._silent = silent

    def _state(self, height: float, moving: bool) -> LiftState:
        at = not moving and abs(height - self.working_mm) < 0.5
        return LiftState(height, at, moving, self._fault, self._model, self._vin, time.time())

    def state(self) -> LiftState:
        """What the PLC serves right now."""
        with self._lock:
            return self._state(*self._now_height(self._clock()))

    # -- the server's side -----------------------------------------------------------------
    async def _action(self, _function_code: int, start: int, _address: int, _count: int,
                      registers: list[int], _values: list[int] | list[bool] | None
                      ) -> ExcCodes | None:
        """Called by pymodbus before each request is served: write the current state into
        the block (writes never reach here: the block is read-only)."""
        for address, value in self.register_map.encode(self.state()).items():
            registers[address - start] = value
        return None

    def _trace(self, sending: bool, packet: bytes) -> bytes:
        return b"" if sending and self._silent else packet

    def _device(self) -> SimDevice:
        addresses = self.register_map.addresses()
        first, last = min(addresses), max(addresses)
        block = SimData(first, count=last - first + 1, datatype=DataType.REGISTERS,
                        readonly=True)
        return SimDevice(id=self.unit, simdata=[block], action=self._action)

    def _run(self, coro: Coroutine[Any, Any, T]) -> T:
        if self._loop is None:
            loop = asyncio.new_event_loop()
            self._thread = threading.Thread(target=loop.run_forever, name="lift-sim-plc",
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
        """Serve Modbus RTU on one end of a pty pair; returns the other end's path."""
        if self._rtu is not None:
            raise RuntimeError("the RTU server is already running")
        if self._pty is None:
            self._pty = PtyPair()
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
        """Stop listening and drop the connections: masters see the PLC disappear."""
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
            asyncio.run_coroutine_threadsafe(_cancel_all(), loop).result(10.0)
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


async def _cancel_all() -> None:
    """Cancel what pymodbus leaves running (request handlers, relisten tasks)."""
    tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


class SimLift(Lift):
    """``sim://lift``: starts a :class:`SimulatedPlc` (``self.plc``, for the world to drive)
    and reads it through a real :class:`ModbusLift` over TCP or RTU."""

    def __init__(self, url: str = "sim://lift", register_map: RegisterMap | None = None, *,
                 timeout: float | None = None, backoff: float | None = None,
                 backoff_max: float | None = None) -> None:
        super().__init__(url, register_map)
        parsed = parse_url(url)
        if parsed.scheme != "sim" or parsed.host != "lift" or parsed.path not in ("", "/"):
            raise parsed.error(f"expected {SIM_FORM}")
        opts = parsed.typed_options({"transport": (_transport, "tcp"), "unit": (int, 1),
                                     "timeout": (float, None)}, SIM_FORM)
        self.transport: str = opts["transport"]
        self.plc = SimulatedPlc(self.register_map, unit=opts["unit"])
        self._timing: dict[str, float | None] = {"timeout": opts["timeout"] or timeout,
                                                 "backoff": backoff, "backoff_max": backoff_max}
        self._link: ModbusLift | None = None

    def identity(self) -> str:
        link = self._link.identity() if self._link is not None else "not started"
        return f"simulated lift PLC ({link})"

    def _open(self) -> None:
        try:
            if self.transport == "tcp":
                port = self.plc.start_tcp()
                target = f"modbus-tcp://127.0.0.1:{port}?unit={self.plc.unit}"
            else:
                path = self.plc.start_rtu()
                target = f"modbus-rtu://{path}?baud=19200&parity=N&unit={self.plc.unit}"
            link = ModbusLift(target, self.register_map, **self._timing)
            link.open()
        except BaseException:
            self.plc.close()
            raise
        self._link = link

    def _close(self) -> None:
        if self._link is not None:
            self._link.close()
            self._link = None
        self.plc.close()

    def _read_registers(self, spans: list[tuple[int, int]],
                        timeout: float | None) -> dict[int, int]:
        if self._link is None:
            raise DeviceError("the lift is not open", device=self.url)
        return self._link._read_registers(spans, timeout)


def _transport(text: str) -> str:
    if text not in ("tcp", "rtu"):
        raise ValueError(text)
    return text
