"""The OPC UA server over real OPC UA on loopback, with an asyncua client as an MES would use it."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import sys
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest

from db.repository import Repository
from stationd.access import hash_password
from stationd.boltfile import import_bolts
from stationd.errors import ConfigError
from stationd.opcua import OpcUaConfig
from stationd.opcua.model import DI_URI, IJT_URI, MACHINERY_URI, RESULT_URI, load_client_types
from stationd.opcua.server import NAMESPACE, OpcUaServer
from stationd.opcua.uatypes import ua
from stationd.yamlio import YamlNode
from tests.db.conftest import BASE, record
from tests.uaclient import Client

VIN = "WVWZZZ1JZXW000001"
ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def repo(tmp_path: Path):
    table = tmp_path / "bolts.yaml"
    table.write_text(BASE)
    r = Repository.open(f"sqlite:///{tmp_path / 'station.db'}")
    import_bolts(r, table)
    r.start_vehicle(VIN, "SEDAN")
    yield r
    r.close()


def config(**kw: Any) -> OpcUaConfig:
    return OpcUaConfig(endpoint=f"opc.tcp://127.0.0.1:{free_port()}", station_id="ST-07",
                       security=("none",), **kw)


class Collector:
    def __init__(self) -> None:
        self.events: list[Any] = []
        self.arrived = asyncio.Event()

    def event_notification(self, event: Any) -> None:
        self.events.append(event)
        self.arrived.set()

    async def wait_for(self, n: int, timeout: float = 60.0) -> None:
        async def enough() -> None:
            while len(self.events) < n:
                self.arrived.clear()
                await self.arrived.wait()
        await asyncio.wait_for(enough(), timeout)


async def serving(cfg: OpcUaConfig, repo: Repository, **server: Any):
    """The server on ``cfg`` (``server`` go to OpcUaServer) started and running on ``repo``
    (its task has not run yet when this returns: the caller may still set the server up)."""
    srv = OpcUaServer(cfg, **server)
    await srv.start()
    stop = asyncio.Event()
    task = asyncio.create_task(srv.run(stop, repo))
    return srv, stop, task


async def stopping(srv: OpcUaServer, stop: asyncio.Event, task: asyncio.Task[None]) -> None:
    stop.set()
    await task
    await srv.stop()


async def subscribed(client: Client) -> Collector:
    """``client`` subscribed to the station's result events at the Server object: what
    arrives goes to the collector returned."""
    await load_client_types(client)
    uris = await client.get_namespace_array()
    etype = client.get_node(ua.NodeId(1007, uris.index(IJT_URI)))
    handler = Collector()
    sub = await client.create_subscription(50, handler)
    await sub.subscribe_events(client.nodes.server, etype)
    await asyncio.sleep(0.3)
    return handler


def events_while(repo: Repository, *stores: Callable[[], object],
                 events: int | None = None) -> list[Any]:
    """The result events a subscribed client gets while each of ``stores`` stores a record
    (one event each, or ``events`` in all)."""
    async def scenario() -> list[Any]:
        srv, stop, task = await serving(config(), repo)
        try:
            async with Client(srv.url) as client:
                handler = await subscribed(client)
                loop = asyncio.get_running_loop()
                for store in stores:
                    await loop.run_in_executor(None, store)
                await handler.wait_for(len(stores) if events is None else events)
                return handler.events
        finally:
            await stopping(srv, stop, task)

    return asyncio.run(scenario())


def test_every_rundown_arrives_as_a_result_event_at_the_server_object(repo):
    tids = {"B1": 41, "B2": 42}          # the controller's numbers of the two tightenings
    events = events_while(
        repo, lambda: record(repo, VIN, "B1", ok=True, tightening_id=tids["B1"]),
        lambda: record(repo, VIN, "B2", ok=False, tightening_id=tids["B2"]),
        # an id no UInt32 holds (a Modbus map's signed register, a 10-digit Open Protocol
        # id): its encoding stopped the subscription, no result came after
        lambda: record(repo, VIN, "B2", ok=True, kind="loosening", operator="olga",
                       tightening_id=2 ** 32 + 5),
        lambda: record(repo, VIN, "B3", ok=True, tightening_id=44))
    db_id = repo.ledger.db_id()
    seqs = [e["seq"] for e in repo.ledger.since(0)]
    assert [e.SourceName for e in events] == ["ST-07"] * 4
    assert events[0].SourceNode == ua.NodeId("JoiningSystem.ST-07", events[0].SourceNode
                                             .NamespaceIndex)
    for event, seq, ok, bolt in zip(events[:2], seqs[:2], (True, False), ("B1", "B2"),
                                    strict=True):
        meta = event.Result.ResultMetaData
        assert meta.ResultId == f"{db_id}:{seq}"
        assert meta.SequenceNumber == seq
        assert meta.Classification == 1
        assert int(meta.ResultEvaluation) == (1 if ok else 2)
        assert meta.CreationTime is not None
        entities = {(x.EntityType, x.EntityId) for x in meta.AssociatedEntities}
        assert entities == {(20, VIN), (23, bolt)}
        # the controller's own number of the rundown, for an MES matching its records (the
        # result carried none: a newcomer's MES could not find it on the controller)
        assert [(kv.Key, kv.Value.Value) for kv in meta.ExtendedMetaData] == [
            ("TighteningId", tids[bolt])]
        content = event.Result.ResultContent[0].Value
        torque, angle = content.OverallResultValues
        assert (torque.Name, torque.MeasuredValue) == ("Torque", 50.0 if ok else 30.0)
        assert (angle.Name, angle.MeasuredValue) == ("Angle", 35.0)
    b1_torque, b1_angle = events[0].Result.ResultContent[0].Value.OverallResultValues
    assert (b1_torque.LowLimit, b1_torque.High, b1_torque.TargetValue) == (45.0, 55.0, 50.0)
    assert (b1_angle.LowLimit, b1_angle.High) == (15.0, 60.0)
    b2_torque, b2_angle = events[1].Result.ResultContent[0].Value.OverallResultValues
    assert (b2_torque.LowLimit, b2_torque.High) == (23.0, 27.0)
    # each value judged against its own limits: B2's NOK is its torque's, not its angle's
    assert [int(v.ResultEvaluation) for v in (b1_torque, b1_angle, b2_torque)] == [1, 1, 2]
    assert int(b2_angle.ResultEvaluation) == (
        1 if b2_angle.LowLimit <= b2_angle.MeasuredValue <= b2_angle.High else 2)
    assert b2_torque.EngineeringUnits.DisplayName.Text == "N·m"
    # a loosening is told apart (a newcomer's MES saw four "OK" results of one joint), and
    # the operator signed in at the station is an entity of the result
    kinds = [e.Result.ResultMetaData.AssemblyType for e in events]
    assert kinds == [1, 1, 2, 1]                    # ASSEMBLED, ..., DISASSEMBLED, ...
    loose = events[2].Result.ResultMetaData
    assert loose.Name.endswith("loosening") and "loosening of B2" in loose.Description.Text
    # judged by the controller's loosen program: not against the bolt's tightening window
    # (an MES integrator's trial read a loosening's 44 Nm as NotOK against 45-55), as the
    # feed and the line database say it
    for value in events[2].Result.ResultContent[0].Value.OverallResultValues:
        assert (value.LowLimit, value.High) == (None, None), value.Name
    assert {(x.EntityType, x.EntityId) for x in loose.AssociatedEntities} == {
        (20, VIN), (23, "B2"), (-1, "olga")}
    # ... and said so where a client that decodes nothing reads it, the event's Message
    assert [e.Message.Text for e in events] == [
        f"{VIN} B1: tightening OK (controller id 41)",
        f"{VIN} B2: tightening NOK (controller id 42)",
        f"{VIN} B2: loosening OK (controller id {2 ** 32 + 5})",
        f"{VIN} B3: tightening OK (controller id 44)"]
    assert events[2].Result.ResultMetaData.ExtendedMetaData is None     # not a UInt32
    assert [(kv.Key, kv.Value.Value) for kv in events[3].Result.ResultMetaData
            .ExtendedMetaData] == [("TighteningId", 44)]
    assert {e.Result.ResultMetaData.JoiningTechnology.Text for e in events} == {"Tightening"}


def test_identification_state_and_the_result_methods(repo):
    record(repo, VIN, "B1", ok=True)         # before the server: kept for the methods
    db_id = repo.ledger.db_id()

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving(config(), repo)
        try:
            await srv.set_state("tracking", "vehicle at the station")
            async with Client(srv.url) as client:
                await load_client_types(client)
                uris = await client.get_namespace_array()
                di, mr = uris.index(DI_URI), uris.index(RESULT_URI)
                machines = await client.nodes.objects.get_child(
                    [f"{uris.index(MACHINERY_URI)}:Machines"])
                js = await machines.get_child([f"{uris.index(NAMESPACE)}:ST-07"])
                ident = await js.get_child([f"{di}:Identification"])
                out: dict[str, Any] = {}
                for name in ("Manufacturer", "ManufacturerUri", "SystemId", "SoftwareRevision"):
                    v = await (await ident.get_child([f"{di}:{name}" if name != "SystemId"
                                                      else f"{uris.index(IJT_URI)}:SystemId"]
                                                     )).read_value()
                    out[name] = getattr(v, "Text", v)
                out["state"] = await (await js.get_child(
                    [f"{uris.index(NAMESPACE)}:State"])).read_value()
                # the building block's Identification is the machine's own, not an empty
                # copy (a newcomer read every value None there)
                blocks = await js.get_child(
                    [f"{uris.index(MACHINERY_URI)}:MachineryBuildingBlocks"])
                block_ident = await blocks.get_child([f"{di}:Identification"])
                out["block_ident"] = block_ident.nodeid == ident.nodeid
                rm = await js.get_child([f"{mr}:ResultManagement"])
                # ... and so is its ResultManagement (a copy there had no result at all)
                block_rm = await blocks.get_child([f"{mr}:ResultManagement"])
                out["block_rm"] = block_rm.nodeid == rm.nodeid
                out["block_latest"] = await block_rm.call_method(f"{mr}:GetLatestResult",
                                                                 ua.Int32(0))
                out["latest"] = await rm.call_method(f"{mr}:GetLatestResult", ua.Int32(0))
                out["by_id"] = await rm.call_method(f"{mr}:GetResultById",
                                                    f"{db_id}:1", ua.Int32(0))
                out["unknown"] = await rm.call_method(f"{mr}:GetResultById", "nope",
                                                      ua.Int32(0))
                for bad in ("", "  "):   # not an id at all: the call is refused
                    with pytest.raises(ua.UaStatusCodeError) as refused:
                        await rm.call_method(f"{mr}:GetResultById", bad, ua.Int32(0))
                    out.setdefault("empty", []).append(type(refused.value).__name__)
                requested = await rm.get_child(
                    [f"{mr}:Results", f"{uris.index(IJT_URI)}:RequestedResult"])
                out["requested type"] = await requested.read_type_definition()
                return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["Manufacturer"] == "stationd"
    assert out["ManufacturerUri"] == "urn:stationd"
    assert out["block_ident"] and out["block_rm"]
    assert out["block_latest"][2] == 0
    assert out["block_latest"][1].ResultMetaData.ResultId == f"{db_id}:1"
    assert out["SystemId"] == "ST-07"
    assert out["SoftwareRevision"]
    assert out["state"] == "tracking"
    _, latest, error = out["latest"]
    assert error == 0 and latest.ResultMetaData.ResultId == f"{db_id}:1"
    _, by_id, error = out["by_id"]
    assert error == 0 and by_id.ResultMetaData.ProductId == VIN
    assert out["unknown"][2] != 0
    assert out["empty"] == ["BadInvalidArgument"] * 2
    assert out["requested type"].Identifier == 2014   # JoiningSystemResultType


async def mes_client_reads(repo: Repository) -> dict[str, Any]:
    """What ``mes_client.py``, a client in its own process sharing no class with the server,
    reads of the latest result from a server serving ``repo``."""
    srv, stop, task = await serving(config(), repo)
    try:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "tests.opcua.mes_client", srv.url, "ST-07",
            cwd=ROOT, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
        out, err = await asyncio.wait_for(proc.communicate(), 60)
        assert proc.returncode == 0, err.decode()[-2000:]
        return dict(json.loads(out.decode().strip().splitlines()[-1]))
    finally:
        await stopping(srv, stop, task)


@pytest.mark.system   # a client in its own process
def test_a_client_in_its_own_process_decodes_the_result(repo):
    """No class shared with the server: the client builds its own from the definitions the
    server exposes (complete, with subtyped fields flagged)."""
    record(repo, VIN, "B2", ok=False)
    db_id = repo.ledger.db_id()

    got = asyncio.run(mes_client_reads(repo))
    assert got["error"] == 0 and got["type"] == "JoiningResultMetaDataType"
    assert got["result_id"] == f"{db_id}:1" and got["seq"] == 1 and got["evaluation"] == 2
    assert sorted(got["entities"]) == [[20, VIN], [23, "B2"]]
    assert got["values"] == [["Torque", 30.0, 23.0, 27.0], ["Angle", 35.0, 10.0, 50.0]]


def test_anonymous_clients_read_but_never_write_and_users_need_their_password(repo):
    cfg = config(users={"mes": hash_password("s3cret")})

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving(cfg, repo)
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:
                uris = await client.get_namespace_array()
                state = client.get_node(ua.NodeId("JoiningSystem.ST-07.State",
                                                  uris.index(NAMESPACE)))
                out["read"] = await state.read_value()
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await state.write_value("hacked")
                out["anonymous write"] = type(refused.value).__name__
            user = Client(srv.url)
            user.set_user("mes")
            user.set_password("s3cret")
            async with user:
                uris = await user.get_namespace_array()
                state = user.get_node(ua.NodeId("JoiningSystem.ST-07.State",
                                                uris.index(NAMESPACE)))
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await state.write_value("hacked")
                out["user write"] = type(refused.value).__name__
            wrong = Client(srv.url)
            wrong.set_user("mes")
            wrong.set_password("guess")
            with pytest.raises(ua.UaStatusCodeError) as refused:
                async with wrong:
                    pass
            out["wrong password"] = type(refused.value).__name__
            return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["read"] is not None
    assert out["anonymous write"] == "BadUserAccessDenied"
    assert out["user write"] == "BadUserAccessDenied"
    assert out["wrong password"] in ("BadUserAccessDenied", "BadIdentityTokenRejected",
                                     "BadIdentityTokenInvalid")


def test_the_opcua_section_is_checked_with_its_line(tmp_path):
    ok = OpcUaConfig.from_node(YamlNode.parse(
        "endpoint: opc.tcp://0.0.0.0:4841\nstation_id: ST-07\ncertificates: pki\n"
        f"users: {{mes: '{hash_password('x')}'}}\nkeep: 10\n"), base_dir=tmp_path)
    assert (ok.endpoint, ok.station_id, ok.certificates, ok.keep) == \
        ("opc.tcp://0.0.0.0:4841", "ST-07", tmp_path / "pki", 10)
    assert ok.security == ("none", "sign", "encrypt") and set(ok.users) == {"mes"}
    for text, needle, line in (("endpoint: http://x:1\nsecurity: [none]\n", "OPC UA endpoint", 1),
                               ("security: [none]\nusers: {mes: plain}\n", "hash", 2),
                               ("security: [sign]\n", "certificates", 1),
                               ("security: [none]\nport: 1\n", "unknown key", 2),
                               ("endpoint: opc.tcp://127.0.0.1:0\nsecurity: [none]\n",
                                "no MES can be told", 1)):
        with pytest.raises(ConfigError) as err:
            OpcUaConfig.from_node(YamlNode.parse(text))
        assert needle in str(err.value) and f":{line}" in str(err.value), str(err.value)


def test_an_opcua_section_without_certificates_says_they_are_missing_and_why():
    """Sign and encrypt are offered by default: a section without ``certificates`` says what
    is missing, why, and the two ways out (it read as a definition of the key)."""
    for text, offered in (("endpoint: opc.tcp://0.0.0.0:4841\n",
                           "the default offers sign and encrypt, which need a folder"),
                          ("security: [none, sign]\n", "security offers sign, which needs")):
        with pytest.raises(ConfigError) as err:
            OpcUaConfig.from_node(YamlNode.parse(text))
        said = str(err.value)
        assert "certificates: missing;" in said and offered in said, said
        assert "'certificates: /var/lib/stationd/opcua'" in said and "'security: [none]'" in said


def test_a_first_start_with_certificates_and_nobody_trusted_yet_serves(repo, tmp_path):
    """The trusted folder is empty on a first start (a newcomer saw the server never start
    and a traceback at stop): it serves, and no client certificate is accepted meanwhile."""
    async def main() -> None:
        srv, stop, task = await serving(config(certificates=tmp_path / "pki"), repo)
        try:
            async with Client(srv.cfg.endpoint) as client:
                assert await client.get_namespace_array()
        finally:
            await stopping(srv, stop, task)
        assert (tmp_path / "pki" / "server-cert.der").exists()
        assert (tmp_path / "pki" / "trusted").is_dir()
    asyncio.run(main())


def test_the_joining_system_is_an_event_notifier_with_the_results(repo):
    """The working group's conformance client checks the JoiningSystem's SubscribeToEvents
    bit, and a client subscribed there gets the results too."""
    async def scenario() -> tuple[int, list[Any]]:
        srv, stop, task = await serving(config(), repo)
        try:
            async with Client(srv.url) as client:
                await load_client_types(client)
                uris = await client.get_namespace_array()
                js = client.get_node(ua.NodeId("JoiningSystem.ST-07", uris.index(NAMESPACE)))
                notifier = await js.read_attribute(ua.AttributeIds.EventNotifier)
                handler = Collector()
                sub = await client.create_subscription(20, handler)
                await sub.subscribe_events(js, client.get_node(
                    ua.NodeId(1007, uris.index(IJT_URI))))
                await asyncio.sleep(0.3)
                await asyncio.get_running_loop().run_in_executor(
                    None, lambda: record(repo, VIN, "B1", ok=True))
                await handler.wait_for(1)
                await asyncio.sleep(0.3)   # one event, not one per emitter
                return int(getattr(notifier.Value, "Value", 0)), handler.events
        finally:
            await stopping(srv, stop, task)

    bits, events = asyncio.run(scenario())
    assert bits & 1
    assert len(events) == 1 and events[0].Result.ResultMetaData.Classification == 1


def test_a_port_in_use_is_no_library_traceback_in_the_journal(caplog):
    """A sweep: an endpoint whose port was taken put asyncua's traceback in the journal before
    the station's own line; the start fails (the caller says "not served on ..."), and the
    library's record is not logged."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        cfg = OpcUaConfig(endpoint=f"opc.tcp://127.0.0.1:{port}", station_id="ST-07",
                          security=("none",))

        async def start() -> None:
            srv = OpcUaServer(cfg)
            try:
                await srv.start()
            finally:
                await srv.stop()

        with caplog.at_level(logging.DEBUG), pytest.raises(OSError):
            asyncio.run(start())
    assert not [r for r in caplog.records if r.exc_info and r.name.startswith("asyncua")]


