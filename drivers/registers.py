"""Register fields and how values are coded in 16-bit registers, for every Modbus device.

The lift's register map (``drivers.lift.base.RegisterMap``) and the wrench's
(``drivers.wrench.modbus_map.WrenchRegisterMap``) are built from the same field types
(:class:`Number`, :class:`Bit`, :class:`Text`), checked and read from station.yaml by the same
functions, so a station.yaml reads the same for both devices and word and byte order mean the
same.  What a field *means* (which fields a map has, which types it allows, how a value is
scaled and rounded) stays with each map.

Addresses are the 0-based addresses sent on the wire (PDU addresses).  A PLC manual that says
"40001" means wire address 0 of the holding registers; mbpoll's ``-0`` flag uses the same
numbering (without it, mbpoll's ``-r 1`` is wire address 0).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Literal

#: register types: struct code and number of 16-bit registers
NUMBER_TYPES: dict[str, tuple[str, int]] = {
    "uint16": ("H", 1), "int16": ("h", 1), "uint32": ("I", 2), "int32": ("i", 2),
    "float32": ("f", 2),
}
ORDERS = ("big", "little")
MAX_READ = 125  # registers in one Modbus read request (the protocol's limit)


class MapError(ValueError):
    """A register map that cannot work; ``field`` names the offending entry."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}")


@dataclass(frozen=True)
class Number:
    """A number in one or two registers; the value is ``raw * scale + offset``."""

    address: int
    type: str = "uint16"
    scale: float = 1.0
    offset: float = 0.0

    @property
    def words(self) -> int:
        return NUMBER_TYPES[self.type][1]

    def pack(self, raw: float | int, word_order: str) -> dict[int, int]:
        """The registers holding ``raw`` (unscaled); ``struct.error`` if it does not fit.
        ``word_order`` big: the high word at the lower address."""
        data = struct.pack(">" + NUMBER_TYPES[self.type][0], raw)
        words = [int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)]
        if word_order == "little":
            words = words[::-1]
        return dict(zip(range(self.address, self.address + self.words), words, strict=True))

    def unpack(self, regs: Mapping[int, int], word_order: str) -> float | int:
        """The raw (unscaled) number in ``regs`` (address -> register value)."""
        words = [regs[a] for a in range(self.address, self.address + self.words)]
        if word_order == "little":
            words = words[::-1]
        raw: float | int = struct.unpack(">" + NUMBER_TYPES[self.type][0],
                                         b"".join(w.to_bytes(2, "big") for w in words))[0]
        return raw


@dataclass(frozen=True)
class Bit:
    """One bit (0 = least significant) of one register."""

    address: int
    bit: int

    def is_set(self, regs: Mapping[int, int]) -> bool:
        return bool(regs[self.address] >> self.bit & 1)

    def applied(self, word: int, on: bool) -> int:
        """``word`` (the register's value) with this bit set or cleared."""
        return word & ~(1 << self.bit) | int(on) << self.bit


@dataclass(frozen=True)
class Text:
    """ASCII text, two characters a register; ``byte_order`` big = first character in the
    high byte (the Modbus convention; some PLCs swap)."""

    address: int
    length: int = 17
    byte_order: str = "big"

    @property
    def words(self) -> int:
        return (self.length + 1) // 2

    def _order(self) -> Literal["big", "little"]:
        return "big" if self.byte_order == "big" else "little"

    def pack(self, data: bytes) -> dict[int, int]:
        """The registers holding ``data`` (at most ``2 * words`` bytes), NUL-padded."""
        data = data.ljust(2 * self.words, b"\0")
        order = self._order()
        return {self.address + i: int.from_bytes(data[2 * i:2 * i + 2], order)
                for i in range(self.words)}

    def unpack(self, regs: Mapping[int, int]) -> bytes:
        """The ``length`` bytes held in ``regs`` (padding and all: the caller strips)."""
        order = self._order()
        return b"".join(regs[a].to_bytes(2, order)
                        for a in range(self.address, self.address + self.words))[:self.length]


def spans(addresses: Iterable[int]) -> list[tuple[int, int]]:
    """(start, count) reads covering ``addresses``: contiguous runs only (reading a gap could
    hit a register the device does not have), at most 125 registers each."""
    out: list[tuple[int, int]] = []
    for a in sorted(addresses):
        if out and out[-1][0] + out[-1][1] == a and out[-1][1] < MAX_READ:
            out[-1] = (out[-1][0], out[-1][1] + 1)
        else:
            out.append((a, 1))
    return out


# -- validation: the checks both maps make, with the same words -------------------------------
def check_word_order(word_order: str) -> None:
    if word_order not in ORDERS:
        raise MapError("word_order", f"{word_order!r} is not one of: big, little")


def check_scale(name: str, num: Number) -> None:
    if not (math.isfinite(num.scale) and num.scale != 0 and math.isfinite(num.offset)):
        raise MapError(name, "scale must be finite and non-zero, offset finite")


def check_bit(name: str, b: Bit) -> None:
    if not 0 <= b.bit <= 15:
        raise MapError(name, f"bit {b.bit} is out of range [0, 15]")


def check_text(name: str, text: Text) -> None:
    if not 1 <= text.length <= 2 * MAX_READ:
        raise MapError(name, f"length {text.length} is out of range [1, 250]")
    if text.byte_order not in ORDERS:
        raise MapError(name, f"byte_order {text.byte_order!r} is not big or little")
