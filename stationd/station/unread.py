"""Results the driver could not read: stored whole, never taken for a bolt done; the bolt whose
result it may be held until a person checked it on the controller.  A readable copy, or the
missing id fetched later, is recognized as that result (one rundown, not two)."""

from __future__ import annotations

from dataclasses import dataclass

from db.kinds import (
    unreadable_note,
)
from drivers.wrench.base import (
    TighteningResult,
)
from stationd.reasons import Unattributed, UnattributedKind
from stationd.station.actions import (
    Acknowledge,
    Action,
    Publish,
    Selection,
    StoreUnattributed,
    StoreUnreadable,
)
from stationd.station.events import (
    Because,
    Notice,
    ResultUnattributed,
    ResultUnreadable,
    Said,
    State,
    StateReason,
)
from stationd.station.inputs import (
    ResultIn,
    UnreadableIn,
)
from stationd.station.lost import CLOCK_SLACK_S, LostRules


@dataclass(frozen=True)
class _Unread:
    """What the core took of an unreadable message with its tightening id: a readable copy
    the controller sends again (its first copy garbled on the line) is that result, never
    another bolt's."""

    pset: int | None
    timestamp: object
    bolt: str | None
    seen_at: float          # when it came (the station's clock)
    #: held only for want of its type (fetched at a revision without one, for the enable on
    #: or whose window ended): that enable and when its tool went on.  The typed push of it
    #: made in between is that enable's rundown (ResultRules._typed_copy)
    en: Selection | None = None
    since: float | None = None
    retry: bool = False     # the enable before it was its bolt's own (either is its rundown)

    def same(self, r: TighteningResult, made_at: float | None) -> bool:
        """``r`` says what could be picked out of the unreadable one (pset, time).  Where the
        controller's time is missing on either side, a result made after the unreadable one
        came (``made_at``: its time on the station's clock, where the controller's clock is
        known) is another one under the same id (a controller whose ids started again):
        taken for a copy, it was lost and its bolt left open with the tool on.  With no time
        to tell, it is taken for the copy: recorded to the bolt enabled now, it would close a
        bolt perhaps never tightened."""
        when = r.timestamp
        if self.pset is not None and int(r.pset) != self.pset:
            return False
        if self.timestamp is not None and when is not None:
            return bool(when == self.timestamp)
        return made_at is None or made_at <= self.seen_at + CLOCK_SLACK_S


@dataclass
class _UnreadGap:
    """An unreadable message without a tightening id that held ``bolt`` of ``vin``: the id
    read (pushed) before it, and the first read after it (None: none yet).  Where they are
    two apart, the message is the one id between them."""

    before: int
    unread: _Unread
    vin: str | None
    after: int | None = None


#: unreadable messages without an id kept to be matched by a fetch (the newest)
UNREAD_GAPS_KEPT = 8


