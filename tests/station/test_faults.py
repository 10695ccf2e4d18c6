"""What devices say besides their faults, through the core (stationd/station/faults.py): a
device's identity and the line database's link are inputs the core keeps and tells, so the
screens, OPC UA and ``status()`` hear them from the one writer of the station's state."""

from __future__ import annotations

import pytest

from drivers.identity import DeviceIdentity
from stationd.station.actions import Publish
from stationd.station.core import StationCore
from stationd.station.events import DeviceIdentified, LineLinkChanged, State
from stationd.station.inputs import DeviceSaid, LineLinkIn, Started
from tests.station.test_core import PARAMS, _ready, published


def test_a_device_s_identity_is_told_once_per_change_and_kept_in_the_status():
    core = StationCore(PARAMS)
    core.feed(Started(1.0))
    first = core.feed(DeviceSaid(2.0, "wrench", "PF6000 (cell 1, channel 1), software 2.1"))
    assert [(e.device, e.identity) for e in published(first, DeviceIdentified)] == [
        ("wrench", "PF6000 (cell 1, channel 1), software 2.1")]
    assert published(first, DeviceIdentified)[0].t == 2.0
    # a reconnect says the same again: nothing new to tell
    assert core.feed(DeviceSaid(3.0, "wrench", "PF6000 (cell 1, channel 1), software 2.1")) == []
    again = core.feed(DeviceSaid(4.0, "wrench", "PF6000 (cell 1, channel 1), software 2.2"))
    assert [e.identity for e in published(again, DeviceIdentified)] == [
        "PF6000 (cell 1, channel 1), software 2.2"]
    assert dict(core.status().identities) == {
        "wrench": "PF6000 (cell 1, channel 1), software 2.2"}


def test_a_typed_identity_reaches_the_event_and_the_status_with_its_words():
    core = StationCore(PARAMS)
    core.feed(Started(1.0))
    plate = DeviceIdentity("PF6000 (cell 0001, channel 01): supplier ACT, serial A1",
                           manufacturer="ACT", model="PF6000", serial_number="A1",
                           software_revision="3.4.1")
    told = published(core.feed(DeviceSaid.of(2.0, "wrench", plate)), DeviceIdentified)
    assert [(e.device, e.identity, e.identification) for e in told] == [
        ("wrench", plate.words, plate)]
    assert core.status().identifications["wrench"] == plate
    assert core.status().identities["wrench"] == plate.words   # the words, as before
    # a field changed under the same words (a serial read anew) is told again
    moved = DeviceIdentity(plate.words, manufacturer="ACT", serial_number="A2")
    assert [e.identification for e in published(
        core.feed(DeviceSaid.of(3.0, "wrench", moved)), DeviceIdentified)] == [moved]
    assert core.feed(DeviceSaid.of(4.0, "wrench", moved)) == []
    # words alone (a device with no nameplate fields) are an identity of words only
    words = published(core.feed(DeviceSaid(5.0, "lift", "Modbus TCP 10.0.0.9:502 unit 1")),
                      DeviceIdentified)
    assert words[0].identification == DeviceIdentity("Modbus TCP 10.0.0.9:502 unit 1")
    # one reading, two views: words that are not the identification's are refused
    with pytest.raises(ValueError, match="identification's words"):
        DeviceSaid(6.0, "wrench", "PF4000", plate)


def test_the_status_is_a_copy_the_caller_cannot_change():
    core = StationCore(PARAMS)
    core.feed(DeviceSaid(1.0, "wrench", "PF6000"))
    status = core.status()
    core.feed(DeviceSaid(2.0, "wrench", "PF4000"))
    assert status.identities["wrench"] == "PF6000"   # the copy taken before
    assert core.status().identities["wrench"] == "PF4000"
    assert status.identifications["wrench"] == DeviceIdentity("PF6000")


def test_the_line_link_is_told_when_it_changes_and_is_never_a_fault_of_the_station():
    d = _ready()
    down = d.feed(LineLinkIn(d.t, False, "connection refused"))
    assert [(e.up, e.reason, e.alarm) for e in published(down, LineLinkChanged)] == [
        (False, "connection refused", None)]
    assert not [a for a in down if not isinstance(a, Publish)]   # nothing to do: no action
    assert d.core.state is State.TRACKING     # the station goes on
    assert "line" not in d.core.status().faults
    assert d.feed(LineLinkIn(d.t, False, "connection refused")) == []   # said already
    alarm = d.feed(LineLinkIn(d.t, False, "connection refused", "backlog over 1000"))
    assert [e.alarm for e in published(alarm, LineLinkChanged)] == ["backlog over 1000"]
    up = d.feed(LineLinkIn(d.t, True))
    assert [(e.up, e.reason) for e in published(up, LineLinkChanged)] == [(True, "")]
    line = d.core.status().line
    assert line is not None and line.up and line.alarm is None


def test_without_a_line_forwarder_the_status_has_no_line():
    assert StationCore(PARAMS).status().line is None
    assert dict(StationCore(PARAMS).status().identities) == {}
