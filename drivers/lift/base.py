"""The lift PLC as the station sees it: one interface, one state, one register map.

The station asks a single question of the lift -- is a vehicle up at working height, steady and
without fault, and which vehicle is it -- so the interface is small: ``read_state()``.  How
that state is laid out in the PLC's registers differs from plant to plant, so the layout is
data (:class:`RegisterMap`, read from station.yaml with file/line errors), not code.  Decoding
and encoding live here, beside the map, so the real backend and the simulated PLC agree by
construction and both stay free of byte fiddling.

Addresses are the 0-based addresses sent on the wire (PDU addresses).  A PLC manual that says
"40001" means wire address 0 of the holding registers; mbpoll's ``-0`` flag uses the same
numbering (without it, mbpoll's ``-r 1`` is wire address 0).
"""

from __future__ import annotations

import math
import struct
import time
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from types import TracebackType
from typing import Any, Literal, Self

from drivers.errors import DeviceError, ProtocolError
from stationd.yamlio import YamlNode

#: register types: struct code and number of 16-bit registers
NUMBER_TYPES: dict[str, tuple[str, int]] = {
    "uint16": ("H", 1), "int16": ("h", 1), "uint32": ("I", 2), "int32": ("i", 2),
    "float32": ("f", 2),
}
TABLES = ("holding", "input")
ORDERS = ("big", "little")
MAX_READ = 125  # registers in one Modbus read request (the protocol's limit)