def test_a_republish_of_a_message_not_held_is_refused_as_the_standard_says(repo):
    """After a reload a client asks the new server again for messages of its old
    subscription: "not available" (not Good and empty, which a stock node-opcua client asked
    again about a thousand times a second, forever), and a subscription the server does not
    know is said to be unknown."""
    async def republish(client: Client, subscription: int, number: int) -> str:
        request = ua.RepublishRequest()
        request.Parameters.SubscriptionId = subscription
        request.Parameters.RetransmitSequenceNumber = number
        protocol = client.uaclient.protocol
        assert protocol is not None
        try:
            await protocol.send_request(request)      # raises the answer's fault
        except ua.UaStatusCodeError as exc:
            return str(ua.StatusCode(exc.code).name)
        return "Good"

    async def scenario() -> tuple[str, str, str]:
        srv, stop, task = await serving(config(), repo)
        try:
            async with Client(srv.url) as client, Client(srv.url) as other:
                sub = await client.create_subscription(50, Collector())
                await sub.subscribe_events(client.nodes.server)
                number = sub.subscription_id
                assert number is not None
                return (await republish(client, number, 99),
                        await republish(client, number + 1000, 1),
                        # another session's subscription (numbers start again at each
                        # start: after a reload an MES may ask about another's)
                        await republish(other, number, 1))
        finally:
            await stopping(srv, stop, task)

    assert asyncio.run(scenario()) == ("BadMessageNotAvailable", "BadSubscriptionIdInvalid",
                                       "BadSubscriptionIdInvalid")


