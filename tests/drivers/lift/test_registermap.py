"""The register map: defaults, layout, decode/encode and the YAML form (no I/O)."""

from __future__ import annotations

import random
from dataclasses import replace

import pytest

from drivers.errors import UrlError
from drivers.lift import FORMS, RegisterMap, lift_class, open_lift
from drivers.lift.base import NUMBER_TYPES, Bit, LiftState, MapError, Number, Text
from drivers.lift.modbus import ModbusLift, parse_modbus_url
from drivers.lift.sim import SimLift
from stationd.devicemaps import lift_map
from stationd.errors import ConfigError
from stationd.yamlio import YamlNode

from .conftest import VIN


def state(**kw) -> LiftState:
    base = {"height_mm": 1750.0, "at_working_height": True, "moving": False, "fault": False,
            "model_code": 4711, "vin": VIN, "timestamp": 0.0}
    return LiftState(**{**base, **kw})


def test_defaults_are_one_read_of_twelve_holding_registers():
    m = RegisterMap()
    assert m.table == "holding"
    assert m.spans() == [(0, 12)]
    regs = m.encode(state(height_mm=1234.5, moving=True, at_working_height=False, fault=True))
    assert regs[0] == 12345                     # 0.1 mm per count
    assert regs[1] == 0b110                     # moving = bit 1, fault = bit 2
    assert regs[2] == 4711
    assert regs[3] == ord("W") << 8 | ord("V")  # first character in the high byte
    assert regs[11] == ord("3") << 8            # 17 characters, NUL-padded


def test_ready_needs_height_stillness_and_no_fault():
    assert state().ready
    assert not state(moving=True).ready
    assert not state(fault=True).ready
    assert not state(at_working_height=False).ready


def test_why_not_ready_says_which_of_the_three():
    """The operator reads "lift moving" while it moves at height, not "not at working
    height" (a newcomer saw that while the lift was settling at height)."""
    assert state().why_not_ready == ""
    assert state(moving=True).why_not_ready == "lift moving"
    assert state(moving=True, at_working_height=False).why_not_ready == "lift moving"
    assert state(at_working_height=False).why_not_ready == "lift not at working height"
    assert state(fault=True, moving=True).why_not_ready == "the lift PLC reports a fault"
    for kw in ({"moving": True}, {"fault": True}, {"at_working_height": False}, {}):
        assert bool(state(**kw).why_not_ready) != state(**kw).ready


@pytest.mark.parametrize("seed", range(6))
def test_encode_decode_round_trip(seed):
    rng = random.Random(seed)
    htype = rng.choice(sorted(NUMBER_TYPES))
    m = RegisterMap(
        table=rng.choice(["holding", "input"]), word_order=rng.choice(["big", "little"]),
        height=Number(100, htype, scale=rng.choice([0.1, 0.5, 1.0]), offset=-50.0),
        at_working_height=Bit(120, rng.randrange(16)), moving=Bit(121, 0), fault=Bit(121, 7),
        model_code=Number(130, rng.choice(["uint16", "uint32", "int32"])),
        vin=Text(140, rng.choice([8, 17, 20]), rng.choice(["big", "little"])))
    height = round(rng.uniform(0, 3000), 1)
    vin = "".join(rng.choice("ABCDEFGHJKLMNPRSTUVWXYZ0123456789") for _ in range(m.vin.length))
    s = state(height_mm=height, moving=rng.random() < 0.5, fault=rng.random() < 0.5,
              model_code=rng.randrange(60000), vin=vin, timestamp=12.5)
    got = m.decode(m.encode(s), 12.5)
    assert got == replace(s, height_mm=pytest.approx(height, abs=m.height.scale / 2))


def test_spans_split_at_gaps_and_at_125_registers():
    m = RegisterMap(height=Number(0), at_working_height=Bit(10, 0), moving=Bit(10, 1),
                    fault=Bit(10, 2), model_code=Number(11), vin=Text(200, 250))
    assert m.spans() == [(0, 1), (10, 2), (200, 125)]


def test_vin_absent_or_blank_is_none():
    assert RegisterMap(vin=None).decode(RegisterMap(vin=None).encode(state()), 0).vin is None
    m = RegisterMap()
    assert m.decode(m.encode(state(vin=None)), 0).vin is None


def test_non_ascii_vin_is_refused():
    m = RegisterMap()
    regs = m.encode(state())
    regs[4] = 0xFF41
    with pytest.raises(ValueError, match="non-ASCII"):
        m.decode(regs, 0)