class MapError(ValueError):
    """A register map that cannot work; ``field`` names the offending entry."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}")


@dataclass(frozen=True)
class LiftState:
    """What the PLC reported, decoded; ``timestamp`` is ``time.time()`` when it arrived."""

    height_mm: float
    at_working_height: bool
    moving: bool
    fault: bool
    model_code: int
    vin: str | None
    timestamp: float

    @property
    def ready(self) -> bool:
        """True only when tightening may start: at height, still, no fault."""
        return self.at_working_height and not self.moving and not self.fault


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


@dataclass(frozen=True)
class Bit:
    """One bit (0 = least significant) of one register."""

    address: int
    bit: int


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


@dataclass(frozen=True)
class RegisterMap:
    """Where the lift PLC keeps each field.  The defaults are a compact layout (one read of
    12 holding registers) to propose to the PLC programmer when nothing exists yet."""

    table: str = "holding"       # holding (function 3) | input (function 4)
    word_order: str = "big"      # 32-bit values: big = high word at the lower address
    height: Number = Number(0, "uint16", scale=0.1)   # 0.1 mm per count
    at_working_height: Bit = Bit(1, 0)
    moving: Bit = Bit(1, 1)
    fault: Bit = Bit(1, 2)
    model_code: Number = Number(2, "uint16")
    vin: Text | None = Text(3, 17)

    def __post_init__(self) -> None:
        self.validate()

    # -- validation -----------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`MapError` for a map that cannot be read unambiguously."""
        if self.table not in TABLES:
            raise MapError("table", f"{self.table!r} is not one of: {', '.join(TABLES)}")
        if self.word_order not in ORDERS:
            raise MapError("word_order", f"{self.word_order!r} is not one of: big, little")
        for name in ("height", "model_code"):
            num: Number = getattr(self, name)
            if num.type not in NUMBER_TYPES:
                raise MapError(name, f"type {num.type!r} is not one of: "
                                     f"{', '.join(NUMBER_TYPES)}")
            if not (math.isfinite(num.scale) and num.scale != 0 and math.isfinite(num.offset)):
                raise MapError(name, "scale must be finite and non-zero, offset finite")
        if self.model_code.type == "float32" or (self.model_code.scale, self.model_code.offset) \
                != (1.0, 0.0):
            raise MapError("model_code", "must be an integer type without scale or offset")
        for name in ("at_working_height", "moving", "fault"):
            b: Bit = getattr(self, name)
            if not 0 <= b.bit <= 15:
                raise MapError(name, f"bit {b.bit} is out of range [0, 15]")
        if self.vin is not None:
            if not 1 <= self.vin.length <= 2 * MAX_READ:
                raise MapError("vin", f"length {self.vin.length} is out of range [1, 250]")
            if self.vin.byte_order not in ORDERS:
                raise MapError("vin", f"byte_order {self.vin.byte_order!r} is not big or little")
        self._check_overlaps()

    def _words(self) -> dict[str, range]:
        """The registers each value field occupies."""
        out = {name: range(n.address, n.address + n.words)
               for name, n in (("height", self.height), ("model_code", self.model_code))}
        if self.vin is not None:
            out["vin"] = range(self.vin.address, self.vin.address + self.vin.words)
        return out

    def _bits(self) -> dict[str, Bit]:
        return {"at_working_height": self.at_working_height, "moving": self.moving,
                "fault": self.fault}

    def _check_overlaps(self) -> None:
        owner: dict[int, str] = {}
        for name, words in self._words().items():
            if words.start < 0 or words.stop > 65536:
                raise MapError(name, "address is out of range [0, 65535]")
            for a in words:
                if a in owner:
                    raise MapError(name, f"register {a} is also used by {owner[a]}")
                owner[a] = name
        seen: dict[tuple[int, int], str] = {}
        for name, b in self._bits().items():
            if not 0 <= b.address <= 65535:
                raise MapError(name, "address is out of range [0, 65535]")
            if b.address in owner:
                raise MapError(name, f"register {b.address} is also used by {owner[b.address]}")
            if (b.address, b.bit) in seen:
                raise MapError(name, f"bit {b.bit} of register {b.address} is also "
                                     f"{seen[(b.address, b.bit)]}")
            seen[(b.address, b.bit)] = name

    # -- layout ---------------------------------------------------------------------------
    def addresses(self) -> set[int]:
        """Every register the map uses."""
        out = {a for words in self._words().values() for a in words}
        return out | {b.address for b in self._bits().values()}

    def spans(self) -> list[tuple[int, int]]:
        """(start, count) reads covering the map: contiguous runs only (reading a gap could
        hit a register the PLC does not have), at most 125 registers each."""
        out: list[tuple[int, int]] = []
        for a in sorted(self.addresses()):
            if out and out[-1][0] + out[-1][1] == a and out[-1][1] < MAX_READ:
                out[-1] = (out[-1][0], out[-1][1] + 1)
            else:
                out.append((a, 1))
        return out

    # -- decoding and encoding ------------------------------------------------------------
    def _ordered(self, words: list[int]) -> bytes:
        if self.word_order == "little":
            words = words[::-1]
        return b"".join(w.to_bytes(2, "big") for w in words)

    def _number(self, num: Number, regs: Mapping[int, int]) -> float | int:
        code = NUMBER_TYPES[num.type][0]
        raw: float | int = struct.unpack(">" + code, self._ordered(
            [regs[a] for a in range(num.address, num.address + num.words)]))[0]
        return raw

    def decode(self, regs: Mapping[int, int], timestamp: float) -> LiftState:
        """The state held in ``regs`` (address -> register value); ValueError if the PLC
        sent something that is not a valid state (NaN height, non-ASCII VIN)."""
        height = self._number(self.height, regs) * self.height.scale + self.height.offset
        if not math.isfinite(height):
            raise ValueError(f"height register(s) at {self.height.address} hold {height}")
        def bit(b: Bit) -> bool:
            return bool(regs[b.address] >> b.bit & 1)

        return LiftState(height_mm=float(height), at_working_height=bit(self.at_working_height),
                         moving=bit(self.moving), fault=bit(self.fault),
                         model_code=int(self._number(self.model_code, regs)),
                         vin=self._vin(regs), timestamp=timestamp)

    def _vin(self, regs: Mapping[int, int]) -> str | None:
        if self.vin is None:
            return None
        words = [regs[a] for a in range(self.vin.address, self.vin.address + self.vin.words)]
        raw = b"".join(w.to_bytes(2, "big" if self.vin.byte_order == "big" else "little")
                       for w in words)[:self.vin.length].strip(b"\0 ")
        if any(not 0x20 <= c < 0x7F for c in raw):
            raise ValueError(f"VIN registers {self.vin.address}-{self.vin.address + len(words) - 1}"
                             f" hold non-ASCII bytes {raw!r}")
        return raw.decode("ascii") or None

    def encode(self, state: LiftState) -> dict[int, int]:
        """Registers (address -> value) holding ``state``: what a PLC with this map serves.
        ValueError for a value the registers cannot hold."""
        out = dict.fromkeys(self.addresses(), 0)
        for name, num, value in (("height", self.height, state.height_mm),
                                 ("model_code", self.model_code, state.model_code)):
            raw: float | int = (value - num.offset) / num.scale
            code = NUMBER_TYPES[num.type][0]
            if code != "f":
                raw = round(raw)
            try:
                data = struct.pack(">" + code, raw)
            except struct.error:
                raise ValueError(f"{name} {value} does not fit a {num.type}") from None
            words = [int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)]
            if self.word_order == "little":
                words = words[::-1]
            out.update(zip(range(num.address, num.address + num.words), words, strict=True))
        for name, b in self._bits().items():
            if getattr(state, name):
                out[b.address] |= 1 << b.bit
        if self.vin is not None:
            text = (state.vin or "").encode("ascii")
            if len(text) > self.vin.length:
                raise ValueError(f"VIN {state.vin!r} is longer than {self.vin.length} characters")
            text = text.ljust(2 * self.vin.words, b"\0")
            order: Literal["big", "little"] = "big" if self.vin.byte_order == "big" else "little"
            for i in range(self.vin.words):
                out[self.vin.address + i] = int.from_bytes(text[2 * i:2 * i + 2], order)
        return out

    # -- configuration --------------------------------------------------------------------
    @classmethod
    def from_node(cls, node: YamlNode) -> RegisterMap:
        """A map from station.yaml; every key is optional and keeps its default, also inside
        a field (``height: {address: 100}`` keeps type and scale)."""
        names = [f.name for f in fields(cls)]
        m = node.mapping(names)
        default = cls()
        kw: dict[str, Any] = {}
        if "table" in m:
            kw["table"] = m["table"].text(TABLES)
        if "word_order" in m:
            kw["word_order"] = m["word_order"].text(ORDERS)
        for name in ("height", "model_code"):
            if name in m:
                sub = m[name].mapping(("address", "type", "scale", "offset"))
                given: dict[str, Any] = {k: v.number() for k, v in sub.items()
                                         if k in ("scale", "offset")}
                if "address" in sub:
                    given["address"] = sub["address"].integer(lo=0, hi=65535)
                if "type" in sub:
                    given["type"] = sub["type"].text(tuple(NUMBER_TYPES))
                kw[name] = replace(getattr(default, name), **given)
        for name in ("at_working_height", "moving", "fault"):
            if name in m:
                sub = m[name].mapping(("address", "bit"))
                kw[name] = replace(getattr(default, name), **{
                    k: v.integer(lo=0, hi=65535 if k == "address" else 15)
                    for k, v in sub.items()})
        if "vin" in m:
            kw["vin"] = None if m["vin"].value() is None else cls._text_node(
                m["vin"], default.vin or Text(0))
        try:
            return cls(**kw)
        except MapError as exc:
            where = m.get(exc.field, node)
            raise where.error(exc.message) from None

    @staticmethod
    def _text_node(node: YamlNode, default: Text) -> Text:
        sub = node.mapping(("address", "length", "byte_order"))
        given: dict[str, Any] = {}
        if "address" in sub:
            given["address"] = sub["address"].integer(lo=0, hi=65535)
        if "length" in sub:
            given["length"] = sub["length"].integer(lo=1, hi=2 * MAX_READ)
        if "byte_order" in sub:
            given["byte_order"] = sub["byte_order"].text(ORDERS)
        return replace(default, **given)


