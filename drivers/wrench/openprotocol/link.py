"""Open Protocol link-level acknowledgement (MID 9997 / 9998): the pure rules, no I/O.

Why it exists: without it, a message lost on the wire (a result pushed while a switch
reboots) is lost for good; with it, each message carries a sequence number in its header and
is resent until the peer acknowledges that number.  The rules, from the specification and
what integrators report (PROTOCOLS.md):

- sequence numbers run 1..99 and wrap to 1, one counter per direction, both reset by the
  communication start (MID 0001/0002, which are not sequenced themselves);
- one message outstanding: the next is sent only once 9997 came for the last;
- no 9997 within the response timeout: resend the same message with the same number, up to
  ``RESENDS`` times, then the link is lost (the reconnect mechanism takes over);
- a message received with the number of the one before is a repeat (our 9997 was lost): it
  is acknowledged again and not processed twice;
- a 9997 (and a 9998) carries the number the sender of the acknowledgement expects next: the
  received number + 1 (99 wraps to 1), as the specification's figures show ("MID 0060 seq.
  01" answered by "MID 9997 seq. 02 next exp seq at Controller = 02") and as integrators'
  libraries check it (node-open-protocol refuses a 9997 that echoes the number sent);
- the keep-alive (9999) is answered by its mirror, so it is not sequenced either.
"""

from __future__ import annotations

from drivers.wrench.openprotocol.message import MID_LINK_ACK, MID_LINK_ERROR, Message

SEQ_MAX = 99
RESENDS = 3
#: MIDs outside the link level: communication start and its answer, the link level's own
#: messages and the keep-alive.
UNSEQUENCED = frozenset({1, 2, MID_LINK_ACK, MID_LINK_ERROR, 9999})
#: MID 9998 error codes (4 digits on the wire)
LINK_ERROR_TEXT = {1: "invalid length", 2: "invalid revision", 3: "invalid sequence number",
                   4: "inconsistency of number of messages, message number"}


def next_seq(seq: int) -> int:
    """The number after ``seq`` (0 = none sent yet): 1, 2, ... 99, 1, ..."""
    return seq % SEQ_MAX + 1


def is_sequenced(mid: int) -> bool:
    return mid not in UNSEQUENCED


def link_ack(msg: Message) -> Message:
    """MID 9997 for ``msg``: its MID as data, and in the header the number expected next
    (``msg``'s + 1, wrapping; none for a message that came without one)."""
    seq = None if msg.sequence is None else next_seq(msg.sequence)
    return Message(MID_LINK_ACK, data=f"{msg.mid:04d}".encode(), sequence=seq)


def answers(ack_seq: int | None, sent_seq: int) -> bool:
    """Whether a 9997/9998 numbered ``ack_seq`` answers the message sent as ``sent_seq``: it
    names the number after it (the one its sender expects next)."""
    return ack_seq == next_seq(sent_seq)


def link_error_code(msg: Message) -> int:
    """The error code of a MID 9998 (MID 4 digits, then the code, 4 digits); 0 if absent."""
    code = msg.data[4:8]
    return int(code) if code.isdigit() else 0


def link_error_text(code: int) -> str:
    return f"MID 9998 error {code:04d} ({LINK_ERROR_TEXT.get(code, 'unknown error code')})"


class RxSequence:
    """The receiving side of one direction: tells a repeat from a new message."""

    def __init__(self) -> None:
        self.last: int | None = None
        self.repeats = 0

    def reset(self) -> None:
        self.last = None

    def is_new(self, seq: int | None) -> bool:
        """False for a repeat of the last message (to acknowledge, not process); a message
        without a number is taken as new (nothing to compare)."""
        if seq is not None and seq == self.last:
            self.repeats += 1
            return False
        if seq is not None:
            self.last = seq
        return True
