"""Open Protocol tightening results: MID 0061 (pushed) and MID 0065 (asked for with MID 0064),
revisions 1 to 7, into one :class:`TighteningResult`.

Why one parser for all of them: every revision is a list of parameters, each a 2-digit tag
then a value of a fixed width, and a later revision only appends parameters (2 reorders
revision 1 and widens the job id).  So revision 1 is read in its fixed order (its byte
positions are in PROTOCOLS.md), and revisions 2 to 7 are read by tag: each tag says which
parameter follows and so how wide it is, so a controller that orders them differently or
sends a later revision's extra parameters is still read right.  MID 0065 has lists of its
own: revision 1 a short one, revisions 2 to 7 parameters 01-38 (the specification's tables
85-91: the tightening id first, no cell, channel or controller name, no limits, the station's
id and name in revision 7).  Read with MID 0061's tags, a controller's MID 0065 lost the
result fetched after a link cut (an independent implementation's trial).

Written from the Open Protocol specification (R2.x); the simulated controller's writer
(``sim/results.py``) is a separate table, so a misreading must be made twice to pass.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Any, TypeVar

from drivers.counting import noun
from drivers.errors import ProtocolError
from drivers.wrench.base import ResultType, Status, TighteningResult, TorqueUnit

MID_RESULT, MID_OLD_RESULT = 61, 65
HEADER_LEN = 20
MAX_REVISION = 7
TIME_FORMAT = "%Y-%m-%d:%H:%M:%S"


class LayoutError(ProtocolError):
    """The parameters are not where the revision puts them (a tag missing, unknown, out of
    place; a length that does not add up; a revision not read here): the body may be laid
    out as another revision.  Any other ProtocolError is a value that does not read in a
    body whose layout is right: that message is not read at another revision."""


@dataclass(frozen=True)
class Param:
    """One parameter: its name in TighteningResult terms, width, kind, and the revision that
    brought it (revisions 2+; a parameter of a revision is required from that one on)."""

    name: str
    width: int
    kind: str            # int, str, status, ok, torque (x100 Nm), angle, pct, time, x100
    since: int = 2
    core: bool = False   # must be a value (not spaces): without it there is no result


def _p(name: str, width: int, kind: str, since: int = 2, core: bool = False) -> Param:
    return Param(name, width, kind, since, core)


#: MID 0061 revision 1: parameters 01-23 in this order (fixed byte positions).
REV1_0061: tuple[Param, ...] = (
    _p("cell_id", 4, "int", 1), _p("channel_id", 2, "int", 1),
    _p("controller_name", 25, "str", 1), _p("vin", 25, "str", 1), _p("job", 2, "int", 1),
    _p("pset", 3, "int", 1, True), _p("batch_size", 4, "int", 1),
    _p("batch_counter", 4, "int", 1), _p("ok", 1, "ok", 1, True),
    _p("torque_status", 1, "status", 1, True), _p("angle_status", 1, "status", 1, True),
    _p("torque_min", 6, "torque", 1, True), _p("torque_max", 6, "torque", 1, True),
    _p("torque_target", 6, "torque", 1, True), _p("torque", 6, "torque", 1, True),
    _p("angle_min", 5, "angle", 1, True), _p("angle_max", 5, "angle", 1, True),
    _p("angle_target", 5, "angle", 1, True), _p("angle", 5, "angle", 1, True),
    _p("timestamp", 19, "time", 1, True), _p("pset_changed", 19, "time", 1),
    _p("batch_status", 1, "int", 1), _p("tightening_id", 10, "int", 1, True),
)

#: MID 0065 revision 1: parameters 01-11 in this order (no limits, no cell or controller).
REV1_0065: tuple[Param, ...] = (
    _p("tightening_id", 10, "int", 1, True), _p("vin", 25, "str", 1),
    _p("pset", 3, "int", 1, True), _p("batch_counter", 4, "int", 1),
    _p("ok", 1, "ok", 1, True), _p("torque_status", 1, "status", 1, True),
    _p("angle_status", 1, "status", 1, True), _p("torque", 6, "torque", 1, True),
    _p("angle", 5, "angle", 1, True), _p("timestamp", 19, "time", 1, True),
    _p("batch_status", 1, "int", 1),
)

#: the parameters revisions 4 to 6 append, to MID 0061 and MID 0065 alike
_REVISIONS_4_TO_6: tuple[Param, ...] = (
    _p("identifier2", 25, "str", 4), _p("identifier3", 25, "str", 4),
    _p("identifier4", 25, "str", 4),
    _p("customer_error_code", 4, "str", 5),
    _p("prevail_torque_compensate", 6, "torque", 6), _p("tightening_error_status2", 10, "int", 6),
)

#: MID 0061 revisions 2-7, by tag.
TAGGED: dict[int, Param] = dict(enumerate((
    _p("cell_id", 4, "int"), _p("channel_id", 2, "int"), _p("controller_name", 25, "str"),
    _p("vin", 25, "str"), _p("job", 4, "int"), _p("pset", 3, "int", core=True),
    _p("strategy", 2, "int"), _p("strategy_options", 5, "int"), _p("batch_size", 4, "int"),
    _p("batch_counter", 4, "int"), _p("ok", 1, "ok", core=True), _p("batch_status", 1, "int"),
    _p("torque_status", 1, "status", core=True), _p("angle_status", 1, "status", core=True),
    _p("rundown_angle_status", 1, "status"), _p("current_monitoring_status", 1, "status"),
    _p("selftap_status", 1, "status"), _p("prevail_torque_monitoring_status", 1, "status"),
    _p("prevail_torque_compensate_status", 1, "status"),
    _p("tightening_error_status", 10, "int"),
    _p("torque_min", 6, "torque", core=True), _p("torque_max", 6, "torque", core=True),
    _p("torque_target", 6, "torque", core=True), _p("torque", 6, "torque", core=True),
    _p("angle_min", 5, "angle", core=True), _p("angle_max", 5, "angle", core=True),
    _p("angle_target", 5, "angle", core=True), _p("angle", 5, "angle", core=True),
    _p("rundown_angle_min", 5, "angle"), _p("rundown_angle_max", 5, "angle"),
    _p("rundown_angle", 5, "angle"), _p("current_monitoring_min", 3, "pct"),
    _p("current_monitoring_max", 3, "pct"), _p("current_monitoring", 3, "pct"),
    _p("selftap_min", 6, "torque"), _p("selftap_max", 6, "torque"),
    _p("selftap", 6, "torque"), _p("prevail_torque_min", 6, "torque"),
    _p("prevail_torque_max", 6, "torque"), _p("prevail_torque", 6, "torque"),
    _p("tightening_id", 10, "int", core=True), _p("job_sequence_number", 5, "int"),
    _p("sync_tightening_id", 5, "int"), _p("tool_serial", 14, "str"),
    _p("timestamp", 19, "time", core=True), _p("pset_changed", 19, "time"),
    _p("pset_name", 25, "str", 3), _p("torque_unit", 1, "int", 3),
    _p("result_type", 2, "int", 3, core=True),   # blank: whether it may close a bolt unknown
    *_REVISIONS_4_TO_6,
    _p("compensated_angle", 7, "x100", 7), _p("angle_decimal", 7, "x100", 7),
), start=1))

#: MID 0065 revisions 2-7, by tag (the specification's tables 86-91).
TAGGED_0065: dict[int, Param] = dict(enumerate((
    _p("tightening_id", 10, "int", core=True), _p("vin", 25, "str"), _p("job", 4, "int"),
    _p("pset", 3, "int", core=True), _p("strategy", 2, "int"),
    _p("strategy_options", 5, "int"), _p("batch_size", 4, "int"),
    _p("batch_counter", 4, "int"), _p("ok", 1, "ok", core=True), _p("batch_status", 1, "int"),
    _p("torque_status", 1, "status", core=True), _p("angle_status", 1, "status", core=True),
    _p("rundown_angle_status", 1, "status"), _p("current_monitoring_status", 1, "status"),
    _p("selftap_status", 1, "status"), _p("prevail_torque_monitoring_status", 1, "status"),
    _p("prevail_torque_compensate_status", 1, "status"),
    _p("tightening_error_status", 10, "int"), _p("torque", 6, "torque", core=True),
    _p("angle", 5, "angle", core=True), _p("rundown_angle", 5, "angle"),
    _p("current_monitoring", 3, "pct"), _p("selftap", 6, "torque"),
    _p("prevail_torque", 6, "torque"), _p("job_sequence_number", 5, "int"),
    _p("sync_tightening_id", 5, "int"), _p("tool_serial", 14, "str"),
    _p("timestamp", 19, "time", core=True),
    _p("torque_unit", 1, "int", 3), _p("result_type", 2, "int", 3, core=True),
    *_REVISIONS_4_TO_6,
    _p("station_id", 10, "int", 7), _p("station_name", 25, "str", 7),
), start=1))


def tags(mid: int) -> dict[int, Param]:
    """The tagged parameters (revisions 2-7) of a MID 0061 or 0065."""
    return TAGGED if mid == MID_RESULT else TAGGED_0065


def fixed_params(mid: int) -> tuple[Param, ...]:
    """Revision 1's parameters, in order, of a MID 0061 or 0065."""
    return REV1_0061 if mid == MID_RESULT else REV1_0065


