"""A rundown's curves in its result: the joining of curves stored after their rundown
(:class:`CurveJoin`, pure), and over OPC UA on loopback: a curve bolt's event and
GetResultById carry the torque and angle traces, decoded by a client in its own process."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from db.curves import store_curve
from stationd.bus import EventBus
from stationd.opcua.curves import CurveJoin
from stationd.opcua.model import IJT_URI, RESULT_URI, load_client_types
from stationd.opcua.results import PQ_ANGLE, PQ_TIME, PQ_TORQUE
from stationd.opcua.uatypes import ua
from stationd.station.events import ResultRecorded
from tests.db.conftest import record
from tests.opcua.test_catchup import Mes, serving_ready
from tests.opcua.test_server import (
    VIN,
    Collector,
    config,
    mes_client_reads,
    repo,
    serving,
    stopping,
)
from tests.uaclient import Client

__all__ = ["repo"]   # the fixture, shared with test_server

N = 50
TORQUE = [round(0.9 * i, 3) for i in range(N)]
ANGLE = [round(1.5 * i, 3) for i in range(N)]


def _rundown(seq: int, rid: int, tid: int | None) -> dict[str, Any]:
    return {"seq": seq, "kind": "rundown", "at": "", "record": {"id": rid, "tightening_id": tid}}


def _curve(seq: int, rid: int | None, tid: int, kind: int) -> dict[str, Any]:
    return {"seq": seq, "kind": "curve", "at": "",
            "record": {"record_id": rid, "tightening_id": tid, "trace_type": kind}}


def test_a_rundown_waits_for_the_curves_the_last_one_had_and_never_longer():
    j = CurveJoin(keep=10, wait_s=1.0)
    j.take(_rundown(1, 1, 11), 0.0, hold=False)            # before the server: history
    for k in (1, 2):
        j.take(_curve(1 + k, 1, 11, k), 0.0, hold=False)
    j.settle()
    assert j.expect == {1, 2}
    j.take(_rundown(4, 2, 12), 10.0)
    j.take(_rundown(5, 3, 13), 10.0)                       # behind the one that waits
    assert j.ready(10.1) == [] and j.holding
    assert j.take(_curve(6, 2, 12, 2), 10.2)["seq"] == 4   # its result changed
    assert j.ready(10.2) == []                             # the angle is missing still
    j.take(_curve(7, 2, 12, 1), 10.3)
    assert [e["seq"] for e in j.ready(10.3)] == [4]        # 5 waits for its own curves
    assert [c["trace_type"] for c in j.curves(2)] == [1, 2]
    assert [e["seq"] for e in j.ready(11.3)] == [5]        # none came: no more waiting
    assert j.expect == frozenset()
    j.take(_rundown(8, 4, 14), 12.0)
    assert [e["seq"] for e in j.ready(12.0)] == [8]        # at once
    j.take(_curve(9, 4, 14, 2), 12.1)                      # curves again, after the event
    assert j.expect == {2} and [c["trace_type"] for c in j.curves(4)] == [2]
    j.take(_curve(10, None, 15, 2), 12.2)                  # stored before its rundown
    j.take(_rundown(11, 5, 15), 12.3)
    assert [e["seq"] for e in j.ready(12.3)] == [11]
    assert [c["trace_type"] for c in j.curves(5)] == [2]
    assert j.curves(99) is None


def _store(repo, tid: int) -> None:
    store_curve(repo, tightening_id=tid, trace_type=2, unit="Nm", values=TORQUE,
                sample_period_s=0.002)
    store_curve(repo, tightening_id=tid, trace_type=1, unit="deg", values=ANGLE,
                sample_period_s=0.002)


def _points(result: Any) -> dict[int, tuple[str, list[float], str]]:
    """PhysicalQuantity -> (name, values, unit) of the result's first step trace."""
    trace = result.ResultContent[0].Value.Trace
    [step] = trace.StepTraces
    assert step.NumberOfTracePoints == N and step.SamplingInterval == pytest.approx(2.0)
    assert trace.ResultId == result.ResultMetaData.ResultId
    return {c.PhysicalQuantity: (c.Name, list(c.Values), c.EngineeringUnits.DisplayName.Text)
            for c in step.StepTraceContent}


