"""Each rundown's curves joined to it before its result event goes out, so that a curve
bolt's event (and GetResultById) carries its torque and angle traces.

Why a wait, and a short one: the controller sends a tightening's result first and its traces
after it (Open Protocol MID 0061, then 0900), so the station records the rundown, then stores
its curves, each a feed entry of its own (:mod:`db.curves`).  An event fired at the rundown
would never carry them.  So while curves come (the station subscribed to them, and the
controller sends them), a rundown's event waits until the trace types the last curve
rundown had are there, at most :data:`WAIT_S`; later rundowns wait behind it, so the events
stay in the order of the records.  When the curves stop (a controller that refuses them, a
station without them) the first wait that runs out stops the waiting: from then on events go
out as soon as the rundown is stored, as without curves, until a curve is seen again (it is
then added to its result for the methods, and the next rundowns wait for theirs).  A
station without curves never waits.

A curve stored before its rundown (no rundown yet with its tightening id) is kept by
tightening id and joined when the rundown comes, as :func:`db.curves.curves_for` does.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from dataclasses import dataclass
from typing import Any

from db.ledger import CURVE, RUNDOWN, is_result

WAIT_S = 2.0            # the longest a result event waits for its curves
LOOSE = 200             # curves kept without their rundown (tightening ids)


@dataclass
class _Held:
    entry: dict[str, Any]
    deadline: float
    waits: bool          # held for its own curves (not only behind another)


class CurveJoin:
    """The rundowns of the feed and their curves: :meth:`take` each feed entry in order,
    then :meth:`ready` gives the rundowns whose events may go out."""

    def __init__(self, keep: int, wait_s: float = WAIT_S) -> None:
        self.keep, self.wait_s = keep, wait_s
        self.expect: frozenset[int] = frozenset()    # the trace types a rundown waits for
        self._curves: OrderedDict[int, dict[int, dict[str, Any]]] = OrderedDict()
        self._entries: dict[int, dict[str, Any]] = {}   # rundown record id -> its entry
        self._loose: OrderedDict[int, dict[int, dict[str, Any]]] = OrderedDict()
        self._held: deque[_Held] = deque()
        self._published: set[int] = set()

    @property
    def holding(self) -> bool:
        return bool(self._held)

    def curves(self, record_id: int) -> list[dict[str, Any]] | None:
        """The curves joined to rundown ``record_id`` (one per trace type); None when the
        rundown is not among those kept here."""
        got = self._curves.get(record_id)
        return None if got is None else [got[k] for k in sorted(got)]

    def take(self, entry: dict[str, Any], now: float, *, hold: bool = True) -> \
            dict[str, Any] | None:
        """One feed entry.  A rundown is kept (and held for its event when ``hold``); a
        curve is joined to its rundown: that rundown's entry is returned when it was kept
        here (its result changed), else None."""
        rec = entry["record"]
        if entry["kind"] == RUNDOWN:
            self._rundown(entry, now, hold)
            return None
        if is_result(entry):   # a result of no joint: no curves, in its turn
            if hold:
                self._held.append(_Held(entry, now, False))
            return None
        if entry["kind"] != CURVE:
            return None
        kind = int(rec["trace_type"])
        rid = rec.get("record_id")
        tid = rec.get("tightening_id")
        if rid is None and tid is not None:   # stored before its rundown: kept till it comes
            self._loose.setdefault(int(tid), {})[kind] = rec
            self._loose.move_to_end(int(tid))
            while len(self._loose) > LOOSE:
                self._loose.popitem(last=False)
            if not self._held:
                self.expect |= {kind}
            return None
        if rid is None or int(rid) not in self._curves:
            return None
        self._curves[int(rid)][kind] = rec
        if int(rid) in self._published:   # came after its event: the next rundowns wait
            self.expect |= {kind}
        return self._entries.get(int(rid))

    def _rundown(self, entry: dict[str, Any], now: float, hold: bool) -> None:
        rec = entry["record"]
        rid, tid = int(rec["id"]), rec.get("tightening_id")
        got: dict[int, dict[str, Any]] = {}
        if tid is not None:
            got.update(self._loose.pop(int(tid), {}))
        self._curves[rid] = got
        self._entries[rid] = entry
        while len(self._curves) > self.keep:
            old, _ = self._curves.popitem(last=False)
            self._entries.pop(old, None)
            self._published.discard(old)
        if not hold:
            self._published.add(rid)
            return
        waits = bool(self.expect) and tid is not None and not self.expect <= set(got)
        self._held.append(_Held(entry, now + self.wait_s if waits else now, waits))

    def ready(self, now: float) -> list[dict[str, Any]]:
        """The rundowns whose events go out now, in order: the first held one has its
        expected curves or waited long enough, and so on."""
        out = []
        while self._held:
            h = self._held[0]
            if h.entry["kind"] != RUNDOWN:    # waits for no curve of its own
                self._held.popleft()
                out.append(h.entry)
                continue
            rid = int(h.entry["record"]["id"])
            got = set(self._curves.get(rid, {}))
            complete = bool(self.expect) and self.expect <= got
            if not complete and h.deadline > now:
                break
            if h.waits and not complete:   # the curves stopped: no more waiting
                self.expect = frozenset(got)
            self._held.popleft()
            self._published.add(rid)
            out.append(h.entry)
        return out

    def settle(self) -> None:
        """After the rundowns stored before the server started (taken without holding):
        the next rundown waits for the trace types the last of them had."""
        if self._curves:
            self.expect = frozenset(next(reversed(self._curves.values())))

    def next_deadline(self) -> float | None:
        return self._held[0].deadline if self._held else None


__all__ = ["WAIT_S", "CurveJoin"]
