"""Reading a result message whatever its body turns out to be: MID 0061/0065 -> a
:class:`TighteningResult`, read at its header's revision or, where the body is laid out as a
lower one, at that one; else an :class:`UnreadableResult` that keeps it whole.  Pure, no I/O.

Why: controllers and emulators in the field accept a subscription at a revision they do not
implement (one accepts MID 0060 revision 7 and sends revision 1 bodies with fields appended,
labelled revision 7, PROTOCOLS.md).  Acknowledging such a message and dropping it as garbage
loses every result of that controller; so the rules, in order:

1. The header's revision is the one read (not the one subscribed: a controller may answer a
   subscription at one revision and label its messages honestly with another).
2. A body whose *layout* does not match its revision (a tag missing, unknown or out of place,
   a length that does not add up: :class:`op_result.LayoutError`) is read as a body of that
   revision or a lower one followed by fields this driver does not know: the first bytes
   are that revision's parameters in the specification's order, the rest is ignored.  The
   highest revision that reads cleanly wins; the result says the revision it was read at
   (``revision``) and the one its header claimed (``header_revision``).  Where the header's
   revision carries a result type (3+) and the one read does not, the result is not handed
   out as read: one byte lost in the type's tag reads that way too, and a loosening read
   without its type would close its bolt.  It is an :class:`UnreadableResult` (rule 3) that
   says the revision it read as (``laid_out_as``): the feed renews its subscription there
   only when the next result reads so too (``resultfeed``).
3. A body whose layout is right but whose values do not read (a torque of letters, a status
   of 7) is not read at another revision: its lower revisions' parameters would read and
   silently drop what the broken one carried (a result type, which decides whether the
   result may close a bolt).  Nor is a body that reads at no revision: both become an
   :class:`UnreadableResult` with the raw text, the header's revision, the error at that
   revision and what could still be picked out of it (tightening id, pset, VIN, timestamp).
"""

from __future__ import annotations

import dataclasses
from datetime import datetime
from typing import Any

from drivers.errors import ProtocolError
from drivers.wrench.base import TighteningResult, UnreadableResult
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.result import (
    HEADER_LEN,
    MAX_REVISION,
    MID_RESULT,
    TIME_FORMAT,
    LayoutError,
    fixed_params,
    parse_tightening,
    tagged_length,
    tags,
)

#: the fields picked out of an unreadable body, for the station to say which bolt it may be
PICKED = ("tightening_id", "pset", "vin", "timestamp")
#: the first revision whose results say their type (parameter 49): whether one may close a bolt
TYPED_FROM = 3


class TypeLostError(ProtocolError):
    """A body labelled with a revision that carries a result type, laid out as one that does
    not: ``result`` is what it reads as (without its type)."""

    def __init__(self, result: TighteningResult, header: int) -> None:
        super().__init__(f"labelled revision {header} but laid out as revision "
                         f"{result.revision}, which carries no result type: whether it is a "
                         "tightening is not known")
        self.result = result


def read_result(mid: int, revision: int, text: str) -> TighteningResult:
    """``text`` (header + data) of a MID 0061/0065 labelled ``revision``, read by the rules
    above; raises the error at ``revision`` when it reads at none."""
    try:
        return parse_tightening(mid, revision, text)
    except LayoutError as e:
        first = e
    for rev in range(min(revision, MAX_REVISION), 0, -1):
        length = tagged_length(mid, rev)
        if len(text) < length or (rev == revision and len(text) == length):
            continue                   # too short for it, or the whole text (failed above)
        try:
            result = parse_tightening(mid, rev, text[:length])
        except ProtocolError:
            continue
        result = dataclasses.replace(result, raw=text, header_revision=revision)
        if rev < TYPED_FROM <= revision:
            raise TypeLostError(result, revision)
        return result
    raise first


class UntypedInARow:
    """Results laid out as a revision without a result type under a header whose revision
    has one (:class:`TypeLostError`), as they come: the second in a row with the same
    header and layout is the controller's habit, not a byte lost on the line.  One per
    stream (the pushed results, the fetched ones), reset at a new session."""

    def __init__(self) -> None:
        self._last: tuple[int, int] | None = None   # the last one's (header, layout)

    def habit(self, item: TighteningResult | UnreadableResult, header: int) -> bool:
        """``item``, received labelled ``header``, is the second such result in a row."""
        last, self._last = self._last, None
        if isinstance(item, UnreadableResult) and item.laid_out_as is not None:
            self._last = (header, item.laid_out_as)
        return self._last is not None and last == self._last

    def reset(self) -> None:
        self._last = None


def receive(msg: Message) -> TighteningResult | UnreadableResult:
    """A MID 0061/0065 as received: the result, or what is left of one that does not read."""
    text = msg.raw.decode("ascii", "replace")       # a non-ASCII byte fails its field
    try:
        return read_result(msg.mid, msg.revision, text)
    except TypeLostError as e:
        r = e.result
        return _unreadable(msg, str(e), r.tightening_id, r.pset, r.vin, r.timestamp, r.revision)
    except ProtocolError as e:
        picked = pick(msg.mid, msg.revision, text)
        return _unreadable(msg, str(e), picked["tightening_id"], picked["pset"], picked["vin"],
                           picked["timestamp"])


