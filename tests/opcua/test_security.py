"""Who may do what on the station's OPC UA server, over real OPC UA on loopback: anonymous
clients read and ask for results again but never acknowledge; a configured user with the right
password acknowledges, a wrong password is refused; Basic256Sha256 Sign and SignAndEncrypt
sessions with client certificates made here, one in the trust list (accepted), one not
(refused)."""

from __future__ import annotations

import asyncio
import shutil
from pathlib import Path
from typing import Any

import pytest
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

from stationd.access import hash_password
from stationd.opcua.catchup import OK
from stationd.opcua.model import IJT_URI, MACHINERY_URI, RESULT_URI
from stationd.opcua.server import NAMESPACE
from stationd.opcua.uatypes import ua
from tests.db.conftest import record
from tests.opcua.test_server import VIN, config, repo, serving, stopping
from tests.uaclient import Client

__all__ = ["repo"]   # the fixture, shared with test_server

USERS = {"mes": hash_password("s3cret")}


async def _result_management(client: Client) -> tuple[Any, int, int]:
    uris = await client.get_namespace_array()
    js = await client.nodes.objects.get_child([f"{uris.index(MACHINERY_URI)}:Machines",
                                               f"{uris.index(NAMESPACE)}:ST-07"])
    mr = uris.index(RESULT_URI)
    return await js.get_child([f"{mr}:ResultManagement"]), mr, uris.index(IJT_URI)


async def _who_may_call(url: str, user: str | None, password: str | None,
                        result_id: str) -> dict[str, str]:
    """What each method answers this client: its Status (or Error) or the refusal's name."""
    client = Client(url)
    if user is not None:
        client.set_user(user)
        client.set_password(password or "")
    out: dict[str, str] = {}
    async with client:
        rm, mr, ijt = await _result_management(client)
        calls = {
            "GetLatestResult": (f"{mr}:GetLatestResult", ua.Int32(0)),
            "RequestResults": (f"{ijt}:RequestResults", ua.Variant(1, ua.VariantType.UInt64),
                               ua.Variant(1, ua.VariantType.UInt64),
                               ua.Variant(None, ua.VariantType.Null),
                               ua.Variant(None, ua.VariantType.Null), 0.0),
            "RequestUnacknowledgedResults": (f"{ijt}:RequestUnacknowledgedResults",
                                             ua.Variant(1, ua.VariantType.UInt32), 0.0),
            "AcknowledgeResults": (f"{mr}:AcknowledgeResults",
                                   ua.Variant([result_id], ua.VariantType.String)),
        }
        for name, (method, *args) in calls.items():
            try:
                answer = await rm.call_method(method, *args)
            except ua.UaStatusCodeError as exc:
                out[name] = type(exc).__name__
                continue
            # the Status (Request*) or Error (the others) is the last but one or the last
            status = answer[-2] if name.startswith("Request") else answer[-1]
            out[name] = "OK" if status == OK else f"status {status}"
    return out


def test_anonymous_reads_and_asks_again_a_user_acknowledges_a_wrong_password_is_refused(repo):
    record(repo, VIN, "B1", ok=True)
    rid = f"{repo.ledger.db_id()}:1"

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving(config(users=USERS), repo)
        try:
            while srv.cursor < 1:     # the recorded result loaded for GetLatestResult
                await asyncio.sleep(0.05)
            out: dict[str, Any] = {
                "anonymous": await _who_may_call(srv.url, None, None, rid),
                "mes": await _who_may_call(srv.url, "mes", "s3cret", rid)}
            for who, password in (("mes", "guess"), ("nobody", "s3cret")):
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await _who_may_call(srv.url, who, password, rid)
                out[f"{who}/{password}"] = type(refused.value).__name__
            await srv.catchup.idle()
            return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["anonymous"] == {"GetLatestResult": "OK", "RequestResults": "OK",
                                "RequestUnacknowledgedResults": "OK",
                                "AcknowledgeResults": "BadUserAccessDenied"}
    assert out["mes"] == {"GetLatestResult": "OK", "RequestResults": "OK",
                          "RequestUnacknowledgedResults": "OK", "AcknowledgeResults": "OK"}
    for key in ("mes/guess", "nobody/s3cret"):
        assert out[key] in ("BadUserAccessDenied", "BadIdentityTokenRejected",
                            "BadIdentityTokenInvalid"), out
    assert repo.ledger.unacknowledged_count() == 0      # the user's acknowledgement, stored


