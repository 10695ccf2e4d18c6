"""Open Protocol tightening curves: MID 0900 (trace curve data) and the generic subscription
that asks for it (MID 0008, stopped with MID 0009).  Pure functions, no I/O.

MID 0900 revision 1, as the specification (R2.8+) lays it out and integrators' libraries read
it (node-open-protocol, OpenProtocolInterpreter): after the 20-byte header,

    result data identifier 10 (the tightening id), time stamp 19 (YYYY-MM-DD:HH:MM:SS),
    number of PIDs 3, then that many data fields,
    trace type 2 (1 angle, 2 torque, 3 current, 4 gradient, 5 stroke, 6 force),
    transducer type 2, unit 3 (001 N m, 050 degree, ...),
    number of parameter data fields 3, then that many data fields,
    number of resolution fields 3, then that many resolution fields,
    number of trace samples 5, a NUL, then the samples: 2 bytes each.

A data field is PID 5, length 3, data type 2, unit 3, step number 4, value (length); a
resolution field is first index 5, last index 5, length 3, data type 2, unit 3 (200 s, 201
min, 202 ms, 203 h), time value (length): the time between samples over that index range.

The samples are read as **signed 16-bit integers, big-endian** (network order): so the
specification's later editions say (R2.21: "big-endian signed Int16"), and so the libraries
read them (node-open-protocol subtracts 0x10000 from a value with bit 15 set).  Their
scaling is a data field: PID 02213 is a coefficient the sample is **divided** by, PID 02214
a multiplier it is **multiplied** by (either may be among the PIDs or the parameter data
fields); with neither, the sample is the value.

Torque traces in a unit this module knows are converted to N m, angle traces in radians to
degrees (as ``TighteningResult`` holds N m and degrees); another unit is kept as sent and
named by its code.

A trace longer than one message (9999 bytes) comes in parts (header "number of parts" > 1):
``parts.py`` puts them together and :func:`parse_curve_data` reads the whole data.  MID
0901 (plot parameters) and 0902 (the result database's extent) are in ``tracedata.py``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime
from enum import IntEnum

from drivers.errors import ProtocolError

MID_DATA_SUBSCRIBE, MID_DATA_UNSUBSCRIBE, MID_TRACE = 8, 9, 900
HEADER_LEN = 20
TIME_FORMAT = "%Y-%m-%d:%H:%M:%S"
PID_COEFFICIENT, PID_MULTIPLIER = "02213", "02214"
#: MID 0004 codes that mean "this controller gives no curves" (the driver turns curves off):
#: unknown MID, MID unsupported, subscribed MID (revision) unsupported, subscription on
#: specific data unsupported
CURVE_REFUSALS = frozenset({73, 74, 75, 76, 78, 97, 99})
#: the trace types the station asks for: angle and torque (the torque-angle plot)
STATION_TRACES = (1, 2)


class TraceType(IntEnum):
    ANGLE = 1
    TORQUE = 2
    CURRENT = 3
    GRADIENT = 4
    STROKE = 5
    FORCE = 6


#: unit code -> (unit name after conversion, factor to it)
UNITS: dict[int, tuple[str, float]] = {
    1: ("Nm", 1.0), 2: ("Nm", 1.3558179483314004), 3: ("Nm", 0.01), 4: ("Nm", 1000.0),
    6: ("Nm", 0.1129848290276167), 11: ("Nm", 0.1),
    50: ("deg", 1.0), 51: ("deg", 180.0 / math.pi),
    750: ("A", 1.0), 300: ("N", 1.0), 301: ("N", 1000.0), 351: ("mm", 1.0),
    9: ("%", 1.0), 800: ("%", 1.0),
}
#: time unit code -> seconds
TIME_UNITS = {200: 1.0, 201: 60.0, 202: 0.001, 203: 3600.0}


@dataclass(frozen=True)
class Curve:
    """One trace of one tightening, as the controller sent it (MID 0900), scaled.

    ``values`` are in ``unit`` (N m and degrees when the controller's unit converts; else
    the controller's unit, named ``"unit NNN"``).  ``time_step_s`` is the time between
    samples when it is one value over the whole trace, else None and ``times_s`` has each
    sample's time from the first (it is filled in both cases)."""

    tightening_id: int
    trace_type: int                       # a TraceType value (others kept as sent)
    values: tuple[float, ...]
    unit: str
    time_step_s: float | None
    times_s: tuple[float, ...]
    timestamp: datetime | None = None     # the controller's clock, naive, as sent
    unit_code: int = 0

    @property
    def name(self) -> str:
        """``torque``, ``angle``, ... (``trace 9`` for a type this module does not know)."""
        try:
            return TraceType(self.trace_type).name.lower()
        except ValueError:
            return f"trace {self.trace_type}"


def subscribe_data(traces: Iterable[int] = STATION_TRACES) -> bytes:
    """MID 0008 (revision 1) data subscribing to MID 0900 revision 1: the subscribed MID,
    its revision, the extra data's length, then the extra data (R2.8.0 table 158): send
    alternative 0 (new data only), the time stamp and index identifiers (zeros: unused), the
    number of trace types (2 digits) and each (3 digits)."""
    return _trace_subscription("0" + "0" * 19 + "0" * 10, traces)


def replay_data(first: int, last: int, traces: Iterable[int] = STATION_TRACES) -> bytes:
    """MID 0008 data asking for the stored traces of the tightenings ``first`` to ``last``
    (R2.8.0 table 158, send alternative 3, "stored data between two indexes": the index is
    the result's id, the tightening id MID 0900 carries): the first and last index (10
    digits each), the number of trace types and each."""
    return _trace_subscription(f"3{first:010d}{last:010d}", traces)


def _trace_subscription(head: str, traces: Iterable[int]) -> bytes:
    kinds = list(traces)
    extra = head + f"{len(kinds):02d}" + "".join(f"{t:03d}" for t in kinds)
    return f"{MID_TRACE:04d}001{len(extra):02d}{extra}".encode("ascii")


def unsubscribe_data() -> bytes:
    """MID 0009 (revision 1) data: the MID to stop, its revision, no extra data."""
    return f"{MID_TRACE:04d}00100".encode("ascii")


class FieldReader:
    """Reads the ASCII part field by field; every failure is a ProtocolError naming it
    (and the MID, ``label``)."""

    def __init__(self, data: bytes, label: str = "MID 0900") -> None:
        self.data, self.pos, self.label = data, 0, label

    def take(self, width: int, what: str) -> str:
        raw = self.data[self.pos:self.pos + width]
        if len(raw) != width:
            raise ProtocolError(f"{self.label} ends inside {what} (at byte "
                                f"{HEADER_LEN + self.pos})")
        if not raw.isascii() or b"\x00" in raw:
            raise ProtocolError(f"{self.label} {what} is not ASCII text: {raw!r}")
        self.pos += width
        return raw.decode("ascii")

    def number(self, width: int, what: str) -> int:
        text = self.take(width, what).strip()
        if not text.isdigit():
            raise ProtocolError(f"{self.label} {what} {text!r} is not a number")
        return int(text)


def data_fields(r: FieldReader, count: int, what: str) -> dict[str, str]:
    """``count`` data fields: PID -> value text (the first of a PID repeated by steps)."""
    out: dict[str, str] = {}
    for i in range(count):
        pid = r.take(5, f"{what} {i + 1} PID")
        length = r.number(3, f"{what} {i + 1} length")
        r.take(2 + 3 + 4, f"{what} {i + 1} type, unit and step")
        out.setdefault(pid, r.take(length, f"{what} {i + 1} ({pid}) value").strip())
    return out


def _float(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ProtocolError(f"MID 0900 {what} {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ProtocolError(f"MID 0900 {what} {text!r} is not a finite number")
    return value


def parse_curve(raw: bytes) -> Curve:
    """A MID 0900 message (header + data, without the framing NUL) -> :class:`Curve`;
    anything that does not read is a ProtocolError saying what.  One part of several is
    refused: its parts are put together first (``parts.py``), then read with
    :func:`parse_curve_data`."""
    if len(raw) < HEADER_LEN or raw[4:8] != b"0900":
        raise ProtocolError(f"not a MID 0900: {raw[:20]!r}")
    parts = raw[18:19].strip(b" 0")
    if parts not in (b"", b"1"):
        raise ProtocolError("MID 0900 part of several (a trace longer than one message): "
                            "put its parts together first")
    return parse_curve_data(raw[HEADER_LEN:])


def parse_curve_data(data: bytes) -> Curve:
    """The data of a MID 0900 revision 1 (after its header; a message's parts joined) ->
    :class:`Curve`; anything that does not read is a ProtocolError saying what."""
    r = FieldReader(data)
    tid = r.number(10, "result data identifier")
    stamp = r.take(19, "time stamp")
    try:
        when: datetime | None = datetime.strptime(stamp, TIME_FORMAT)
    except ValueError:
        when = None                      # a curve with an odd clock is still a curve
    pids = data_fields(r, r.number(3, "number of PIDs"), "PID")
    trace_type = r.number(2, "trace type")
    r.take(2, "transducer type")
    unit_code = r.number(3, "unit")
    params = data_fields(r, r.number(3, "number of parameter data fields"), "parameter field")
    steps: list[tuple[int, float]] = []          # (samples covered, seconds between them)
    for i in range(r.number(3, "number of resolution fields")):
        first = r.number(5, f"resolution field {i + 1} first index")
        last = r.number(5, f"resolution field {i + 1} last index")
        length = r.number(3, f"resolution field {i + 1} length")
        r.take(2, f"resolution field {i + 1} data type")
        tunit = r.number(3, f"resolution field {i + 1} unit")
        value = _float(r.take(length, f"resolution field {i + 1} time value").strip(),
                       f"resolution field {i + 1} time value")
        if last < first or tunit not in TIME_UNITS:
            raise ProtocolError(f"MID 0900 resolution field {i + 1}: indexes {first}-{last}, "
                                f"time unit {tunit:03d}")
        steps.append((last - first + 1, value * TIME_UNITS[tunit]))
    count = r.number(5, "number of trace samples")
    if r.data[r.pos:r.pos + 1] != b"\x00":
        raise ProtocolError("MID 0900: no NUL between the trace's description and its "
                            "samples")
    binary = r.data[r.pos + 1:]
    if len(binary) != 2 * count:
        raise ProtocolError(f"MID 0900 says {count} samples (2 bytes each) but carries "
                            f"{len(binary)} bytes of them")
    scale = 1.0
    fields = {**pids, **params}
    if PID_COEFFICIENT in fields:
        coefficient = _float(fields[PID_COEFFICIENT], "coefficient (PID 02213)")
        if coefficient == 0:
            raise ProtocolError("MID 0900 coefficient (PID 02213) is 0")
        scale = 1.0 / coefficient
    elif PID_MULTIPLIER in fields:
        scale = _float(fields[PID_MULTIPLIER], "multiplier (PID 02214)")
    unit, factor = UNITS.get(unit_code, (f"unit {unit_code:03d}", 1.0))
    samples = struct.unpack(f">{count}h", binary)
    values = tuple(s * scale * factor for s in samples)
    uniform = {step for _, step in steps}
    times: list[float] = []
    t = 0.0
    for covered, step in steps or [(count, 0.0)]:
        for _ in range(covered):
            if len(times) == count:
                break
            times.append(t)
            t += step
    while len(times) < count:            # samples past the last range: its step goes on
        times.append(t)
        t += steps[-1][1] if steps else 0.0
    return Curve(tightening_id=tid, trace_type=trace_type, values=values, unit=unit,
                 time_step_s=uniform.pop() if len(uniform) == 1 else None,
                 times_s=tuple(times), timestamp=when, unit_code=unit_code)