def tagged_length(mid: int, revision: int) -> int:
    """The length (header included) of a MID 0061/0065 of ``revision`` with every parameter
    of that revision once: what a controller sends, and what the simulator's writer is
    checked against."""
    if revision == 1:
        return HEADER_LEN + sum(2 + p.width for p in fixed_params(mid))
    return HEADER_LEN + sum(2 + p.width for p in tags(mid).values() if p.since <= revision)


def split_fields(mid: int, revision: int, text: str) -> dict[str, str]:
    """The raw parameter values of a result message (``text``: header + data), by name."""
    what = f"MID {mid:04d} revision {revision}"
    if revision == 1:
        return _split_fixed(what, fixed_params(mid), text)
    table = tags(mid)
    out: dict[str, str] = {}
    pos = HEADER_LEN
    while pos < len(text):
        tag_text = text[pos:pos + 2]
        param = table.get(int(tag_text)) if tag_text.isdigit() else None
        if param is None:
            raise LayoutError(f"{what}: unknown parameter {tag_text!r} at byte {pos + 1}")
        if param.name in out:
            raise LayoutError(f"{what}: parameter {tag_text} ({param.name}) twice")
        if pos + 2 + param.width > len(text):
            raise LayoutError(f"{what}: parameter {tag_text} ({param.name}) cut short "
                                f"at byte {len(text)}")
        out[param.name] = text[pos + 2:pos + 2 + param.width]
        pos += 2 + param.width
    missing = [f"{tag:02d} ({p.name})" for tag, p in table.items()
               if p.since <= revision and p.name not in out]
    if missing:
        raise LayoutError(f"{what}: {noun(len(missing), 'parameter')} missing: "
                          f"{', '.join(missing[:4])}" + (" ..." if len(missing) > 4 else ""))
    return out


