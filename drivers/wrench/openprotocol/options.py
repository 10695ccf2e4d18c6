"""The driver's URLs and their options: ``openprotocol://HOST[:4545]`` and
``openprotocol+serial:///dev/tty..``.

Why a module apart from the session: the simulated controller's URL (``sim://wrench``) takes
the same options by the same names and builds its own link, without any of the session's
machinery; and a URL is refused (wrong scheme shape, unknown option, a value that does not
read) before anything is connected.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from drivers.counting import noun
from drivers.endpoint import SerialEndpoint, TcpEndpoint
from drivers.link import Link, SerialLink, TcpLink, baud_rate
from drivers.url import DeviceUrl, OptionError

#: Open Protocol's port, where an ``openprotocol://`` URL without one connects
DEFAULT_PORT = 4545
REFUSED = "controller off, or Open Protocol not enabled on this port?"
Spec = dict[str, tuple[Callable[[str], Any], Any]]   # option -> (converter, default)


def link_ack_option(text: str) -> str:
    """``link_ack``: auto (as the controller's 0002 says), 1/on (always), 0/off (never)."""
    value = {"auto": "auto", "1": "on", "on": "on", "true": "on", "yes": "on", "0": "off",
             "off": "off", "false": "off", "no": "off"}.get(text.strip().lower())
    if value is None:
        raise OptionError("expected auto, 1 or 0")
    return value


def flag_option(text: str) -> bool:
    """A yes/no option: 1, on, true, yes or 0, off, false, no."""
    value = {"1": True, "on": True, "true": True, "yes": True, "0": False, "off": False,
             "false": False, "no": False}.get(text.strip().lower())
    if value is None:
        raise OptionError("expected 1 or 0")
    return value


OPTIONS: Spec = {
    "timeout": (float, 2.0), "connect_timeout": (float, 5.0), "keepalive": (float, 10.0),
    "link_ack": (link_ack_option, "auto"), "curves": (flag_option, False),
}


def keyword_options(kw: dict[str, Any], spec: Spec) -> dict[str, Any]:
    """Keyword overrides of URL options: the same names, already typed."""
    unknown = sorted(set(kw) - set(spec))
    if unknown:
        raise TypeError(f"unknown {noun(len(unknown), 'option')} {', '.join(unknown)} (accepted: "
                        f"{', '.join(sorted(spec))})")
    return kw


def link_from_url(url: DeviceUrl, kw: dict[str, Any]) -> tuple[Link, dict[str, Any]]:
    """The link ``url`` names and the driver's options (the URL's, overridden by ``kw``):
    ``openprotocol://HOST[:PORT]`` or ``openprotocol+serial:///dev/ttyUSB1?baud=9600``."""
    if url.scheme == "openprotocol+serial":
        spec: Spec = {**OPTIONS, "baud": (baud_rate, 9600)}
        opts = url.typed_options(spec, "openprotocol+serial:///dev/ttyUSB1?baud=9600")
        if url.host or not url.path:
            raise url.error("expected a device path: openprotocol+serial:///dev/ttyUSB1")
        opts.update(keyword_options(kw, spec))
        return SerialLink(url.path, opts.pop("baud")), opts
    opts = url.typed_options(OPTIONS, "openprotocol://192.168.10.30:4545?timeout=2")
    if not url.host or url.path not in ("", "/"):
        raise url.error("expected openprotocol://HOST[:PORT] (port 4545 by default)")
    opts.update(keyword_options(kw, OPTIONS))
    return TcpLink(url.host, url.port or DEFAULT_PORT, REFUSED), opts


def link_endpoint(url: DeviceUrl) -> TcpEndpoint | SerialEndpoint:
    """What ``url`` drives: the link it names (:func:`link_from_url`, so the same rules and
    refusals) as an endpoint.  The TCP port is the controller (one Open Protocol session
    per port); an RS-232 line is the controller on it."""
    link, _ = link_from_url(url, {})
    if isinstance(link, TcpLink):
        return TcpEndpoint(link.host, link.port)
    if isinstance(link, SerialLink):
        return SerialEndpoint(link.port)
    raise TypeError(f"link_from_url made a {type(link).__name__}, neither TCP nor serial")
