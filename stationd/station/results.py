"""Results from the controller: which are tightenings, to which enable each belongs (also
after a link cut), unreadable ones held, the NOK policy after each (retry, lock, loosen,
skip).  Typed, not words: a result's type goes out as its code and why a result is
unattributed as an :class:`~stationd.reasons.Unattributed`; :mod:`stationd.words` names them
at the edge (the records, the journal, the bus)."""

from __future__ import annotations

from dataclasses import dataclass

from db.kinds import (
    LOOSENING,
    LOST_UNKNOWN,
    NOT_TAKEN,
    TIGHTENING,
    cut_unknown_note,
    lost_unknown_note,
    not_taken_note,
    unreadable_note,
)
from drivers.wrench.base import (
    ResultKind,
    TighteningResult,
    TorqueUnit,
    result_kind,
)
from stationd.reasons import Unattributed, UnattributedKind, Unproved, UnprovedKind
from stationd.station.actions import (
    Acknowledge,
    Action,
    Publish,
    Record,
    Reply,
    Selection,
    SettleEnable,
    StoreControllerEvent,
    StoreCutUnknown,
    StoreGap,
    StoreUnattributed,
    StoreUnreadable,
    torque_window,
)
from stationd.station.commands import Answer, EnterOutcome, Issuer
from stationd.station.events import (
    Because,
    BoltSkipped,
    ControllerResultEvent,
    Notice,
    ResultRecorded,
    ResultUnattributed,
    ResultUnreadable,
    Said,
    State,
    StateReason,
)
from stationd.station.inputs import (
    CaughtUp,
    CommandDone,
    NotStored,
    ResultCopy,
    ResultIn,
    ResultsMissed,
    ResultsSkipped,
    UnreadableIn,
    Written,
)
from stationd.station.orders import OrderRules
from stationd.station.state import NOK_SKIPPED, ON_A_BOLT, PENDING_PUSH_S, _Cut

#: the controller stamps its results to the second, and its clock's offset is measured to
#: the second: a result fetched after a link cut is placed between the enable and the cut
#: within this much
CLOCK_SLACK_S = 2.0


def _said(result: TighteningResult) -> object:
    """What a result says besides its id: equal for a copy the controller sends again,
    different for another result under the same id (a controller whose ids started again)."""
    return (type_code(result), getattr(result, "pset", None), getattr(result, "ok", None),
            getattr(result, "torque_nm", None), getattr(result, "angle_deg", None),
            getattr(result, "timestamp", None))


def type_code(result: TighteningResult) -> int | None:
    """A result's type code as the controller sent it (Open Protocol MID 0061 revision 3+,
    parameter 49), None where its revision (or the backend) carries none."""
    code = getattr(result, "result_type_code", None)
    if code is not None:
        return int(code)
    t = getattr(result, "result_type", None)
    return None if t is None else int(t)


def rundown_kind(result: TighteningResult, sent_loosen: bool) -> str:
    """A rundown's kind (db.kinds): its own type where its revision carries it, else what
    the station sent (a loosen pset or the tightening one).  The type wins: a controller
    reversed by hand reports the loosening it made, whatever was sent.  Only for results
    that are rundowns (:func:`result_kind` says which are not)."""
    return LOOSENING if result_kind(type_code(result), sent_loosen) is ResultKind.LOOSENING \
        else TIGHTENING


@dataclass(frozen=True)
class _Unread:
    """What the core took of an unreadable message with its tightening id: a readable copy
    the controller sends again (its first copy garbled on the line) is that result, never
    another bolt's."""

    pset: int | None
    timestamp: object
    bolt: str | None
    seen_at: float          # when it came (the station's clock)

    def same(self, r: TighteningResult, made_at: float | None) -> bool:
        """``r`` says what could be picked out of the unreadable one (pset, time).  Where the
        controller's time is missing on either side, a result made after the unreadable one
        came (``made_at``: its time on the station's clock, where the controller's clock is
        known) is another one under the same id (a controller whose ids started again):
        taken for a copy, it was lost and its bolt left open with the tool on.  With no time
        to tell, it is taken for the copy: recorded to the bolt enabled now, it would close a
        bolt perhaps never tightened."""
        when = getattr(r, "timestamp", None)
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