def untyped_below(msg: Message, item: TighteningResult | UnreadableResult, asked: int | None,
                  pushed: int | None = None) -> TighteningResult | UnreadableResult:
    """``item`` as handed out when ``asked``, the revision subscribed or requested, carries a
    result type and the controller sent one, labelled honestly, at a revision that does not:
    not a result that may close a bolt (a loosening read so closed its bolt, an independent
    controller's trial) but an :class:`UnreadableResult` laid out as its revision, held like
    a body that lost its type; the feed renews its subscription there only when the next
    result comes so too (:class:`UntypedInARow`).  So too a MID 0065 without a type from a
    controller whose pushed results carry one (``pushed``, the MID 0060 revision agreed): it
    refuses MID 0064 at a revision with a type, and what it made during a link cut, a
    loosening as well as a tightening, came as a result able to close the cut's bolt."""
    if not isinstance(item, TighteningResult) or asked is None:
        return item
    if item.revision < TYPED_FROM <= asked:
        return _unreadable(msg, f"sent at revision {item.revision} though asked for at "
                                f"revision {asked}: revision {item.revision} carries no "
                                "result type, so whether it is a tightening is not known",
                           item.tightening_id, item.pset, item.vin, item.timestamp,
                           item.revision)
    if pushed is not None and item.revision < TYPED_FROM <= pushed:
        return _unreadable(msg, f"fetched at revision {item.revision}, the highest the "
                                "controller gives for MID 0064, which carries no result type "
                                f"(its pushed results, at revision {pushed}, do): whether it "
                                "is a tightening is not known", item.tightening_id, item.pset,
                           item.vin, item.timestamp, item.revision)
    return item


def layout_words(header: int, laid_out_as: int, asked: int | None) -> str:
    """How a result without a type came, for the journal: labelled one revision and laid out
    as another, or honestly labelled below the revision ``asked`` for (subscribed, or
    requested with MID 0064)."""
    if header == laid_out_as:
        return f"revision {header} came though revision {asked} was asked for"
    return f"revision {header} is laid out as revision {laid_out_as}"


def _unreadable(msg: Message, error: str, tightening_id: int | None, pset: int | None,
                vin: str, timestamp: datetime | None,
                laid_out_as: int | None = None) -> UnreadableResult:
    return UnreadableResult(raw=_printable(msg.raw), mid=msg.mid,
                            revision=msg.revision, error=error, tightening_id=tightening_id,
                            pset=pset, vin=vin, timestamp=timestamp,
                            fetched=msg.mid != MID_RESULT, laid_out_as=laid_out_as,
                            header_len=HEADER_LEN)


def _printable(raw: bytes) -> str:
    """A message's bytes as text for the record, every byte that is not printable ASCII
    escaped (``\\x00``): a non-ASCII byte and a control character alike (line noise).  A
    NUL kept as such was refused by the line database's JSON (quarantined for good); the
    same message gives the same text, so a copy is still told by it."""
    return "".join(c if " " <= c <= "~" else f"\\x{ord(c):02x}"
                   for c in raw.decode("latin-1"))


def pick(mid: int, revision: int, text: str) -> dict[str, Any]:
    """The tightening id, pset, VIN and timestamp of a body that does not read, as far as
    its parameters can be followed from the start (by tag at its header's revision, or at
    revision 1's fixed places); each None (VIN: empty) where it is not there or not valid."""
    best: dict[str, Any] = {"tightening_id": None, "pset": None, "vin": "",
                            "timestamp": None}
    candidates = [_walk_tagged(mid, text), _walk_fixed(mid, text)]
    if revision == 1:
        candidates.reverse()
    for raw in candidates:
        got = _values(raw)
        if got["tightening_id"] is not None:
            return got
        for name in PICKED:
            if best[name] in (None, "") and got[name] not in (None, ""):
                best[name] = got[name]
    return best


def _walk_tagged(mid: int, text: str) -> dict[str, str]:
    """Parameters read by tag from the start until one is unknown, repeated or cut short."""
    table = tags(mid)
    out: dict[str, str] = {}
    pos = HEADER_LEN
    while pos + 2 <= len(text):
        tag = text[pos:pos + 2]
        param = table.get(int(tag)) if tag.isdigit() else None
        if param is None or param.name in out or pos + 2 + param.width > len(text):
            break
        out[param.name] = text[pos + 2:pos + 2 + param.width]
        pos += 2 + param.width
    return out


def _walk_fixed(mid: int, text: str) -> dict[str, str]:
    """Revision 1's parameters at their fixed places, up to the first tag out of place."""
    out: dict[str, str] = {}
    pos = HEADER_LEN
    for tag, param in enumerate(fixed_params(mid), start=1):
        if text[pos:pos + 2] != f"{tag:02d}" or pos + 2 + param.width > len(text):
            break
        out[param.name] = text[pos + 2:pos + 2 + param.width]
        pos += 2 + param.width
    return out


def _values(raw: dict[str, str]) -> dict[str, Any]:
    tid, pset = raw.get("tightening_id", ""), raw.get("pset", "")
    try:
        stamp: datetime | None = datetime.strptime(raw.get("timestamp", ""), TIME_FORMAT)
    except ValueError:
        stamp = None
    vin = raw.get("vin", "").rstrip(" \x00")
    return {"tightening_id": int(tid) if tid.isdigit() else None,
            "pset": int(pset) if pset.isdigit() else None,
            "vin": vin if vin.isprintable() and "\ufffd" not in vin else "",
            "timestamp": stamp}


__all__ = ["PICKED", "TYPED_FROM", "TypeLostError", "UntypedInARow", "layout_words", "pick",
           "read_result", "receive", "untyped_below"]
