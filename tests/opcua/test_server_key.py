"""The OPC UA server's private key, made at its first start in ``opcua.certificates``, is
readable by its owner alone, whatever the umask (the unit's ``UMask=0027`` let the
``stationd`` group read it, the group an engineer joins to read the database; a daemon run by
hand, ``0022``, let every user of the station PC read it).  A key an earlier release left
readable is made so at the next start.  No server is started: ``_security`` is given a
stand-in for asyncua's."""

from __future__ import annotations

import asyncio
import os
import stat
from pathlib import Path
from typing import Any

from stationd.opcua import OpcUaConfig
from stationd.opcua.server import OpcUaServer


class StandIn:
    """What ``_security`` asks of asyncua's server."""

    def __init__(self) -> None:
        self.key: str | None = None

    def set_security_policy(self, *a: Any, **kw: Any) -> None:
        pass

    def set_identity_tokens(self, *a: Any) -> None:
        pass

    async def load_certificate(self, path: str) -> None:
        pass

    async def load_private_key(self, path: str) -> None:
        self.key = path

    def set_certificate_validator(self, *a: Any) -> None:
        pass


def _secure(pki: Path) -> StandIn:
    cfg = OpcUaConfig(endpoint="opc.tcp://127.0.0.1:4840", station_id="ST-07",
                      security=("none", "sign"), certificates=pki)
    server = StandIn()
    asyncio.run(OpcUaServer(cfg)._security(server))  # type: ignore[arg-type]
    return server


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_the_servers_private_key_is_its_owners_alone_whatever_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        server = _secure(tmp_path / "pki")
    finally:
        os.umask(old)
    key = tmp_path / "pki" / "server-key.pem"
    assert server.key == str(key) and key.read_bytes().startswith(b"-----BEGIN")
    assert _mode(key) == 0o600, oct(_mode(key))


def test_a_key_an_earlier_start_left_readable_is_made_the_owners_alone(tmp_path: Path) -> None:
    _secure(tmp_path / "pki")
    key = tmp_path / "pki" / "server-key.pem"
    before = key.read_bytes()
    key.chmod(0o644)
    _secure(tmp_path / "pki")
    assert key.read_bytes() == before           # the same key: the MES trusts its certificate
    assert _mode(key) == 0o600, oct(_mode(key))
