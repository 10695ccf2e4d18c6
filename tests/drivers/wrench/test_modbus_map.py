"""The wrench's register map: defaults, station.yaml with file/line errors, the codec, and a
non-default layout driven end to end (other addresses, 32-bit values in little word order,
ack code apart from ack, no VIN) through the real backend and the simulated controller."""

from __future__ import annotations

import pytest

from drivers.wrench import open_wrench
from drivers.wrench.modbus import ModbusWrench
from drivers.wrench.modbus_map import (
    Bit,
    MapError,
    Number,
    Text,
    WrenchRegisterMap,
    next_sequence,
    pack_status,
    spans,
    unpack_status,
)
from drivers.wrench.modbus_sim import SimParameters, SimRegisterController
from stationd.devicemaps import wrench_map
from stationd.errors import ConfigError
from stationd.yamlio import YamlNode

from .modbus_helpers import FAST


def test_the_default_layout_is_two_compact_blocks():
    m = WrenchRegisterMap()
    assert m.station_addresses() == {0, 1, 2, 3, 4, 5, *range(16, 29)}
    assert m.controller_addresses() == set(range(6, 16))
    assert m.status_spans() == [(6, 10)]                   # one read per poll


def test_codec_round_trips():
    m = WrenchRegisterMap()
    assert m.encode("torque_target", 44.0) == {1: 4400}
    assert m.encode("angle_target", 123.4) == {2: 1234}
    assert m.decode("result_angle", {13: 1058}) == 105.8    # not 105.80000000000001
    assert m.encode("result_id", 70000) == {14: 1, 15: 4464}
    little = WrenchRegisterMap(word_order="little")
    assert little.encode("result_id", 70000) == {14: 4464, 15: 1}
    assert little.integer("result_id", {14: 4464, 15: 1}) == 70000
    signed = WrenchRegisterMap(result_angle=Number(13, "int16", scale=0.1))
    assert signed.decode("result_angle", signed.encode("result_angle", -12.5)) == -12.5
    for bad in (655.36, -0.01, float("nan")):
        with pytest.raises(ValueError, match="torque_target"):
            m.encode("torque_target", bad)
    vin = m.encode_vin("WVW")          # two characters a register, NUL-padded to 25
    assert vin == {16: 0x5756, 17: 0x5700, **dict.fromkeys(range(18, 29), 0)}
    assert pack_status(True, 1, 1) == 0b01011 and unpack_status(0b10001) == (True, 0, 2)
    with pytest.raises(ValueError, match="status 3"):
        unpack_status(0b110)
    assert [next_sequence(v) for v in (0, 1, 65534, 65535)] == [1, 2, 65535, 1]
    assert spans({1, 2, 3, 7, *range(10, 140)}) == [(1, 3), (7, 1), (10, 125), (135, 5)]


@pytest.mark.parametrize(("kw", "field", "text"), [
    ({"request": Number(3, "uint32")}, "request", "plain uint16"),
    ({"pset": Number(0, scale=2.0)}, "pset", "without scale"),
    ({"torque_target": Number(1, "float32")}, "torque_target", "scaled integers"),
    ({"angle_target": Number(1)}, "angle_target", "register 1 is also used by torque_target"),
    ({"tool_enable": Bit(6, 3)}, "tool_enabled", "register 6 is also used by tool_enable"),
    ({"parameters_valid": Bit(6, 0)}, "parameters_valid", "same bit as tool_enabled"),
    ({"vin": Text(10, 4)}, "vin", "also used by"),
    ({"result_id": Number(65535, "uint32")}, "result_id", "out of range"),
    ({"word_order": "middle"}, "word_order", "big, little"),
])
def test_maps_that_cannot_work_are_refused(kw, field, text):
    with pytest.raises(MapError, match=text) as info:
        WrenchRegisterMap(**kw)
    assert info.value.field == field


def test_from_node_keeps_defaults_inside_fields():
    node = YamlNode.parse("torque_target: {address: 40, type: uint32}\n"
                          "tool_enable: {bit: 3}\nvin: null\nword_order: little\n")
    m = wrench_map(node)
    assert m.torque_target == Number(40, "uint32", scale=0.01)
    assert m.tool_enable == Bit(4, 3) and m.vin is None and m.word_order == "little"
    assert m.pset == WrenchRegisterMap().pset
    assert wrench_map(YamlNode.parse("vin: {length: 17}")).vin == Text(16, 17)


@pytest.mark.parametrize(("text", "where"), [
    ("request: {address: 3, type: uint32}\n", "wrench.yaml:1: request.type: unknown key"),
    ("pset: {address: 0}\nack: {address: 0}\n", "wrench.yaml:2: ack: register 0 is also"),
    ("torque_target: {scale: 0}\n", "wrench.yaml:1: torque_target: scale must be"),
    ("tool_enable: {bit: 16}\n", "wrench.yaml:1: tool_enable.bit: 16 is out of range"),
    ("tork_target: {address: 1}\n", "wrench.yaml:1: tork_target: unknown key"),
])
def test_from_node_errors_name_file_line_and_key(text, where):
    with pytest.raises(ConfigError) as info:
        wrench_map(YamlNode.parse(text, "wrench.yaml"))
    assert str(info.value).startswith(where), info.value


def test_a_plant_layout_end_to_end():
    """Status block first, ack code below ack and in its own span, 32-bit targets in little
    word order, no VIN: the handshake and results still work over the wire."""
    m = wrench_map(YamlNode.parse(
        "word_order: little\n"
        "tool_enabled: {address: 100, bit: 4}\nparameters_valid: {address: 100, bit: 5}\n"
        "ack_code: {address: 98}\nack: {address: 101}\nresult_counter: {address: 102}\n"
        "result_status: {address: 103}\nresult_pset: {address: 104}\n"
        "result_torque: {address: 105, type: uint32, scale: 0.001}\n"
        "result_angle: {address: 107, type: int16}\nresult_id: {address: 108}\n"
        "pset: {address: 200}\ntorque_target: {address: 201, type: int32, scale: 0.001}\n"
        "angle_target: {address: 203}\nrequest: {address: 204}\n"
        "tool_enable: {address: 205, bit: 15}\nresult_ack: {address: 206}\nvin: null\n"))
    assert m.status_spans() == [(98, 1), (100, 10)]
    with SimRegisterController(m, seed=4, nok_rate=0.0) as c:
        w = open_wrench(f"modbus-tcp://127.0.0.1:{c.start_tcp()}", register_map=m, **FAST)
        assert isinstance(w, ModbusWrench)
        with w:
            w.set_parameters(3, torque_nm=115.125, angle_deg=50.0)
            assert c.active == SimParameters(3, 115.125, 50.0)
            regs = c.registers()
            assert (regs[201], regs[202]) == (115125 & 0xFFFF, 115125 >> 16)   # little order
            w.enable_tool()
            assert regs[205] == 0 and c.registers()[205] == 1 << 15
            t = c.pull_trigger()
            r = w.wait_result(1.0)
            assert t is not None and r is not None
            assert (r.torque_nm, r.angle_deg, r.tightening_id) == (t.torque_nm, t.angle_deg, 1)
            with pytest.raises(ValueError, match="no VIN registers"):
                w.send_vin("WVW")
