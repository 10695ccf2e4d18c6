"""Open Protocol MID 0901 (trace plot parameters) and MID 0902 (tightening result database
info): read, so that a controller that sends them is understood and acknowledged, and what
they say can be logged.  Pure functions, no I/O.

What they carry, from the specification's tables as integrators' libraries implement them
(OpenProtocolInterpreter's Mid0901 revisions 1-3 after spec R2.21.1 section 5.8.10; the Rust
``open-protocol`` crate's MID0902rev1 after section 5.8.11):

- **MID 0901**, subscribed like the traces (MID 0008 naming 0901), one per tightening:
  result data identifier 10 (the tightening id), time stamp 19, number of PIDs 3, then
  revision 2 the request MID 4 (0008 or 0006), revision 3 also object id 4, object type 1,
  reference object id 4 and trace type 2; then the data fields (PID 5, length 3, data type
  2, unit 3, step 4, value): the limits "for drawing the limit figures in relation to the
  trace curve", which PIDs depending on the traces subscribed.
- **MID 0902**, asked for with MID 0006 (or subscribed): capacity 10 (how many results the
  controller keeps), the oldest result's tightening id 10 and time 19, the newest's id 10
  and time 19, number of PIDs 3, data fields.

What the station does with them: nothing that could change a record.  It does not subscribe
to 0901: its torque-angle plot draws the rundown's own limits, which MID 0061 gives for every
result, in the pset's units and already checked by the controller, whereas 0901's PIDs are
not listed in any source at hand (a plot from guessed PIDs would be a wrong plot).  It does
not ask for 0902: the catch-up after a reconnect asks for each missed id (MID 0064) and a
"tightening id not found" is a gap, which is what 0902's oldest id would say in one message.
A 0901 or 0902 that comes anyway (a controller configured to push it) is read, acknowledged
with MID 0005 naming it (the generic acknowledgement of subscribed data) and logged, never a
fault; one that does not read is logged and acknowledged the same.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime

from drivers.counting import counted
from drivers.errors import ProtocolError
from drivers.wrench.openprotocol.curve import TIME_FORMAT, FieldReader, data_fields

MID_PLOT, MID_DB_INFO = 901, 902
REQUEST_DATA = 6          # MID 0006: application data message request (one upload)


def _time(text: str) -> datetime | None:
    try:
        return datetime.strptime(text, TIME_FORMAT)
    except ValueError:
        return None      # an odd clock does not make the rest unreadable


@dataclass(frozen=True)
class PlotParameters:
    """MID 0901: the plot parameters of tightening ``tightening_id`` (PID -> value text)."""

    tightening_id: int
    timestamp: datetime | None
    fields: dict[str, str] = field(default_factory=dict)
    request_mid: int | None = None      # revision 2+
    trace_type: int | None = None       # revision 3

    def describe(self) -> str:
        return (f"plot parameters of tightening {self.tightening_id}: "
                f"{counted(len(self.fields), 'field')}"
                + (f" for trace type {self.trace_type}" if self.trace_type else ""))


@dataclass(frozen=True)
class ResultDbInfo:
    """MID 0902: how many results the controller keeps and which it has now."""

    capacity: int
    oldest_id: int
    oldest_at: datetime | None
    newest_id: int
    newest_at: datetime | None
    fields: dict[str, str] = field(default_factory=dict)

    def describe(self) -> str:
        return (f"result database: tightenings {self.oldest_id}-{self.newest_id} kept "
                f"(capacity {self.capacity})")


def parse_plot(revision: int, data: bytes) -> PlotParameters:
    """The data of a MID 0901 (revisions 1-3) -> :class:`PlotParameters`."""
    if not 1 <= revision <= 3:
        raise ProtocolError(f"MID 0901 revision {revision} is not read (1-3 are)")
    r = FieldReader(data, "MID 0901")
    tid = r.number(10, "result data identifier")
    when = _time(r.take(19, "time stamp"))
    count = r.number(3, "number of PIDs")
    request = r.number(4, "request MID") if revision >= 2 else None
    trace = None
    if revision >= 3:
        r.take(4 + 1 + 4, "object id, type and reference")
        trace = r.number(2, "trace type")
    fields = data_fields(r, count, "PID")
    if r.pos != len(data):
        raise ProtocolError(f"MID 0901: {counted(len(data) - r.pos, 'byte')} after its "
                            f"{counted(count, 'PID')}")
    return PlotParameters(tid, when, fields, request, trace)


def parse_db_info(revision: int, data: bytes) -> ResultDbInfo:
    """The data of a MID 0902 (revision 1; later ones read as far as revision 1 goes)."""
    r = FieldReader(data, "MID 0902")
    capacity = r.number(10, "capacity")
    oldest = r.number(10, "oldest sequence number")
    oldest_at = _time(r.take(19, "oldest time"))
    newest = r.number(10, "newest sequence number")
    newest_at = _time(r.take(19, "newest time"))
    fields = data_fields(r, r.number(3, "number of PIDs"), "PID")
    return ResultDbInfo(capacity, oldest, oldest_at, newest, newest_at, fields)


__all__ = ["MID_DB_INFO", "MID_PLOT", "REQUEST_DATA", "PlotParameters", "ResultDbInfo",
           "parse_db_info", "parse_plot"]
