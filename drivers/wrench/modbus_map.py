"""Where a register-driven tightening controller keeps each value, and how values are coded.

The backend (``modbus.py``) and the simulated controller (``modbus_sim.py``) both code and
decode through this module, so they agree by construction; the tests cross-check the layout
with an independent master (mbpoll).  The field types (:class:`Number`, :class:`Bit`,
:class:`Text`) and their coding come from ``drivers.registers``, shared with the lift, so
a station.yaml reads the same for both devices.  Addresses are 0-based wire (PDU) addresses of
holding registers.

Default layout, proposed to the controller's programmer when nothing exists yet (a compact
block: the station polls registers 6-15 in one read)::

    written by the station                    written by the controller
    0  pset                                   6  status: bit 0 tool enabled,
    1  torque target   (0.01 Nm, 0 = pset's)        bit 1 parameters valid
    2  angle target    (0.1 deg, 0 = pset's)  7  ack       (copy of the request number)
    3  request         (sequence number)      8  ack code  (0 accepted, else ACK_CODES)
    4  control: bit 0 tool enable             9  result counter
    5  result ack      (counter taken)        10 result status (RESULT_* bits)
    16-28 VIN (25 ASCII characters)           11 result pset
                                              12 torque (0.01 Nm)  13 angle (0.1 deg)
                                              14-15 tightening id (uint32)

Sequence numbers and counters are uint16 and wrap from 65535 to 1; 0 means "never".

``result_type`` (none in the default layout): where a controller reports what a result is,
a register holding Open Protocol's codes (MID 0061 parameter 49: 1 tightening, 2 loosening,
3 batch increment, ...), read into ``TighteningResult.result_type_code`` the same way, so
that a batch step on such a controller never closes a bolt either.  Without it a result
carries no type (the station then goes by what it sent).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime

from drivers import registers
from drivers.registers import Bit, MapError, Number, Text, spans
from drivers.wrench.base import ResultType, Status, TighteningResult, UnreadableResult

__all__ = ["ACK_CODES", "Bit", "MapError", "Number", "Text", "WrenchRegisterMap", "spans"]

#: ack codes the controller writes; any other non-zero code is a refusal too
ACK_CODES = {
    1: "unknown parameter set",
    2: "torque target outside the parameter set's limits",
    3: "angle target outside the parameter set's limits",
    4: "tool running: parameters cannot change now",
    5: "parameters locked on the controller",
}
#: result status register: bit 0 OK, bits 1-2 torque status, bits 3-4 angle status
#: (each 0 low, 1 OK, 2 high, as in Open Protocol)
RESULT_OK_BIT, TORQUE_STATUS_SHIFT, ANGLE_STATUS_SHIFT = 0, 1, 3
INTEGER_TYPES = ("uint16", "int16", "uint32", "int32")

# field kinds: what a field may be configured to (and which YAML keys it takes)
COUNTERS = ("request", "result_ack", "ack", "ack_code", "result_counter", "result_status")
INTEGERS = ("pset", "result_pset", "result_id")
SCALED = ("torque_target", "angle_target", "result_torque", "result_angle")
STATION_NUMBERS = ("pset", "torque_target", "angle_target", "request", "result_ack")
CONTROLLER_NUMBERS = ("ack", "ack_code", "result_counter", "result_status", "result_pset",
                      "result_torque", "result_angle", "result_id")
BITS = ("tool_enable", "tool_enabled", "parameters_valid")


def next_sequence(value: int) -> int:
    """The number after ``value`` in a 1..65535 cycle (0 is reserved for "never")."""
    return value % 0xFFFF + 1


def pack_status(ok: bool, torque_status: int, angle_status: int) -> int:
    return (int(ok) << RESULT_OK_BIT | torque_status << TORQUE_STATUS_SHIFT
            | angle_status << ANGLE_STATUS_SHIFT)


def unpack_status(value: int) -> tuple[bool, int, int]:
    """(ok, torque status, angle status); ValueError for a status 3 (undefined)."""
    t, a = value >> TORQUE_STATUS_SHIFT & 3, value >> ANGLE_STATUS_SHIFT & 3
    if 3 in (t, a):
        raise ValueError(f"result status register 0x{value:04x} holds status 3 (undefined)")
    return bool(value >> RESULT_OK_BIT & 1), t, a


@dataclass(frozen=True)
class WrenchRegisterMap:
    """Where each value lives (see the module docstring for the default layout).  Station
    registers are only written by the station and controller registers only by the
    controller, so the two never share a register."""

    # field(default=...): the defaults are frozen dataclasses from drivers.registers,
    # immutable, which ruff's RUF009 cannot see across modules
    word_order: str = "big"            # 32-bit values: big = high word at the lower address
    pset: Number = field(default=Number(0))
    torque_target: Number = field(default=Number(1, scale=0.01))
    angle_target: Number = field(default=Number(2, scale=0.1))
    request: Number = field(default=Number(3))
    tool_enable: Bit = field(default=Bit(4, 0))
    result_ack: Number = field(default=Number(5))
    tool_enabled: Bit = field(default=Bit(6, 0))
    parameters_valid: Bit = field(default=Bit(6, 1))
    ack: Number = field(default=Number(7))
    ack_code: Number = field(default=Number(8))
    result_counter: Number = field(default=Number(9))
    result_status: Number = field(default=Number(10))
    result_pset: Number = field(default=Number(11))
    result_torque: Number = field(default=Number(12, scale=0.01))
    result_angle: Number = field(default=Number(13, scale=0.1))
    result_id: Number = field(default=Number(14, "uint32"))
    vin: Text | None = field(default=Text(16, 25))
    result_type: Number | None = None  # the result's type code, where the controller has one

    def __post_init__(self) -> None:
        self.validate()

    # -- validation -----------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`MapError` for a map the handshake cannot work with."""
        registers.check_word_order(self.word_order)
        for name in (*COUNTERS, *INTEGERS, *SCALED):
            num: Number = getattr(self, name)
            if name in COUNTERS and (num.type, num.scale, num.offset) != ("uint16", 1.0, 0.0):
                raise MapError(name, "must be a plain uint16 (a sequence number or code)")
            if num.type not in INTEGER_TYPES:
                raise MapError(name, f"type {num.type!r} is not one of: "
                                     f"{', '.join(INTEGER_TYPES)} (scaled integers)")
            if name in INTEGERS and (num.scale, num.offset) != (1.0, 0.0):
                raise MapError(name, "must be an integer without scale or offset")
            registers.check_scale(name, num)
        for name in BITS:
            registers.check_bit(name, getattr(self, name))
        if self.tool_enabled == self.parameters_valid:
            raise MapError("parameters_valid", "uses the same bit as tool_enabled")
        if self.vin is not None:
            registers.check_text("vin", self.vin)
        if self.result_type is not None and (self.result_type.type, self.result_type.scale,
                                             self.result_type.offset) != ("uint16", 1.0, 0.0):
            raise MapError("result_type", "must be a plain uint16 (a type code)")
        owner: dict[int, str] = {}
        for name, words in self._registers().items():
            for a in words:
                if not 0 <= a <= 65535:
                    raise MapError(name, "address is out of range [0, 65535]")
                if a in owner and {name, owner[a]} != {"tool_enabled", "parameters_valid"}:
                    raise MapError(name, f"register {a} is also used by {owner[a]}")
                owner[a] = name

    def _registers(self) -> dict[str, range]:
        out = {name: range(n.address, n.address + n.words) for name in
               (*STATION_NUMBERS, *CONTROLLER_NUMBERS) for n in [getattr(self, name)]}
        out.update({name: range(b.address, b.address + 1) for name in BITS
                    for b in [getattr(self, name)]})
        if self.vin is not None:
            out["vin"] = range(self.vin.address, self.vin.address + self.vin.words)
        if self.result_type is not None:
            out["result_type"] = range(self.result_type.address, self.result_type.address + 1)
        return out

    # -- layout ---------------------------------------------------------------------------
    def station_addresses(self) -> set[int]:
        """Registers the station writes (the controller only reads them)."""
        regs = self._registers()
        names = (*STATION_NUMBERS, "tool_enable", *(("vin",) if self.vin else ()))
        return {a for name in names for a in regs[name]}

    def controller_addresses(self) -> set[int]:
        """Registers the controller writes: what the station polls."""
        regs = self._registers()
        names = (*CONTROLLER_NUMBERS, "tool_enabled", "parameters_valid",
                 *(("result_type",) if self.result_type else ()))
        return {a for name in names for a in regs[name]}

    def status_spans(self) -> list[tuple[int, int]]:
        return spans(self.controller_addresses())

    # -- coding ---------------------------------------------------------------------------
    def encode(self, name: str, value: float) -> dict[int, int]:
        """Registers holding ``value`` in field ``name``; ValueError if it does not fit."""
        num: Number = getattr(self, name)
        if not math.isfinite(value):
            raise ValueError(f"{name} must be a finite number, not {value}")
        raw = round((value - num.offset) / num.scale)
        try:
            return num.pack(raw, self.word_order)
        except struct.error:
            raise ValueError(f"{name} {value:g} does not fit a {num.type} with scale "
                             f"{num.scale:g}") from None

    def decode(self, name: str, regs: Mapping[int, int]) -> float:
        """The value of field ``name`` in ``regs`` (address -> register value)."""
        num: Number = getattr(self, name)
        raw = num.unpack(regs, self.word_order)
        # rounded to 9 decimals: 1058 * 0.1 is 105.8, not 105.80000000000001
        return round(raw * num.scale + num.offset, 9) if name in SCALED else raw

    def integer(self, name: str, regs: Mapping[int, int]) -> int:
        return int(self.decode(name, regs))

    def bit(self, name: str, regs: Mapping[int, int]) -> bool:
        b: Bit = getattr(self, name)
        return b.is_set(regs)

    def result(self, regs: Mapping[int, int], timestamp: datetime) -> TighteningResult:
        """The tightening in the result registers; ValueError for an undefined status.  The
        registers hold no VIN, limits, targets or controller clock: those are "" and 0.0,
        and ``timestamp`` is when the station read them (its own clock).  Its type code is
        the ``result_type`` register's, where the map has one (else None)."""
        ok, torque_status, angle_status = unpack_status(self.integer("result_status", regs))
        code = self.integer("result_type", regs) if self.result_type is not None else None
        try:
            kind = None if code is None else ResultType(code)
        except ValueError:
            kind = None                  # a code the specification does not name: kept
        return TighteningResult(
            ok=ok, torque_nm=self.decode("result_torque", regs),
            angle_deg=self.decode("result_angle", regs), torque_status=Status(torque_status),
            angle_status=Status(angle_status), tightening_id=self.integer("result_id", regs),
            pset=self.integer("result_pset", regs), vin="", timestamp=timestamp,
            torque_min_nm=0.0, torque_max_nm=0.0, torque_target_nm=0.0, angle_min_deg=0.0,
            angle_max_deg=0.0, angle_target_deg=0.0, result_type=kind, result_type_code=code,
            raw=" ".join(f"{a}={regs[a]}" for a in sorted(regs)), controller_clock=False)

    def unreadable(self, regs: Mapping[int, int], error: str) -> UnreadableResult:
        """The result registers that do not read (:meth:`result`'s ValueError, ``error``),
        kept whole: the result's registers as text (its counter among them; not the status
        and ack registers, which change with the station's commands: the same result read
        again after a restart is the same text, a copy), with its tightening id and pset (a
        register holds each on its own, so they read whatever the status says)."""
        names = ("result_counter", "result_status", "result_pset", "result_torque",
                 "result_angle", "result_id", *(("result_type",) if self.result_type else ()))
        mine = sorted({a for n in names for f in [getattr(self, n)]
                       for a in range(f.address, f.address + f.words)})
        return UnreadableResult(
            raw=" ".join(f"{a}={regs[a]}" for a in mine), mid=0, revision=0,
            error=f"result status: {error}", tightening_id=self.integer("result_id", regs),
            pset=self.integer("result_pset", regs))

    def encode_vin(self, vin: str) -> dict[int, int]:
        """The VIN registers, NUL-padded; ValueError if there are none or it does not fit."""
        if self.vin is None:
            raise ValueError("the register map has no VIN registers")
        if len(vin) > self.vin.length or not vin.isascii() or not vin.isprintable():
            raise ValueError(f"VIN must be printable ASCII, at most {self.vin.length} "
                             f"characters: {vin!r}")
        return self.vin.pack(vin.encode("ascii"))