#: a controller's own time of a result, its clock a minute behind the station's
CONTROLLER_AT = datetime(2026, 12, 1, 9, 59, 1, tzinfo=UTC)


def test_a_result_of_no_bolt_and_one_not_readable_arrive_as_results_told_apart(repo):
    """A rundown the station attributed to no bolt and a result message it could not read
    are results of the controller too: an MES counting them from the station's results saw
    neither.  Each comes as a result event in its turn, told apart from a joint's rundown in
    its metadata (no Joint; NotDecidable) and its Message ("of no bolt", "not readable"),
    and counts among those to acknowledge."""
    events = events_while(
        repo, lambda: repo.others.record_unattributed(
            vin=VIN, controller_vin=None, tightening_id=51, pset=3, ok=False, torque_nm=12.5,
            angle_deg=40.0, result_at=CONTROLLER_AT, result_type=2,
            reason="outside a tool enable"),
        lambda: repo.others.record_unreadable(
            mid=61, revision=2, raw="0231006100" + "x" * 40,
            error="torque '00ABCD' is not a number", vin=VIN, bolt="B2", controller_vin=None,
            tightening_id=52, pset=1, result_at=CONTROLLER_AT),
        lambda: record(repo, VIN, "B1", ok=True, tightening_id=53))
    assert [e.Message.Text for e in events] == [
        f"{VIN}: loosening NOK of no bolt (controller id 51)",
        f"{VIN} B2: result not readable (controller id 52): held for a supervisor",
        f"{VIN} B1: tightening OK (controller id 53)"]
    loose, unread, rundown = (e.Result.ResultMetaData for e in events)
    assert [m.SequenceNumber for m in (loose, unread, rundown)] == \
        [e["seq"] for e in repo.ledger.since(0)]
    assert [int(m.ResultEvaluation) for m in (loose, unread, rundown)] == [2, 3, 1]
    assert {(x.EntityType, x.EntityId) for x in loose.AssociatedEntities} == {(20, VIN)}
    assert loose.AssemblyType == 2 and "attributed to no bolt: outside a tool enable" in \
        loose.Description.Text
    assert [(kv.Key, kv.Value.Value) for kv in loose.ExtendedMetaData] == [("TighteningId", 51)]
    torque, angle = events[0].Result.ResultContent[0].Value.OverallResultValues
    assert (torque.MeasuredValue, angle.MeasuredValue) == (12.5, 40.0)
    assert torque.LowLimit is None and torque.High is None
    assert {(x.EntityType, x.EntityId) for x in unread.AssociatedEntities} == {
        (20, VIN), (23, "B2")}
    assert "MID 0061 revision 2 not readable" in unread.Description.Text
    assert not events[1].Result.ResultContent[0].Value.OverallResultValues
    assert repo.ledger.unacknowledged_count() == 3
    # every kind's CreationTime on the station's clock (an MES integrator's trial: the
    # unreadable one's was the controller's, to the second, its clock apart): when stored
    stored = [datetime.fromisoformat(e["record"]["recorded_at"])
              for e in repo.ledger.since(0)[:2]]
    assert [m.CreationTime.replace(tzinfo=UTC) for m in (loose, unread)] == stored


