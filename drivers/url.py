"""Device URLs, like pyserial's ``serial_for_url``: the scheme picks the backend, the query
string carries options, and anything unknown is an error that shows the accepted forms.

    modbus-tcp://192.168.10.20:502?unit=1
    modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&unit=3
    openprotocol://192.168.10.30:4545
    openprotocol+serial:///dev/ttyUSB1?baud=9600
    sim://lift
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from drivers.counting import noun
from drivers.errors import UrlError


class OptionError(ValueError):
    """A converter's refusal of an option value that says why (the range, the choices)."""


@dataclass(frozen=True)
class DeviceUrl:
    """A parsed device URL: ``scheme``, ``host``, ``port``, ``path`` and raw ``options``."""

    text: str
    scheme: str
    host: str | None
    port: int | None
    path: str
    options: dict[str, str] = field(default_factory=dict)

    def error(self, message: str) -> UrlError:
        return UrlError(message, device=self.text)

    def typed_options(self, spec: Mapping[str, tuple[Callable[[str], Any], Any]],
                      forms: str = "") -> dict[str, Any]:
        """Options converted by ``spec`` (name -> (converter, default)); unknown ones are
        errors naming the accepted options (and ``forms``, an example of the URL)."""
        unknown = sorted(set(self.options) - set(spec))
        if unknown:
            accepted = ", ".join(sorted(spec)) or "none"
            hint = f"; e.g. {forms}" if forms else ""
            raise self.error(f"unknown {noun(len(unknown), 'option')} {', '.join(unknown)} "
                             f"(accepted: {accepted}{hint})")
        out: dict[str, Any] = {}
        for name, (conv, default) in spec.items():
            if name not in self.options:
                out[name] = default
                continue
            try:
                out[name] = conv(self.options[name])
            except (TypeError, ValueError) as exc:
                why = str(exc) if isinstance(exc, OptionError) else ""
                raise self.error(f"option {name}={self.options[name]!r} is not valid"
                                 + (f": {why}" if why else "")) from None
        return out


def parse_url(text: str) -> DeviceUrl:
    """Split a device URL; the backend checks what it needs (host, port, path, options)."""
    if not isinstance(text, str) or "://" not in text:
        raise UrlError(f"{text!r} is not a device URL (scheme://...)")
    try:
        parts = urlsplit(text)
    except ValueError as exc:  # e.g. "modbus-tcp://[::1": an unclosed IPv6 bracket
        raise UrlError(f"not a valid URL: {exc}", device=text) from None
    try:
        port = parts.port
    except ValueError:
        port = -1
    if port is not None and not 1 <= port <= 65535:
        # port 0 is "any free port" to a server; a client given it reaches nothing (and
        # ``port or DEFAULT`` would silently swap in the default)
        raise UrlError("the port is not a number in 1-65535", device=text) from None
    options: dict[str, str] = {}
    for k, v in parse_qsl(parts.query, keep_blank_values=True):
        if k in options:
            raise UrlError(f"option {k} given twice", device=text)
        options[k] = v
    return DeviceUrl(text=text, scheme=parts.scheme.lower(), host=parts.hostname, port=port,
                     path=parts.path, options=options)


def load_backend(backends: Mapping[str, str], scheme: str) -> Any:
    """The class registered for ``scheme`` in ``backends`` (scheme -> "module:Class"),
    imported only now (python-can's interface registry), or None for an unknown scheme."""
    target = backends.get(scheme)
    if target is None:
        return None
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)
