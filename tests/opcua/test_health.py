"""The devices' health in the joining-system model (AssetManagement/Assets, each asset's
Health.DeviceHealth), read by an asyncua client on loopback while the station's events say a
device went to fault and came back."""

from __future__ import annotations

import asyncio
import contextlib
from datetime import UTC, datetime
from typing import Any

from drivers.identity import DeviceIdentity
from stationd.bus import EventBus
from stationd.opcua.health import FAILURE, NO_ERROR, NORMAL, OFF_SPEC
from stationd.opcua.model import DI_URI, IJT_URI, MACHINERY_URI
from stationd.opcua.server import NAMESPACE, current
from stationd.opcua.uatypes import ua
from stationd.station.events import (
    Because,
    DeviceHealth,
    DeviceIdentified,
    LineLinkChanged,
    StateChanged,
    StateReason,
)
from tests.opcua.test_server import config, repo, serving, stopping
from tests.uaclient import Client

__all__ = ["repo"]   # the fixture, shared with test_server

DEVICES = ("lift", "wrench", "front", "database", "line")


class Changes:
    """Data changes of the subscribed variables, by node."""

    def __init__(self) -> None:
        self.seen: list[tuple[Any, Any]] = []
        self.arrived = asyncio.Event()

    def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
        self.seen.append((node, value))
        self.arrived.set()

    async def until(self, node: Any, value: Any, timeout: float = 60.0) -> None:
        async def seen() -> None:
            while (node, value) not in self.seen:
                self.arrived.clear()
                await self.arrived.wait()
        await asyncio.wait_for(seen(), timeout)


async def _asset(client: Client, folder: str, device: str) -> tuple[Any, Any, Any]:
    """The DeviceHealth, ErrorMessage and the asset of ``device``, found by browsing from
    Machines as an MES would."""
    uris = await client.get_namespace_array()
    ijt, di, app = uris.index(IJT_URI), uris.index(DI_URI), uris.index(NAMESPACE)
    asset = await client.nodes.objects.get_child([
        f"{uris.index(MACHINERY_URI)}:Machines", f"{app}:ST-07", f"{ijt}:AssetManagement",
        f"{ijt}:Assets", f"{ijt}:{folder}", f"{app}:{device}"])
    health = await asset.get_child([f"{ijt}:Health", f"{di}:DeviceHealth"])
    message = await asset.get_child([f"{ijt}:Health", f"{ijt}:ErrorMessage"])
    return health, message, asset


def test_a_client_sees_a_device_go_to_fault_and_back(repo):
    bus = EventBus()

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving(config(), repo, bus=bus, devices=DEVICES)
        loop = asyncio.get_running_loop()
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:
                health, message, _ = await _asset(client, "Controllers", "wrench")
                out["start"] = await health.read_value()
                uris = await client.get_namespace_array()
                out["type"] = await health.read_data_type()
                out["enum"] = out["type"] == client.get_node(
                    f"ns={uris.index(DI_URI)};i=6244").nodeid
                for folder, device in (("Accessories", "lift"), ("Sensors", "front"),
                                       ("SoftwareComponents", "database"),
                                       ("SoftwareComponents", "line")):
                    h, _, asset = await _asset(client, folder, device)
                    out[device] = await h.read_value()
                    refs = await asset.get_references(refs=17603)   # HasInterface
                    out[f"{device} interface"] = [r.NodeId.Identifier for r in refs]
                changes = Changes()
                sub = await client.create_subscription(20, changes)
                await sub.subscribe_data_change(health)
                # the station publishes from its own threads
                await loop.run_in_executor(None, bus.publish, DeviceHealth(
                    "wrench", False, "down", "controller 10.0.0.5:4545: connection refused"))
                await changes.until(health, FAILURE)
                out["fault"] = await message.read_value()
                await loop.run_in_executor(None, bus.publish, DeviceHealth("wrench", True))
                await changes.until(health, NORMAL)
                out["back"] = (await health.read_value(), await message.read_value())
                # a pair first named in an event (a reload added it) gets its asset then
                await loop.run_in_executor(None, bus.publish, DeviceHealth(
                    "rear", False, "timeout", "no frame in 2 s"))
                for _ in range(100):
                    with contextlib.suppress(ua.UaError):   # not made yet
                        h, m, _ = await _asset(client, "Sensors", "rear")
                        if await h.read_value() == FAILURE:
                            break
                    await asyncio.sleep(0.05)
                out["rear"] = (await h.read_value(), (await m.read_value()).Text)
                line, line_msg, _ = await _asset(client, "SoftwareComponents", "line")
                await loop.run_in_executor(None, bus.publish, LineLinkChanged(
                    False, "connection refused"))
                await _until(line, FAILURE)
                out["line down"] = (await line_msg.read_value()).Text
                await loop.run_in_executor(None, bus.publish, LineLinkChanged(
                    True, "", "12000 records not forwarded (bound 10000)"))
                await _until(line, OFF_SPEC)
                await loop.run_in_executor(None, bus.publish, LineLinkChanged(True))
                await _until(line, NORMAL)
                return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["start"] == NORMAL and out["enum"]
    assert all(out[d] == NORMAL for d in ("lift", "front", "database", "line"))
    assert out["lift interface"] == [1015] and out["front interface"] == [1011]
    assert out["line interface"] == [1019]
    assert "connection refused" in out["fault"].Text
    assert out["back"][0] == NORMAL and out["back"][1].Text == ""
    assert out["rear"] == (FAILURE, "no frame in 2 s")
    assert out["line down"] == "connection refused"


