"""How the station's journal lines are written: with a time stamp unless systemd's journal
takes them (it stamps each line itself), and library lines in the station's words.

Why: ``stationd run`` in a terminal, under another supervisor or with its standard error in a
file wrote lines with no time ("INFO vehicle ... opened"), so nobody could tell when anything
happened; and asyncua's and asyncio's own lines ("sending service fault response: ...",
"socket.send() raised exception.") reached the operator's output without saying which client
or request.  systemd's journal is recognised as systemd documents it: ``JOURNAL_STREAM`` holds
the device and inode of the stream it connected to standard error (``man systemd.exec``); a
process whose standard error is something else (a terminal, a file, a pipe) stamps its lines.
Under the journal each line begins with its syslog priority (``<4>`` a warning, ``man
sd-daemon``), which the journal takes off and keeps as the entry's priority: without it every
line was stored at "info", and ``journalctl -u stationd -p warning`` (the README's way to find
faults, refused reloads and vehicles that left with bolts not OK) showed nothing.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Callable
from types import FrameType
from typing import Any, TextIO

#: the library's words for a refused OPC UA request, from asyncua's uaprocessor
SERVICE_FAULT = "sending service fault response"
#: asyncio's words for writing to a connection the peer has closed (after 5 tries)
SEND_RAISED = "socket.send() raised exception."
#: the connections already said closed (so a client that went away is one line, not many)
_SAID_MAX = 256


def under_journal(stream: TextIO | None = None) -> bool:
    """Whether ``stream`` (standard error) is connected to systemd's journal:
    ``JOURNAL_STREAM`` is ``DEVICE:INODE`` of that very stream (a child whose standard error
    was redirected inherits the variable, so the stream itself is compared)."""
    value = os.environ.get("JOURNAL_STREAM", "")
    dev, _, ino = value.partition(":")
    if not dev.isdigit() or not ino.isdigit():
        return False
    try:
        st = os.fstat((stream or sys.stderr).fileno())
    except (OSError, ValueError, AttributeError):
        return False
    return (st.st_dev, st.st_ino) == (int(dev), int(ino))


def error_mark(stream: TextIO | None = None) -> str:
    """What begins a command's one-line error on ``stream`` (standard error): ``<3>`` (err)
    where that is the journal, so ``journalctl -p warning`` shows why a service did not start
    (an IT administrator's trial: the exit line stored at the default priority), else
    nothing."""
    return f"<{priority(logging.ERROR)}>" if under_journal(stream) else ""


class StampedFormatter(logging.Formatter):
    """``2026-11-29 04:31:07.412 INFO ...`` in local time with its UTC offset: a line
    whose time is its own (outside the journal)."""

    def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:  # noqa: N802
        t = time.localtime(record.created)
        return (time.strftime("%Y-%m-%d %H:%M:%S", t) + f".{int(record.msecs):03d}"
                + time.strftime("%z", t))


#: a log level's syslog priority, as the journal reads it from a line's ``<N>`` prefix
#: (``sd-daemon.h``: SD_CRIT 2, SD_ERR 3, SD_WARNING 4, SD_INFO 6, SD_DEBUG 7)
PRIORITIES = ((logging.CRITICAL, 2), (logging.ERROR, 3), (logging.WARNING, 4),
              (logging.INFO, 6))
DEBUG_PRIORITY = 7


def priority(levelno: int) -> int:
    """The syslog priority of a record at ``levelno`` (a level between two: the lower's)."""
    return next((p for level, p in PRIORITIES if levelno >= level), DEBUG_PRIORITY)


class JournalFormatter(logging.Formatter):
    """Each line of a record (a traceback's too) prefixed with its priority, ``<3>ERROR
    fault: ...``: the journal keeps the priority and shows the line without it."""

    def format(self, record: logging.LogRecord) -> str:
        prefix = f"<{priority(record.levelno)}>"
        return "\n".join(prefix + line for line in super().format(record).split("\n"))


def _frame_local(name: str, code: str, limit: int = 30) -> Any:
    """The local ``name`` of the nearest caller frame running ``code`` (the library's method
    that logs), or None: the client and the request are there, not in the record."""
    frame: FrameType | None = sys._getframe(2)
    for _ in range(limit):
        if frame is None:
            return None
        if frame.f_code.co_name == code and name in frame.f_locals:
            return frame.f_locals[name]
        frame = frame.f_back
    return None


def _peer(transport: Any) -> str:
    try:
        peer = transport.get_extra_info("peername")
    except Exception:   # a library's object: any failure only loses the name
        return "a client"
    if isinstance(peer, tuple) and len(peer) >= 2:
        return f"the client at {peer[0]}:{peer[1]}"
    return "a client"


class LibraryWords(logging.Filter):
    """asyncua's refused request and asyncio's write to a closed connection, in the
    station's words with the client and the request; each closed connection said once."""

    def __init__(self) -> None:
        super().__init__()
        self._said: dict[int, None] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        msg = record.msg if isinstance(record.msg, str) else ""
        if record.name.startswith("asyncua") and msg.startswith(SERVICE_FAULT):
            self._service_fault(record)
        elif record.name == "asyncio" and msg == SEND_RAISED:
            return self._send_raised(record)
        return True

    def _service_fault(self, record: logging.LogRecord) -> None:
        processor = _frame_local("self", "process_message")
        typeid = _frame_local("typeid", "process_message")
        who = _peer(getattr(processor, "_transport", None))
        request = _request_name(typeid)
        doc, status = (record.args if isinstance(record.args, tuple)
                       and len(record.args) == 2 else ("", "a fault"))
        record.msg = "OPC UA: %s's %s refused with %s: %s"
        record.args = (who, request, status, str(doc).rstrip(".") or "no description")
        record.levelno, record.levelname = logging.WARNING, "WARNING"

    def _send_raised(self, record: logging.LogRecord) -> bool:
        transport = _frame_local("self", "write")
        key = id(transport)
        if key in self._said:
            return False
        if len(self._said) >= _SAID_MAX:
            self._said.pop(next(iter(self._said)))
        self._said[key] = None
        record.msg = "%s closed its connection: what was still to be sent to it is dropped"
        record.args = (_peer(transport),)
        record.levelno, record.levelname = logging.INFO, "INFO"
        return True


def _request_name(typeid: Any) -> str:
    """"ReadRequest" from a request's type node id, else "request"."""
    try:
        from asyncua.ua.object_ids import ObjectIdNames

        name = ObjectIdNames.get(int(typeid.Identifier), "")
    except Exception:   # no asyncua, or not a numeric id: the words go on without it
        return "request"
    return name.removesuffix("_Encoding_DefaultBinary") or "request"


class Sparing:
    """Journal lines a client can cause at any rate (refused logins, connections over a limit):
    each key's first line at once, then at most one a minute, saying how many were left
    untold.  Why: a guesser or a flood filled the journal (135,000 lines in 80 s) and
    journald's own rate limit then drops the lines that matter."""

    def __init__(self, log: logging.Logger, *, every_s: float = 60.0,
                 clock: Callable[[], float] = time.monotonic, most_keys: int = 1000) -> None:
        self._log, self.every_s, self._clock, self._most = log, every_s, clock, most_keys
        self._last: dict[str, float] = {}
        self._untold: dict[str, int] = {}

    def tell(self, key: str, line: str) -> None:
        """A warning ``line`` of kind ``key``, or counted when one of that kind was told in
        the last ``every_s``."""
        now = self._clock()
        if now - self._last.get(key, -self.every_s) < self.every_s:
            self._untold[key] = self._untold.get(key, 0) + 1
            return
        more = self._untold.pop(key, 0)
        self._log.warning("%s%s", line, f" ({more} more like it in the last minute)"
                          if more else "")
        self._last[key] = now
        if len(self._last) > self._most:       # bounded: keys a guesser chose
            self._last.pop(next(iter(self._last)))


def setup_logging(level: int, stream: TextIO, *, levelname: bool = True,
                  loud: tuple[str, ...] = ()) -> logging.Handler:
    """The station's one handler on the root logger: ``level`` for every logger but
    ``loud`` ones (they write from INFO: the demo's command lines), a time stamp unless
    ``stream`` is systemd's journal (then each line's priority), the library lines in the
    station's words.  As
    ``logging.basicConfig``: nothing is added when the root logger has a handler already (a
    second demo in one process, a test's capture); the handler is returned either way."""
    fmt = ("%(levelname)s " if levelname else "") + "%(message)s"
    handler = logging.StreamHandler(stream)
    handler.setFormatter(JournalFormatter(fmt) if under_journal(stream)
                         else StampedFormatter("%(asctime)s " + fmt))
    handler.addFilter(LibraryWords())
    logging.basicConfig(level=level, handlers=[handler])
    for name in loud:
        logging.getLogger(name).setLevel(logging.INFO)
    return handler


__all__ = ["JournalFormatter", "LibraryWords", "Sparing", "StampedFormatter", "priority",
           "quiet_opencv", "setup_logging", "under_journal"]


def quiet_opencv() -> None:
    """Keep OpenCV's own log lines (``[ WARN:0@0.02] global grfmt_png.cpp:793 ... PNG input
    buffer is incomplete``) off stderr: every failure is told as one line of ours.  Called
    once at startup, before OpenCV loads (this module does not load it, so a command that
    needs no image does not pay for it); ``OPENCV_LOG_LEVEL`` set by the user wins (to
    debug a camera).  Errors only: OpenCV reads the variable when it loads, and its level
    once loaded."""
    os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    cv = sys.modules.get("cv2")
    if cv is not None and os.environ["OPENCV_LOG_LEVEL"] == "ERROR":
        cv.utils.logging.setLogLevel(cv.utils.logging.LOG_LEVEL_ERROR)
