"""The lift PLC as the station sees it: one interface, one state, one register map.

The station asks a single question of the lift -- is a vehicle up at working height, steady and
without fault, and which vehicle is it -- so the interface is small: ``read_state()``.  How
that state is laid out in the PLC's registers differs from plant to plant, so the layout is
data (:class:`RegisterMap`, read from station.yaml with file/line errors), not code.  Decoding
and encoding live here, beside the map, so the real backend and the simulated PLC agree by
construction and both stay free of byte fiddling; the field types and their coding
(:class:`Number`, :class:`Bit`, :class:`Text`) come from ``drivers.registers``, shared with
the wrench's register map.

Addresses are the 0-based addresses sent on the wire (PDU addresses), see ``drivers.registers``.
"""

from __future__ import annotations

import math
import struct
import time
from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field

from drivers import registers
from drivers.counting import noun
from drivers.errors import DeviceError, ProtocolError
from drivers.lifecycle import Device
from drivers.registers import MAX_READ, NUMBER_TYPES, ORDERS, Bit, MapError, Number, Text, spans

__all__ = ["MAX_READ", "NUMBER_TYPES", "ORDERS", "TABLES", "Bit", "Lift", "LiftState",
           "MapError", "Number", "RegisterMap", "Text"]

TABLES = ("holding", "input")


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

    @property
    def why_not_ready(self) -> str:
        """What the operator reads while tightening may not start (empty when ready): the
        lift's own fault bit first, then moving (at the working height or not), then
        not at the working height."""
        if self.fault:
            return "the lift PLC reports a fault"
        if self.moving:
            return "lift moving"
        if not self.at_working_height:
            return "lift not at working height"
        return ""


@dataclass(frozen=True)
class RegisterMap:
    """Where the lift PLC keeps each field.  The defaults are a compact layout (one read of
    12 holding registers) to propose to the PLC programmer when nothing exists yet."""

    # field(default=...): the defaults are frozen dataclasses from drivers.registers,
    # immutable, which ruff's RUF009 cannot see across modules
    table: str = "holding"       # holding (function 3) | input (function 4)
    word_order: str = "big"      # 32-bit values: big = high word at the lower address
    height: Number = field(default=Number(0, "uint16", scale=0.1))   # 0.1 mm per count
    at_working_height: Bit = field(default=Bit(1, 0))
    moving: Bit = field(default=Bit(1, 1))
    fault: Bit = field(default=Bit(1, 2))
    model_code: Number = field(default=Number(2, "uint16"))
    vin: Text | None = field(default=Text(3, 17))

    def __post_init__(self) -> None:
        self.validate()

    # -- validation -----------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`MapError` for a map that cannot be read unambiguously."""
        if self.table not in TABLES:
            raise MapError("table", f"{self.table!r} is not one of: {', '.join(TABLES)}")
        registers.check_word_order(self.word_order)
        for name in ("height", "model_code"):
            num: Number = getattr(self, name)
            if num.type not in NUMBER_TYPES:
                raise MapError(name, f"type {num.type!r} is not one of: "
                                     f"{', '.join(NUMBER_TYPES)}")
            registers.check_scale(name, num)
        if self.model_code.type == "float32" or (self.model_code.scale, self.model_code.offset) \
                != (1.0, 0.0):
            raise MapError("model_code", "must be an integer type without scale or offset")
        for name in ("at_working_height", "moving", "fault"):
            registers.check_bit(name, getattr(self, name))
        if self.vin is not None:
            registers.check_text("vin", self.vin)
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
        return spans(self.addresses())

    # -- decoding and encoding ------------------------------------------------------------
    def decode(self, regs: Mapping[int, int], timestamp: float) -> LiftState:
        """The state held in ``regs`` (address -> register value); ValueError if the PLC
        sent something that is not a valid state (NaN height, non-ASCII VIN)."""
        height = self.height.unpack(regs, self.word_order) * self.height.scale \
            + self.height.offset
        if not math.isfinite(height):
            words = self.height.words
            raise ValueError(f"height {noun(words, 'register')} at {self.height.address} "
                             f"{noun(words, 'holds', 'hold')} {height}")
        return LiftState(height_mm=float(height),
                         at_working_height=self.at_working_height.is_set(regs),
                         moving=self.moving.is_set(regs), fault=self.fault.is_set(regs),
                         model_code=int(self.model_code.unpack(regs, self.word_order)),
                         vin=self._vin(regs), timestamp=timestamp)

    def _vin(self, regs: Mapping[int, int]) -> str | None:
        if self.vin is None:
            return None
        raw = self.vin.unpack(regs).strip(b"\0 ")
        if any(not 0x20 <= c < 0x7F for c in raw):
            last = self.vin.address + self.vin.words - 1
            raise ValueError(f"VIN registers {self.vin.address}-{last} hold non-ASCII bytes "
                             f"{raw!r}")
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
                out.update(num.pack(raw, self.word_order))
            except struct.error:
                raise ValueError(f"{name} {value} does not fit a {num.type}") from None
        for name, b in self._bits().items():
            if getattr(state, name):
                out[b.address] = b.applied(out[b.address], True)
        if self.vin is not None:
            text = (state.vin or "").encode("ascii")
            if len(text) > self.vin.length:
                raise ValueError(f"VIN {state.vin!r} is longer than {self.vin.length} characters")
            out.update(self.vin.pack(text))
        return out


class Lift(Device):
    """One lift PLC.  ``open()`` and ``close()`` are idempotent and the lift is a context
    manager (``drivers.lifecycle.Device``); backends implement the small ``_open`` /
    ``_close`` / ``_read_registers`` hooks and this class does the shared work (state checks,
    decoding, typed errors)."""

    def __init__(self, url: str, register_map: RegisterMap | None = None) -> None:
        super().__init__()
        self.url = url
        self.register_map = register_map if register_map is not None else RegisterMap()

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
    def _read_registers(self, spans: list[tuple[int, int]],
                        timeout: float | None) -> dict[int, int]:
        """Read every (start, count) span of the map's table: address -> value."""