async def _certificate(folder: Path, name: str) -> tuple[Path, Path, str]:
    """A client's key and self-signed certificate (as an MES would make its own)."""
    key, cert, uri = folder / f"{name}-key.pem", folder / f"{name}-cert.der", f"urn:test:{name}"
    await setup_self_signed_certificate(
        key, cert, uri, "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH],
        {"commonName": name, "organizationName": "test"})
    return key, cert, uri


async def _secure_session(url: str, server_cert: Path, key: Path, cert: Path, uri: str,
                          mode: ua.MessageSecurityMode) -> str:
    """Connect with ``mode``, log in as the user, acknowledge nothing: what the server said."""
    client = Client(url)
    client.application_uri = uri
    client.set_user("mes")
    client.set_password("s3cret")
    await client.set_security(SecurityPolicyBasic256Sha256, str(cert), str(key),
                              server_certificate=str(server_cert), mode=mode)
    try:
        async with client:
            rm, mr, _ = await _result_management(client)
            _, error = await rm.call_method(f"{mr}:AcknowledgeResults",
                                            ua.Variant([], ua.VariantType.String))
            policy = client.security_policy.URI.rsplit("#", 1)[-1]
            return f"{policy} {ua.MessageSecurityMode(client.security_policy.Mode).name} " \
                f"error {error}"
    except (ua.UaError, OSError, TimeoutError) as exc:
        return type(exc).__name__


def test_signed_and_encrypted_sessions_need_a_trusted_client_certificate(repo, tmp_path,
                                                                        caplog):
    """Only Sign and SignAndEncrypt offered: a client whose certificate is in the trust list
    connects in both modes; one whose certificate is not is refused in both (a journal line,
    no traceback); without security nothing is offered."""
    pki, mine = tmp_path / "pki", tmp_path / "clients"
    mine.mkdir()
    cfg = config(users=USERS, certificates=pki)
    cfg = type(cfg)(cfg.endpoint, cfg.station_id, ("sign", "encrypt"), pki, USERS, cfg.keep)

    async def scenario() -> dict[str, str]:
        trusted = await _certificate(mine, "mes")
        stranger = await _certificate(mine, "stranger")
        (pki / "trusted").mkdir(parents=True)
        shutil.copy(trusted[1], pki / "trusted" / "mes.der")
        srv, stop, task = await serving(cfg, repo)
        out: dict[str, str] = {}
        try:
            server_cert = pki / "server-cert.der"
            for mode in (ua.MessageSecurityMode.Sign, ua.MessageSecurityMode.SignAndEncrypt):
                out[f"trusted {mode.name}"] = await _secure_session(
                    srv.url, server_cert, *trusted, mode)
                out[f"stranger {mode.name}"] = await _secure_session(
                    srv.url, server_cert, *stranger, mode)
            try:
                async with Client(srv.url) as client:
                    await client.get_namespace_array()
                out["none"] = "connected"
            except (ua.UaError, OSError, TimeoutError) as exc:
                out["none"] = type(exc).__name__
            return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["trusted Sign"] == "Basic256Sha256 Sign error 0", out
    assert out["trusted SignAndEncrypt"] == "Basic256Sha256 SignAndEncrypt error 0", out
    assert out["stranger Sign"] == "BadCertificateUntrusted", out
    assert out["stranger SignAndEncrypt"] == "BadCertificateUntrusted", out
    assert out["none"] != "connected", out
    untrusted = [r for r in caplog.records if "Not trusted certificate" in r.getMessage()]
    assert untrusted and not any(r.exc_info for r in untrusted)