def test_an_ok_not_taken_for_a_tightening_arrives_as_a_result_not_decided(repo):
    """An OK without a result type whose torque lies outside its bolt's window is not taken
    for the bolt's tightening (perhaps none: a batch increment at a revision without types),
    its bolt held.  It is a rundown of the controller all the same: an MES counting them
    missed it (a reviewer).  It comes as a result, NotDecidable in its metadata and in each
    value (the controller's OK is not the station's), the held bolt its Joint, and counts
    among those to acknowledge; a batch increment, no rundown, does not come."""
    from db.kinds import NOT_TAKEN

    def event(what: str, tid: int) -> Callable[[], Any]:
        return lambda: repo.others.record_controller_event(
            result_type=0, what=what, vin=VIN, bolt="B2", controller_vin=None,
            tightening_id=tid, pset=1, ok=True, torque_nm=4.97, angle_deg=30.0,
            result_at=None)

    events = events_while(repo, event("batch increment", 60), event(NOT_TAKEN, 61),
                          lambda: record(repo, VIN, "B1", ok=True, tightening_id=62),
                          events=2)
    assert [e.Message.Text for e in events] == [
        f"{VIN} B2: OK not taken for a tightening (controller id 61): held for a supervisor",
        f"{VIN} B1: tightening OK (controller id 62)"]
    meta = events[0].Result.ResultMetaData
    assert int(meta.ResultEvaluation) == 3
    assert {(x.EntityType, x.EntityId) for x in meta.AssociatedEntities} == {
        (20, VIN), (23, "B2")}
    assert "not taken for a tightening; B2 held for a supervisor" in meta.Description.Text
    assert [(kv.Key, kv.Value.Value) for kv in meta.ExtendedMetaData] == [("TighteningId", 61)]
    torque, angle = events[0].Result.ResultContent[0].Value.OverallResultValues
    assert (torque.MeasuredValue, angle.MeasuredValue) == (4.97, 30.0)
    assert [int(v.ResultEvaluation) for v in (torque, angle)] == [3, 3]
    assert repo.ledger.unacknowledged_count() == 2


