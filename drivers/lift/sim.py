"""The simulated lift PLC: a real pymodbus server on loopback, driven by the simulated world.

Tests and ``stationd demo`` must exercise the same bytes a plant does, so the twin is not a
mock: :class:`SimulatedPlc` serves the register map over Modbus TCP on 127.0.0.1 (a free port)
and over Modbus RTU on a pair of pseudo-terminals joined back to back, and the world changes
what it serves (``raise_lift()``, ``set_fault()``, ``set_vehicle()``...).  ``sim://lift``
(:class:`SimLift`) starts one and reads it through the real :class:`ModbusLift`, so the
station's polling, timeouts and reconnects run over the real protocol path.

    sim://lift                 Modbus TCP on 127.0.0.1
    sim://lift?transport=rtu   Modbus RTU over a pty pair (parity N: ptys refuse parity bits)

The server (its event loop thread, TCP and RTU, the pty pair) comes from
``drivers.modbus_server``, shared with the wrench's simulated register controller; the action
that refreshes the registers before every request is here.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from drivers.errors import DeviceError
from drivers.lift.base import Lift, LiftState, RegisterMap
from drivers.lift.modbus import ModbusLift
from drivers.modbus_server import PtyPair, SimServer
from drivers.url import OptionError, parse_url

__all__ = ["SIM_FORM", "PtyPair", "SimLift", "SimulatedPlc", "parse_sim_lift_url"]

SIM_FORM = "sim://lift?transport=tcp|rtu&unit=1&timeout=1.0"


class SimulatedPlc(SimServer):
    """A lift PLC serving ``register_map`` as Modbus unit ``unit``.

    The world moves the lift with :meth:`raise_lift` / :meth:`lower_lift` (instantly, or over
    ``duration`` seconds of ``clock`` with the moving bit set), sets faults and the vehicle;
    each request sees the state of that moment.  ``clock`` lets a simulation use its own time.
    """

    def __init__(self, register_map: RegisterMap | None = None, *, unit: int = 1,
                 low_mm: float = 0.0, working_mm: float = 1750.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(thread_name="lift-sim-plc", pty_name="lift-sim-pty")
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
        self.requests = 0      # register reads served

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
    def _action(self, function_code: int, start: int, address: int, count: int,
                registers: list[int], values: list[int] | list[bool] | None) -> int | None:
        """Write the current state into the block (writes never reach here: the block is
        read-only); counted in ``requests`` (how hard the station polls its PLC)."""
        self.requests += 1
        for addr, value in self.register_map.encode(self.state()).items():
            registers[addr - start] = value
        return None

    def _trace(self, sending: bool, packet: bytes) -> bytes:
        return b"" if sending and self._silent else packet

    def _blocks(self) -> list[tuple[int, int, bool]]:
        addresses = self.register_map.addresses()
        first, last = min(addresses), max(addresses)
        return [(first, last - first + 1, True)]


class SimLift(Lift):
    """``sim://lift``: starts a :class:`SimulatedPlc` (``self.plc``, for the world to drive)
    and reads it through a real :class:`ModbusLift` over TCP or RTU."""

    simulated = True

    def __init__(self, url: str = "sim://lift", register_map: RegisterMap | None = None, *,
                 timeout: float | None = None) -> None:
        super().__init__(url, register_map)
        opts = parse_sim_lift_url(url)
        self.transport: str = opts["transport"]
        self.plc = SimulatedPlc(self.register_map, unit=opts["unit"])
        self._timing: dict[str, float | None] = {"timeout": opts["timeout"] or timeout}
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

    def _reconnect(self) -> None:
        """Reconnect the link only: the simulated PLC (the world's) keeps running."""
        if self._link is None:
            super()._reconnect()
            return
        self._link.reconnect()

    def _read_registers(self, spans: list[tuple[int, int]],
                        timeout: float | None) -> dict[int, int]:
        if self._link is None:
            raise DeviceError("the lift is not open", device=self.url)
        return self._link._read_registers(spans, timeout)


def _transport(text: str) -> str:
    if text not in ("tcp", "rtu"):
        raise OptionError("tcp or rtu")
    return text


def _unit(text: str) -> int:
    value = int(text)
    if not 0 <= value <= 247:
        raise OptionError("a Modbus unit id is 0-247")
    return value


def _timeout(text: str) -> float:
    value = float(text)
    if not 0 < value < 3600:
        raise OptionError("seconds, > 0")
    return value


def parse_sim_lift_url(url: str) -> dict[str, Any]:
    """The options (transport, unit, timeout) of a ``sim://lift`` URL; UrlError otherwise,
    saying which simulated device a ``sim://`` URL names when it is not the lift."""
    parsed = parse_url(url)
    if parsed.scheme == "sim" and parsed.host not in (None, "lift"):
        other = " (the simulated tightening controller: wrench.url)" \
            if parsed.host == "wrench" else ""
        raise parsed.error(f"not the simulated lift{other}; expected {SIM_FORM}")
    if parsed.scheme != "sim" or parsed.host != "lift" or parsed.path not in ("", "/"):
        raise parsed.error(f"expected {SIM_FORM}")
    return parsed.typed_options({"transport": (_transport, "tcp"), "unit": (_unit, 1),
                                 "timeout": (_timeout, None)}, SIM_FORM)
