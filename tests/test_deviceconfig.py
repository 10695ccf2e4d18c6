"""The station file's device sections (stationd.deviceconfig), read on their own through the
generic reader: what a device can do is asked of its driver, the cameras and pairs are
checked against each other.  The whole file through the loader and the checker, with every
message's line and key, is tests/test_config.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from stationd.configread import SectionReader
from stationd.deviceconfig import DeviceSections, PairConfig, WrenchConfig, one_device_each
from stationd.errors import ConfigError
from stationd.yamlio import YamlNode

SIM = Path(__file__).resolve().parents[1] / "config" / "sim"


def _section(text: str, key: str) -> YamlNode:
    return YamlNode.parse(text, "s.yaml").mapping((key,))[key]


@pytest.mark.parametrize(("url", "takes"), [
    ("modbus-tcp://10.0.0.9:502?unit=2", True), ("modbus-rtu:///dev/ttyUSB2?unit=1", True),
    ("sim+modbus://wrench", True), ("openprotocol://10.0.0.9", False), ("sim://wrench", False)])
def test_a_register_map_is_for_a_controller_whose_driver_takes_one(url, takes):
    """Asked of the backend (``drivers.wrench.takes_register_map``), not of "modbus" in the
    scheme's name."""
    node = _section(f"wrench:\n  url: '{url}'\n  registers:\n    vin: null\n", "wrench")
    if takes:
        w = WrenchConfig.from_node(node)
        assert w.registers is not None and w.open_options() == {"register_map": w.registers}
    else:
        with pytest.raises(ConfigError, match=r"s\.yaml:4: wrench\.registers: a register map "
                                              r"is for a Modbus controller, not "):
            WrenchConfig.from_node(node)


def test_the_lift_and_the_controller_are_two_devices():
    node = _section("wrench: {url: 'modbus-tcp://127.0.0.1:502?unit=1'}\n", "wrench")
    with pytest.raises(ConfigError, match=r"the same device as lift\.url"):
        one_device_each("modbus-tcp://localhost?unit=1", "modbus-tcp://127.0.0.1:502?unit=1",
                        node)
    one_device_each("modbus-tcp://localhost?unit=1", "modbus-tcp://127.0.0.1:502?unit=2", node)
    one_device_each("sim://lift", "sim://wrench", node)   # each simulates its own


def _devices(text: str) -> tuple[SectionReader, dict[str, PairConfig]]:
    """The cameras and pairs of ``text`` (calibrations from config/sim), read collecting."""
    reader = SectionReader(collect=True)
    reader.sections(YamlNode.parse(text, str(SIM / "s.yaml")), "station", ("cameras", "pairs"))
    devices = DeviceSections(reader, SIM, check=True)
    _, names = devices.cameras(reader.top["cameras"])
    return reader, devices.pairs(reader.top["pairs"], names)


def test_every_mistake_of_the_cameras_and_pairs_is_told_and_the_good_pairs_read():
    reader, pairs = _devices(
        "cameras:\n"
        "  a: {url: 'sim://pair1/left'}\n"
        "  b: {url: 'sim://pair1/right'}\n"
        "  c: {url: 'sim://pair2/left'}\n"
        "  d: {url: 'sim://pair2/left?seed=4'}\n"
        "pairs:\n"
        "  pair1: {calibration: pair1.yaml, left: a, right: b}\n"
        "  pair2: {calibration: pair2.yaml, left: c, right: a}\n")
    assert list(pairs) == ["pair1"]
    assert [(e.line, e.key) for e in reader.errors] == [(5, "cameras.d"),
                                                        (8, "pairs.pair2.right")]
    assert "the same camera as 'c'" in str(reader.errors[0])
    assert "camera 'a' is already the left camera of pair 'pair1'" in str(reader.errors[1])


def test_a_simulated_camera_must_show_the_pair_it_serves():
    """The camera's driver says which view of the simulated world it shows."""
    reader, pairs = _devices(
        "cameras:\n"
        "  a: {url: 'sim://pair1/left'}\n"
        "  b: {url: 'sim://pair2/right'}\n"
        "pairs:\n"
        "  pair1: {calibration: pair1.yaml, left: a, right: b}\n")
    [error] = reader.errors
    assert (error.line, error.key) == (3, "cameras.b.url")
    assert error.message == ("camera 'b' is the right camera of pair 'pair1' but shows pair "
                             "'pair2', which the simulated world does not have (it renders "
                             "this file's pairs: pair1): write sim://pair1/right")
    assert list(pairs) == ["pair1"]     # read: the mismatch is the cameras' to fix
