"""Tightening controllers, chosen by URL (like pyserial's ``serial_for_url``).

    openprotocol://192.168.10.30:4545            Open Protocol over TCP (port 4545 by default;
                                                  ?link_ack=1 forces link-level acknowledgement,
                                                  =0 refuses it, auto by default)
    openprotocol+serial:///dev/ttyUSB1?baud=9600  Open Protocol over RS-232
    sim://wrench                                  a simulated controller, spoken to over the
                                                  real protocol on loopback (or a pty)
    modbus-tcp://192.168.10.31:502?unit=1         register-driven controller, Modbus TCP
    modbus-rtu:///dev/ttyUSB2?baud=19200&parity=E  register-driven controller, Modbus RTU
    sim+modbus://wrench?transport=tcp|rtu         a simulated register-driven controller, a
                                                  real Modbus server on loopback (or a pty)

Backends are imported only when their scheme is used (python-can's interface registry), so
a station without a serial adapter never imports pyserial.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from drivers.errors import UrlError
from drivers.url import load_backend, parse_url
from drivers.wrench.base import (
    LinkStatus,
    Received,
    ResultKind,
    ResultType,
    Status,
    TighteningResult,
    TorqueUnit,
    UnreadableResult,
    Wrench,
    result_kind,
)

__all__ = ["BACKENDS", "FORMS", "LinkStatus", "Received", "ResultKind", "ResultType", "Status",
           "TighteningResult", "TorqueUnit", "UnreadableResult", "Wrench", "fetches", "open_wrench",
           "result_kind", "takes_register_map", "takes_targets", "wrench_class"]

#: scheme -> "module:Class"; the class has ``from_url(url: DeviceUrl, **kw) -> Wrench``.
BACKENDS: dict[str, str] = {
    "openprotocol": "drivers.wrench.openprotocol.client:OpenProtocolWrench",
    "openprotocol+serial": "drivers.wrench.openprotocol.client:OpenProtocolWrench",
    "sim": "drivers.wrench.sim.controller:SimWrench",
    "modbus-tcp": "drivers.wrench.modbus:ModbusWrench",
    "modbus-rtu": "drivers.wrench.modbus:ModbusWrench",
    "sim+modbus": "drivers.wrench.modbus_sim:SimModbusWrench",
}
FORMS = ("openprotocol://HOST[:4545], openprotocol+serial:///dev/ttyUSB1?baud=9600, "
         "sim://wrench, modbus-tcp://HOST[:502]?unit=1, "
         "modbus-rtu:///dev/ttyUSB2?baud=19200&parity=E&unit=1, "
         "sim+modbus://wrench[?transport=rtu]")


def wrench_class(url: str) -> type[Wrench]:
    """The backend class for ``url``'s scheme, imported now and not built; UrlError showing
    the accepted forms when the URL does not parse or names no backend."""
    try:
        parsed = parse_url(url)
    except UrlError as exc:
        raise UrlError(f"{exc.reason}; accepted: {FORMS}", device=url) from None
    backend: type[Wrench] | None = load_backend(BACKENDS, parsed.scheme)
    if backend is None:
        raise UrlError(f"unknown wrench scheme {parsed.scheme!r} (accepted: {FORMS})",
                       device=url)
    return backend


def _can(url: str, ability: Callable[[type[Wrench]], bool]) -> bool:
    """What ``ability`` reads of ``url``'s backend class, asked without building it; False
    for a URL that does not parse or names no backend (the URL's own check says why)."""
    try:
        return bool(ability(wrench_class(url)))
    except UrlError:
        return False


def takes_targets(url: str) -> bool:
    """Whether the controller at ``url`` takes a bolt's own targets (else psets only): a
    property of its backend (:attr:`Wrench.takes_targets`), asked without opening it."""
    return _can(url, lambda backend: backend.takes_targets)


def takes_register_map(url: str) -> bool:
    """Whether the controller at ``url`` is driven through a register map the station file
    may give (:attr:`Wrench.takes_register_map`): its backend says, not its scheme's name."""
    return _can(url, lambda backend: backend.takes_register_map)


def fetches(url: str) -> bool:
    """Whether the controller at ``url`` keeps its results for the station to fetch
    (:attr:`Wrench.can_fetch`), asked without opening it."""
    return _can(url, lambda backend: backend.can_fetch)


def open_wrench(url: str, *, connect: bool = True, **kw: Any) -> Wrench:
    """The backend for ``url``, opened unless ``connect=False``; keywords override the URL's
    options (e.g. ``timeout=0.5``; ``psets=...`` for ``sim://``).  An unknown scheme or
    option is a UrlError that shows the accepted forms."""
    backend: Any = wrench_class(url)     # every backend has from_url (BACKENDS' comment)
    wrench: Wrench = backend.from_url(parse_url(url), **kw)
    if connect:
        try:
            wrench.open()
        except BaseException:
            wrench.close()
            raise
    return wrench
