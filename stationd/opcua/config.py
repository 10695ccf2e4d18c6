"""The ``opcua:`` section of the station file (optional: without it no OPC UA server runs)::

    opcua:
      endpoint: opc.tcp://0.0.0.0:4840
      station_id: ST-07                  # the JoiningSystem's SystemId and name
      security: [none, sign, encrypt]    # the default: None and Basic256Sha256 Sign, SignAndEncrypt
      certificates: /var/lib/stationd/opcua   # the server's key and certificate (made on first
                                              # start) and trusted/ (the clients' certificates)
      users:                             # user tokens (scrypt hashes: ``stationd user hash``)
        mes: "scrypt$16384$8$1$<salt>$<key>"
      keep: 1000                         # results kept for GetLatestResult / GetResultById
      anonymous: true                    # false: only the users above (the default: true)

Secure by default: anonymous clients may browse, read, subscribe and call the methods that only
read (GetLatestResult, GetResultById, RequestResults, RequestUnacknowledgedResults); only a user
of this section may call AcknowledgeResults; nobody may write a variable or change the address
space; a user name is accepted only with its password's hash in this section (with
``anonymous: false``, nobody else: the results carry VINs and operators' names); with ``sign`` or
``encrypt`` offered, a client's certificate must be in ``certificates/trusted`` (the server's
own certificate is generated there on first start, one year valid).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlparse

from stationd.access import parse_hash
from stationd.configread import is_local
from stationd.yamlio import YamlNode

SECURITY = ("none", "sign", "encrypt")


@dataclass(frozen=True)
class OpcUaConfig:
    endpoint: str = "opc.tcp://0.0.0.0:4840"
    station_id: str = "stationd"
    security: tuple[str, ...] = SECURITY
    certificates: Path | None = None
    users: dict[str, str] = field(default_factory=dict)
    keep: int = 1000
    anonymous: bool = True

    @property
    def on_loopback(self) -> bool:
        """Whether the endpoint listens on this machine's loopback only."""
        return is_local(urlparse(self.endpoint).hostname or "")

    @classmethod
    def from_node(cls, node: YamlNode, base_dir: Path | None = None) -> OpcUaConfig:
        m = node.mapping(("endpoint", "station_id", "security", "certificates", "users", "keep",
                          "anonymous"))
        d = cls()
        endpoint = m["endpoint"].text() if "endpoint" in m else d.endpoint
        url = urlparse(endpoint)
        try:
            port = url.port
        except ValueError:
            port = None
        if url.scheme != "opc.tcp" or not url.hostname or port is None:
            raise m["endpoint"].error(f"not an OPC UA endpoint: {endpoint!r} "
                                      "(opc.tcp://HOST:PORT, e.g. opc.tcp://0.0.0.0:4840)")
        if port == 0:   # a port the system picks: no MES could be told where to connect
            raise m["endpoint"].error(f"{endpoint}: port 0 is any free port, which no MES "
                                      "can be told: give the port the MES connects to (4840)")
        sid = m["station_id"].text() if "station_id" in m else d.station_id
        if not 1 <= len(sid) <= 64 or not sid.isprintable():
            raise m["station_id"].error("1-64 printable characters")
        security = d.security
        if "security" in m:
            security = tuple(n.text(SECURITY) for n in m["security"].items())
            if not security:
                raise m["security"].error(f"one or more of {', '.join(SECURITY)}")
        certs = d.certificates
        if "certificates" in m:
            certs = Path(m["certificates"].text())
            if not certs.is_absolute() and base_dir is not None:
                certs = base_dir / certs
        if certs is None and security != ("none",):
            signed = [x for x in security if x != "none"]
            given = "security offers" if "security" in m else \
                "security is not given: the default offers"
            raise node.error(f"certificates: missing; {given} {' and '.join(signed)}, which "
                             f"need{'s' if len(signed) == 1 else ''} a folder "
                             "for the server's certificate (made there on first start) and "
                             "the trusted clients' (certificates/trusted): add "
                             "'certificates: /var/lib/stationd/opcua', or 'security: [none]' "
                             "for no signing or encryption")
        users: dict[str, str] = {}
        if "users" in m:
            for name, value in m["users"].pairs():
                stored = value.text(secret=True)
                try:
                    parse_hash(stored)
                except ValueError:
                    raise value.error("a password hash (stationd user hash), "
                                      "never a password") from None
                users[str(name)] = stored
        keep = m["keep"].integer(lo=1, hi=1_000_000) if "keep" in m else d.keep
        anonymous = m["anonymous"].flag() if "anonymous" in m else d.anonymous
        if not anonymous and not users:
            raise m["anonymous"].error("false with no users: no client could connect (add "
                                       "the MES's user under users)")
        return cls(endpoint, sid, security, certs, users, keep, anonymous)


__all__ = ["SECURITY", "OpcUaConfig"]
