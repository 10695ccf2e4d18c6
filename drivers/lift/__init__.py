"""The lift PLC, chosen by URL: ``open_lift("modbus-tcp://192.168.10.20:502?unit=1")``.

Backends are imported only when their scheme is used (so a station without serial adapters
never imports pyserial, and a typo in the scheme fails before any import), like pyserial's
``serial_for_url`` and python-can's interface registry.
"""

from __future__ import annotations

from typing import Any

from drivers.errors import UrlError
from drivers.lift.base import Lift, LiftState, MapError, RegisterMap
from drivers.url import load_backend, parse_url

#: scheme -> "module:Class"
BACKENDS: dict[str, str] = {
    "modbus-tcp": "drivers.lift.modbus:ModbusLift",
    "modbus-rtu": "drivers.lift.modbus:ModbusLift",
    "sim": "drivers.lift.sim:SimLift",
}
FORMS = ("modbus-tcp://HOST[:PORT]?unit=N | "
         "modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&unit=N | sim://lift[?transport=rtu]")

__all__ = ["BACKENDS", "FORMS", "Lift", "LiftState", "MapError", "RegisterMap", "lift_class",
           "open_lift"]


def lift_class(url: str) -> type[Lift]:
    """The backend class for ``url``'s scheme; UrlError listing the accepted forms if none."""
    scheme = parse_url(url).scheme
    cls: type[Lift] | None = load_backend(BACKENDS, scheme)
    if cls is None:
        raise UrlError(f"unknown lift scheme {scheme!r}; accepted: {FORMS}", device=url)
    return cls


def open_lift(url: str, register_map: RegisterMap | None = None, **kw: Any) -> Lift:
    """An open lift for ``url``; ``kw`` go to the backend (e.g. ``timeout`` in seconds; the
    URL's own options win).  Close it, or use ``with``."""
    lift = lift_class(url)(url, register_map, **kw)
    lift.open()
    return lift
