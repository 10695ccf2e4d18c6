"""Results from the controller: which are tightenings, to which enable each belongs (also
after a link cut), unreadable ones held, the NOK policy after each (retry, lock, loosen,
skip).  Typed, not words: a result's type goes out as its code and why a result is
unattributed as an :class:`~stationd.reasons.Unattributed`; :mod:`stationd.words` names them
at the edge (the records, the journal, the bus)."""

from __future__ import annotations

from db.kinds import (
    LOOSENING,
    NOT_TAKEN,
    TIGHTENING,
    UNKNOWN_TYPE_HELD,
    not_taken_note,
    other_pset_note,
    ran_again_why,
    unknown_type_note,
)
from drivers.wrench.base import (
    ResultKind,
    TighteningResult,
    TorqueUnit,
    result_kind,
)
from stationd.reasons import Unattributed, UnattributedKind
from stationd.station.actions import (
    Acknowledge,
    Action,
    Publish,
    Record,
    Selection,
    StoreControllerEvent,
    StoreGap,
    StoreUnattributed,
    torque_window,
)
from stationd.station.events import (
    Because,
    ControllerResultEvent,
    Notice,
    ResultRecorded,
    ResultUnattributed,
    Said,
    State,
    StateReason,
)
from stationd.station.inputs import (
    NotStored,
    ResultCopy,
    ResultIn,
    ResultsMissed,
    Written,
)
from stationd.station.lost import CLOCK_SLACK_S
from stationd.station.state import NOK_SKIPPED, ON_A_BOLT, UNANSWERED
from stationd.station.unread import UnreadRules, _Unread


def _said(result: TighteningResult) -> object:
    """What a result says besides its id: equal for a copy the controller sends again,
    different for another result under the same id (a controller whose ids started again)."""
    return (type_code(result), result.pset, result.ok, result.torque_nm, result.angle_deg,
            result.timestamp)


def _copy_of(seen: object, result: TighteningResult) -> bool:
    """Whether ``result`` is a copy of the one recorded under its id (``seen``, what
    :func:`_said` said of it): the same, its result type left out where either has none (a
    result fetched as MID 0065 at a revision without one, then pushed as MID 0061 with one,
    is one rundown: a reviewer found it recorded twice, its NOK counted twice)."""
    said = _said(result)
    if not (isinstance(seen, tuple) and isinstance(said, tuple)):
        return False
    if seen == said:
        return True
    return (seen[0] is None or said[0] is None) and seen[1:] == said[1:]


def type_code(result: TighteningResult) -> int | None:
    """A result's type code as the controller sent it (Open Protocol MID 0061 revision 3+,
    parameter 49), None where its revision (or the backend) carries none."""
    if result.result_type_code is not None:
        return int(result.result_type_code)
    return None if result.result_type is None else int(result.result_type)


def rundown_kind(result: TighteningResult, sent_loosen: bool) -> str:
    """A rundown's kind (db.kinds): its own type where its revision carries it, else what
    the station sent (a loosen pset or the tightening one).  The type wins: a controller
    reversed by hand reports the loosening it made, whatever was sent.  Only for results
    that are rundowns (:func:`result_kind` says which are not)."""
    return LOOSENING if result_kind(type_code(result), sent_loosen) is ResultKind.LOOSENING \
        else TIGHTENING


