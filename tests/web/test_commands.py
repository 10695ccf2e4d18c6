"""The command route's answers over real HTTP on loopback (the screens' server in this
process): a refusal carrying a reason inside it reaches the person whole, as JSON."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from aiohttp import ClientSession, CookieJar

from stationd.access import AccessConfig, hash_password
from stationd.bus import EventBus
from stationd.reasons import Reason, Why
from stationd.station.commands import Answer, Command, Issuer, TeachPoint
from stationd.web.commands import reason_json
from stationd.web.server import WebServer
from stationd.yamlio import YamlNode
from tests.web.scenario import VIN, results_db

#: what the core answers a teach point whose localizations were too few to be steady: the
#: reason carries, inside it, what the vision missed (as ``stationd.station.teaching`` does)
MISSED = Reason(Why.NOT_LOCALIZED, per_pair=(("pair1", "left", "no purple region"),))
NOT_STEADY = Reason(Why.NOT_STEADY, count=2, needed=10, cause=MISSED, limit=40)


def test_a_reason_inside_a_reason_is_json_with_its_kind_and_words() -> None:
    got = reason_json(NOT_STEADY)
    assert json.loads(json.dumps(got)) == got
    assert got["kind"] == "not steady" and got["cause"]["kind"] == "not localized"
    assert got["cause"]["per_pair"] == [["pair1", "left", "no purple region"]]
    assert "no purple region" in got["words"] and "10" in got["words"]


def test_a_refused_teach_point_is_answered_409_with_its_reason_not_a_server_error() -> None:
    """A newcomer's teach points were all "500 Internal Server Error": the answer's reason
    held a reason with an enum inside, which the JSON encoder refused."""
    access = AccessConfig.from_node(YamlNode.parse(
        f"users:\n  ed: {{role: engineer, password: '{hash_password('pw-of-ed')}'}}\n",
        "station.yaml"))

    async def submit(command: Command, issuer: Issuer) -> Answer:
        return Answer(1, command, issuer, NOT_STEADY)

    async def main() -> tuple[int, dict[str, Any]]:
        srv = WebServer(EventBus(), listen="127.0.0.1:0")
        srv.commands.access, srv.commands.submit = access, submit
        await srv.start()
        try:
            # the session's cookie kept for a loopback address (aiohttp keeps none by default)
            async with ClientSession(cookie_jar=CookieJar(unsafe=True)) as http:
                async with http.post(srv.url + "api/login",
                                     json={"user": "ed", "password": "pw-of-ed"}) as r:
                    assert r.status == 200
                async with http.get(srv.url + "api/nonce") as r:
                    nonce = (await r.json())["nonce"]
                async with http.post(srv.url + "api/commands", json={
                        "nonce": nonce, "kind": "teach-point", "bolt": "B11"}) as r:
                    return r.status, await r.json()
        finally:
            await srv.stop()

    status, body = asyncio.run(main())
    assert status == 409 and body["accepted"] is False, body
    assert body["reason"]["kind"] == "not steady"
    assert body["reason"]["cause"]["kind"] == "not localized"
    assert "no purple region" in body["words"]
    assert isinstance(TeachPoint("B11"), Command)


def _posted_as_sam(bodies: list[dict[str, Any]]) -> tuple[list[tuple[int, str]],
                                                         list[Command]]:
    """Each body posted to ``/api/commands`` (with a fresh nonce) by sam, a supervisor
    logged in: the answers (status, text) and the commands that reached the station."""
    access = AccessConfig.from_node(YamlNode.parse(
        f"users:\n  sam: {{role: supervisor, password: '{hash_password('pw-of-sam')}'}}\n",
        "station.yaml"))
    given: list[Command] = []

    async def submit(command: Command, issuer: Issuer) -> Answer:
        given.append(command)
        return Answer(1, command, issuer)

    async def main() -> list[tuple[int, str]]:
        srv = WebServer(EventBus(), listen="127.0.0.1:0")
        srv.commands.access, srv.commands.submit = access, submit
        await srv.start()
        got = []
        try:
            async with ClientSession(cookie_jar=CookieJar(unsafe=True)) as http:
                async with http.post(srv.url + "api/login",
                                     json={"user": "sam", "password": "pw-of-sam"}) as r:
                    assert r.status == 200
                for body in bodies:
                    async with http.get(srv.url + "api/nonce") as r:
                        nonce = (await r.json())["nonce"]
                    async with http.post(srv.url + "api/commands",
                                         json={**body, "nonce": nonce}) as r:
                        got.append((r.status, (await r.text()).strip()))
        finally:
            await srv.stop()
        return got

    return asyncio.run(main()), given


def test_a_blank_vin_is_refused_as_required_not_as_too_long() -> None:
    """An operator trial: a VIN of spaces in the Reopen form was answered "vin: a text of at
    most 32 characters (required)", read as too long."""
    got, _ = _posted_as_sam([{"kind": "reopen", "vin": vin} for vin in ("   ", "V" * 40, 17)])
    assert got == [
        (400, "vin: required (empty)"),
        (400, "vin: a text of at most 32 characters (required)"),
        (400, "vin: a text of at most 32 characters (required)")]


