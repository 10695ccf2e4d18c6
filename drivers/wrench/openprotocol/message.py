"""Open Protocol messages: header, TCP and serial framing, and the replies the station reads.

Pure functions and small stateful framers, no I/O (pymodbus's protocol/transport split): the
links are in ``link.py`` and the request/answer rules in ``channel.py``.  Everything here is
written from docs/PROTOCOLS.md: a message is a 20-byte ASCII header (length, MID, revision,
no-ack flag, station, spindle, sequence, parts, part), data, then NUL; over TCP messages follow
each other; over RS-232 the integrator sends ``BEL HT BEL HT STX message ETX`` and the
controller ``STX message ETX``.  The results (MID 0061/0065, revisions 1-7) are read in
``result.py``, the controller's identity (MID 0002) in ``identity.py``, and the
link-level acknowledgement rules (MID 9997/9998) are in ``link.py``.

Decoding never trusts the peer: every malformed input is a :class:`ProtocolError` naming what
was wrong, never another exception, and framers hold at most one message (9999 bytes) of
state, so garbage can neither crash nor stall them (property-tested with hypothesis).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime

from drivers.errors import ProtocolError
from drivers.wrench.base import TighteningResult
from drivers.wrench.openprotocol.identity import parse_identity
from drivers.wrench.openprotocol.result import parse_tightening

HEADER_LEN = 20
MAX_LENGTH = 9999                  # the length field has 4 digits
NUL, STX, ETX = b"\x00", b"\x02", b"\x03"
INTEGRATOR_PREFIX = b"\x07\x09\x07\x09"   # BEL HT BEL HT, before STX, integrator -> controller

MID_START, MID_START_ACK, MID_STOP, MID_ERROR, MID_ACCEPTED = 1, 2, 3, 4, 5
MID_PSET_SELECT, MID_TOOL_DISABLE, MID_TOOL_ENABLE, MID_VIN = 18, 42, 43, 50
MID_RESULT_SUBSCRIBE, MID_RESULT, MID_RESULT_ACK, MID_RESULT_UNSUBSCRIBE = 60, 61, 62, 63
MID_OLD_RESULT_REQUEST, MID_OLD_RESULT = 64, 65
MID_TIME_REQUEST, MID_TIME = 80, 81          # read time upload request / reply (revision 1)
MID_LINK_ACK, MID_LINK_ERROR, MID_KEEPALIVE = 9997, 9998, 9999
#: MID 0004 codes that mean "not this revision": ask again one lower (integrators' practice)
REVISION_REFUSALS = frozenset({74, 76, 97})
#: MID 0004 codes that mean "this controller does not do that request" (at the lowest
#: revision tried): unknown MID, requested MID unsupported, a revision refusal.  Others (98
#: "controller internal request timeout", ...) say nothing of what it does another time.
UNSUPPORTED = REVISION_REFUSALS | {75, 99}
NOT_FOUND = 15                     # MID 0004 to a MID 0064: no result with that id

#: MID 0004 error codes (Open Protocol specification); others are shown as their number.
ERROR_TEXT: dict[int, str] = {
    1: "invalid data", 2: "parameter set not present", 3: "parameter set cannot be set",
    4: "parameter set not running", 6: "VIN upload subscription already exists",
    7: "VIN upload subscription does not exist", 8: "VIN input source not granted",
    9: "result subscription already exists", 10: "result subscription does not exist",
    15: "tightening id not found", 74: "subscribed MID revision unsupported",
    75: "requested MID unsupported", 76: "requested MID revision unsupported",
    78: "subscription on specific data not supported",
    96: "client already connected", 97: "MID revision unsupported",
    98: "controller internal request timeout", 99: "unknown MID",
}


def _show(data: bytes, limit: int = 32) -> str:
    """Peer bytes for an error message: repr, cut short."""
    return repr(data[:limit]) + ("..." if len(data) > limit else "")


@dataclass(frozen=True)
class Message:
    """One Open Protocol message; optional header fields are None when sent as spaces."""

    mid: int
    revision: int = 1
    data: bytes = b""
    no_ack: bool = False
    station: int | None = None
    spindle: int | None = None
    sequence: int | None = None
    parts: int | None = None
    part: int | None = None
    raw: bytes = field(default=b"", repr=False, compare=False)   # as received (no NUL)

    def encode(self) -> bytes:
        """Header + data, without the terminating NUL (the framing adds it)."""
        if not 0 <= self.mid <= 9999 or not 0 <= self.revision <= 999:
            raise ValueError(f"MID {self.mid} / revision {self.revision} out of range")
        if any(b < 0x20 or b > 0x7E for b in self.data):
            raise ValueError(f"data must be printable ASCII: {_show(self.data)}")
        length = HEADER_LEN + len(self.data)
        if length > MAX_LENGTH:
            raise ValueError(f"message of {length} bytes exceeds {MAX_LENGTH}")
        head = (f"{length:04d}{self.mid:04d}{self.revision:03d}{'1' if self.no_ack else ' '}"
                + _opt(self.station, 2) + _opt(self.spindle, 2) + _opt(self.sequence, 2)
                + _opt(self.parts, 1) + _opt(self.part, 1))
        return head.encode("ascii") + self.data


def _opt(value: int | None, width: int) -> str:
    if value is None:
        return " " * width
    if not 0 <= value < 10**width:
        raise ValueError(f"header field {value} does not fit in {width} digits")
    return f"{value:0{width}d}"


def frame_tcp(msg: Message) -> bytes:
    return msg.encode() + NUL


def frame_serial(msg: Message) -> bytes:
    """Integrator -> controller over RS-232: BEL HT BEL HT STX message NUL ETX."""
    return INTEGRATOR_PREFIX + STX + msg.encode() + NUL + ETX


def _number(raw: bytes, what: str) -> int:
    if not raw.isdigit():
        raise ProtocolError(f"{what} field {raw!r} is not a number")
    return int(raw)


def _optional(raw: bytes, what: str) -> int | None:
    text = raw.strip(b" ")
    if not text:
        return None
    if not text.isdigit():
        raise ProtocolError(f"header {what} {raw!r} is neither digits nor spaces")
    return int(text)


def decode(raw: bytes) -> Message:
    """Parse one message (header + data, NUL already removed)."""
    if len(raw) < HEADER_LEN:
        raise ProtocolError(f"message shorter than the 20-byte header: {_show(raw)}")
    length = _number(raw[0:4], "length")
    if length != len(raw):
        raise ProtocolError(f"length field says {length} bytes but the message has {len(raw)}")
    mid = _number(raw[4:8], "MID")
    rev_text = raw[8:11].strip(b" ")                 # spaces, 000 and 001 all mean revision 1
    if rev_text and not rev_text.isdigit():
        raise ProtocolError(f"revision field {raw[8:11]!r} is not a number")
    flag = raw[11:12]
    if flag not in (b" ", b"0", b"1"):
        raise ProtocolError(f"no-ack flag {flag!r} is not 0, 1 or space")
    return Message(mid=mid, revision=max(int(rev_text or b"1"), 1), data=raw[HEADER_LEN:],
                   no_ack=flag == b"1", station=_optional(raw[12:14], "station id"),
                   spindle=_optional(raw[14:16], "spindle id"),
                   sequence=_optional(raw[16:18], "sequence number"),
                   parts=_optional(raw[18:19], "number of parts"),
                   part=_optional(raw[19:20], "part number"), raw=raw)


class TcpFramer:
    """Split a TCP byte stream into messages: length-prefixed, each followed by NUL.

    ``feed`` returns messages in order and, if the stream stops being Open Protocol, one
    ProtocolError as its last item; after that the stream cannot be trusted (there is no
    marker to resynchronise on), the framer ignores further input and the link must be reset.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._broken = False

    @property
    def pending(self) -> int:
        """Bytes of an unfinished message held (to say "closed in the middle of a message")."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Message | ProtocolError]:
        out: list[Message | ProtocolError] = []
        if self._broken:
            return out
        self._buf += data
        try:
            while len(self._buf) >= 4:
                head = bytes(self._buf[:4])
                if not head.isdigit():
                    raise ProtocolError(f"garbage where a message should start: "
                                        f"{_show(bytes(self._buf))}")
                length = int(head)
                if length < HEADER_LEN:
                    raise ProtocolError(f"length field {head!r} is shorter than the header")
                if len(self._buf) < length + 1:
                    break
                if self._buf[length] != 0:
                    raise ProtocolError(f"message of {length} bytes is not followed by NUL "
                                        f"(got {bytes(self._buf[length:length + 1])!r})")
                raw = bytes(self._buf[:length])
                del self._buf[:length + 1]
                out.append(decode(raw))
        except ProtocolError as e:
            self._broken = True
            self._buf.clear()
            out.append(e)
        return out


class SerialFramer:
    """Split the controller's RS-232 stream (``STX message ETX``) into messages.

    Serial framing can resynchronise, so errors are items, not the end: bytes outside a frame
    are line noise (counted in ``noise``), a frame cut short by a new STX, a frame longer than
    any message, or a frame that does not decode gives a ProtocolError and parsing goes on.
    The NUL before ETX is optional on input.
    """

    MAX_FRAME = MAX_LENGTH + 1

    def __init__(self) -> None:
        self._buf = bytearray()
        self._inside = False
        self.noise = 0

    @property
    def pending(self) -> int:
        return len(self._buf) + self._inside

    def feed(self, data: bytes) -> list[Message | ProtocolError]:
        out: list[Message | ProtocolError] = []
        i, n = 0, len(data)
        while i < n:
            if not self._inside:
                j = data.find(STX, i)
                if j < 0:
                    self.noise += n - i
                    break
                self.noise += j - i
                self._inside, i = True, j + 1
                self._buf.clear()
                continue
            etx, stx = data.find(ETX, i), data.find(STX, i)
            end = min(k for k in (etx, stx, n) if k >= 0)
            self._buf += data[i:end]
            i = end
            if len(self._buf) > self.MAX_FRAME:    # the delimiter at ``end`` is looked at again
                out.append(ProtocolError(f"serial frame without ETX after {len(self._buf)} "
                                         "bytes; dropped"))
                self._buf.clear()
                self._inside = False
            elif end == n:
                break
            elif end == stx:
                out.append(ProtocolError(f"serial frame cut short by a new STX after "
                                         f"{len(self._buf)} bytes: {_show(bytes(self._buf))}"))
                self._buf.clear()
                i += 1
            else:
                out.append(self._unframe(bytes(self._buf)))
                self._buf.clear()
                self._inside = False
                i += 1
        return out

    @staticmethod
    def _unframe(body: bytes) -> Message | ProtocolError:
        if body.endswith(NUL):
            body = body[:-1]
        try:
            return decode(body)
        except ProtocolError as e:
            return e


# -- replies --------------------------------------------------------------------------------
def refusal(msg: Message) -> tuple[int, int]:
    """(refused MID, error code) of a 0004; the code may be missing on odd controllers (0)."""
    mid = _number(msg.data[:4], "MID 0004 refused-MID")
    code_text = msg.data[4:6]
    return mid, (_number(code_text, "MID 0004 error code") if code_text else 0)


def refusal_text(code: int) -> str:
    return f"error {code:02d} ({ERROR_TEXT.get(code, 'unknown error code')})"


def controller_time(msg: Message) -> datetime:
    """MID 0081 (revision 1): the controller's clock, ``YYYY-MM-DD:HH:MM:SS``, naive (its
    local time, as its results' timestamps are)."""
    text = msg.data[:19].decode("ascii", "replace")
    try:
        return datetime.strptime(text, "%Y-%m-%d:%H:%M:%S")
    except ValueError:
        raise ProtocolError(f"MID 0081 time {msg.data[:19]!r} is not "
                            "YYYY-MM-DD:HH:MM:SS") from None


def identity(msg: Message) -> str:
    """MID 0002 (any revision) as one line: name, cell, channel and what it adds."""
    return parse_identity(msg.revision, msg.data).describe()


def parse_result(raw: bytes) -> TighteningResult:
    """A MID 0061 or 0065 message, revisions 1-7 (header included, NUL excluded) ->
    TighteningResult (``result.py`` reads the parameters)."""
    msg = decode(raw)
    if msg.mid not in (MID_RESULT, MID_OLD_RESULT):
        raise ProtocolError(f"expected MID 0061 or 0065, got MID {msg.mid:04d} revision "
                            f"{msg.revision}")
    if not raw.isascii():
        raise ProtocolError(f"MID {msg.mid:04d} contains non-ASCII bytes: "
                            f"{_show(raw[HEADER_LEN:])}")
    return parse_tightening(msg.mid, msg.revision, raw.decode("ascii"))