def test_error_timestamp_is_null_without_an_error_and_when_the_error_occurred_with_one(repo):
    """A trial's MES read ErrorTimestamp set on every asset though none had an error (the
    server's start, or the time the device came back): null (DateTime.MinValue, OPC UA's
    null DateTime) while DeviceHealth is NORMAL; the time of the event that put the device
    in error while it is, kept when the same error is said again in other words, moved by
    another health (the line link's backlog alarm after it was down)."""
    bus = EventBus()
    t_down, t_again, t_line, t_alarm = 1_800_000_000.0, 1_800_000_060.0, 1_800_000_100.0, \
        1_800_000_200.0

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving(config(), repo, bus=bus, devices=DEVICES)
        loop = asyncio.get_running_loop()
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:
                ijt = (await client.get_namespace_array()).index(IJT_URI)

                async def stamp(folder: str, device: str) -> Any:
                    _, _, asset = await _asset(client, folder, device)
                    node = await asset.get_child([f"{ijt}:Health", f"{ijt}:ErrorTimestamp"])
                    return await node.read_value()

                out["start"] = {d: await stamp(f, d) for f, d in (
                    ("Controllers", "wrench"), ("Accessories", "lift"),
                    ("SoftwareComponents", "line"))}
                health, message, _ = await _asset(client, "Controllers", "wrench")
                await loop.run_in_executor(None, bus.publish, DeviceHealth(
                    "wrench", False, "down", "connection refused", t=t_down))
                await _until(health, FAILURE)
                out["down"] = await stamp("Controllers", "wrench")
                await loop.run_in_executor(None, bus.publish, DeviceHealth(
                    "wrench", False, "timeout", "no answer in 10 s", t=t_again))
                for _ in range(250):
                    if (await message.read_value()).Text == "no answer in 10 s":
                        break
                    await asyncio.sleep(0.02)
                out["again"] = await stamp("Controllers", "wrench")
                await loop.run_in_executor(None, bus.publish, DeviceHealth("wrench", True))
                await _until(health, NORMAL)
                out["back"] = await stamp("Controllers", "wrench")
                line, _, _ = await _asset(client, "SoftwareComponents", "line")
                await loop.run_in_executor(None, bus.publish, LineLinkChanged(
                    False, "connection refused", t=t_line))
                await _until(line, FAILURE)
                out["line down"] = await stamp("SoftwareComponents", "line")
                await loop.run_in_executor(None, bus.publish, LineLinkChanged(
                    True, "", "12000 records not forwarded (bound 10000)", t=t_alarm))
                await _until(line, OFF_SPEC)
                out["line alarm"] = await stamp("SoftwareComponents", "line")
                await loop.run_in_executor(None, bus.publish, LineLinkChanged(True))
                await _until(line, NORMAL)
                out["line back"] = await stamp("SoftwareComponents", "line")
                return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["start"] == {"wrench": NO_ERROR, "lift": NO_ERROR, "line": NO_ERROR}
    assert out["down"] == datetime.fromtimestamp(t_down, UTC)
    assert out["again"] == out["down"]              # the same error, other words
    assert out["back"] == NO_ERROR
    assert out["line down"] == datetime.fromtimestamp(t_line, UTC)
    assert out["line alarm"] == datetime.fromtimestamp(t_alarm, UTC)
    assert out["line back"] == NO_ERROR