def test_values_that_do_not_fit_are_refused():
    with pytest.raises(ValueError, match="does not fit a uint16"):
        RegisterMap().encode(state(height_mm=7000.0))
    with pytest.raises(ValueError, match="longer than 17"):
        RegisterMap().encode(state(vin=VIN + "X"))


@pytest.mark.parametrize(("kw", "field", "text"), [
    ({"model_code": Number(0)}, "model_code", "register 0 is also used by height"),
    ({"fault": Bit(2, 0)}, "fault", "also used by model_code"),
    ({"fault": Bit(1, 1)}, "fault", "bit 1 of register 1 is also moving"),
    ({"moving": Bit(1, 16)}, "moving", "out of range"),
    ({"height": Number(0, "int8")}, "height", "is not one of"),
    ({"model_code": Number(2, "float32")}, "model_code", "integer type"),
    ({"vin": Text(65530, 17)}, "vin", "out of range"),
    ({"table": "coils"}, "table", "not one of"),
])
def test_bad_maps_name_the_field(kw, field, text):
    with pytest.raises(MapError, match=text) as info:
        RegisterMap(**kw)
    assert info.value.field == field


def test_from_node_keeps_defaults_inside_fields():
    node = YamlNode.parse(
        "table: input\nword_order: little\nheight: {address: 20, type: float32}\n"
        "fault: {bit: 5}\nvin: null\n")
    m = lift_map(node)
    assert m.table == "input" and m.word_order == "little"
    assert m.height == Number(20, "float32", scale=0.1)     # scale kept from the default
    assert m.fault == Bit(1, 5)
    assert m.vin is None
    assert lift_map(YamlNode.parse("vin: {length: 8}\n")).vin == Text(3, 8)


@pytest.mark.parametrize(("text", "where"), [
    ("height: {adress: 3}\n", "lift.yaml:1: height.adress: unknown key"),
    ("moving: {bit: 16}\n", "lift.yaml:1: moving.bit: 16 is out of range"),
    ("table: coils\n", "lift.yaml:1: table: 'coils' is not one of"),
    ("height: {address: 0}\nmodel_code:\n  address: 0\n",
     "lift.yaml:3: model_code: register 0 is also used by height"),
])
def test_from_node_errors_name_file_line_and_key(text, where):
    with pytest.raises(ConfigError) as info:
        lift_map(YamlNode.parse(text, "lift.yaml"))
    assert str(info.value).startswith(where)


def test_registry_and_urls():
    assert lift_class("modbus-tcp://10.0.0.1:502") is ModbusLift
    assert lift_class("modbus-rtu:///dev/ttyUSB0") is ModbusLift
    assert lift_class("sim://lift") is SimLift
    with pytest.raises(UrlError) as info:
        open_lift("opcua://10.0.0.1")
    assert FORMS in str(info.value) and "'opcua'" in str(info.value)
    spec, opts = parse_modbus_url("modbus-rtu:///dev/ttyUSB0?baud=9600&parity=n&unit=3")
    assert (spec.target, spec.baud, spec.parity, spec.unit) == ("/dev/ttyUSB0", 9600, "N", 3)
    assert spec.describe() == "Modbus RTU /dev/ttyUSB0 9600 8N1 unit 3"
    assert opts == {"timeout": None}
    spec, _ = parse_modbus_url("modbus-tcp://plc.local?unit=2")
    assert (spec.target, spec.port, spec.unit) == ("plc.local", 502, 2)


@pytest.mark.parametrize(("url", "text"), [
    ("modbus-tcp://10.0.0.1?slave=1", "unknown option slave (accepted: timeout"),
    ("modbus-tcp://10.0.0.1?unit=300", "option unit='300' is not valid"),
    ("modbus-tcp:///dev/ttyUSB0", "expected a host"),
    ("modbus-rtu://host:502", "expected a serial port path"),
    ("modbus-rtu:///dev/ttyUSB0?parity=X", "option parity='X' is not valid"),
    ("sim://wrench", "expected sim://lift"),
    ("sim://lift?transport=udp", "option transport='udp' is not valid"),
])
def test_bad_urls_say_what_is_accepted(url, text):
    with pytest.raises(UrlError) as info:
        lift_class(url)(url)
    assert text in str(info.value)


def test_url_timing_wins_over_keywords():
    lift = ModbusLift("modbus-tcp://127.0.0.1?timeout=0.5", timeout=2.0)
    assert lift.timeout == 0.5
    assert not lift.is_open
    lift.close()  # closing a lift never opened is fine