class ResultRules(OrderRules):
    """Results: tightenings closing bolts, controller events, unreadable and late results,
    the NOK policy after each."""

    def _on_result_in(self, ev: ResultIn) -> list[Action]:
        """:meth:`_result_read`; a result pushed is the one owed since ids it skipped were
        fetched (or one after it; or that one fetched after a reconnect): owed no longer
        once it is judged, then the NOK policy waiting for it (:meth:`_push_judged`)."""
        waited, tid = self._pending_push, int(ev.result.tightening_id)
        try:
            acts = self._result_read(ev)
        finally:
            if not ev.fetched or tid == waited:
                self._pending_push = None
        # the newest result judged: during which enable, the tool left on or off (an older id
        # judged later, a catch-up's or a copy's, says nothing of the order: a reviewer)
        if self._judged is None or tid > self._judged[0]:
            self._judged = (tid, self._enable_serial, self.tool_on)
        return acts + self._push_judged(ev.t)

    def _push_judged(self, t: float) -> list[Action]:
        """The pushed result that skipped ids is judged (or no longer waited for): the NOK
        policy of each bolt whose NOK came fetched before it and is still its last result
        (a reviewer: a batch increment pushed after a lost NOK left the bolt unlocked)."""
        if self._pending_push is not None or not self._nok_owed:
            return []
        owed, self._nok_owed = self._nok_owed, {}
        m, acts = self.matcher, []
        for bolt, pset in owed.items():
            if m is not None and bolt in m.bolts and bolt in self._nok_last \
                    and bolt not in m.done and bolt not in m.locked and bolt not in m.held:
                acts += self._after_nok(t, bolt, pset, counted=True)
        return acts

    def _pending_overdue(self, t: float) -> list[Action]:
        """A pushed result waited for longer than :data:`PENDING_PUSH_S` (never fed: a fault
        of the shell): no longer waited for."""
        if self._pending_push is None or t - self._pending_at < PENDING_PUSH_S:
            return []
        return self._end_wait(t)

    def _end_wait(self, t: float) -> list[Action]:
        """No pushed result is waited for any more: :meth:`_push_judged` then."""
        self._pending_push = None
        return self._push_judged(t)

    def _result_read(self, ev: ResultIn) -> list[Action]:
        """A result: a controller event (never a rundown) by its type; else recorded to the
        bolt the tool was enabled for (its pset, while on or within the late-result window,
        or after a link cut where the controller's own data places it there), else stored
        unattributed with why."""
        r = ev.result
        tid = int(r.tightening_id)
        if self._recorded.get(tid, None) == _said(r):
            return [Acknowledge(r)]   # sent again by the controller: stored once already
        seen = self._recorded.get(tid)
        if isinstance(seen, _Unread) and seen.same(r, ev.made_at):
            # an unreadable message's copy that reads: stored (whole) once, its bolt held;
            # taken for the enable owed now, it closed a bolt never tightened
            return [Publish(Notice(Said.SENT_AGAIN, tightening_id=tid, bolt=seen.bolt,
                                   t=ev.t)), Acknowledge(r)]
        again: list[Action] = [] if tid not in self._recorded else [
            Publish(Notice(Said.IDS_AGAIN, tightening_id=tid, t=ev.t))]
        # the id after any unreadable one waiting for it: this one read as pushed, or the
        # pushed one that revealed this one (fed after it)
        after = tid if not ev.fetched else ev.before
        if after is not None:
            for gap in self._unread_gaps:
                if gap.after is None and after > gap.before:
                    gap.after = after
        if not ev.fetched:
            self._last_pushed = tid
        return again + self._result_in(ev, tid)

    def _on_result_copy(self, ev: ResultCopy) -> list[Action]:
        """A result the database had stored already (the shell asked before this core saw
        it): a copy the controller sent again.  Nothing is attributed: no bolt is closed,
        counted or reopened, the tool and its enable stay as they are (the enabled bolt's
        own result may still come), and the copy is said with the bolt it was stored for
        (and its vehicle, where it is not the one at the station), then acknowledged: the
        controller may forget it."""
        r = ev.result
        tid = int(r.tightening_id)
        # the pushed one waited for: a copy, it is in
        owed = self._end_wait(ev.t) if tid == self._pending_push else []
        if self._recorded.get(tid, None) == _said(r):
            return [*owed, Acknowledge(r)]   # said already by this core
        self._recorded[tid] = _said(r)
        return [*owed, Publish(Notice(Said.SENT_AGAIN, tightening_id=tid, bolt=ev.bolt,
                                      vin=ev.vin if ev.vin != self.vin else None, t=ev.t)),
                Acknowledge(r)]

    def _on_results_skipped(self, ev: ResultsSkipped) -> list[Action]:
        """A pushed result skipped ids, fetched and fed before it: the rundown is over, the
        tool goes off now (a reviewer: it stayed on through the fetches, the operator could
        pull again), and the enable's result stays owed until the pushed one is in."""
        self._pending_push, self._pending_at = ev.tightening_id, ev.t
        if self.state not in ON_A_BOLT and not self.tool_on:
            return []
        return self._drop(ev.t, State.TRACKING, StateReason(Because.PUSH_AFTER_LOST,
                                                            bolt=self.bolt))

    def _result_in(self, ev: ResultIn, tid: int) -> list[Action]:
        r = ev.result
        en = self._enabled
        kind = result_kind(type_code(r), en is not None and en.loosen)
        if kind in (ResultKind.EVENT, ResultKind.UNKNOWN):
            return self._controller_event(ev, kind)
        read = self._unread_read(ev, tid)
        if read is not None:
            return read
        ours = en is not None and (en.pset is None or int(r.pset) == en.pset) and not (
            ev.fetched and self._enabled_at is not None
            and self._enabled_at > self._link_lost_at)
        if ours and en is not None and en.vin and self._result_owed(ev.t):
            return self._attribute(ev, en)
        if en is not None and self._made_under(ev, en):
            return self._attribute(ev, en, lost=True)
        proved, not_proved = self._made_during_cut(ev)
        if proved is not None:
            return self._attribute(ev, proved, cut=True)
        why = Unattributed(UnattributedKind.OUTSIDE if not ev.fetched else
                           UnattributedKind.FETCHED_LIVE if ev.live else
                           UnattributedKind.FETCHED, tid, int(r.pset), not_proved)
        lost = self._lost_enables(ev)
        # filed under the vehicle its only possible enables were on (one that has left: the
        # result of its last bolt, its push lost, was filed under the next car)
        vins = {u.selection.vin for u in lost}
        filed = vins.pop() if len(vins) == 1 else self.vin
        return [StoreUnattributed(r, filed, why),
                Publish(ResultUnattributed(tid, int(r.pset), bool(r.ok), t=ev.t)),
                Publish(Notice(Said.UNATTRIBUTED, tightening_id=tid, pset=int(r.pset),
                               unattributed=why, t=ev.t)),
                *self._cut_in_doubt(ev), *self._lost_in_doubt(ev, lost)]

    def _lost_enables(self, ev: ResultIn) -> list[_Cut]:
        """The enables that got no result in their window (the operator left the bolt) whose
        result a result fetched late (its push lost: a later one skipped its id, or a
        reconnect's catch-up found it) may be: of its pset, made within that enable and its
        window (or when, not known), its bolt still open and not selected now (of a vehicle
        that has left: whatever it is now, not known here)."""
        m, r = self.matcher, ev.result
        if not ev.fetched:
            return []
        found: list[_Cut] = []
        for u in self._unanswered:
            en, b = u.selection, u.selection.bolt
            if en.pset is None or int(r.pset) != en.pset:
                continue
            if en.vin == self.vin and m is not None and (
                    b == self.bolt or b in m.done or b in m.held or b in m.skipped
                    or b in m.locked):
                continue
            if ev.made_at is not None and not u.spans(ev.made_at, CLOCK_SLACK_S):
                continue    # made while its tool was off for good: not its own
            found.append(u)
        return found

    def _lost_in_doubt(self, ev: ResultIn, lost: list[_Cut]) -> list[Action]:
        """The result may be that of each of the ``lost`` enables (:meth:`_lost_enables`).
        Never taken for one (other enables came between: the data cannot prove it), never
        left open either (it may be tightened: a quality trial's bolt was tightened twice):
        each such bolt is held for a person, stored so that the hold outlives a restart and
        comes back with its vehicle where that one has left."""
        acts: list[Action] = []
        tid = int(ev.result.tightening_id)
        for u in lost:
            en, b = u.selection, u.selection.bolt
            assert en.pset is not None  # noqa: S101 - _lost_enables' guard
            note = lost_unknown_note(tid, en.pset, u.enabled_at)
            stored = StoreCutUnknown(en.vin, b, note, en, what=LOST_UNKNOWN)
            if en.vin != self.vin or self.matcher is None:
                acts += [stored, Publish(Notice(Said.CUT_UNKNOWN, bolt=b, vin=en.vin, note=note,
                                                t=ev.t))]
            else:
                acts += [stored, *self._hold(ev.t, b, note, Notice(
                    Said.CUT_UNKNOWN, bolt=b, note=note, t=ev.t), under=en)]
            self._answered_bolt(en.vin, b)
        return acts

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

    def _cut_in_doubt(self, ev: ResultIn) -> list[Action]:
        """A result stored unattributed while a link cut's result is owed, of the pset sent
        then (pushed again by the controller after the reconnect, or fetched and not proved
        by its data): it may be that bolt's, or not.  Never taken for it, and never left
        open either (it may be tightened): the bolt is held for a person."""
        cut, r = self._cut, ev.result
        if cut is None or cut.selection.pset is None or int(r.pset) != cut.selection.pset:
            return []
        return self._cut_unknown(ev.t, f"tightening {int(r.tightening_id)} may be its own "
                                       "(not proved by the controller's data)")

    def _on_caught_up(self, ev: CaughtUp) -> list[Action]:
        """:meth:`_cut_caught_up`; a pushed result waited for since ids it skipped were told
        is waited for no longer (the reconnect's catch-up fed what the controller has)."""
        return self._end_wait(ev.t) + self._cut_caught_up(ev)

    def _cut_caught_up(self, ev: CaughtUp) -> list[Action]:
        """The catch-up after a reconnect ended.  A link cut's result still owed was not among
        the results fetched: where they are all of them, none was made (the bolt open as
        before); else what the controller did is not known, and the bolt is held."""
        cut = self._cut
        if cut is None:
            return []
        if cut.reconnects is not None and ev.reconnects is not None \
                and ev.reconnects <= cut.reconnects:
            return []       # a catch-up of the connection that was cut, or of an earlier one
        if not ev.complete:
            return self._cut_unknown(ev.t, ev.reason or "its results not fetched")
        # none made so far; its late-result window, where it still runs, still takes one
        # pushed now (a restart during a rundown: the result comes after the catch-up)
        self._cut = None
        said = Publish(Notice(Said.CUT_NOTHING, bolt=cut.selection.bolt, t=ev.t))
        if self._enabled is cut.selection:
            if self._result_owed(ev.t):
                return [said]
            self._enabled = None
        return [SettleEnable(cut.selection), said]

    def _cut_unknown(self, t: float, why: str) -> list[Action]:
        """The link cut's bolt held (its result not known: ``why``); the cut ends."""
        cut = self._cut
        assert cut is not None  # noqa: S101 - the callers' guard
        en = cut.selection
        self._answered(en)
        note = cut_unknown_note(why, en.pset, cut.enabled_at)
        stored = StoreCutUnknown(en.vin, en.bolt, note, en)
        if self.matcher is None or self.vin != en.vin or en.bolt not in self.matcher.bolts:
            # held when that vehicle is at the station again
            return [stored, Publish(Notice(Said.CUT_UNKNOWN, bolt=en.bolt, vin=en.vin,
                                           note=note, t=t))]
        return [stored, *self._hold(t, en.bolt, note, Notice(
            Said.CUT_UNKNOWN, bolt=en.bolt, note=note, t=t), under=en)]

    def _answered(self, en: Selection) -> None:
        """``en``'s result is in, or settled for a person (held): its enable is owed nothing
        more, and a link cut during it is over."""
        if self._enabled is en:
            self._enabled = None
        if self._cut is not None and self._cut.selection is en:
            self._cut = None

    def _made_during_cut(self, ev: ResultIn) -> tuple[Selection | None, Unproved | None]:
        """The selection a result fetched after a link cut belongs to, when the controller's
        own data proves it (its pset the one sent, its VIN the one sent where it echoes one,
        its tightening id the first after the last the station accounted for, its
        timestamp between the enable and the cut); else None and what did not agree (None
        where nothing was to prove: not fetched, or no cut)."""
        cut, r = self._cut, ev.result
        if not ev.fetched:
            return None, None
        if cut is None:   # after a reconnect, said (a quality trial: no word of why)
            return None, None if ev.live else Unproved(UnprovedKind.NO_CUT)
        en = cut.selection
        echoed = str(r.vin or "").strip()
        if en.pset is None or int(r.pset) != en.pset:
            return None, Unproved(UnprovedKind.PSET, bolt=en.bolt, pset=int(r.pset),
                                  sent_pset=en.pset)
        if echoed and echoed != en.vin:
            return None, Unproved(UnprovedKind.VIN, vin=echoed, sent_vin=en.vin)
        if ev.follows is None:
            return None, Unproved(UnprovedKind.FOLLOWS_UNKNOWN)
        if int(r.tightening_id) != ev.follows + 1:
            return None, Unproved(UnprovedKind.NOT_FIRST, follows=ev.follows)
        if ev.made_at is None:
            return None, Unproved(UnprovedKind.CLOCK_UNKNOWN)
        if not cut.spans(ev.made_at, CLOCK_SLACK_S):
            return None, Unproved(UnprovedKind.OUTSIDE_CUT, bolt=en.bolt)
        return en, None

    def _made_under(self, ev: ResultIn, en: Selection) -> bool:
        """Whether a result fetched with the link up (a later one pushed skipped its id: its
        push lost) was made under the enable ``en`` owed now: of its pset and vehicle (where
        it echoes one), the link up since the enable, and either its id after the last result
        judged, that one judged during this enable or, the tool off after it, during the one
        before and made after that tool-off (:meth:`_after_last_off`; the tool is on for one
        bolt at a time: only this enable could have made it), or its time after the tool
        went on for it (beyond the clock's slack).  Its
        time, where known, never before the enable or after its tool went off.  A
        supervisor's trial: the operator pulled again at once, the first NOK stored
        unattributed and uncounted (by its time alone, within the slack, never proved)."""
        r, made = ev.result, ev.made_at
        if not (ev.fetched and ev.live and ev.before is not None) \
                or not en.vin or self._cut is not None or self._enabled_at is None \
                or self._enabled_at <= self._link_lost_at or not self._result_owed(ev.t):
            return False
        echoed = str(r.vin or "").strip()
        if (en.pset is not None and int(r.pset) != en.pset) or (echoed and echoed != en.vin):
            return False
        off = ev.t if self.tool_on or self._off_at is None else self._off_at
        if made is not None and not \
                self._enabled_at - CLOCK_SLACK_S <= made <= off + CLOCK_SLACK_S:
            return False
        last, n = self._judged, self._enable_serial
        ordered = last is not None and last[0] < int(r.tightening_id) and (
            last[1] == n or (last[1] == n - 1 and not last[2] and self._after_last_off(made)))
        return ordered or (made is not None and made >= self._enabled_at + CLOCK_SLACK_S)

    def _after_last_off(self, made: float | None) -> bool:
        """Whether a result was made after the tool went off for the enable before this one
        (beyond the clock's slack): one made sooner may be that bolt's, the operator pulling
        again as its disable was sent (a rundown begun before the disable took effect ends
        after it; a reviewer: credited to the next bolt of the same pset enabled within the
        slack).  Its time not known: not proved."""
        off = self._off_before_enable
        return made is not None and (off is None or made > off + CLOCK_SLACK_S)

    def _controller_event(self, ev: ResultIn, kind: ResultKind) -> list[Action]:
        """A result that is not a tightening or a loosening (a batch increment a line lead
        pressed, a bypassed pset, an aborted job, a reference setup, or a type the station
        does not know): stored as a controller event, said, and nothing else: no bolt is
        closed, opened or counted, and the tool stays as the station decided."""
        r, code = ev.result, type_code(ev.result)
        self._recorded[int(r.tightening_id)] = _said(r)
        bolt = self.bolt if self.tool_on else None
        said = Said.UNKNOWN_TYPE if kind is ResultKind.UNKNOWN else Said.CONTROLLER_EVENT
        # named by its type code: the type's name in words is written by the shell (stored,
        # published: stationd.words.result_type_words), never built here
        return [StoreControllerEvent(r, self.vin, bolt),
                Publish(ControllerResultEvent(code or 0, "", int(r.tightening_id),
                                              int(r.pset), bool(r.ok), bolt, t=ev.t)),
                Publish(Notice(said, bolt=bolt, result_type=code, t=ev.t))]

    def _on_written(self, ev: Written) -> list[Action]:
        """A result on disk: published for the screens, then the controller may forget it.
        One the database had already (a copy the controller sent again: this core had not
        seen it, after a reload or a restart, and the shell's check before it came in did
        not find it: a race) is said in the journal with the bolt it was stored for and
        acknowledged; no new result is published (none was stored).  Where that is another
        bolt than the one this core attributed it to, that attribution is undone
        (:meth:`_not_its_copy`)."""
        a, r = ev.record, ev.record.result
        if ev.again:
            stored = (ev.stored_vin or a.vin, ev.stored_bolt or a.bolt)
            acts: list[Action] = []
            if stored != (a.vin, a.bolt):
                acts += self._not_its_copy(ev, stored)
            return [*acts,
                    Publish(Notice(Said.SENT_AGAIN, tightening_id=int(r.tightening_id),
                                   bolt=stored[1],
                                   vin=stored[0] if stored[0] != self.vin else None,
                                   t=ev.t)),
                    Acknowledge(r)]
        return [Publish(ResultRecorded(
            a.vin, a.bolt, bool(r.ok), float(r.torque_nm), float(r.angle_deg),
            int(r.tightening_id), int(r.pset), float(r.torque_min_nm), float(r.torque_max_nm),
            float(r.angle_min_deg), float(r.angle_max_deg), a.late, tuple(ev.images), a.kind,
            a.selection.operator if a.selection is not None else None, t=ev.t)),
            Acknowledge(r)]

    def _not_its_copy(self, ev: Written, stored: tuple[str, str]) -> list[Action]:
        """A copy of ``stored``'s (vin, bolt) result that this core had attributed to
        ``ev.record``'s bolt: that bolt is not done by it, the NOK it counted is taken back
        (with the skip that NOK made), and the bolt is held for a supervisor, with which
        result it was.  Why held, not only reopened: the tool was enabled for that bolt, and
        it may have been tightened with its own result not here (lost, or coming late):
        open again, it could be tightened twice; a person checks the controller's results
        and releases it (open again) or enters its outcome.  The enable stays cleared (its
        tool is off): a late result of its own is stored unattributed, for that person."""
        a, r = ev.record, ev.record.result
        m = self.matcher
        if m is None or self.vin != a.vin or a.bolt not in m.bolts:
            return []
        m.done.discard(a.bolt)
        m.counted.discard(a.bolt)
        if not bool(r.ok) and self._noks.get(a.bolt, 0) > 0:
            self._noks[a.bolt] -= 1
            if not self._noks[a.bolt]:
                del self._noks[a.bolt]
            if m.skipped.get(a.bolt) == NOK_SKIPPED:
                del m.skipped[a.bolt]
        return self._hold(ev.t, a.bolt, f"tightening {int(r.tightening_id)} was "
                          f"{stored[1]}'s" + (f" of {stored[0]}" if stored[0] != a.vin else "")
                          + f" (sent again), not a result of {a.bolt}", under=a.selection)

    def _on_results_missed(self, ev: ResultsMissed) -> list[Action]:
        return [StoreGap(ev.first, ev.last, self.vin, ev.reason),
                Publish(Notice(Said.GAP, tightening_id=ev.first, last_id=ev.last,
                               link_up=ev.live, note=ev.reason, t=ev.t))]

    def _on_not_stored(self, ev: NotStored) -> list[Action]:
        return [Publish(Notice(Said.NOT_STORED, tightening_id=ev.tightening_id, bolt=ev.bolt,
                               note=ev.reason, t=ev.t))]

    def _on_unreadable_in(self, ev: UnreadableIn) -> list[Action]:
        """:meth:`_unreadable_read`; one pushed (its id picked out, it may be the one whose
        skipped ids were fetched) is judged as the result owed, then owed no longer."""
        u, waited = ev.unreadable, self._pending_push
        try:
            acts = self._unreadable_read(ev)
        finally:
            if not u.fetched or (u.tightening_id is not None and u.tightening_id == waited):
                self._pending_push = None
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
        if en is not None and u.pset is not None and en.pset is not None \
                and u.pset != en.pset and not u.fetched:
            # its pset could be read, and it is not the one sent.  Not for one fetched after
            # a link cut: a pset picked out of a body that does not read may be another
            # field (a job id read as the pset, an independent controller's trial), and
            # taken as proof, the cut's bolt, perhaps tightened, was left open
            en = None
        bolt = en.bolt if en is not None and en.vin else None
        if u.tightening_id is not None:
            self._recorded[u.tightening_id] = _Unread(u.pset, u.timestamp, bolt, ev.t)
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

    def _outside_window(self, r: TighteningResult, en: Selection
                        ) -> tuple[float, float] | None:
        """The bolt's torque window (min, max of its process parameters) that ``r``, an OK
        result without a result type answering ``en``'s tightening pset, lies outside of;
        None for any other result, or where the window or the torque in Nm is not known
        (then it is taken as today: a revision without types reports tightenings)."""
        if type_code(r) is not None or not bool(r.ok) or en.loosen:
            return None
        if getattr(r, "torque_unit", None) is TorqueUnit.PERCENT:
            return None      # kept as sent: a percentage of the tool's maximum, not Nm
        window = en.torque_window
        spec = self._specs.get(en.bolt) if en.vin == self.vin else None
        if window is None and spec is not None:
            window = torque_window(spec.parameters)
        if window is None:
            return None
        lo, hi = window
        return None if lo <= float(r.torque_nm) <= hi else (lo, hi)

    def _not_taken(self, ev: ResultIn, en: Selection, window: tuple[float, float],
                   cut: bool) -> list[Action]:
        """An OK result without a type whose torque is outside its bolt's window: perhaps no
        tightening at all (at a revision without types, a batch increment or a bypass reads
        as an OK, of 0 Nm), perhaps one whose limits on the controller are not the station's.
        Never taken as the bolt done: stored as a controller event (the enable it answers
        settled with it), the tool off, and the bolt held, as for a result that could not be
        read, until a supervisor checked it on the controller and released it or entered its
        outcome (a real tightening counted once, never tightened twice)."""
        r = ev.result
        tid = int(r.tightening_id)
        self._recorded[tid] = _said(r)
        lo, hi = window
        said = Notice(Said.NOT_TAKEN, bolt=en.bolt, torque_nm=float(r.torque_nm),
                      torque_min=lo, torque_max=hi, tightening_id=tid, t=ev.t)
        acts: list[Action] = []
        if self.tool_on and not cut:    # (a lost one's: its rundown ended there)
            acts += self._tool_off(ev.t, StateReason(Because.NOT_TAKEN, bolt=en.bolt))
        acts.append(StoreControllerEvent(r, en.vin, en.bolt, NOT_TAKEN, en))
        acts.append(Publish(ControllerResultEvent(0, NOT_TAKEN, tid, int(r.pset), True,
                                                  en.bolt, t=ev.t)))
        self._answered(en)
        self._not_before = max(self._not_before, ev.t)
        if self.matcher is not None and self.vin == en.vin and en.bolt in self.matcher.bolts:
            acts += self._hold(ev.t, en.bolt, not_taken_note(float(r.torque_nm), tid), said)
        else:
            acts.append(Publish(said))
        if self.bolt == en.bolt and self.vin == en.vin:
            acts += self._drop(ev.t, State.TRACKING,
                               StateReason(Because.NOT_TAKEN_HELD, bolt=en.bolt))
        return acts

    def _attribute(self, ev: ResultIn, en: Selection, cut: bool = False,
                   lost: bool = False) -> list[Action]:
        """The result of the tightening the tool was enabled for: recorded to that bolt (of
        the vehicle it was enabled on, also after a reload or restart, or fetched after a
        link cut that the controller's data places it in, ``cut``, or fetched with the link
        up, made under that enable, ``lost``: the later result that revealed it, pushed,
        comes next and is judged under the same enable); an OK without a type outside the
        bolt's torque window is not (:meth:`_not_taken`)."""
        r = ev.result
        self._answered_bolt(en.vin, en.bolt)     # its own result came: nothing unanswered
        window = self._outside_window(r, en)
        if window is not None:
            return self._not_taken(ev, en, window, cut)
        # (the pushed one that skipped ids: its tool went off when they were told, not late)
        pushed = not ev.fetched and int(r.tightening_id) == self._pending_push
        late = (not self.tool_on and not pushed) or cut or lost
        kind = LOOSENING if result_kind(type_code(r), en.loosen) is ResultKind.LOOSENING \
            else TIGHTENING
        acts: list[Action] = []
        if self.tool_on and not cut:    # (a lost one's: its rundown ended there)
            acts += self._tool_off(ev.t, StateReason(Because.RUNDOWN, bolt=en.bolt,
                                                     loosen=kind == LOOSENING, ok=bool(r.ok)))
        acts.append(Record(en.vin, en.bolt, r, en, late, kind, offline=self._offline(ev)))
        if cut or lost:
            acts.append(Publish(Notice(Said.CUT_RECORDED if cut else Said.LOST_RECORDED,
                                       tightening_id=int(r.tightening_id), bolt=en.bolt,
                                       t=ev.t)))
        elif late:
            acts.append(Publish(Notice(Said.LATE_RESULT, bolt=en.bolt,
                                       vin=en.vin if en.vin != self.vin else None,
                                       tightening_id=int(r.tightening_id), t=ev.t)))
        self._recorded[int(r.tightening_id)] = _said(r)
        if not cut and not lost:
            self._enabled = None    # (a cut's result leaves an enable made since owed)
        if not lost:
            self._answered(en)      # the cut's result is in too (fetched, or pushed late)
        if en.operator is not None and en.operator == self.operator:
            self._operator_seen = max(self._operator_seen, ev.t)
        if self.matcher is not None and self.vin == en.vin:
            if kind == LOOSENING:
                acts += self._after_loosening(ev.t, en.bolt, bool(r.ok))
            elif bool(r.ok):
                if en.loosen:
                    acts.append(Publish(Notice(Said.LOOSEN_PSET_TIGHTENED, bolt=en.bolt,
                                               pset=en.pset, t=ev.t)))
                self.matcher.mark_done(en.bolt)
                self._noks.pop(en.bolt, None)
                self._nok_owed.pop(en.bolt, None)
                self._loosen.discard(en.bolt)
                self._nok_last.discard(en.bolt)
                self.matcher.counted.discard(en.bolt)
            else:
                # (after an OK of its own only where that one's push was lost: the later
                # rundown, its last result, says the bolt is NOK, as its records do)
                self.matcher.done.discard(en.bolt)
                self._nok_last.add(en.bolt)
                if lost and self._pending_push is not None:
                    # counted; the NOK policy after the later one, pushed next (a lock for a
                    # NOK that a later OK answered: a reviewer; :meth:`_push_judged`)
                    self._noks[en.bolt] = self._noks.get(en.bolt, 0) + 1
                    self._nok_owed[en.bolt] = en.pset
                else:
                    self._nok_owed.pop(en.bolt, None)
                    acts += self._after_nok(ev.t, en.bolt, en.pset)
            self.matcher.reset()     # a new selection: a new streak, from new frames
        self._not_before = max(self._not_before, ev.t)
        said = StateReason(Because.RESULT, bolt=en.bolt, ok=bool(r.ok), loosen=kind == LOOSENING)
        if self.bolt == en.bolt and self.vin == en.vin:   # (a reviewer: the next car's B1)
            self.bolt, self._selection, self._acked_at, self._away = None, None, None, 0
            if self.state in ON_A_BOLT:
                self._to(State.TRACKING, said)
        elif pushed and self.state is State.TRACKING and self.reason == StateReason(
                Because.PUSH_AFTER_LOST, bolt=en.bolt):
            self._to(State.TRACKING, said)    # (it said the results not pushed came first)
        return acts

    def _offline(self, ev: ResultIn) -> bool:
        """Whether ``ev`` was made while the link to the controller was down: by its own time
        between the link lost and back (each within the clock's slack), whether fetched after the
        reconnect or pushed then (a reviewer: only fetched ones were); where its time or the
        link's return is not known, whether it was fetched after a reconnect."""
        lost, back = self._link_lost_at, self._link_back_at
        if ev.made_at is not None and back >= lost > float("-inf"):
            # (its time to the second, through an offset measured at connect: one made just
            # after the link came back, the station's start too, is not taken for offline)
            return lost - CLOCK_SLACK_S <= ev.made_at <= back - CLOCK_SLACK_S
        return ev.fetched and not ev.live

    def _after_loosening(self, t: float, bolt: str, ok: bool) -> list[Action]:
        """A loosening (measured, or its outcome entered by a person) is never the bolt done
        (it undoes a tightening).  OK: the bolt's tightening pset goes next; NOK: it counts as
        a NOK of the bolt (the joint did not come loose: ``max_nok`` of them lock it) and a
        bolt to loosen stays so."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self.matcher.done.discard(bolt)
        self._nok_last.discard(bolt)
        self.matcher.counted.discard(bolt)   # undone: no longer counts in its batch
        if ok:
            self._loosen.discard(bolt)
            return [Publish(Notice(Said.LOOSENED, bolt=bolt, t=t))]
        n = self._noks[bolt] = self._noks.get(bolt, 0) + 1
        rule = self.nok.rule(bolt, self._specs[bolt].pset)
        if n >= rule.max_nok:
            return self._lock(t, bolt, n)
        return [Publish(Notice(Said.LOOSENING_NOK, bolt=bolt, count=n, t=t))]

    def _after_nok(self, t: float, bolt: str, pset: int | None,
                   counted: bool = False) -> list[Action]:
        """The NOK policy: the bolt locks after ``max_nok`` in a row; with ``loosen`` it gets
        its loosen pset next (also once released); with ``skip`` it is marked NOK and skipped
        for this vehicle; with ``repeat`` it is open again."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        n = self._noks[bolt] = self._noks.get(bolt, 0) + (0 if counted else 1)
        rule = self.nok.rule(bolt, self._specs[bolt].pset if bolt in self._specs else pset)
        if rule.strategy == "loosen" and rule.loosen_pset is not None:
            self._loosen.add(bolt)
        if rule.count_in_batch:     # the sequence goes on without an OK of this bolt
            self.matcher.counted.add(bolt)
        if n >= rule.max_nok:
            return self._lock(t, bolt, n)
        if bolt in self._loosen:
            return [self._to_loosen(t, bolt)]
        if rule.strategy == "skip":
            why = NOK_SKIPPED
            self.matcher.skipped[bolt] = why
            return [Publish(BoltSkipped(bolt, skip=why, t=t))]
        return []

    # -- an outcome entered by a person for a held bolt -----------------------------------------
    def _is_entered_outcome(self, ev: CommandDone) -> bool:
        """Whether ``ev`` is an entered outcome recorded (its rundown with it, in one
        transaction): a result, which the results' rules apply (the dispatch's case)."""
        c = self._commands.get(ev.request)
        return c is not None and ev.reason is None and isinstance(c.command, EnterOutcome)

    def _on_entered_outcome_done(self, ev: CommandDone) -> list[Action]:
        c = self._commands.pop(ev.request)
        assert isinstance(c.command, EnterOutcome)  # noqa: S101 - the dispatch's guard
        return [*self._outcome_entered(ev.t, c.command, c.issuer),
                Reply(Answer(ev.request, c.command, c.issuer))]

    def _outcome_entered(self, t: float, cmd: EnterOutcome, who: Issuer) -> list[Action]:
        """The outcome a person read on the controller's screen, now on disk as a rundown
        entered by them: the hold ends.  Of a tightening: OK closes the bolt as a measured
        OK does; NOK is a NOK result under the NOK policy (counted in the row, locked at
        ``max_nok``, to be loosened, skipped, or open again).  Of a loosening (the hold's
        result came under the bolt's loosen pset, ``cmd.loosening``): as a measured
        loosening, never the bolt done: OK, its tightening pset goes next; NOK counts."""
        m = self.matcher
        if m is None or self.vin != cmd.vin or cmd.bolt not in m.bolts:
            return []   # the vehicle left while the command was being recorded
        b, spec = cmd.bolt, self._specs.get(cmd.bolt)
        held = self._unhold(b)
        p = spec.parameters if spec is not None and not cmd.loosening else None
        acts: list[Action] = [Publish(ResultRecorded(
            cmd.vin, b, cmd.ok, float(cmd.torque_nm), float(cmd.angle_deg), 0,
            cmd.loosen_pset if cmd.loosening else spec.pset if spec is not None else None,
            p.torque.min if p is not None else None, p.torque.max if p is not None else None,
            p.angle.min if p is not None and p.angle is not None else None,
            p.angle.max if p is not None and p.angle is not None else None,
            kind=LOOSENING if cmd.loosening else TIGHTENING, entered_by=who.user, t=t))]
        said = (Said.ENTERED_LOOSENING_OK if cmd.ok else Said.ENTERED_LOOSENING_NOK) \
            if cmd.loosening else Said.ENTERED_OK if cmd.ok else Said.ENTERED_NOK
        acts.append(Publish(Notice(said, bolt=b, torque_nm=float(cmd.torque_nm),
                                   angle_deg=float(cmd.angle_deg), user=who.user,
                                   note=held or None, pset=cmd.loosen_pset, t=t)))
        if cmd.loosening:
            acts += self._after_loosening(t, b, cmd.ok)
        elif cmd.ok:
            m.mark_done(b)
            self._noks.pop(b, None)
            self._loosen.discard(b)
            self._nok_last.discard(b)
            m.counted.discard(b)
        else:
            self._nok_last.add(b)
            acts += self._after_nok(t, b, spec.pset if spec is not None else None)
        m.reset()
        return acts
