"""Shared helpers for the Modbus wrench tests: a simulated controller on a transport, fast
timings, and the backend connected to it."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from drivers.wrench import open_wrench
from drivers.wrench.modbus import ModbusWrench
from drivers.wrench.modbus_sim import SimParameters, SimRegisterController

# short timeouts keep every file well under 10 s
FAST = {"timeout": 0.3, "connect_timeout": 0.5, "poll": 0.02}
TRANSPORTS = ["tcp", "rtu"]
VIN = "WVWZZZ1KZAW000123"
P1 = SimParameters(1, 0.0, 0.0)
P2 = SimParameters(2, 44.0, 100.0)


def controller() -> Iterator[SimRegisterController]:
    """The body of each file's ``ctl`` fixture (fixtures cannot be shared without conftest)."""
    with SimRegisterController(seed=1, nok_rate=0.0) as c:
        yield c


def url_for(ctl: SimRegisterController, transport: str) -> str:
    """Serve ``ctl`` on ``transport`` and give the URL a station would configure."""
    if transport == "tcp":
        return f"modbus-tcp://127.0.0.1:{ctl.start_tcp()}?unit=1"
    return f"modbus-rtu://{ctl.start_rtu()}?baud=19200&parity=N&unit=1"


def connect(ctl: SimRegisterController, transport: str = "tcp", **kw: Any) -> ModbusWrench:
    wrench = open_wrench(url_for(ctl, transport), **{**FAST, **kw})
    assert isinstance(wrench, ModbusWrench)
    return wrench