def test_a_client_reads_the_controller_s_manufacturer_and_serial_number(repo):
    """The controller's MID 0002, typed by its driver, on its asset's Identification as a
    stock asyncua client browses it: Manufacturer and SerialNumber (mandatory, empty until
    the controller said them), Model, SoftwareRevision, IJT's Description (its words)."""
    bus = EventBus()
    plate = DeviceIdentity("PF6000 (cell 0001, channel 01): supplier ACT, serial A123456789",
                           manufacturer="ACT", model="PF6000 (RBU Premium)",
                           serial_number="A123456789", software_revision="PF6000 3.4.1")

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving(config(), repo, bus=bus, devices=DEVICES)
        loop = asyncio.get_running_loop()
        out: dict[str, Any] = {}
        try:
            async with Client(srv.url) as client:
                uris = await client.get_namespace_array()
                di, ijt = uris.index(DI_URI), uris.index(IJT_URI)
                _, _, asset = await _asset(client, "Controllers", "wrench")
                ident = await asset.get_child([f"{di}:Identification"])

                async def read(name: str, ns: int = di) -> Any:
                    value = await (await ident.get_child([f"{ns}:{name}"])).read_value()
                    return value.Text if isinstance(value, ua.LocalizedText) else value

                out["before"] = (await read("Manufacturer"), await read("SerialNumber"))
                await loop.run_in_executor(None, bus.publish,
                                           DeviceIdentified("wrench", plate.words, plate))
                for _ in range(100):
                    if await read("SerialNumber") == "A123456789":
                        break
                    await asyncio.sleep(0.05)
                out["after"] = {n: await read(n) for n in (
                    "Manufacturer", "SerialNumber", "Model", "SoftwareRevision")}
                out["description"] = await read("Description", ijt)
                refs = await ident.get_references(refs=ua.ObjectIds.HasProperty)
                out["properties"] = {r.BrowseName.Name for r in refs}
                # a controller that says less later (words only): no field is left over
                await loop.run_in_executor(None, bus.publish,
                                           DeviceIdentified("wrench", "Short (cell 1)"))
                for _ in range(100):
                    if await read("Model") == "Short (cell 1)":
                        break
                    await asyncio.sleep(0.05)
                out["less"] = {n: await read(n) for n in (
                    "Manufacturer", "SerialNumber", "Model", "SoftwareRevision")}
                return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["before"] == ("", "")
    assert out["after"] == {"Manufacturer": "ACT", "SerialNumber": "A123456789",
                            "Model": "PF6000 (RBU Premium)",
                            "SoftwareRevision": "PF6000 3.4.1"}
    assert out["description"] == plate.words
    assert {"Manufacturer", "SerialNumber", "Model", "SoftwareRevision",
            "Description"} <= out["properties"]
    assert out["less"] == {"Manufacturer": "", "SerialNumber": "", "Model": "Short (cell 1)",
                           "SoftwareRevision": ""}


async def _until(node: Any, value: int, timeout: float = 5.0) -> None:
    end = asyncio.get_running_loop().time() + timeout
    while await node.read_value() != value:
        assert asyncio.get_running_loop().time() < end, f"never {value}"
        await asyncio.sleep(0.02)


def test_what_the_station_said_before_the_server_listened_is_read_by_the_client(repo):
    """OPC UA starts seconds after the station's devices (its model loads meanwhile): the
    lift's fault, the station's fault state and the controller's nameplate were said once,
    before it listened, and a client read the lift healthy, the state 'unknown' and an empty
    nameplate (an MES integrator's trial).  The server says what is true now from the bus's
    history as it starts; a reload's station reports its own devices (the last start's
    reports are not replayed)."""
    plate = DeviceIdentity("PF6000: supplier ACT, serial A123456789", manufacturer="ACT",
                           serial_number="A123456789")
    bus = EventBus()
    for e in (StateChanged("starting", StateReason(Because.OPENING)),
              DeviceHealth("front", False, "down", "camera unplugged"),   # the last station's
              StateChanged("starting", StateReason(Because.OPENING)),           # a reload's start
              DeviceIdentified("wrench", plate.words, plate),
              DeviceHealth("lift", False, "down", "no answer from 127.0.0.1:1"),
              StateChanged("fault", StateReason(Because.FAULT))):
        bus.publish(e)

    async def scenario() -> dict[str, Any]:
        srv, stop, task = await serving(config(), repo, bus=bus, devices=DEVICES)
        try:
            async with Client(srv.url) as client:
                uris = await client.get_namespace_array()
                out: dict[str, Any] = {}
                for folder, device in (("Accessories", "lift"), ("Sensors", "front")):
                    health, message, _ = await _asset(client, folder, device)
                    out[device] = (await health.read_value(),
                                   getattr(await message.read_value(), "Text", None))
                _, _, asset = await _asset(client, "Controllers", "wrench")
                ident = await asset.get_child([f"{uris.index(DI_URI)}:Identification"])
                serial = await ident.get_child([f"{uris.index(DI_URI)}:SerialNumber"])
                out["serial"] = await serial.read_value()
                machine = await client.nodes.objects.get_child(
                    [f"{uris.index(MACHINERY_URI)}:Machines", f"{uris.index(NAMESPACE)}:ST-07"])
                state = await machine.get_child([f"{uris.index(NAMESPACE)}:State"])
                out["state"] = await state.read_value()
                return out
        finally:
            await stopping(srv, stop, task)

    out = asyncio.run(scenario())
    assert out["lift"] == (FAILURE, "no answer from 127.0.0.1:1")
    assert out["front"][0] == NORMAL          # the last start's report is not this one's
    assert out["serial"] == "A123456789"
    assert out["state"] == "fault"