def test_a_skip_a_release_and_a_loosen_order_are_refused_without_their_reason() -> None:
    """A quality engineer's trial: a NOK bolt released with no word of why, and a loosen
    order the same (an entered outcome needed its comment); a reopen still takes none."""
    bodies: list[dict[str, Any]] = []
    for kind, comment in (("skip", None), ("release", "  "), ("loosen", ""),
                          ("release", "joint\x01checked"), ("release", "joint checked"),
                          ("reopen", None)):
        body: dict[str, Any] = {"kind": kind, "vin": "VIN1", "bolt": "B1"}
        if comment is not None:
            body["comment"] = comment
        bodies.append(body)
    got, given = _posted_as_sam(bodies)
    why = "comment: required: say why (a skip, a release or a loosen order is kept with its reason)"
    assert got[:3] == [(400, why)] * 3
    assert got[3] == (400, "comment: printable characters only (no newline, tab or control "
                           "character)")
    assert [g[0] for g in got[4:]] == [200, 200]
    assert [type(c).__name__ for c in given] == ["ReleaseBolt", "ReopenVehicle"]


def test_the_feed_gives_each_record_the_id_the_line_keeps_it_under(tmp_path: Path) -> None:
    """After a database put back from a copy renewed its id (the forwarder does), the records
    before the renewal go to the line under the earlier id: a feed reader (an MES joining
    ``/api/feed`` to the line's rows) had the new id alone, at the top, for all."""
    sedan = results_db(tmp_path)                      # three rundowns
    old = sedan.ledger.db_id()
    new = sedan.ledger.renew_db_id(sedan.ledger.last_seq() + 1).db_id
    sedan.record_tightening(VIN, "B1", ok=True, torque_nm=50.0, tightening_id=103,
                            position_mm=(1.0, 1.0, 0.0), match_distance_mm=1.0, tilt_deg=1.0,
                            angle_deg=30.0)

    async def main() -> dict[str, Any]:
        srv = WebServer(EventBus(), sedan, listen="127.0.0.1:0")
        await srv.start()
        try:
            async with ClientSession() as http, http.get(srv.url + "api/feed") as r:
                assert r.status == 200
                return dict(await r.json())
        finally:
            await srv.stop()

    doc = asyncio.run(main())
    last = sedan.ledger.last_seq()
    assert doc["db_id"] == new and doc["last_seq"] == last
    assert {e["seq"]: e["db_id"] for e in doc["entries"] if e["kind"] == "rundown"} == {
        e["seq"]: old if e["seq"] < last else new
        for e in sedan.ledger.since(0) if e["kind"] == "rundown"}
    sedan.close()
