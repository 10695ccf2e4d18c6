"""Open Protocol messages sent in several parts, put back together.  Pure, no I/O.

Why: a message's length field has four digits, so a message longer than 9999 bytes (a long
tightening curve, MID 0900 with more than about 4 900 samples) is sent as up to nine
messages, each with its own 20-byte header whose "number of parts" (byte 19) says how many
there are and "part number" (byte 20) which one it is, 1 first.  The data of the parts, in
order, is the message's data (integrators' libraries cut it every 9979 bytes, the most one
part holds; the reader does not rely on that size).  Each part is a message on the link: with
link-level acknowledgement each is numbered and acknowledged on its own (``link.py``),
before it gets here; the application acknowledges the whole message once (a MID 0005 for
subscribed data), so nothing is acknowledged before its last part came.

A part out of order, a new first part while a message is incomplete, a part that disagrees
with its first part on the MID's revision or the number of parts: that message cannot be
trusted, it is given up (:class:`BrokenParts`, for the journal and its acknowledgement) and
the stream goes on: the framing of the link is intact, only that message is lost.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from drivers.wrench.openprotocol.message import HEADER_LEN, MAX_LENGTH, Message

MAX_PARTS = 9                             # the header's field is one digit
PART_DATA = MAX_LENGTH - HEADER_LEN       # the most data one part carries: 9979 bytes


@dataclass(frozen=True)
class BrokenParts:
    """A message in parts given up: its MID, why, and whether it asked for no
    acknowledgement (its first part's flag)."""

    mid: int
    reason: str
    no_ack: bool = False


@dataclass
class _Partial:
    first: Message
    parts: int
    data: list[bytes] = field(default_factory=list)


def in_parts(msg: Message) -> bool:
    """Whether ``msg`` is one part of several (its header says more than one part)."""
    return (msg.parts or 0) > 1


class PartAssembler:
    """Collects the parts of messages, one message per MID at a time (a controller sends a
    message's parts one after the other; another MID may come between them)."""

    def __init__(self) -> None:
        self._open: dict[int, _Partial] = {}

    def reset(self) -> None:
        """A new session: parts of the old one never complete."""
        self._open.clear()

    @property
    def pending(self) -> int:
        """Messages whose first parts came and whose last has not."""
        return len(self._open)

    def feed(self, msg: Message) -> list[Message | BrokenParts]:
        """The messages ``msg`` completes (``msg`` itself when it is not in parts), and
        those it shows broken, in order; empty while a message waits for more parts."""
        out: list[Message | BrokenParts] = []
        partial = self._open.get(msg.mid)
        if not in_parts(msg):
            if partial is not None:
                del self._open[msg.mid]
                out.append(_broken(partial, "a whole message came before its last part"))
            out.append(msg)
            return out
        parts, part = int(msg.parts or 0), int(msg.part or 0)
        if parts > MAX_PARTS or not 1 <= part <= parts:
            if partial is not None:
                del self._open[msg.mid]
                out.append(_broken(partial, f"part {part} of {parts} came next"))
            out.append(BrokenParts(msg.mid, f"part {part} of {parts} is not a part number "
                                            f"1-{parts} of at most {MAX_PARTS}", msg.no_ack))
            return out
        if part == 1:
            if partial is not None:
                out.append(_broken(partial, "a new first part came before its last part"))
            partial = self._open[msg.mid] = _Partial(msg, parts)
        elif partial is None:
            out.append(BrokenParts(msg.mid, f"part {part} of {parts} without the parts "
                                            "before it", msg.no_ack))
            return out
        elif part != len(partial.data) + 1 or parts != partial.parts \
                or msg.revision != partial.first.revision:
            del self._open[msg.mid]
            out.append(_broken(partial, f"part {part} of {parts} (revision {msg.revision}) "
                                        f"after part {len(partial.data)} of {partial.parts} "
                                        f"(revision {partial.first.revision})"))
            return out
        partial.data.append(msg.data)
        if part == parts:
            del self._open[msg.mid]
            data = b"".join(partial.data)
            out.append(dataclasses.replace(
                partial.first, data=data, sequence=None, parts=None, part=None,
                raw=partial.first.raw[:HEADER_LEN] + data))
        return out


def _broken(partial: _Partial, why: str) -> BrokenParts:
    return BrokenParts(partial.first.mid, f"{why} ({len(partial.data)} of {partial.parts} "
                                          "parts received)", partial.first.no_ack)


__all__ = ["MAX_PARTS", "PART_DATA", "BrokenParts", "PartAssembler", "in_parts"]
