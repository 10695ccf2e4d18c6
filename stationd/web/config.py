"""The ``http:`` section of the station file: where the screens listen and the token that
guards a non-local bind.

Why a check function apart from the reader: the config checker reports every problem of a
file at once, and an open bind on a plant network is one of them (anyone on the line's
network could watch the station), not a reason to stop reading the rest.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

from stationd.configread import is_local
from stationd.errors import ConfigError
from stationd.yamlio import YamlNode

DEFAULT_LISTEN = "127.0.0.1:8080"


@dataclass(frozen=True)
class HttpConfig:
    """``listen``: ``host:port`` (``[::1]:8080`` for IPv6); ``token``: required by every
    request (``Authorization: Bearer``, a ``token`` cookie or ``?token=``) when set."""

    listen: str = DEFAULT_LISTEN
    token: str | None = None

    @classmethod
    def from_node(cls, node: YamlNode) -> HttpConfig:
        m = node.mapping(("listen", "token"))
        listen = m["listen"].text() if "listen" in m else DEFAULT_LISTEN
        try:
            split_listen(listen)
        except ValueError as exc:
            raise m["listen"].error(str(exc)) from None
        token = m["token"].text(secret=True) if "token" in m else None
        cfg = cls(listen, token)
        # off this machine the longer rule is the one said (open_bind_problem), once: an IT
        # administrator's trial was told "at least 8 characters" and "set http.token" of a
        # token set, then "16" with 10 characters
        if token is not None and len(token) < 8 and is_local(cfg.host):
            raise m["token"].error(f"token: at least 8 characters ({OPEN_TOKEN_MIN} for a "
                                   "listen off this machine)")
        problem = open_bind_problem(cfg)
        if problem is not None:
            # a token too short for the bind: the section's own error (its listen and its
            # token together), told once, not again with either left out
            raise (m["listen"] if "listen" in m and token is None else node).error(problem)
        return cfg

    @property
    def host(self) -> str:
        return split_listen(self.listen)[0]

    @property
    def port(self) -> int:
        return split_listen(self.listen)[1]


def split_listen(listen: str) -> tuple[str, int]:
    """``host:port`` -> (host, port); ValueError with a readable message otherwise."""
    host, sep, port_text = listen.rpartition(":")
    if not sep or not host or not port_text.isdigit():
        raise ValueError(f"listen {listen!r}: expected host:port, e.g. {DEFAULT_LISTEN}")
    port = int(port_text)
    if not 0 <= port <= 65535:
        raise ValueError(f"listen {listen!r}: port {port} is not 0-65535")
    host = host.strip("[]")
    if not _host_ok(host):
        raise ValueError(f"listen {listen!r}: {host!r} is not an IP address or a host name")
    return host, port


def _host_ok(host: str) -> bool:
    """An IPv4/IPv6 address, or a host name (letters, digits, '-' and '.'): "999.1.1.1" is
    neither (it was refused as "a non-local bind", which sent the user after a token)."""
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        pass
    if ":" in host or host.replace(".", "").isdigit():
        return False
    return all(part and len(part) <= 63 and part.replace("-", "").isalnum()
               and part.isascii() for part in host.split("."))


#: the shortest token a non-local bind takes, and the example file's placeholder's words
OPEN_TOKEN_MIN = 16
PLACEHOLDER = "change-me"


def open_bind_problem(cfg: HttpConfig) -> str | None:
    """The reason a configuration must be refused (a non-local bind without a token), or
    None.  The config checker calls this; :class:`WebServer` refuses to start on it too."""
    try:
        host, _ = split_listen(cfg.listen)
    except ValueError as exc:
        return str(exc)
    if not is_local(host) and not cfg.token:
        return (f"http listen {cfg.listen}: a non-local bind needs a token (anyone on the "
                "network could watch the station); set http.token or listen on 127.0.0.1")
    if not is_local(host) and cfg.token and (len(cfg.token) < OPEN_TOKEN_MIN
                                             or PLACEHOLDER in cfg.token):
        return (f"a non-local bind ({cfg.listen}) needs a token of at least "
                f"{OPEN_TOKEN_MIN} characters that is not the example's (anyone on the "
                "network may guess it); make one with `openssl rand -hex 16`")
    return None


def check_http(cfg: HttpConfig) -> None:
    """Raise :class:`ConfigError` when :func:`open_bind_problem` finds one."""
    problem = open_bind_problem(cfg)
    if problem is not None:
        raise ConfigError(problem)