class ResultRules(UnreadRules):
    """Results: tightenings closing bolts, controller events, unreadable and late results,
    the NOK policy after each."""

    def _on_result_in(self, ev: ResultIn) -> list[Action]:
        """:meth:`_result_read`; a result pushed is the one owed since ids it skipped were
        fetched (or one after it; or that one fetched after a reconnect): owed no longer
        once it is judged, then the NOK policy waiting for it (:meth:`_push_judged`)."""
        waited, tid, en = self._pending_push, int(ev.result.tightening_id), self._enabled
        try:
            acts = self._result_read(ev)
        finally:
            if not ev.fetched or tid == waited:
                self._pending_push = None
            u = self._cut_unsettled
            if u is not None and (u[1] is None or tid > u[1]):
                self._cut_unsettled = None   # a later id judged: what follows, made since
        if ev.fetched and en is not None:
            self._gaps_superseded(tid, acts, en)
        # (a result fetched late and not taken for the enable owed now was made before it,
        # under no enable known: it proves nothing of the order for this enable; nor does a
        # typed copy of one held, made under an earlier enable: a reviewer found the next
        # result, perhaps the bolt before's, recorded to the enable on by that order)
        typed = any(isinstance(a, Publish) and isinstance(a.event, Notice)
                    and a.event.said is Said.TYPED_COPY for a in acts)
        self._judge(tid, (not ev.fetched and not typed) or any(
            isinstance(a, Record) and a.selection is self._enabled for a in acts), ev.t)
        return acts + self._push_judged(ev.t)

    def _result_read(self, ev: ResultIn) -> list[Action]:
        """A result: a controller event (never a rundown) by its type; else recorded to the
        bolt the tool was enabled for (its pset, while on or within the late-result window,
        or after a link cut where the controller's own data places it there), else stored
        unattributed with why."""
        r = ev.result
        tid = int(r.tightening_id)
        if _copy_of(self._recorded.get(tid), r):
            return [Acknowledge(r)]   # sent again by the controller: stored once already
        seen = self._recorded.get(tid)
        typed = self._typed_copy(ev, seen)
        if typed is not None:
            return typed
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
        seen = self._recorded.get(tid)
        if isinstance(seen, _Unread) and seen.en is not None and ev.of is not None:
            # this core held its bolt for want of its type: judged as the result it is
            # (:meth:`_typed_copy`), as it came, not echoed as a copy
            return self._on_result_in(ev.of)
        # the pushed one waited for: a copy, it is in
        owed = self._end_wait(ev.t) if tid == self._pending_push else []
        if _copy_of(self._recorded.get(tid), r):
            return [*owed, Acknowledge(r)]   # said already by this core
        self._recorded[tid] = _said(r)
        return [*owed, Publish(Notice(Said.SENT_AGAIN, tightening_id=tid, bolt=ev.bolt,
                                      vin=ev.vin if ev.vin != self.vin else None, t=ev.t)),
                Acknowledge(r)]

    def _result_in(self, ev: ResultIn, tid: int) -> list[Action]:
        r = ev.result
        en = self._enabled
        kind = result_kind(type_code(r), en is not None and en.loosen)
        if kind is ResultKind.EVENT:
            return self._controller_event(ev, kind)
        # (a type the station does not know: judged as a rundown is, for whose enable it may
        # answer: that bolt held, never closed (:meth:`_not_taken`), and the bolts it may be
        # of held as for a rundown; stored as a controller event, never as a rundown of no
        # bolt)
        unknown = kind is ResultKind.UNKNOWN
        read = self._unread_read(ev, tid)
        if read is not None:
            return read
        # (made before the enable owed now, by the order of ids or its own time: never its;
        # the order of ids only while the controller's count did not start again)
        self._count_restarted(ev)
        before = self._before_enable(ev)
        ours = not before and en is not None and (
            en.pset is None or int(r.pset) == en.pset) and not (
            ev.fetched and self._enabled_at is not None
            and self._enabled_at > self._link_lost_at)
        # (pushed while its enable's check runs, the window over: that enable's still, every
        # tool off since; a reviewer: stored as no bolt's, or recorded, by which came first)
        if ours and en is not None and en.vin and (
                self._result_owed(ev.t) or (self._checking_owed() and not ev.fetched)):
            return self._attribute(ev, en)
        if en is not None and not before and self._made_under(ev, en):
            return self._attribute(ev, en, lost=True)
        if en is not None and not before and self._of_another_pset(ev, en):
            return self._other_pset(ev, en)
        proved, not_proved = self._made_during_cut(ev)
        if proved is not None:
            if self._cut is not None:
                self._cut_closed, self._cut_watch_held = (self._cut, tid, None), False
            return self._attribute(ev, proved, cut=True)
        why = Unattributed(UnattributedKind.OUTSIDE if not ev.fetched else
                           UnattributedKind.FETCHED_CHECKED if ev.live and ev.before is None
                           and self._checking is not None else
                           UnattributedKind.FETCHED_LIVE if ev.live else
                           UnattributedKind.FETCHED, tid, int(r.pset), not_proved)
        lost = self._lost_enables(ev)
        # filed under the vehicle its only possible enables were on (one that has left: the
        # result of its last bolt, its push lost, was filed under the next car)
        vins = {u.selection.vin for u in lost}
        filed = vins.pop() if len(vins) == 1 else self.vin
        stored = self._controller_event(ev, kind) if unknown else [
            StoreUnattributed(r, filed, why),
            Publish(ResultUnattributed(tid, int(r.pset), bool(r.ok), t=ev.t)),
            Publish(Notice(Said.UNATTRIBUTED, tightening_id=tid, pset=int(r.pset),
                           unattributed=why, t=ev.t))]
        return [*stored, *self._cut_in_doubt(ev), *self._lost_in_doubt(ev, lost),
                *self._fetched_in_doubt(ev), *self._late_cut_in_doubt(ev),
                *self._ran_again_after_cut(ev, kind)]

    def _typed_copy(self, ev: ResultIn, seen: object) -> list[Action] | None:
        """A result pushed with its type whose copy fetched without one (MID 0065 at a
        revision that has none) held the bolt of the enable it was fetched for
        (:class:`_Unread` ``en``): where its own time puts it after that enable's tool went
        on and before the copy was fetched (each within the clock's slack), of that enable's
        pset and a rundown by its type, it is that enable's rundown: recorded to its bolt
        (late), the hold ended.  An integrator's trial: the push, 7 s late, was taken for a
        copy "stored once", B11's second NOK never counted and B47's OK left held, released
        and tightened twice.  None where that is not shown (its time not known, the hold
        ended already, the vehicle gone): held, as before."""
        r = ev.result
        if not isinstance(seen, _Unread) or seen.en is None or seen.since is None \
                or ev.made_at is None or ev.fetched:
            return None
        en, code = seen.en, type_code(r)
        if code is None or result_kind(code, en.loosen) not in (ResultKind.TIGHTENING,
                                                                 ResultKind.LOOSENING) \
                or en.pset != int(r.pset) or not seen.same(r, ev.made_at):
            return None
        # (beyond the slack after the tool went on, the bolt before another: a rundown of
        # that one begun as its disable was sent ends after it; a retry's is its own)
        lower = seen.since + (-CLOCK_SLACK_S if seen.retry else CLOCK_SLACK_S)
        if not lower <= ev.made_at <= seen.seen_at + CLOCK_SLACK_S:
            return None
        m = self.matcher
        if m is None or self.vin != en.vin or m.held.get(en.bolt) is None:
            return None
        self._unhold(en.bolt)
        return [Publish(Notice(Said.TYPED_COPY, tightening_id=int(r.tightening_id),
                               bolt=en.bolt, t=ev.t)), *self._attribute(ev, en, typed=True)]

    def _of_another_pset(self, ev: ResultIn, en: Selection) -> bool:
        """Whether ``ev``, pushed while the tool is on for ``en`` (or within its late-result
        window), the link up since, is of another pset than the one sent for it: a rundown
        with another program (one selected on the controller's own screen) where the
        operator was, or no rundown of this bolt at all.  Fetched with the link up (its push
        lost) as well, where its own time puts it after the tool went on for ``en`` (beyond
        the clock's slack: only that enable's tool was on since; a reviewer: the same rundown
        reached through a lost push was stored outside any tightening, the tool left on)."""
        at = self._enabled_at
        if ev.fetched and not (ev.live and ev.made_at is not None and at is not None
                               and ev.made_at >= at + CLOCK_SLACK_S):
            return False
        return bool(en.vin) and en.pset is not None \
            and int(ev.result.pset) != en.pset and self._cut is None \
            and at is not None and at > self._link_lost_at \
            and (self.tool_on or self._result_owed(ev.t) or (ev.fetched
                                                              and self._checking_owed()))

    def _other_pset(self, ev: ResultIn, en: Selection) -> list[Action]:
        """A result of another pset than the one sent for the enable on (:meth:`
        _of_another_pset`): never that bolt's result, never "outside any tightening" either
        (an integrator's trial: the tool stayed on, the bolt was run down again and closed OK,
        the other program's rundown in no bolt's history).  Stored naming the bolt, the tool
        off, the bolt held for a person who checks it on the controller (released, or its
        outcome entered); the enable owes nothing more.  One of a type the station does not
        know is stored as a controller event naming the bolt (a review: left as a controller
        event, the tool on, where a known type held the bolt)."""
        r, tid = ev.result, int(ev.result.tightening_id)
        self._recorded[tid] = _said(r)
        why = Unattributed(UnattributedKind.OTHER_PSET, tid, int(r.pset), bolt=en.bolt)
        since = self._enabled_at if self._enabled_at is not None else ev.t
        acts: list[Action] = self._controller_event(ev, ResultKind.UNKNOWN, en) \
            if result_kind(type_code(r)) is ResultKind.UNKNOWN else [
            StoreUnattributed(r, en.vin, why),
            Publish(ResultUnattributed(tid, int(r.pset), bool(r.ok), t=ev.t)),
            Publish(Notice(Said.UNATTRIBUTED, tightening_id=tid, pset=int(r.pset),
                           unattributed=why, t=ev.t))]
        return acts + self._hold_enable(ev.t, en, since, lambda u: other_pset_note(
            tid, int(r.pset), int(en.pset or 0)), tid)

    def _ran_again_after_cut(self, ev: ResultIn, kind: ResultKind) -> list[Action]:
        """A rundown fetched after the rundown of a link cut's bolt was proved and recorded
        (:meth:`_ran_again_of`).  The tool, still enabled on the controller during the cut
        (the station cannot turn it off), ran again, with that pset or another the
        controller selected itself: on the cut's bolt (the operator's retry after a NOK, or
        a second hit), or on another bolt.  Never left as the first rundown said, without a
        word: the cut's bolt, the one the operator was at, held for a person, stored so,
        naming the result (an outcome entered for the bolt is that result: one tightening,
        not two).  A review held it for a loosening only (done OK, the loosening stored as
        no bolt's); an integrator's trial with an independent controller: a NOK then an OK
        during one cut left the bolt "ending NOK", its OK stored as no bolt's, and its tool
        went on again (tightened twice)."""
        found = self._ran_again_of(ev) if kind is not ResultKind.EVENT else None
        if found is None or self._cut_watch_held:
            return []    # (held once: the watch, and the tool off, last until the catch-up ends)
        cut, after = found
        r, en = ev.result, cut.selection
        tid = int(r.tightening_id)
        self._cut_watch_held = True
        # (untyped, its kind by what was sent for the cut's enable, not the enable on now)
        kind = result_kind(type_code(r), en.loosen)
        what = "a loosening" if kind is ResultKind.LOOSENING and not en.loosen \
            else "a rundown"
        # (of another pset: the controller's own program selected, the tool still on; a
        # trial: a NOK then a rundown of another pset left the bolt ending NOK, its tool on;
        # named as the result an outcome entered is only of the pset sent: a reviewer, an
        # entered outcome carried another program's result)
        own = int(r.pset) == en.pset
        return self._cut_unknown(ev.t, ran_again_why(tid, what, None if own else int(r.pset),
                                                     after), cut, tid if own else None)

    def _controller_event(self, ev: ResultIn, kind: ResultKind,
                          held: Selection | None = None) -> list[Action]:
        """A result that is not a tightening or a loosening (a batch increment a line lead
        pressed, a bypassed pset, an aborted job, a reference setup, or a type the station
        does not know): stored as a controller event, said, and nothing else: no bolt is
        closed, opened or counted, and the tool stays as the station decided.  ``held``: the
        enable whose bolt the caller holds for it (:meth:`_other_pset`): stored naming that
        bolt, said by its hold."""
        r, code = ev.result, type_code(ev.result)
        self._recorded[int(r.tightening_id)] = _said(r)
        vin, bolt = (held.vin, held.bolt) if held is not None \
            else (self.vin, self.bolt if self.tool_on else None)
        said = Said.UNKNOWN_TYPE if kind is ResultKind.UNKNOWN else Said.CONTROLLER_EVENT
        # named by its type code: the type's name in words is written by the shell (stored,
        # published: stationd.words.result_type_words), never built here
        acts: list[Action] = [
            StoreControllerEvent(r, vin, bolt),
            Publish(ControllerResultEvent(code or 0, "", int(r.tightening_id), int(r.pset),
                                          bool(r.ok), bolt, t=ev.t))]
        if held is None:
            acts.append(Publish(Notice(said, bolt=bolt, result_type=code, t=ev.t)))
        return acts

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
            int(r.tightening_id), int(r.pset), *self._limits(a, r), a.late, tuple(ev.images),
            a.kind, a.selection.operator if a.selection is not None else None, t=ev.t)),
            Acknowledge(r)]

    def _limits(self, a: Record, r: TighteningResult) -> tuple[float | None, float | None,
                                                              float | None, float | None]:
        """The windows ``r`` was judged against (torque min and max, angle min and max), as
        the controller sent them; a result fetched late (MID 0065 carries none: 0 to 0) has
        its bolt's tightening window where it ran under the bolt's pset, as the records give
        it, else none known (a new user's trial: the screen said a fetched NOK of 44.6 Nm
        "torque high" against "0.0-0.0", where it was low against 45-55)."""
        if r.torque_min_nm or r.torque_max_nm:
            return (float(r.torque_min_nm), float(r.torque_max_nm), float(r.angle_min_deg),
                    float(r.angle_max_deg))
        spec = self._specs.get(a.bolt) if a.vin == self.vin else None
        p = spec.parameters if spec is not None else None
        if p is None or a.kind == LOOSENING or p.pset != r.pset:
            return None, None, None, None
        return (p.torque.min, p.torque.max, None if p.angle is None else p.angle.min,
                None if p.angle is None else p.angle.max)

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
        """A gap stored and said; with the link up, the bolts whose result may be in it
        held (:meth:`_gap_in_doubt`)."""
        self._gaps_told = [*self._gaps_told, (ev.first, ev.last, self._enable_serial)
                           ][-UNANSWERED:]
        return [StoreGap(ev.first, ev.last, self.vin, ev.reason),
                Publish(Notice(Said.GAP, tightening_id=ev.first, last_id=ev.last,
                               link_up=ev.live, note=ev.reason, t=ev.t)),
                *self._gap_in_doubt(ev)]

    def _on_not_stored(self, ev: NotStored) -> list[Action]:
        return [Publish(Notice(Said.NOT_STORED, tightening_id=ev.tightening_id, bolt=ev.bolt,
                               note=ev.reason, t=ev.t))]

    def _outside_window(self, r: TighteningResult, en: Selection
                        ) -> tuple[float, float] | None:
        """The bolt's torque window (min, max of its process parameters) that ``r``, an OK
        result without a result type answering ``en``'s tightening pset, lies outside of;
        None for any other result, or where the window or the torque in Nm is not known
        (then it is taken as today: a revision without types reports tightenings)."""
        if type_code(r) is not None or not bool(r.ok) or en.loosen:
            return None
        if r.torque_unit is TorqueUnit.PERCENT:
            return None      # kept as sent: a percentage of the tool's maximum, not Nm
        window = en.torque_window
        spec = self._specs.get(en.bolt) if en.vin == self.vin else None
        if window is None and spec is not None:
            window = torque_window(spec.parameters)
        if window is None:
            return None
        lo, hi = window
        return None if lo <= float(r.torque_nm) <= hi else (lo, hi)

    def _not_taken(self, ev: ResultIn, en: Selection, window: tuple[float, float] | None,
                   cut: bool) -> list[Action]:
        """An OK result without a type whose torque is outside its bolt's ``window``: perhaps
        no tightening at all (at a revision without types, a batch increment or a bypass
        reads as an OK, of 0 Nm), perhaps one whose limits on the controller are not the
        station's; or (``window`` None) a result of a type the station does not know (0, 9
        or more): perhaps the bolt's tightening, perhaps none (an MES integrator's trial:
        stored as a controller event, the bolt left open and run down again, or left
        "missing" after a link cut said nothing was made).  Never taken as the bolt done:
        stored as a controller event (the enable it answers settled with it), the tool off,
        and the bolt held, as for a result that could not be read, until a supervisor
        checked it on the controller and released it or entered its outcome (a real
        tightening counted once, never tightened twice)."""
        r = ev.result
        tid = int(r.tightening_id)
        self._recorded[tid] = _said(r)
        if window is None:
            code = type_code(r)
            what, note = UNKNOWN_TYPE_HELD, unknown_type_note(code, tid)
            said = Notice(Said.UNKNOWN_TYPE_HELD, bolt=en.bolt, result_type=code,
                          tightening_id=tid, t=ev.t)
            reason = StateReason(Because.NOT_TAKEN, bolt=en.bolt, note=note)
            held = StateReason(Because.NOT_TAKEN_HELD, bolt=en.bolt, note=note)
        else:
            lo, hi = window
            code, what, note = 0, NOT_TAKEN, not_taken_note(float(r.torque_nm), tid)
            said = Notice(Said.NOT_TAKEN, bolt=en.bolt, torque_nm=float(r.torque_nm),
                          torque_min=lo, torque_max=hi, tightening_id=tid, t=ev.t)
            reason = StateReason(Because.NOT_TAKEN, bolt=en.bolt)
            held = StateReason(Because.NOT_TAKEN_HELD, bolt=en.bolt)
        acts: list[Action] = []
        if self.tool_on and not cut:    # (a lost one's: its rundown ended there)
            acts += self._tool_off(ev.t, reason)
        acts.append(StoreControllerEvent(r, en.vin, en.bolt, what, en))
        acts.append(Publish(ControllerResultEvent(code or 0, what, tid, int(r.pset),
                                                  bool(r.ok), en.bolt, t=ev.t)))
        self._answered(en)
        self._not_before = max(self._not_before, ev.t)
        if self.matcher is not None and self.vin == en.vin and en.bolt in self.matcher.bolts:
            # (under its enable: one of a loosen pset is a loosening's hold, an outcome
            # entered for it a loosening's: a review found an entered OK closing a bolt that
            # was only loosened)
            acts += self._hold(ev.t, en.bolt, note, said, under=en)
        else:
            acts.append(Publish(said))
        if self.bolt == en.bolt and self.vin == en.vin:
            acts += self._drop(ev.t, State.TRACKING, held)
        return acts

    def _attribute(self, ev: ResultIn, en: Selection, cut: bool = False,
                   lost: bool = False, typed: bool = False) -> list[Action]:
        """The result of the tightening the tool was enabled for: recorded to that bolt (of
        the vehicle it was enabled on, also after a reload or restart, or fetched after a
        link cut that the controller's data places it in, ``cut``, or fetched with the link
        up, made under that enable, ``lost``: the later result that revealed it, pushed,
        comes next and is judged under the same enable); an OK without a type outside the
        bolt's torque window is not (:meth:`_not_taken`)."""
        r = ev.result
        self._answered_bolt(en.vin, en.bolt)     # its own result came: nothing unanswered
        if result_kind(type_code(r)) is ResultKind.UNKNOWN:
            return self._not_taken(ev, en, None, cut)
        window = self._outside_window(r, en)
        if window is not None:
            return self._not_taken(ev, en, window, cut)
        # (the pushed one that skipped ids: its tool went off when they were told, not late)
        pushed = not ev.fetched and int(r.tightening_id) == self._pending_push
        late = (not self.tool_on and not pushed) or cut or lost or typed
        kind = LOOSENING if result_kind(type_code(r), en.loosen) is ResultKind.LOOSENING \
            else TIGHTENING
        acts: list[Action] = []
        # (a lost one's: its rundown ended there; a typed copy's enable ended long since)
        if self.tool_on and not cut and not typed:
            acts += self._tool_off(ev.t, StateReason(Because.RUNDOWN, bolt=en.bolt,
                                                     loosen=kind == LOOSENING, ok=bool(r.ok)))
        acts.append(Record(en.vin, en.bolt, r, en, late, kind, offline=self._offline(ev),
                           t=ev.t))
        if typed:
            pass    # said by the caller (Said.TYPED_COPY)
        elif cut or lost:
            checked = not cut and ev.before is None
            acts.append(Publish(Notice(Said.CUT_RECORDED if cut else Said.LOST_RECORDED
                                       if not checked else Said.LOST_FOUND_ON
                                       if self._checking_on else Said.LOST_CHECKED,
                                       tightening_id=int(r.tightening_id), bolt=en.bolt,
                                       vin=en.vin if checked and en.vin != self.vin else None,
                                       t=ev.t)))
        elif late:
            acts.append(Publish(Notice(Said.LATE_RESULT, bolt=en.bolt,
                                       vin=en.vin if en.vin != self.vin else None,
                                       tightening_id=int(r.tightening_id), t=ev.t)))
        echoed = str(r.vin or "").strip()
        if echoed and en.vin and echoed != en.vin:
            # an integrator's trial: four results under another VIN recorded without a word
            acts.append(Publish(Notice(Said.OTHER_VIN, tightening_id=int(r.tightening_id),
                                       bolt=en.bolt, vin=en.vin, note=echoed, t=ev.t)))
        self._recorded[int(r.tightening_id)] = _said(r)
        if not cut and not lost and not typed:
            self._enabled = None    # (a cut's result leaves an enable made since owed)
        if not lost and not typed:  # (a typed copy's enable was answered by its hold)
            self._answered(en)      # the cut's result is in too (fetched, or pushed late)
        if en.operator is not None and en.operator == self.operator:
            self._operator_seen = max(self._operator_seen, ev.t)
        if self.matcher is not None and self.vin == en.vin:
            self._ran_once(en.bolt, kind == LOOSENING, bool(r.ok))
            if kind == LOOSENING:
                acts += self._after_loosening(ev.t, en.bolt, bool(r.ok),
                                              tid=int(r.tightening_id))
            elif bool(r.ok):
                if en.loosen:
                    acts.append(Publish(Notice(Said.LOOSEN_PSET_TIGHTENED, bolt=en.bolt,
                                               pset=en.pset, t=ev.t)))
                self.matcher.mark_done(en.bolt)
                self._noks.pop(en.bolt, None)
                self._nok_owed.pop(en.bolt, None)
                self._lock_due.pop(en.bolt, None)   # (answered by an OK: a reviewer)
                self._loosen.discard(en.bolt)
                self._nok_last.discard(en.bolt)
                self.matcher.counted.discard(en.bolt)
            else:
                # (after an OK of its own only where that one's push was lost: the later
                # rundown, its last result, says the bolt is NOK, as its records do)
                self.matcher.done.discard(en.bolt)
                self._nok_last.add(en.bolt)
                if lost and self._pending_push is not None \
                        and en.bolt not in self.matcher.locked:
                    # counted; the NOK policy after the later one, pushed next (a lock for a
                    # NOK that a later OK answered: a reviewer; :meth:`_push_judged`); where
                    # this one reaches max_nok, the lock, if it comes, is at this count (a
                    # supervisor's trial: locked after 4 NOK in a row with max_nok 3)
                    n = self._noks[en.bolt] = self._noks.get(en.bolt, 0) + 1
                    self._nok_owed[en.bolt] = en.pset
                    if n >= self._nok_rule(en.bolt, en.pset).max_nok:
                        self._lock_due.setdefault(en.bolt, n)
                else:
                    self._nok_owed.pop(en.bolt, None)
                    acts += self._after_nok(ev.t, en.bolt, en.pset,
                                            tid=int(r.tightening_id))
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

