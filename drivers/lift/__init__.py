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

__all__ = ["BACKENDS", "FORMS", "Lift", "LiftState", "MapError", "RegisterMap", "check_lift_url",
           "lift_class", "open_lift"]


#: schemes of the other devices, named when given as the lift's (a URL pasted in the wrong
#: section says so, not only "unknown scheme")
OTHER_DEVICES = {"openprotocol": "a tightening controller's URL (wrench.url)",
                 "openprotocol+serial": "a tightening controller's URL (wrench.url)",
                 "aravis": "a camera's URL", "opencv": "a camera's URL",
                 "file": "a camera replay's URL"}


def lift_class(url: str) -> type[Lift]:
    """The backend class for ``url``'s scheme; UrlError listing the accepted forms if none."""
    scheme = parse_url(url).scheme
    cls: type[Lift] | None = load_backend(BACKENDS, scheme)
    if cls is None:
        other = f" ({scheme}:// is {OTHER_DEVICES[scheme]}, not a lift's)" \
            if scheme in OTHER_DEVICES else ""
        raise UrlError(f"unknown lift scheme {scheme!r}{other}; accepted: {FORMS}", device=url)
    return cls


def check_lift_url(url: str) -> None:
    """Check ``url`` as the lift's without opening anything: its scheme, form and options
    with their ranges (UrlError).  Nothing connects, no simulated PLC starts."""
    cls = lift_class(url)
    if parse_url(url).scheme == "sim":
        from drivers.lift.sim import parse_sim_lift_url

        parse_sim_lift_url(url)
    else:   # a Modbus lift only parses its URL when built
        cls(url, None)


def open_lift(url: str, register_map: RegisterMap | None = None, **kw: Any) -> Lift:
    """An open lift for ``url``; ``kw`` go to the backend (e.g. ``timeout`` in seconds; the
    URL's own options win).  Close it, or use ``with``."""
    lift = lift_class(url)(url, register_map, **kw)
    lift.open()
    return lift