class UnreadRules(LostRules):
    """Results the driver could not read: stored whole, the bolt they may be held; one read
    later by its id found for what it was."""

    def _unread_read(self, ev: ResultIn, tid: int) -> list[Action] | None:
        """A result fetched for the one id missing between two results read, the link up,
        where an unreadable message without an id came between them and held a bolt: that
        message, read now (its pset and time, where they could be picked out, agree; the VIN
        it echoes is the held bolt's vehicle).  Stored apart with its values, its reason
        naming the held bolt; the bolt stays held for a person, as for an unreadable result
        whose readable copy comes (a quality trial: it was stored unattributed with no word
        of the hold, one rundown twice in the records).  None where it is not."""
        if not (ev.fetched and ev.live):
            return None
        r = ev.result
        echoed = str(r.vin or "").strip()
        for gap in self._unread_gaps:
            if gap.before != tid - 1 or gap.after != tid + 1 \
                    or not gap.unread.same(r, ev.made_at) or (echoed and echoed != gap.vin):
                continue
            self._unread_gaps.remove(gap)
            self._recorded[tid] = gap.unread   # a copy sent again is that result too
            why = Unattributed(UnattributedKind.UNREAD_READ, tid, int(r.pset),
                               bolt=gap.unread.bolt, between=(gap.before, tid + 1))
            return [StoreUnattributed(r, gap.vin, why),
                    Publish(ResultUnattributed(tid, int(r.pset), bool(r.ok), t=ev.t)),
                    Publish(Notice(Said.UNATTRIBUTED, tightening_id=tid, pset=int(r.pset),
                                   unattributed=why, t=ev.t))]
        return None

    def _on_unreadable_in(self, ev: UnreadableIn) -> list[Action]:
        """:meth:`_unreadable_read`; one pushed (its id picked out, it may be the one whose
        skipped ids were fetched) is judged as the result owed, then owed no longer."""
        u, waited = ev.unreadable, self._pending_push
        try:
            acts = self._unreadable_read(ev)
        finally:
            if not u.fetched or (u.tightening_id is not None and u.tightening_id == waited):
                self._pending_push = None
        if u.tightening_id is not None and not u.fetched:
            # its id read, pushed: it orders the ids as a read result does (judged during
            # the enable it came under, the tool off after it: a result fetched later was
            # made under a later enable; a new user's trial: the next bolt's lost push,
            # fetched, was stored unattributed, "other enables came between", none had).  An
            # id misread proves no result anyone's alone: a result placed by the order is
            # also made after the tool went off for this enable (:meth:`_after_last_off`)
            self._judge(u.tightening_id, True, ev.t)
        return acts + self._push_judged(ev.t)

    def _unreadable_read(self, ev: UnreadableIn) -> list[Action]:
        """A result the driver could not read: stored whole; the bolt it may belong to (the
        tool's, while on or within the late-result window, or the one of a link cut for a
        fetched one; of the same pset where one could be read) is held until a supervisor
        has checked the result on the controller and releases it."""
        u = ev.unreadable
        # a copy by its text after the header, where that text says which result it is (an
        # id or a time picked out): two results cut short the same way are not one
        known = u.tightening_id is not None or u.timestamp is not None
        if ev.stored is not None or (known and (u.mid, u.body) in self._unreadable_seen):
            # a copy the controller sent again (its acknowledgement lost, or not sent yet):
            # stored once, held against no bolt (that of the enable owed now is another
            # one's), acknowledged: the controller may forget it
            vin, bolt = ev.stored if ev.stored is not None else (
                None, self._unreadable_seen[(u.mid, u.body)])
            return [Publish(Notice(Said.SENT_AGAIN, tightening_id=u.tightening_id, bolt=bolt,
                                   vin=vin if vin != self.vin else None, t=ev.t)),
                    Acknowledge(u)]
        en = self._enabled if self._result_owed(ev.t) else None
        if u.fetched:   # after a reconnect (a renewal's catch-up hands its results as pushed)
            en = self._cut.selection if self._cut is not None else None
            if en is None and self._checking_owed():
                # fetched by a check of the controller's newest for the enable owed now (the
                # tool on, or its window ended): it may be that enable's rundown, its push
                # lost; held (a supervisor's trial: "no bolt it could belong to", the bolt
                # left open, the window-end check then finding the newest already heard)
                en = self._enabled
        if en is not None and u.pset is not None and en.pset is not None \
                and u.pset != en.pset and not u.fetched:
            # its pset could be read, and it is not the one sent.  Not for one fetched after
            # a link cut: a pset picked out of a body that does not read may be another
            # field (a job id read as the pset, an independent controller's trial), and
            # taken as proof, the cut's bolt, perhaps tightened, was left open
            en = None
        bolt = en.bolt if en is not None and en.vin else None
        if u.tightening_id is not None:
            untyped = u.fetched and u.laid_out_as is not None and bolt is not None \
                and en is self._enabled and self._cut is None and self._enabled_at is not None
            self._recorded[u.tightening_id] = _Unread(
                u.pset, u.timestamp, bolt, ev.t, en if untyped else None,
                self._enabled_at if untyped else None, self._same_bolt_before)
        elif bolt is not None and en is not None and self._last_pushed is not None \
                and not u.fetched:   # which id it is, the next result read may tell
            self._unread_gaps = [*self._unread_gaps[-(UNREAD_GAPS_KEPT - 1):], _UnreadGap(
                self._last_pushed, _Unread(u.pset, u.timestamp, bolt, ev.t), en.vin)]
        if known:
            self._unreadable_seen[(u.mid, u.body)] = bolt
        acts: list[Action] = []
        # the selection it came under: its loosen pset's result is a loosening's
        loosen = en is not None and en.loosen
        if bolt is not None and self.tool_on:
            acts += self._tool_off(ev.t, StateReason(Because.UNREADABLE, bolt=bolt,
                                                     loosen=loosen))
        acts.append(StoreUnreadable(u, en.vin if en is not None and bolt else self.vin, bolt,
                                    en if bolt else None))
        acts.append(Publish(ResultUnreadable(u.error, u.revision, u.tightening_id, bolt,
                                             t=ev.t)))
        if bolt is None or en is None:
            return [*acts, Publish(Notice(Said.UNREADABLE, note=u.error, t=ev.t))]
        self._answered(en)
        if self.matcher is not None and self.vin == en.vin and bolt in self.matcher.bolts:
            acts += self._hold(ev.t, bolt, unreadable_note(u.tightening_id, u.mid, u.revision),
                               under=en)
        if self.bolt == bolt and self.vin == en.vin:   # (not the next car's of that name)
            acts += self._drop(ev.t, State.TRACKING,
                               StateReason(Because.UNREADABLE_HELD, bolt=bolt, loosen=loosen))
        return acts
