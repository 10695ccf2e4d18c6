"""Other client stacks decoding a result event: node-opcua (an independent implementation, run
from npm where node is present) and stock asyncua.

Why: an MES is built on whatever stack its integrator knows; the station encodes per Part 6
(held by :mod:`tests.opcua.test_dictionary`), so what a stack misreads is the stack's, and
is shown here with the client-side fix (README.md, "MES clients: which stack decodes what").
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from db.kinds import NOT_TAKEN
from db.repository import Repository
from tests.db.conftest import record
from tests.opcua.test_server import VIN, config, repo, serving, stopping

__all__ = ["repo"]   # the fixture, shared with test_server

ROOT = Path(__file__).resolve().parents[2]
NODE = shutil.which("node")
NPM = shutil.which("npm")
#: the node-opcua the test installs (a version known here; newer ones may fix the bit order)
NODE_OPCUA = os.environ.get("STATIOND_NODE_OPCUA", "node-opcua@2.186.4")
#: where it is installed: beside the repository's venv, never in the repository's files
CACHE = Path(os.environ.get("STATIOND_NODE_CACHE", ROOT / ".venv" / "node-opcua"))


def node_opcua() -> Path:
    """The folder holding node-opcua (installed with npm on first use)."""
    marker = CACHE / "node_modules" / "node-opcua" / "package.json"
    if not marker.is_file():
        if NPM is None:
            pytest.skip("npm is not installed")
        CACHE.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(
            [NPM, "install", "--no-audit", "--no-fund", "--prefix", str(CACHE), NODE_OPCUA],
            capture_output=True, text=True, timeout=600, check=False)
        if done.returncode != 0:
            pytest.skip(f"npm could not install {NODE_OPCUA}: {done.stderr[-500:]}")
    return CACHE


#: what ``node_reads`` stores for a "bolt" of these names: a result of no bolt, one not read,
#: an OK not taken for a tightening (a controller event)
NO_BOLT, NOT_READ, NOT_TAKEN_ = "(unattributed)", "(unreadable)", "(not taken)"


def _recorder(repo: Repository, bolt: str, kw: dict[str, Any]) -> Callable[[], object]:
    if bolt == NO_BOLT:
        return lambda: repo.others.record_unattributed(vin=VIN, controller_vin=None, result_at=None,
                                                       **kw)
    if bolt == NOT_READ:
        return lambda: repo.others.record_unreadable(vin=VIN, controller_vin=None, result_at=None,
                                                     **kw)
    if bolt == NOT_TAKEN_:
        return lambda: repo.others.record_controller_event(
            result_type=0, what=NOT_TAKEN, vin=VIN, controller_vin=None, result_at=None, **kw)
    return lambda: record(repo, VIN, bolt, **kw)


async def node_reads(repo: Repository, bolts: list[tuple[str, dict[str, Any]]],
                     *flags: str) -> list[dict[str, Any]]:
    """The events a node-opcua client decodes while ``bolts`` (bolt, record()'s keywords)
    are recorded."""
    folder = node_opcua()
    srv, stop, task = await serving(config(), repo)
    try:
        proc = await asyncio.create_subprocess_exec(
            str(NODE), str(ROOT / "tests" / "opcua" / "node_client.mjs"), srv.url,
            str(len(bolts)), *flags, cwd=ROOT, env={**os.environ, "NODE_OPCUA_DIR": str(folder)},
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL)
        assert proc.stdout is not None
        try:
            while (line := await asyncio.wait_for(proc.stdout.readline(), 120)).strip() \
                    != b"ready":   # node-opcua logs to stdout too
                assert line, "node-opcua's client ended before it subscribed"
            loop = asyncio.get_running_loop()
            for bolt, kw in bolts:
                await loop.run_in_executor(None, _recorder(repo, bolt, kw))
            out, _ = await asyncio.wait_for(proc.communicate(), 120)
        finally:
            if proc.returncode is None:   # failed or timed out: not left running
                proc.kill()
                await proc.wait()
        assert proc.returncode == 0, out.decode()[-3000:]
        return [json.loads(x) for x in out.decode().splitlines() if x.startswith("{")]
    finally:
        await stopping(srv, stop, task)


RUNDOWNS = [("B2", {"ok": False, "torque_nm": 30.0, "tightening_id": 71}),
            ("B2", {"ok": True, "kind": "loosening", "torque_nm": 20.0, "angle_deg": 303.0,
                    "tightening_id": 72})]


@pytest.mark.system
@pytest.mark.skipif(NODE is None, reason="node is not installed")
def test_node_opcua_decodes_a_result_event_with_the_client_side_fix(repo):
    events = asyncio.run(node_reads(repo, RUNDOWNS, "--fix"))
    db_id = repo.ledger.db_id()
    assert [e["message"] for e in events] == [f"{VIN} B2: tightening NOK (controller id 71)",
                                              f"{VIN} B2: loosening OK (controller id 72)"]
    for e, seq, evaluation, assembly, tid in zip(events, (1, 2), (2, 1), (1, 2), (71, 72),
                                                 strict=True):
        assert [(kv["Key"], kv["Value"]) for kv in
                e["result"]["ResultMetaData"]["ExtendedMetaData"]] == [("TighteningId", tid)]
        meta = e["result"]["ResultMetaData"]
        assert meta["ResultId"] == f"{db_id}:{seq}"
        assert meta["SequenceNumber"] == seq
        assert meta["ResultEvaluation"] == evaluation
        assert meta["JoiningTechnology"] == "Tightening"
        assert meta["AssemblyType"] == assembly
        assert sorted([x["EntityType"], x["EntityId"]] for x in meta["AssociatedEntities"]) \
            == [[20, VIN], [23, "B2"]]
        values = e["result"]["ResultContent"][0]["OverallResultValues"]
        assert [v["Name"] for v in values] == ["Torque", "Angle"]
        # the bolt's window for the tightening; none for the loosening (its loosen program's)
        assert (values[0].get("LowLimit"), values[0].get("High")) == (
            (23.0, 27.0) if assembly == 1 else (None, None))
    assert [v["MeasuredValue"] for v in
            events[1]["result"]["ResultContent"][0]["OverallResultValues"]] == [20.0, 303.0]


@pytest.mark.system
@pytest.mark.skipif(NODE is None, reason="node is not installed")
def test_a_node_opcua_mes_filtering_of_type_result_ready_gets_every_result(repo):
    """An MES integrator's trial: node-opcua's ``ofType(JoiningSystemResultReadyEventType)``
    where clause, as the README tells an MES to subscribe, got no event (the server matched
    the type named alone; the station fires its subtype).  Part 4: the type or a subtype."""
    events = asyncio.run(node_reads(repo, RUNDOWNS, "--fix", "--of-type"))
    assert [e["message"] for e in events] == [f"{VIN} B2: tightening NOK (controller id 71)",
                                              f"{VIN} B2: loosening OK (controller id 72)"]


@pytest.mark.system
@pytest.mark.skipif(NODE is None, reason="node is not installed")
def test_node_opcua_decodes_a_result_of_no_bolt_and_one_not_readable(repo):
    """An independent stack reads the results that are no joint's rundown as the station
    sends them: told apart by their Message, their evaluation (NotDecidable for one not
    read and an OK not taken), no Joint for one of no bolt, no values for one not read."""
    events = asyncio.run(node_reads(repo, [
        (NO_BOLT, {"tightening_id": 81, "pset": 1, "ok": True, "torque_nm": 25.0,
                   "angle_deg": 33.0, "reason": "outside a tool enable", "result_type": 1}),
        (NOT_READ, {"mid": 61, "revision": 2, "raw": "0231006100" + "x" * 40,
                    "error": "torque '00ABCD' is not a number", "bolt": "B2",
                    "tightening_id": 82, "pset": 1}),
        (NOT_TAKEN_, {"bolt": "B3", "tightening_id": 83, "pset": 1, "ok": True,
                      "torque_nm": 4.97, "angle_deg": 30.0})], "--fix"))
    assert [e["message"] for e in events] == [
        f"{VIN}: tightening OK of no bolt (controller id 81)",
        f"{VIN} B2: result not readable (controller id 82): held for a supervisor",
        f"{VIN} B3: OK not taken for a tightening (controller id 83): held for a supervisor"]
    loose, unread, not_taken = (e["result"]["ResultMetaData"] for e in events)
    assert (loose["ResultEvaluation"], unread["ResultEvaluation"],
            not_taken["ResultEvaluation"]) == (1, 3, 3)
    assert sorted([x["EntityType"], x["EntityId"]] for x in not_taken["AssociatedEntities"]) \
        == [[20, VIN], [23, "B3"]]
    assert [(v["MeasuredValue"], v["ResultEvaluation"]) for v in
            events[2]["result"]["ResultContent"][0]["OverallResultValues"]] == [(4.97, 3),
                                                                                (30.0, 3)]
    assert [[x["EntityType"], x["EntityId"]] for x in loose["AssociatedEntities"]] == \
        [[20, VIN]]
    assert sorted([x["EntityType"], x["EntityId"]] for x in unread["AssociatedEntities"]) \
        == [[20, VIN], [23, "B2"]]
    values = events[0]["result"]["ResultContent"][0]["OverallResultValues"]
    assert [(v["Name"], v["MeasuredValue"]) for v in values] == [("Torque", 25.0),
                                                                 ("Angle", 33.0)]
    assert not events[1]["result"]["ResultContent"][0].get("OverallResultValues")


@pytest.mark.system
@pytest.mark.skipif(NODE is None, reason="node is not installed")
def test_a_node_opcua_mes_gets_results_again_after_the_server_restarts(repo):
    """A reload restarts the OPC UA server on the same endpoint: node-opcua's own recovery
    (reconnect, a new session, its subscription made again) brings the next results.  (It
    asks the new server to republish its old messages first; answered Good and empty, it
    asked again for ever and received nothing more.)"""
    cfg = config()

    async def scenario() -> list[str]:
        folder = node_opcua()
        srv, stop, task = await serving(cfg, repo)
        proc = await asyncio.create_subprocess_exec(
            str(NODE), str(ROOT / "tests" / "opcua" / "node_client.mjs"), srv.url, "2",
            "--reconnect", cwd=ROOT, env={**os.environ, "NODE_OPCUA_DIR": str(folder)},
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL)
        out = proc.stdout
        assert out is not None
        loop = asyncio.get_running_loop()

        async def next_event() -> str:
            while not (line := await asyncio.wait_for(out.readline(), 120)) \
                    .startswith(b"{"):       # node-opcua logs to stdout too
                assert line, "node-opcua's client ended"
            return str(json.loads(line)["message"])

        try:
            while (line := await asyncio.wait_for(out.readline(), 120)).strip() != b"ready":
                assert line, "node-opcua's client ended before it subscribed"
            await loop.run_in_executor(None, _recorder(repo, "B1", {"ok": True}))
            messages = [await next_event()]
            await stopping(srv, stop, task)
            srv, stop, task = await serving(cfg, repo)
            # results fired before the client has subscribed again reach no one (events
            # are not kept for a subscription that is gone): one each second until one does
            waiting = asyncio.ensure_future(next_event())
            for _ in range(60):
                await loop.run_in_executor(None, _recorder(repo, "B3", {"ok": True}))
                done, _ = await asyncio.wait({waiting}, timeout=1.0)
                if done:
                    break
            messages.append(await asyncio.wait_for(waiting, 5))
            await asyncio.wait_for(proc.wait(), 60)
            return messages
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
            await stopping(srv, stop, task)

    messages = asyncio.run(scenario())
    assert messages[0] == f"{VIN} B1: tightening OK"
    assert messages[1].startswith(f"{VIN} B3: tightening OK")