def _split_fixed(what: str, table: tuple[Param, ...], text: str) -> dict[str, str]:
    length = HEADER_LEN + sum(2 + p.width for p in table)
    if len(text) != length:
        raise LayoutError(f"{what} has {length} bytes, got {len(text)}")
    out: dict[str, str] = {}
    pos = HEADER_LEN
    for tag, param in enumerate(table, start=1):
        found = text[pos:pos + 2]
        if found != f"{tag:02d}":
            raise LayoutError(f"{what}: expected tag {tag:02d} ({param.name}) at byte "
                                f"{pos + 1}, found {found!r}")
        out[param.name] = text[pos + 2:pos + 2 + param.width]
        pos += 2 + param.width
    return out


class _Reader:
    """Typed values out of the raw fields, each failure a ProtocolError naming the field."""

    def __init__(self, what: str, fields: dict[str, str], params: dict[str, Param]) -> None:
        self.what, self.fields, self.params = what, fields, params

    def get(self, name: str) -> Any:
        raw = self.fields.get(name)
        if raw is None:
            return None
        param = self.params[name]
        if param.kind == "str":
            # spaces or NULs after the text are padding.  The VIN (the one the station sent,
            # echoed: printable ASCII) with any other byte was garbled on the line, as a
            # letter in a number is: not the controller's.  Another text (a pset name a
            # controller may write in its own character set) is kept, what is not printable
            # written as ``\\xNN`` (a NUL refused by the line database's JSON)
            text = raw.rstrip(" \x00")
            if all(" " <= c <= "~" for c in text):
                return text
            if name == "vin":
                raise ProtocolError(f"{self.what} {name} {text!r} is not printable ASCII")
            return "".join(c if c.isprintable() else f"\\x{ord(c):02x}" for c in text)
        if not raw.strip(" "):
            if param.core:
                raise ProtocolError(f"{self.what} {name} is empty")
            return None
        return _CONVERT[param.kind](self, name, raw)

    def number(self, name: str, raw: str) -> int:
        if not raw.isdigit():
            raise ProtocolError(f"{self.what} {name} {raw!r} is not a number")
        return int(raw)

    def status(self, name: str, raw: str, allowed: int = 3) -> int:
        value = self.number(name, raw)
        if value >= allowed:
            raise ProtocolError(f"{self.what} {name} {value} is out of range")
        return value

    def time(self, name: str, raw: str) -> datetime | None:
        try:
            return datetime.strptime(raw, TIME_FORMAT)
        except ValueError:
            if self.params[name].core:
                raise ProtocolError(f"{self.what} {name} {raw!r} is not "
                                    "YYYY-MM-DD:HH:MM:SS") from None
            return None   # e.g. a pset never changed sent as zeros: not worth a lost result


