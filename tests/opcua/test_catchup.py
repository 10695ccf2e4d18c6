"""An MES that was away catches up over real OPC UA on loopback: RequestResults from a
sequence number, RequestUnacknowledgedResults and AcknowledgeResults (OPC 40450-1 1.01), the
acknowledgements kept in the station's database across a restart of the server."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from asyncua.common.node import Node

from db.repository import Repository
from stationd.access import hash_password
from stationd.opcua import OpcUaConfig, catchup
from stationd.opcua.catchup import (
    BAD_ARGUMENTS,
    MAX_INTERVAL_MS,
    MIN_INTERVAL_MS,
    OK,
    UNKNOWN_RESULT,
)
from stationd.opcua.model import IJT_URI, MACHINERY_URI, RESULT_URI, load_client_types
from stationd.opcua.server import NAMESPACE
from stationd.opcua.uatypes import ua
from tests.db.conftest import record
from tests.opcua.test_server import VIN, Collector, config, repo, serving, stopping
from tests.uaclient import Client

__all__ = ["repo"]   # the fixture, shared with test_server

USERS = {"mes": hash_password("s3cret")}
BOLTS = ("B1", "B2", "B3")
NULL_TIME = datetime(1601, 1, 1, tzinfo=UTC)   # a null UtcTime: encoded as 0


async def serving_ready(cfg: OpcUaConfig, repo: Repository) -> Any:
    """The server, once it has read the station's records (the methods answer "not ready"
    for the moment before)."""
    srv, stop, task = await serving(cfg, repo)
    while srv.catchup.repo is None or srv.cursor < repo.ledger.last_seq():
        await asyncio.sleep(0.05)
    return srv, stop, task


def _asked(repo: Repository, body: Callable[[Mes, dict[str, Any]], Awaitable[None]]
           ) -> dict[str, Any]:
    """``body`` run as an MES's session on the station's server (the results recorded so
    far published first): what it put in its ``out``."""
    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving_ready(config(), repo)
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:
                await body(await Mes(client).open(), out)
        finally:
            await stopping(srv, stop, task)
        return out

    return asyncio.run(scenario())


def _record(repo: Repository, n: int) -> None:
    for i in range(n):
        record(repo, VIN, BOLTS[i % len(BOLTS)], ok=i % 4 != 3)


class Mes:
    """An MES's session: the ResultManagement, a subscription to result events at the
    Server object, and the methods as an MES calls them."""

    def __init__(self, client: Client) -> None:
        self.client = client
        self.events = Collector()

    async def open(self) -> Mes:
        await load_client_types(self.client)
        uris = await self.client.get_namespace_array()
        self.ijt, self.mr = uris.index(IJT_URI), uris.index(RESULT_URI)
        machines = await self.client.nodes.objects.get_child(
            [f"{uris.index(MACHINERY_URI)}:Machines"])
        js = await machines.get_child([f"{uris.index(NAMESPACE)}:ST-07"])
        self.rm: Node = await js.get_child([f"{self.mr}:ResultManagement"])
        # the server's concrete RequestedResultEventType: requested, not live, results
        requested = self.client.get_node(ua.NodeId(1035, self.ijt))
        self.requested_types = {c.nodeid for c in await requested.get_children(
            refs=ua.ObjectIds.HasSubtype)}
        sub = await self.client.create_subscription(20, self.events)
        await sub.subscribe_events(self.client.nodes.server,
                                   self.client.get_node(ua.NodeId(1007, self.ijt)))
        return self

    async def request_results(self, first: int, last: int, interval_ms: float = 0.0,
                              t0: datetime | None = None, t1: datetime | None = None) -> Any:
        return await self.rm.call_method(
            f"{self.ijt}:RequestResults", ua.Variant(first, ua.VariantType.UInt64),
            ua.Variant(last, ua.VariantType.UInt64),
            ua.Variant(t0 or NULL_TIME, ua.VariantType.DateTime),
            ua.Variant(t1 or NULL_TIME, ua.VariantType.DateTime),
            ua.Variant(interval_ms, ua.VariantType.Double))

    async def request_unacknowledged(self, most: int = 0) -> Any:
        return await self.rm.call_method(
            f"{self.ijt}:RequestUnacknowledgedResults", ua.Variant(most, ua.VariantType.UInt32),
            ua.Variant(0.0, ua.VariantType.Double))

    async def acknowledge(self, ids: list[str]) -> Any:
        return await self.rm.call_method(f"{self.mr}:AcknowledgeResults",
                                          ua.Variant(ids, ua.VariantType.String))

    def requested(self) -> list[Any]:
        """The requested results received so far (not the live ones), by sequence number."""
        return [e.Result.ResultMetaData.SequenceNumber for e in self.events.events
                if e.EventType in self.requested_types]

    async def wait_requested(self, n: int, timeout: float = 60.0) -> list[int]:
        async def enough() -> None:
            while len(self.requested()) < n:
                await asyncio.sleep(0.02)
        await asyncio.wait_for(enough(), timeout)
        await asyncio.sleep(0.2)   # and no more than asked for
        return self.requested()


def test_a_client_that_missed_events_catches_up_with_request_results(repo):
    """Connected, then away while rundowns are recorded, then back: RequestResults from the
    sequence number after the last one it got sends exactly the missed ones, in order, as
    requested-result events that decode as results."""
    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving_ready(config(), repo)
        loop = asyncio.get_running_loop()
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:
                mes = await Mes(client).open()
                at_rm = Collector()      # the ResultManagement is an event notifier too
                sub = await client.create_subscription(20, at_rm)
                await sub.subscribe_events(mes.rm, client.get_node(ua.NodeId(1007, mes.ijt)))
                await asyncio.sleep(0.2)
                await loop.run_in_executor(None, _record, repo, 2)
                await mes.events.wait_for(2)
                await at_rm.wait_for(2)
                out["live"] = [e.Result.ResultMetaData.SequenceNumber for e in mes.events.events]
                out["at_rm"] = [e.Result.ResultMetaData.SequenceNumber for e in at_rm.events]
            await loop.run_in_executor(None, _record, repo, 5)     # missed: nobody listens
            async with Client(srv.url) as client:
                mes = await Mes(client).open()
                last = max(out["live"])
                revised, status, text = await mes.request_results(last + 1, 10**6)
                out["answer"] = (revised, status, text.Text)
                out["got"] = await mes.wait_requested(5)
                out["event"] = next(e for e in mes.events.events
                                    if e.EventType in mes.requested_types)
                # Results/RequestedResult holds the last result sent again
                requested = await mes.rm.get_child([f"{mes.mr}:Results",
                                                    f"{mes.ijt}:RequestedResult"])
                out["variable"] = await requested.read_data_value()
                out["bad"] = await mes.request_results(5, 2)
                out["half"] = await mes.request_results(0, 3)
        finally:
            await stopping(srv, stop, task)
        return out

    out = asyncio.run(scenario())
    seqs = [e["seq"] for e in repo.ledger.since(0) if e["kind"] == "rundown"]
    assert out["live"] == out["at_rm"] == seqs[:2]
    revised, status, text = out["answer"]
    assert status == OK and revised >= MIN_INTERVAL_MS and "sent" in text
    assert out["got"] == seqs[2:]
    meta = out["event"].Result.ResultMetaData
    assert meta.ResultId == f"{repo.ledger.db_id()}:{seqs[2]}"
    assert out["event"].SourceName == "ST-07"
    assert {(x.EntityType, x.EntityId) for x in meta.AssociatedEntities} == {(20, VIN),
                                                                            (23, "B1")}
    assert out["bad"][1] == BAD_ARGUMENTS and out["half"][1] == BAD_ARGUMENTS
    variable = out["variable"]
    assert variable.Value.Value.ResultMetaData.SequenceNumber == seqs[-1]
    assert variable.SourceTimestamp is not None


def test_request_results_by_time_and_a_paced_range(repo):
    """A time range (sequence numbers 0) and a range of sequence numbers with a requested
    interval: the results in it, no other, at least that far apart."""
    _record(repo, 6)
    seqs = [e["seq"] for e in repo.ledger.since(0) if e["kind"] == "rundown"]

    async def body(mes: Mes, out: dict[str, Any]) -> None:
        now = datetime.now(UTC)
        out["future"] = await mes.request_results(0, 0, t0=now + timedelta(hours=1))
        out["time"] = await mes.request_results(0, 0, t0=now - timedelta(hours=1),
                                                t1=now + timedelta(minutes=1))
        out["by_time"] = list(await mes.wait_requested(6))
        mes.events.events.clear()
        started = asyncio.get_running_loop().time()
        out["paced"] = await mes.request_results(seqs[1], seqs[3], interval_ms=100.0)
        out["range"] = await mes.wait_requested(3)
        out["took"] = asyncio.get_running_loop().time() - started

    out = _asked(repo, body)
    assert out["future"][1] == OK
    assert out["by_time"] == seqs          # the future range sent nothing
    assert out["paced"][0] == pytest.approx(100.0)
    assert out["range"] == seqs[1:4]
    assert out["took"] >= 0.19             # two gaps of 100 ms between three results


def test_a_request_says_how_many_results_it_sends_and_arguments_are_counted(repo):
    """An MES integrator's trial: RequestResults for numbers past the last answered "the
    results ... are sent as events" and nothing came; RequestResults with no argument was
    answered Good and sent every result from the first; GetResultById without its Timeout
    was Good.  The answer counts what it sends (none said as none, with the last number so
    far); a call with fewer arguments than its method declares is BadArgumentsMissing, with
    more BadTooManyArguments (Part 4), and sends nothing."""
    _record(repo, 3)
    seqs = [e["seq"] for e in repo.ledger.since(0) if e["kind"] == "rundown"]

    async def body(mes: Mes, out: dict[str, Any]) -> None:
        out["past"] = await mes.request_results(10**8, 10**8)
        out["two"] = await mes.request_results(seqs[1], 10**6)
        out["sent"] = await mes.wait_requested(2)
        calls: dict[str, tuple[Any, ...]] = {
            "none": (f"{mes.ijt}:RequestResults",),
            "by id alone": (f"{mes.mr}:GetResultById", "x:1"),
            "by id and more": (f"{mes.mr}:GetResultById", "x:1",
                               ua.Variant(0, ua.VariantType.Int32), 7)}
        for name, (method, *args) in calls.items():
            try:
                await mes.rm.call_method(str(method), *args)
                out[name] = "Good"
            except ua.UaStatusCodeError as exc:
                out[name] = type(exc).__name__
        await asyncio.sleep(0.5)
        out["after"] = mes.requested()

    out = _asked(repo, body)
    last = repo.ledger.last_seq()
    assert out["past"][1] == OK and out["past"][2].Text == (
        f"no result with sequence numbers {10**8} to {10**8}: none is sent (the last "
        f"sequence number so far: {last})")
    assert out["two"][1] == OK and out["two"][2].Text.startswith(
        f"2 of the 2 results with sequence numbers {seqs[1]} to {10**6} are sent as events")
    assert out["sent"] == seqs[1:]
    assert (out["none"], out["by id alone"], out["by id and more"]) == (
        "BadArgumentsMissing", "BadArgumentsMissing", "BadTooManyArguments")
    assert out["after"] == seqs[1:]      # the refused call sent nothing


def test_no_request_holds_the_queue_for_long(repo, monkeypatch):
    """An anonymous client asks with an infinite interval: it is revised to the maximum, and
    a request sends at most MAX_PER_REQUEST results, so the next client is served (an
    infinite interval held the queue until the server stopped)."""
    _record(repo, 6)
    seqs = [e["seq"] for e in repo.ledger.since(0) if e["kind"] == "rundown"]
    monkeypatch.setattr(catchup, "MAX_PER_REQUEST", 2)

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving_ready(config(), repo)
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as hog, Client(srv.url) as client:
                await load_client_types(hog)
                greedy = await Mes(hog).open()
                mes = await Mes(client).open()
                out["greedy"] = await greedy.request_results(seqs[0], seqs[-1],
                                                             interval_ms=float("inf"))
                out["next"] = await mes.request_results(seqs[3], seqs[5])
                # events go to every subscriber: the greedy request's, then this one's
                out["got"] = await mes.wait_requested(4, timeout=5.0)
        finally:
            await stopping(srv, stop, task)
        return out

    out = asyncio.run(scenario())
    assert out["greedy"][0] == pytest.approx(MAX_INTERVAL_MS) and out["greedy"][1] == OK
    assert "at most 2 per request" in out["greedy"][2].Text
    assert out["next"][1] == OK
    assert out["got"] == seqs[0:2] + seqs[3:5]    # no more than the bound each, both served


def test_acknowledged_results_are_no_longer_unacknowledged_also_after_a_restart(repo):
    """A user acknowledges two results (one id unknown): RequestUnacknowledgedResults counts
    and sends the others, also from a new server on the same database; MaxResults bounds it."""
    _record(repo, 5)
    db_id = repo.ledger.db_id()
    seqs = [e["seq"] for e in repo.ledger.since(0) if e["kind"] == "rundown"]
    cfg = config(users=USERS)

    def user_client(url: str) -> Client:
        c = Client(url)
        c.set_user("mes")
        c.set_password("s3cret")
        return c

    async def first_run() -> dict[str, Any]:
        srv, stop, task = await serving_ready(cfg, repo)
        out: dict[str, Any] = {}
        try:
            async with user_client(srv.url) as client:
                mes = await Mes(client).open()
                _, count, status, _ = await mes.request_unacknowledged()
                out["before"] = (count, status, await mes.wait_requested(5))
                mes.events.events.clear()
                out["ack"] = await mes.acknowledge([f"{db_id}:{seqs[0]}", f"{db_id}:{seqs[2]}",
                                                    "other-db:1"])
                out["again"] = await mes.acknowledge([f"{db_id}:{seqs[0]}"])
                out["empty"] = await mes.acknowledge([])
                _, count, status, _ = await mes.request_unacknowledged()
                out["after"] = (count, status, await mes.wait_requested(3))
        finally:
            await stopping(srv, stop, task)
        return out

    async def second_run() -> dict[str, Any]:
        srv, stop, task = await serving_ready(config(users=USERS), repo)
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:      # anonymous: may ask, not acknowledge
                mes = await Mes(client).open()
                _, count, status, _ = await mes.request_unacknowledged(most=2)
                out["restarted"] = (count, status, await mes.wait_requested(2))
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await mes.acknowledge([f"{db_id}:{seqs[1]}"])
                out["anonymous"] = type(refused.value).__name__
        finally:
            await stopping(srv, stop, task)
        return out

    first = asyncio.run(first_run())
    assert first["before"] == (5, OK, seqs)
    per_id, error = first["ack"]
    assert per_id == [OK, OK, UNKNOWN_RESULT] and error == UNKNOWN_RESULT
    assert first["again"] == [[], OK]
    assert first["empty"] == [[], OK]
    assert first["after"] == (3, OK, [seqs[1], seqs[3], seqs[4]])
    second = asyncio.run(second_run())
    assert second["restarted"] == (3, OK, [seqs[1], seqs[3]])
    assert second["anonymous"] == "BadUserAccessDenied"
    assert repo.ledger.unacknowledged_count() == 3


def test_after_a_database_put_back_each_result_keeps_the_id_the_line_keeps_it_under(repo):
    """An MES integrator's join: the line keeps a database's records below a renewal of its
    id (a backup put back: :meth:`db.ledger.Ledger.renew_db_id`) under the earlier id, the
    rest under the new one.  OPC UA gave every result the id it read at its start, so an
    MES joining ResultId to the line's rows found none for the records after the renewal
    (nor, after a restart, for those before).  The renewal made while the server runs (as
    the forwarder makes it): new results, the kept ones, GetResultById and
    AcknowledgeResults all go by each record's own id."""
    _record(repo, 2)
    old = repo.ledger.db_id()
    before = [e["seq"] for e in repo.ledger.since(0) if e["kind"] == "rundown"]
    cfg = config(users=USERS)

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving_ready(cfg, repo)
        loop = asyncio.get_running_loop()
        out: dict[str, Any] = {}
        try:
            c = Client(srv.url)
            c.set_user("mes")
            c.set_password("s3cret")
            async with c as client:
                mes = await Mes(client).open()
                await asyncio.sleep(0.2)
                series = await loop.run_in_executor(
                    None, repo.ledger.renew_db_id, repo.ledger.last_seq() + 1)
                out["new"] = series.db_id
                await loop.run_in_executor(None, _record, repo, 2)
                await mes.events.wait_for(2)
                out["live"] = [e.Result.ResultMetaData.ResultId for e in mes.events.events]
                after = [e["seq"] for e in repo.ledger.since(before[-1])
                         if e["kind"] == "rundown"]
                out["after"] = after
                out["by_old"] = await mes.rm.call_method(f"{mes.mr}:GetResultById",
                                                         f"{old}:{before[0]}", ua.Int32(0))
                out["by_new"] = await mes.rm.call_method(
                    f"{mes.mr}:GetResultById", f"{series.db_id}:{after[0]}", ua.Int32(0))
                out["ack"] = await mes.acknowledge([
                    f"{old}:{before[0]}", f"{series.db_id}:{after[0]}",
                    f"{series.db_id}:{before[1]}", f"{old}:{after[1]}"])
        finally:
            await stopping(srv, stop, task)
        return out

    out = asyncio.run(scenario())
    new, after = out["new"], out["after"]
    assert out["live"] == [f"{new}:{s}" for s in after]
    assert out["by_old"][1].ResultMetaData.ResultId == f"{old}:{before[0]}"
    assert out["by_new"][1].ResultMetaData.ResultId == f"{new}:{after[0]}"
    per_id, _ = out["ack"]
    assert per_id == [OK, OK, UNKNOWN_RESULT, UNKNOWN_RESULT]