def test_a_curve_bolts_event_and_get_result_by_id_carry_its_curve(repo):
    record(repo, VIN, "B1", tightening_id=1)     # a curve bolt before the server started
    _store(repo, 1)
    db_id = repo.ledger.db_id()

    async def scenario() -> dict[str, Any]:
        bus = EventBus()   # the station says each result was recorded: read at once
        srv, stop, task = await serving(config(), repo, bus=bus)
        srv.join.wait_s = 1.0   # before the server's task first runs
        loop = asyncio.get_running_loop()
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:
                await load_client_types(client)
                uris = await client.get_namespace_array()
                handler = Collector()
                sub = await client.create_subscription(20, handler)
                await sub.subscribe_events(client.nodes.server,
                                           client.get_node(ua.NodeId(1007, uris.index(IJT_URI))))
                await asyncio.sleep(0.3)

                def curve_bolt() -> None:   # the controller's order: the result, its traces
                    record(repo, VIN, "B2", tightening_id=2)
                    _store(repo, 2)
                await loop.run_in_executor(None, curve_bolt)
                await handler.wait_for(1)
                # curves stopped (the controller refuses them): one wait, then at once
                await loop.run_in_executor(None, lambda: record(repo, VIN, "B3",
                                                                tightening_id=3))
                await handler.wait_for(2)
                t0 = loop.time()
                await loop.run_in_executor(None, lambda: record(repo, VIN, "B1", ok=False,
                                                                tightening_id=4))
                bus.publish(ResultRecorded(VIN, "B1", False, 30.0, 35.0, 4))
                await handler.wait_for(3)
                out["at once s"] = loop.time() - t0
                out["events"] = handler.events
                mr = uris.index(RESULT_URI)
                rm = await (await client.nodes.objects.get_child(
                    [f"{uris.index('http://opcfoundation.org/UA/Machinery/')}:Machines",
                     f"{uris.index('urn:stationd:opcua')}:ST-07"])).get_child(
                    [f"{mr}:ResultManagement"])
                out["by id"] = await rm.call_method(f"{mr}:GetResultById",
                                                    f"{db_id}:1", ua.Int32(0))
                return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    first, second, third = (e.Result for e in out["events"])
    got = _points(first)
    assert set(got) == {PQ_TIME, PQ_TORQUE, PQ_ANGLE}
    assert got[PQ_TORQUE][0] == "Torque" and got[PQ_TORQUE][1] == pytest.approx(TORQUE)
    assert got[PQ_ANGLE][1] == pytest.approx(ANGLE) and got[PQ_ANGLE][2] == "°"
    assert got[PQ_TIME][1] == pytest.approx([0.002 * i for i in range(N)])
    [step] = first.ResultContent[0].Value.StepResults
    assert step.StepTraceId == first.ResultContent[0].Value.Trace.StepTraces[0].StepTraceId
    assert second.ResultContent[0].Value.Trace is None
    assert third.ResultContent[0].Value.Trace is None and out["at once s"] < 0.5
    _, by_id, error = out["by id"]
    assert error == 0 and _points(by_id)[PQ_TORQUE][1] == pytest.approx(TORQUE)


@pytest.mark.system   # a client in its own process
def test_a_client_in_its_own_process_decodes_the_curve(repo):
    """The trace is plain structures of the model: a client that builds its classes from the
    server's definitions (the same as for the rest of a result) decodes every point."""
    record(repo, VIN, "B2", tightening_id=7)
    _store(repo, 7)

    got = asyncio.run(mes_client_reads(repo))
    trace = {pq: (name, values) for name, pq, values in got["trace"]}
    assert trace[PQ_TORQUE][0] == "Torque" and trace[PQ_TORQUE][1] == pytest.approx(TORQUE)
    assert trace[PQ_ANGLE][1] == pytest.approx(ANGLE) and len(trace[PQ_TIME][1]) == N


def test_a_requested_result_carries_its_curve_also_when_no_longer_kept(repo):
    """RequestResults sends an old curve bolt again with its curve: read from the station's
    records when the server keeps it no more (``keep: 1``)."""
    record(repo, VIN, "B2", tightening_id=21)
    _store(repo, 21)
    record(repo, VIN, "B3", tightening_id=22)   # the one kept
    first = repo.ledger.since(0)[0]["seq"]

    async def scenario() -> list[Any]:
        srv, stop, task = await serving_ready(config(keep=1), repo)
        try:
            async with Client(srv.url) as client:
                mes = await Mes(client).open()
                await asyncio.sleep(0.3)
                assert srv.join.curves(int(repo.ledger.since(0)[0]["record"]["id"])) is None
                _, status, _ = await mes.request_results(first, first)
                assert status == 0
                await mes.events.wait_for(1)
                return mes.events.events
        finally:
            await stopping(srv, stop, task)

    [event] = asyncio.run(scenario())
    assert event.Result.ResultMetaData.SequenceNumber == first
    assert _points(event.Result)[PQ_TORQUE][1] == pytest.approx(TORQUE)