_CONVERT: dict[str, Callable[[_Reader, str, str], Any]] = {
    "int": _Reader.number,
    "ok": lambda r, n, raw: bool(r.status(n, raw, 2)),
    "status": lambda r, n, raw: Status(r.status(n, raw)),
    "torque": lambda r, n, raw: r.number(n, raw) / 100,
    "angle": lambda r, n, raw: float(r.number(n, raw)),
    "pct": lambda r, n, raw: float(r.number(n, raw)),
    "time": _Reader.time,
    "x100": lambda r, n, raw: r.number(n, raw) / 100,
}
_TORQUES = ("torque", "torque_min", "torque_max", "torque_target", "selftap_min",
            "selftap_max", "selftap", "prevail_torque_min", "prevail_torque_max",
            "prevail_torque", "prevail_torque_compensate")


E = TypeVar("E", ResultType, TorqueUnit)


def _enum(cls: type[E], code: int | None) -> E | None:
    """A code the specification names, else None (a newer controller's code is not a reason
    to lose the result; ``raw`` keeps it)."""
    try:
        return None if code is None else cls(code)
    except ValueError:
        return None


def parse_tightening(mid: int, revision: int, text: str) -> TighteningResult:
    """A MID 0061 or 0065 message of revision 1-7 (``text``: header + data, ASCII) -> the
    result.  Torques are converted to Nm from the controller's unit where it says one."""
    if mid not in (MID_RESULT, MID_OLD_RESULT):
        raise ProtocolError(f"MID {mid:04d} is not a tightening result")
    if not 1 <= revision <= MAX_REVISION:
        raise LayoutError(f"MID {mid:04d} revision {revision} is not supported (1-"
                            f"{MAX_REVISION})")
    what = f"MID {mid:04d}" if revision == 1 else f"MID {mid:04d} revision {revision}"
    fields = split_fields(mid, revision, text)
    params = {p.name: p for p in (fixed_params(mid) if revision == 1
                                  else tags(mid).values())}
    r = _Reader(what, fields, params)
    v: dict[str, Any] = {name: r.get(name) for name in params}
    unit = _enum(TorqueUnit, v.get("torque_unit"))
    factor = unit.to_nm if unit is not None else None
    if factor is not None and factor != 1.0:
        for name in _TORQUES:
            if v.get(name) is not None:
                v[name] = round(v[name] * factor, 6)
    result_type = _enum(ResultType, v.get("result_type"))

    def num(name: str, default: float = 0.0) -> float:
        value = v.get(name)
        return default if value is None else float(value)

    def whole(name: str) -> int:
        value = v.get(name)
        return 0 if value is None else int(value)

    return TighteningResult(
        ok=v["ok"], torque_nm=v["torque"], angle_deg=v["angle"],
        torque_status=v["torque_status"], angle_status=v["angle_status"],
        tightening_id=v["tightening_id"], pset=v["pset"], vin=v.get("vin") or "",
        timestamp=v["timestamp"], torque_min_nm=num("torque_min"),
        torque_max_nm=num("torque_max"), torque_target_nm=num("torque_target"),
        angle_min_deg=num("angle_min"), angle_max_deg=num("angle_max"),
        angle_target_deg=num("angle_target"), cell_id=whole("cell_id"),
        channel_id=whole("channel_id"), controller_name=v.get("controller_name") or "",
        job=whole("job"), batch_size=whole("batch_size"),
        batch_counter=whole("batch_counter"), batch_status=whole("batch_status"),
        pset_changed=v.get("pset_changed"), raw=text, revision=revision,
        fetched=mid == MID_OLD_RESULT, strategy=v.get("strategy"),
        strategy_options=v.get("strategy_options"), result_type=result_type,
        result_type_code=v.get("result_type"),
        pset_name=v.get("pset_name") or "", torque_unit=unit,
        rundown_angle_status=v.get("rundown_angle_status"),
        current_monitoring_status=v.get("current_monitoring_status"),
        selftap_status=v.get("selftap_status"),
        prevail_torque_monitoring_status=v.get("prevail_torque_monitoring_status"),
        prevail_torque_compensate_status=v.get("prevail_torque_compensate_status"),
        tightening_error_status=v.get("tightening_error_status"),
        tightening_error_status2=v.get("tightening_error_status2"),
        rundown_angle_min_deg=v.get("rundown_angle_min"),
        rundown_angle_max_deg=v.get("rundown_angle_max"),
        rundown_angle_deg=v.get("rundown_angle"),
        current_monitoring_min_pct=v.get("current_monitoring_min"),
        current_monitoring_max_pct=v.get("current_monitoring_max"),
        current_monitoring_pct=v.get("current_monitoring"),
        selftap_min_nm=v.get("selftap_min"), selftap_max_nm=v.get("selftap_max"),
        selftap_nm=v.get("selftap"), prevail_torque_min_nm=v.get("prevail_torque_min"),
        prevail_torque_max_nm=v.get("prevail_torque_max"),
        prevail_torque_nm=v.get("prevail_torque"),
        prevail_torque_compensate_nm=v.get("prevail_torque_compensate"),
        job_sequence_number=v.get("job_sequence_number"),
        sync_tightening_id=v.get("sync_tightening_id"), tool_serial=v.get("tool_serial") or "",
        identifiers=tuple(v[f"identifier{i}"] for i in (2, 3, 4) if f"identifier{i}" in fields),
        customer_error_code=v.get("customer_error_code") or "",
        compensated_angle_deg=v.get("compensated_angle"),
        angle_decimal_deg=v.get("angle_decimal"))
