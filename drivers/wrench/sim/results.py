"""The simulated controller's result writer: MID 0061 and 0065, revisions 1 to 7 (each MID
its own lists: MID 0065 is not MID 0061 relabelled).

Why a module of its own, and tables rather than a loop over the client's: the simulator must
be an independent reading of the specification.  Here each revision is written out as the
list of parameters it appends (tag, width, value), the way the specification's tables read;
the client (``result.py``) reads by tag from a table of its own, so a wrong width or tag
has to be made twice, differently, to pass the tests.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from datetime import datetime

TIME = "%Y-%m-%d:%H:%M:%S"
#: Nm per unit for the torque units the simulator can be set to (MID 0061 parameter 48)
NM_PER = {1: 1.0, 2: 1.3558179483314004, 3: 0.1129848290276167, 4: 9.80665}


@dataclass(frozen=True)
class SimRecord:
    """Everything the controller knows about one tightening; torques in Nm x 100 (integers,
    as on the wire), angles in degrees."""

    tightening_id: int
    cell: int
    channel: int
    name: str
    vin: str
    pset: int
    pset_name: str
    batch_size: int
    batch_counter: int
    batch_status: int
    ok: bool
    torque_status: int
    angle_status: int
    torque_min: int
    torque_max: int
    torque_target: int
    torque: int
    angle_min: int
    angle_max: int
    angle_target: int
    angle: int
    angle_exact: float
    timestamp: datetime
    pset_changed: datetime
    result_type: int = 1
    torque_unit: int = 1
    tool_serial: str = "SIMTOOL0000001"


#: a record's times, written as ISO text in a line of the controller's memory
_TIMES = ("timestamp", "pset_changed")


def record_line(r: SimRecord) -> str:
    """``r`` as one line of JSON (no newline): how the controller keeps it in a file of its
    own (:meth:`~drivers.wrench.sim.controller.SimController.keep_results_in`)."""
    doc = asdict(r)
    for key in _TIMES:
        doc[key] = doc[key].isoformat()
    return json.dumps(doc, separators=(",", ":"))


def record_of(line: str) -> SimRecord | None:
    """The record a line of :func:`record_line` holds; None for one that does not read (cut
    short by a process killed while writing it, or of another layout)."""
    try:
        doc = json.loads(line)
        known = {f.name for f in fields(SimRecord)}
        if not isinstance(doc, dict) or not known >= set(doc):
            return None
        for key in _TIMES:
            doc[key] = datetime.fromisoformat(doc[key])
        return SimRecord(**doc)
    except (ValueError, TypeError, KeyError):
        return None


def fixed(value: float, width: int) -> str:
    return f"{min(max(round(value), 0), 10**width - 1):0{width}d}"


def text(value: str, width: int) -> str:
    return value[:width].ljust(width)


def _tq(r: SimRecord, nm_x100: int) -> str:
    """A torque in the record's unit, x100, 6 digits."""
    return fixed(nm_x100 / NM_PER[r.torque_unit], 6)


def _rev1_0061(r: SimRecord) -> list[str]:
    return [fixed(r.cell, 4), fixed(r.channel, 2), text(r.name, 25), text(r.vin, 25), "00",
            fixed(r.pset, 3), fixed(r.batch_size, 4), fixed(r.batch_counter, 4),
            str(int(r.ok)), str(r.torque_status), str(r.angle_status), _tq(r, r.torque_min),
            _tq(r, r.torque_max), _tq(r, r.torque_target), _tq(r, r.torque),
            fixed(r.angle_min, 5), fixed(r.angle_max, 5), fixed(r.angle_target, 5),
            fixed(r.angle, 5), r.timestamp.strftime(TIME), r.pset_changed.strftime(TIME),
            str(r.batch_status), fixed(r.tightening_id, 10)]


def _rev1_0065(r: SimRecord) -> list[str]:
    return [fixed(r.tightening_id, 10), text(r.vin, 25), fixed(r.pset, 3),
            fixed(r.batch_counter, 4), str(int(r.ok)), str(r.torque_status),
            str(r.angle_status), _tq(r, r.torque), fixed(r.angle, 5),
            r.timestamp.strftime(TIME), str(r.batch_status)]


def _error_bits(r: SimRecord) -> int:
    """Tightening error status: bit 2 torque low, 3 torque high, 4 angle low, 5 angle high
    (a simulation's choice; the client keeps the number as it came)."""
    return ((r.torque_status == 0) << 2 | (r.torque_status == 2) << 3
            | (r.angle_status == 0) << 4 | (r.angle_status == 2) << 5)