class Lift(ABC):
    """One lift PLC.  ``open()`` and ``close()`` are idempotent and the lift is a context
    manager; backends implement the small ``_open`` / ``_close`` / ``_read_registers`` hooks
    and this class does the shared work (state checks, decoding, typed errors)."""

    def __init__(self, url: str, register_map: RegisterMap | None = None) -> None:
        self.url = url
        self.register_map = register_map if register_map is not None else RegisterMap()
        self._is_open = False

    @property
    def is_open(self) -> bool:
        return self._is_open

    def open(self) -> None:
        """Connect; a :class:`DeviceError` (e.g. ConnectError) if the PLC cannot be reached."""
        if not self._is_open:
            self._open()
            self._is_open = True

    def close(self) -> None:
        """Disconnect and stop any background work; safe to call twice."""
        if self._is_open:
            self._is_open = False
            self._close()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def read_state(self, timeout: float | None = None) -> LiftState:
        """Poll the PLC once; ``timeout`` (s) bounds the whole poll (default: the backend's).
        Raises DeviceTimeoutError, ConnectionLostError, RefusedError (a Modbus exception)
        or ProtocolError (registers that do not decode)."""
        if not self._is_open:
            raise DeviceError("the lift is not open", device=self.url)
        if timeout is not None and not timeout > 0:
            raise ValueError(f"timeout must be > 0, got {timeout}")
        regs = self._read_registers(self.register_map.spans(), timeout)
        try:
            return self.register_map.decode(regs, time.time())
        except ValueError as exc:
            raise ProtocolError(str(exc), device=self.url) from None

    @abstractmethod
    def identity(self) -> str:
        """A one-line description of the device and link, for logs and ``stationd probe``."""

    @abstractmethod
    def _open(self) -> None:
        """Connect; clean up everything itself if it fails."""

    @abstractmethod
    def _close(self) -> None:
        """Release everything; must not raise."""

    @abstractmethod
    def _read_registers(self, spans: list[tuple[int, int]],
                        timeout: float | None) -> dict[int, int]:
        """Read every (start, count) span of the map's table: address -> value."""