def test_the_replay_is_the_running_stations_last_word_per_device_in_order():
    start = StateChanged("starting", StateReason(Because.OPENING))
    old = DeviceHealth("lift", False, "down", "gone")
    h1, h2 = DeviceHealth("wrench", False, "down", "cut"), DeviceHealth("wrench", True)
    ident = DeviceIdentified("wrench", "SIM")
    line = LineLinkChanged(True, "")
    tracking = StateChanged("tracking", StateReason(Because.TRACKING))
    assert current([start, old, start, h1, ident, h2, line, tracking]) == [ident, h2, line,
                                                                           tracking]
    assert current([]) == []
    # a history whose start was pushed out keeps every device's last word
    assert current([old, h1, h2]) == [old, h2]


def test_a_device_down_across_a_reload_keeps_the_time_it_failed():
    """An MES trial: the controller down at 14:39:40, a reload at 14:39:48 (the new station
    reports it again, the OPC UA server restarts with it): its ErrorTimestamp read the
    reload's time.  The replay stamps a failing device with its failure's first report,
    back to its last word that it was ok (before the last start too)."""
    def health(history: list[Any]) -> DeviceHealth:
        [h] = [e for e in current(history) if isinstance(e, DeviceHealth)]
        return h

    start = StateChanged("starting", StateReason(Because.OPENING))
    down = DeviceHealth("wrench", False, "down", "refused", t=100.0)
    timeout = DeviceHealth("wrench", False, "timeout", "no answer", t=105.0)
    again = DeviceHealth("wrench", False, "down", "refused", t=160.0)
    replayed = health([start, down, timeout, start, again])
    assert replayed.t == 100.0 and replayed.reason == "refused"
    ok = DeviceHealth("wrench", True, t=120.0)
    replayed = health([start, down, ok, start, again])
    assert replayed.t == 160.0                      # back in between: failing since 160
    replayed = health([start, down, start, DeviceHealth("wrench", True, t=170.0)])
    assert replayed.ok and replayed.t == 170.0      # ok now: nothing to stamp


def test_a_subscriber_with_a_replay_gets_it_first_then_every_event_none_twice():
    bus = EventBus()
    first, second = DeviceHealth("lift", False, "down", "x"), DeviceHealth("lift", True)
    bus.publish(first)
    got: list[Any] = []
    bus.subscribe(got.append, replay=lambda history: history[-1:])
    bus.publish(second)
    assert got == [first, second]


def test_a_replay_taken_while_another_thread_publishes_misses_and_doubles_nothing():
    """The OPC UA server subscribes from its own thread while the station's loop publishes:
    the replay and the live events after it are every event once, in order (without the
    bus's lock, most trials here missed or doubled some: a reviewer's stress test)."""
    import threading
    import time

    for trial in range(5):
        bus = EventBus()
        events = [DeviceHealth(f"d{i}", i % 2 == 0) for i in range(2000)]
        got: list[Any] = []
        started = threading.Event()

        def publish(bus: EventBus, events: list[Any], started: threading.Event) -> None:
            for k, e in enumerate(events):
                bus.publish(e)
                time.sleep(0)        # the GIL let go, as a loop between frames does
                if k == 200:
                    started.set()

        def slow(history: list[Any]) -> list[Any]:
            time.sleep(0.002)   # a replay that takes a while (the GIL let go: publishing
            return history      # could go on meanwhile)

        t = threading.Thread(target=publish, args=(bus, events, started))
        t.start()
        started.wait(10)
        bus.subscribe(got.append, replay=slow)
        t.join()
        assert got == events, f"trial {trial}: {len(got)} events, not the {len(events)} published"