def test_a_result_of_an_unknown_type_that_held_its_bolt_arrives_as_a_result_not_decided(repo):
    """A result of a type the station does not know under a bolt's enable (type 9: an MES
    integrator's trial found such rundowns in the export and not on OPC UA, GetResultById
    answering "not found"): it holds its bolt and comes as a result, NotDecidable, its type
    said; one with no bolt's enable (a plain controller event) does not come."""
    from db.kinds import UNKNOWN_TYPE_HELD

    def event(what: str, tid: int, bolt: str | None) -> Callable[[], Any]:
        return lambda: repo.others.record_controller_event(
            result_type=9, what=what, vin=VIN, bolt=bolt, controller_vin=None,
            tightening_id=tid, pset=1, ok=True, torque_nm=49.38, angle_deg=30.0,
            result_at=None)

    events = events_while(repo, event("result type 9 (unknown)", 70, None),
                          event(UNKNOWN_TYPE_HELD, 71, "B2"),
                          lambda: record(repo, VIN, "B1", ok=True, tightening_id=72),
                          events=2)
    assert [e.Message.Text for e in events] == [
        f"{VIN} B2: result of unknown type 9 not taken for a tightening (controller id 71): "
        "held for a supervisor", f"{VIN} B1: tightening OK (controller id 72)"]
    meta = events[0].Result.ResultMetaData
    assert int(meta.ResultEvaluation) == 3
    assert meta.Description.Text == ("a result of type 9 of pset 1, a type the station does "
                                      "not know: not taken for a tightening; B2 held for a "
                                      "supervisor")
    torque, _ = events[0].Result.ResultContent[0].Value.OverallResultValues
    assert torque.MeasuredValue == 49.38 and int(torque.ResultEvaluation) == 3