def _rev2(r: SimRecord) -> list[str]:
    """Parameters 01-46 (revision 2 reorders revision 1 and adds the monitors)."""
    rundown = 720 + r.angle
    return [fixed(r.cell, 4), fixed(r.channel, 2), text(r.name, 25), text(r.vin, 25),
            "0000", fixed(r.pset, 3), "02", "00000", fixed(r.batch_size, 4),
            fixed(r.batch_counter, 4), str(int(r.ok)), str(r.batch_status),
            str(r.torque_status), str(r.angle_status), "1", "1", "1", "1", "1",
            fixed(_error_bits(r), 10), _tq(r, r.torque_min), _tq(r, r.torque_max),
            _tq(r, r.torque_target), _tq(r, r.torque), fixed(r.angle_min, 5),
            fixed(r.angle_max, 5), fixed(r.angle_target, 5), fixed(r.angle, 5),
            fixed(360, 5), fixed(1800, 5), fixed(rundown, 5), "030", "090", "055",
            _tq(r, 0), _tq(r, 500), _tq(r, 150), _tq(r, 0), _tq(r, 300), _tq(r, 80),
            fixed(r.tightening_id, 10), fixed(r.tightening_id % 100000, 5), "00000",
            text(r.tool_serial, 14), r.timestamp.strftime(TIME),
            r.pset_changed.strftime(TIME)]


def _rev2_0065(r: SimRecord) -> list[str]:
    """MID 0065's parameters 01-28 (the specification's table 86): the tightening id first,
    no cell, channel, controller name or limits."""
    return [fixed(r.tightening_id, 10), text(r.vin, 25), "0000", fixed(r.pset, 3), "02",
            "00000", fixed(r.batch_size, 4), fixed(r.batch_counter, 4), str(int(r.ok)),
            str(r.batch_status), str(r.torque_status), str(r.angle_status), "1", "1", "1",
            "1", "1", fixed(_error_bits(r), 10), _tq(r, r.torque), fixed(r.angle, 5),
            fixed(720 + r.angle, 5), "055", _tq(r, 150), _tq(r, 80),
            fixed(r.tightening_id % 100000, 5), "00000", text(r.tool_serial, 14),
            r.timestamp.strftime(TIME)]


def _rev3_0065(r: SimRecord) -> list[str]:
    return [str(r.torque_unit), f"{r.result_type:02d}"]


def _rev7_0065(r: SimRecord) -> list[str]:
    return [fixed(1, 10), text("Sim station", 25)]


def _rev3(r: SimRecord) -> list[str]:
    return [text(r.pset_name, 25), str(r.torque_unit), f"{r.result_type:02d}"]


def _rev4(r: SimRecord) -> list[str]:
    return [text("", 25), text("", 25), text("", 25)]


def _rev5(r: SimRecord) -> list[str]:
    return [text("" if r.ok else "E001", 4)]


def _rev6(r: SimRecord) -> list[str]:
    return [_tq(r, 40), fixed(0, 10)]


def _rev7(r: SimRecord) -> list[str]:
    """The compensated and the final angle, each x 100 in 7 digits."""
    return [fixed(r.angle_exact * 100, 7), fixed(r.angle_exact * 100, 7)]


_APPENDED = (_rev3, _rev4, _rev5, _rev6, _rev7)   # revisions 3..7
#: MID 0065's revisions 3..7 (tables 87-91): no pset name; the station's id and name last
_APPENDED_0065 = (_rev3_0065, _rev4, _rev5, _rev6, _rev7_0065)


def result_data(mid: int, revision: int, r: SimRecord) -> bytes:
    """The data of a MID 0061 (or 0065) of ``revision`` 1-7 for ``r``: each parameter its
    2-digit tag (numbered on, over the revisions), then its value."""
    if revision == 1:
        values = _rev1_0061(r) if mid == 61 else _rev1_0065(r)
    else:
        values = _rev2(r) if mid == 61 else _rev2_0065(r)
        for extend in (_APPENDED if mid == 61 else _APPENDED_0065)[:revision - 2]:
            values += extend(r)
    return "".join(f"{tag:02d}{v}" for tag, v in enumerate(values, 1)).encode("ascii")


def mislabelled_data(mid: int, revision: int, r: SimRecord) -> bytes:
    """The body a controller that claims more than it implements sends when asked for a
    later revision: ``revision``'s parameters, then fields of its own appended (the field
    case, PROTOCOLS.md: revision 1 followed by the pset name, torque unit and result type,
    numbered on from 24 (0061) or 12 (0065); after a tagged revision, one parameter 90 that
    no revision names).  It is labelled as asked, not as laid out."""
    body = result_data(mid, revision, r).decode("ascii")
    if revision > 1:
        return (body + "900000").encode("ascii")
    first = 24 if mid == 61 else 12
    extra = [text(r.pset_name, 25), str(r.torque_unit), f"{r.result_type:02d}"]
    return (body + "".join(f"{tag:02d}{v}" for tag, v in enumerate(extra, first))
            ).encode("ascii")
