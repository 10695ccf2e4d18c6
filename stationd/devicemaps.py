"""Register maps from station.yaml: YAML nodes -> the drivers' plain map values.

The drivers know registers, not YAML (``drivers`` imports nothing from ``stationd``); reading
a map out of the station file, with errors that name file, line and key, is the
configuration's job and lives here.  Every key is optional and keeps its default, also inside a
field (``height: {address: 100}`` keeps the type and scale).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import fields, replace
from typing import Any

from drivers.lift.base import TABLES, RegisterMap
from drivers.registers import MAX_READ, NUMBER_TYPES, ORDERS, Bit, MapError, Number, Text
from drivers.wrench.modbus_map import (
    BITS,
    COUNTERS,
    INTEGER_TYPES,
    INTEGERS,
    SCALED,
    WrenchRegisterMap,
)
from stationd.yamlio import YamlNode


def number_from_node(node: YamlNode, default: Number, types: Sequence[str],
                     keys: Sequence[str] = ("address", "type", "scale", "offset")) -> Number:
    """``default`` with what ``node`` gives of ``keys``; a type must be one of ``types``."""
    sub = node.mapping(keys)
    given: dict[str, Any] = {k: v.number() for k, v in sub.items() if k in ("scale", "offset")}
    if "address" in sub:
        given["address"] = sub["address"].integer(lo=0, hi=65535)
    if "type" in sub:
        given["type"] = sub["type"].text(types)
    return replace(default, **given)


def bit_from_node(node: YamlNode, default: Bit) -> Bit:
    sub = node.mapping(("address", "bit"))
    return replace(default, **{k: v.integer(lo=0, hi=65535 if k == "address" else 15)
                               for k, v in sub.items()})


def text_from_node(node: YamlNode, default: Text) -> Text:
    sub = node.mapping(("address", "length", "byte_order"))
    given: dict[str, Any] = {}
    if "address" in sub:
        given["address"] = sub["address"].integer(lo=0, hi=65535)
    if "length" in sub:
        given["length"] = sub["length"].integer(lo=1, hi=2 * MAX_READ)
    if "byte_order" in sub:
        given["byte_order"] = sub["byte_order"].text(ORDERS)
    return replace(default, **given)


def lift_map(node: YamlNode) -> RegisterMap:
    """The lift PLC's register map (``drivers.lift.RegisterMap``)."""
    m = node.mapping([f.name for f in fields(RegisterMap)])
    default = RegisterMap()
    kw: dict[str, Any] = {}
    if "table" in m:
        kw["table"] = m["table"].text(TABLES)
    if "word_order" in m:
        kw["word_order"] = m["word_order"].text(ORDERS)
    for name in ("height", "model_code"):
        if name in m:
            kw[name] = number_from_node(m[name], getattr(default, name), tuple(NUMBER_TYPES))
    for name in ("at_working_height", "moving", "fault"):
        if name in m:
            kw[name] = bit_from_node(m[name], getattr(default, name))
    if "vin" in m:
        kw["vin"] = None if m["vin"].value() is None else text_from_node(
            m["vin"], default.vin or Text(0))
    try:
        return RegisterMap(**kw)
    except MapError as exc:
        raise m.get(exc.field, node).error(exc.message) from None


def wrench_map(node: YamlNode) -> WrenchRegisterMap:
    """A register-driven controller's map; counters take only an address; ``vin: null`` says
    the controller has no VIN registers; ``result_type: {address: N}`` that it reports each
    result's type (Open Protocol's codes) there."""
    m = node.mapping([f.name for f in fields(WrenchRegisterMap)])
    default = WrenchRegisterMap()
    kw: dict[str, Any] = {}
    if "word_order" in m:
        kw["word_order"] = m["word_order"].text(ORDERS)
    for name in (*COUNTERS, *INTEGERS, *SCALED):
        if name not in m:
            continue
        keys = ("address",) if name in COUNTERS else ("address", "type") \
            if name in INTEGERS else ("address", "type", "scale", "offset")
        kw[name] = number_from_node(m[name], getattr(default, name), INTEGER_TYPES, keys)
    for name in BITS:
        if name in m:
            kw[name] = bit_from_node(m[name], getattr(default, name))
    if "vin" in m:
        kw["vin"] = None if m["vin"].value() is None else text_from_node(
            m["vin"], default.vin or Text(0, 25))
    if "result_type" in m and m["result_type"].value() is not None:   # none by default
        kw["result_type"] = number_from_node(m["result_type"], Number(0), INTEGER_TYPES,
                                             ("address",))
    try:
        return WrenchRegisterMap(**kw)
    except MapError as exc:
        raise m.get(exc.field, node).error(exc.message) from None
