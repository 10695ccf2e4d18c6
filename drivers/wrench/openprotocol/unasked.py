"""MID 0901 (plot parameters) and 0902 (the result database's extent) that come unasked: read,
acknowledged and logged, never used (``tracedata.py`` says why), and the last 0902 kept for
whoever looks.

Why handled at all: a controller configured to push them waits for their acknowledgement;
left unanswered it would resend them, or take the link for dead.
"""

from __future__ import annotations

import logging

from drivers.errors import ProtocolError
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.dataacks import DataAcks
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.tracedata import (
    MID_DB_INFO,
    MID_PLOT,
    ResultDbInfo,
    parse_db_info,
    parse_plot,
)


class UnaskedData:
    """The 0901/0902 of one wrench's sessions; ``db_info`` (guarded by the channel's
    ``cond``) is the last 0902 read."""

    def __init__(self, channel: Channel, acks: DataAcks) -> None:
        self._channel = channel
        self._acks = acks
        self._log = channel.log
        self.device = channel.device
        self.db_info: ResultDbInfo | None = None
        self._seen: set[int] = set()            # logged at info once a session (the reader's)
        channel.route(MID_PLOT, self.received)
        channel.route(MID_DB_INFO, self.received)

    def reset(self) -> None:
        """A new session: each MID is said at info level again, once."""
        self._seen.clear()

    def received(self, msg: Message) -> None:
        """A MID 0901 or 0902 (the reading thread): read, logged, its acknowledgement owed
        (sent by the supervisor), not used."""
        try:
            what = (parse_plot(msg.revision, msg.data) if msg.mid == MID_PLOT
                    else parse_db_info(msg.revision, msg.data))
        except ProtocolError as e:
            self._log.warning("%s: unreadable MID %04d, acknowledged anyway: %s", self.device,
                              msg.mid, e)
        else:
            first = msg.mid not in self._seen
            self._seen.add(msg.mid)
            self._log.log(logging.INFO if first else logging.DEBUG, "%s: MID %04d received, "
                          "acknowledged, not used: %s", self.device, msg.mid, what.describe())
            if isinstance(what, ResultDbInfo):
                with self._channel.cond:
                    self.db_info = what
        if not msg.no_ack:
            self._acks.owe(msg.mid)
