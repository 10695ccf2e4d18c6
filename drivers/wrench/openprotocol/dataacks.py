"""The acknowledgements owed for subscribed data (MID 0900, 0901, 0902): MID 0005 naming the
MID, the generic subscription's acknowledgement.

Why owed rather than sent: the data is read by the reading thread, which must never wait to
send (the one numbered message outstanding may be a caller's, whose 9997 that thread has to
read); the supervisor sends what is owed between reads, without waiting.  A message in parts
that did not add up is lost but still acknowledged: the controller keeps its own record, and
waits for the 0005.
"""

from __future__ import annotations

from collections import deque

from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.curve import MID_TRACE
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.parts import BrokenParts
from drivers.wrench.openprotocol.tracedata import MID_DB_INFO, MID_PLOT

#: subscribed data acknowledged with MID 0005 naming its MID (the generic acknowledgement)
DATA_MIDS = frozenset({MID_TRACE, MID_PLOT, MID_DB_INFO})


class DataAcks:
    """The MID 0005s owed on one wrench's session (guarded by the channel's ``cond``)."""

    def __init__(self, channel: Channel) -> None:
        self._channel = channel
        self._owed: deque[int] = deque()
        channel.on_broken(self.broken)

    def reset(self) -> None:
        """A new session owes nothing (the last one's are moot)."""
        with self._channel.cond:
            self._owed.clear()

    def owe(self, mid: int) -> None:
        """A MID 0005 naming ``mid`` is to be sent."""
        with self._channel.cond:
            self._owed.append(mid)

    def broken(self, broken: BrokenParts) -> None:
        """A message in parts given up: still acknowledged when it was subscribed data."""
        if broken.mid in DATA_MIDS and not broken.no_ack:
            self.owe(broken.mid)

    def flush(self) -> None:
        """Send what is owed (the supervisor), never waiting for the one-outstanding slot;
        nothing once the communication stop is being sent (a 0005 after the 0003 reaches a
        controller that has stopped listening to this session)."""
        channel = self._channel
        while True:
            with channel.cond:
                if not self._owed or channel.stopping:
                    return
                mid = self._owed[0]
            if not channel.send(Message(op.MID_ACCEPTED, data=f"{mid:04d}".encode()),
                                block=False):
                return
            with channel.cond:
                if self._owed and self._owed[0] == mid:
                    self._owed.popleft()
