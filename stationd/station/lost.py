"""Results the station heard late: fetched because a later one skipped their ids (a push lost),
or after a link cut (the catch-up).  Which enable each was made under, by the controller's
own data (its pset, VIN, id and time) and the order of ids; where nothing proves it, never
taken for a bolt and never left open: the bolts it may be are held for a person."""

from __future__ import annotations

from collections.abc import Callable

from db.kinds import (
    LOST_UNKNOWN,
    check_unknown_note,
    cut_own_why,
    cut_unknown_note,
    id_span,
    lost_gap_note,
    lost_unknown_note,
    other_pset_note,
)
from drivers.keeper import FaultKind
from stationd.reasons import Unproved, UnprovedKind
from stationd.station.actions import (
    Action,
    Publish,
    Record,
    Selection,
    SettleEnable,
    StoreCutUnknown,
)
from stationd.station.events import (
    Because,
    Notice,
    Said,
    State,
    StateReason,
)
from stationd.station.inputs import (
    WRENCH,
    CaughtUp,
    DeviceFault,
    NewestChecked,
    ResultIn,
    ResultsMissed,
    ResultsSkipped,
)
from stationd.station.nok import NokRules
from stationd.station.state import CHECK_WAIT_S, ON_A_BOLT, PENDING_PUSH_S, UNANSWERED, _Cut

#: the controller stamps its results to the second, and its clock's offset is measured to
#: the second: a result fetched after a link cut is placed between the enable and the cut
#: within this much
CLOCK_SLACK_S = 2.0


class LostRules(NokRules):
    """Results whose push was lost or whose link was cut: under which enable each was made,
    the bolts held where the data cannot tell, a pushed result waited for while the ids it
    skipped are fetched, and the catch-up's end."""

    def _on_results_skipped(self, ev: ResultsSkipped) -> list[Action]:
        """A pushed result skipped ids, fetched and fed before it: the rundown is over, the
        tool goes off now (a reviewer: it stayed on through the fetches, the operator could
        pull again), and the enable's result stays owed until the pushed one is in."""
        self._pending_push, self._pending_at = ev.tightening_id, ev.t
        if self.state not in ON_A_BOLT and not self.tool_on:
            return []
        return self._drop(ev.t, State.TRACKING, StateReason(Because.PUSH_AFTER_LOST,
                                                            bolt=self.bolt))

    def _on_newest_checked(self, ev: NewestChecked) -> list[Action]:
        """The controller's newest result was asked for and what it had fed (recorded to the
        enable owed where made under it: :meth:`_made_under`), or the check could not be
        made: that enable is owed nothing more.  Nothing made since the last result heard:
        its bolt was not tightened, and no later result is its own (a reviewer: a later gap
        held it beside the bolt whose result was in it)."""
        if self._checking is None or ev.serial not in (None, self._checking[1]):
            return []       # an earlier check's answer (a reviewer: it ended this one)
        if self._checking_on:
            # asked with the tool on (:meth:`_check_while_on`): what it found was fed and
            # recorded already.  Nothing made: the tool stays on, nothing said.  Could not
            # tell: nothing either -- the tool stays on and the next period asks again; the
            # bolt is held only by the window-end check, as the enable's window ends without
            # a result (a hold mid-enable would stop an operator at every slow answer)
            return self._gaps_on_check_decided(ev.t) + self._check_ended()
        en, acts = self._enabled, []
        if en is not None and self._checking_owed() and not self.tool_on:
            if ev.nothing_made:
                self._answered_bolt(en.vin, en.bolt)
                if self._enabled_at is not None and self._off_at is not None:
                    self._cleared = [*self._cleared, _Cut(
                        en, self._enabled_at, self._off_at + self.late_result_s)
                    ][-UNANSWERED:]
                # nothing since the last result judged until this window's end: a later id
                # is the next enable's by the order of ids (a supervisor's trial: held as
                # "other enables came between", released, and tightened twice)
                self._checked_clear = self._checking[1]
                if self._judged is not None:
                    self._judged = (self._judged[0], self._checking[1], False)
            elif ev.unknown:
                acts = self._check_unknown(ev.t, en, ev.unknown)
        return acts + self._check_ended()

    def _on_device_fault(self, ev: DeviceFault) -> list[Action]:
        """The wrench's link cut as a check with the tool on runs: the gaps it told decide
        now, while the enable on is the one they may hold (:meth:`_gaps_on_check_decided`);
        what the check would have fetched after them is the catch-up's.  Decided only at
        the check's end, a catch-up ending first (complete, nothing after the gap's ids)
        settled the cut's enable, and the check's end found none to hold: its bolt open."""
        acts: list[Action] = []
        if ev.device == WRENCH and self._checking_on and self._gaps_on_check \
                and ev.kind is not FaultKind.REFUSED:
            acts = self._gaps_on_check_decided(ev.t)
        return acts + super()._on_device_fault(ev)

    def _gaps_on_check_decided(self, t: float) -> list[Action]:
        """The gaps a check with the tool on told (ids the controller no longer gives, made
        with the link up): the enable on now may have been run down in them, so its bolt is
        held (:meth:`_doubt_while_on`) -- unless a rundown made under that enable, fetched
        after them in the same check, was recorded to it (:meth:`_gaps_superseded`): its
        last result, as where a push revealed the same ids (the two paths decided alike: a
        check between two pulls held the bolt and stored its later rundown as no bolt's)."""
        told, self._gaps_on_check = self._gaps_on_check, []
        if not told:
            return []
        ids = ", ".join(id_span(first, last) for first, last in told)

        def note(u: _Cut) -> str:
            return lost_gap_note(ids, u.selection.pset, u.enabled_at)

        en, since = self._enabled, self._enabled_at
        if self._checking_owed() and en is not None and since is not None \
                and en.vin != self.vin:
            # its vehicle left as the check ran (the lift down): held all the same, stored
            # for when it is back, as the gap held it at once before it was decided here
            acts = self._hold_unanswered(t, [_Cut(en, since, t)], note)
            self._enabled, self._off_at = None, None
            return acts
        return self._doubt_while_on(t, None, note)

    def _gaps_superseded(self, tid: int, acts: list[Action], en: Selection) -> None:
        """``tid``, fetched by a check with the tool on, recorded to ``en``, the enable on
        as it came (in ``acts``): the gaps that check told before it no longer hold that
        enable."""
        if self._gaps_on_check and self._checking_on and any(
                isinstance(a, Record) and a.selection is en for a in acts):
            self._gaps_on_check = [g for g in self._gaps_on_check if g[1] > tid]

    def _check_unknown(self, t: float, en: Selection, why: str) -> list[Action]:
        """The controller could not tell whether it made a rundown under ``en`` (``why``):
        its bolt, unanswered and not done since, is held (selected again meanwhile too: no
        tool went on during the check)."""
        lost = [u for u in self._unanswered if u.selection is en and self._still_open(u)]
        return self._hold_unanswered(t, lost, lambda u: check_unknown_note(
            why, u.selection.pset, u.enabled_at))

    def _check_overdue(self, t: float) -> list[Action]:
        """A check of the controller's newest never answered in :data:`CHECK_WAIT_S` (a fault
        of the shell, or a catch-up it waits for running long): the tool waits no longer, and
        the enable's bolt is held as where the controller could not tell."""
        if self._checking is None or t - self._checking[0] < CHECK_WAIT_S:
            return []
        return self._on_newest_checked(NewestChecked(
            t, unknown=f"no answer in {CHECK_WAIT_S:.0f} s", serial=self._checking[1]))

    def _check_ended(self) -> list[Action]:
        """The check is over: the enable it was for is owed nothing more (an enable since, of
        that bolt, is its own: kept)."""
        if self._checking_owed() and not self.tool_on and (
                not self._checking_on or self._answered_now()):
            self._enabled, self._off_at = None, None
        self._checking, self._checking_on = None, False
        return []

    def _answered_now(self) -> bool:
        """The enable owed now had its result (a check with the tool on found it): it owes
        nothing more (a check asked as the tool went off for the operator leaving, without
        one, leaves its window to run and its own check at the end)."""
        return self._judged is not None and self._judged[1] == self._enable_serial

    def _push_judged(self, t: float) -> list[Action]:
        """The pushed result that skipped ids is judged (or no longer waited for): the NOK
        policy of each bolt whose NOK came fetched before it and is still its last result
        (a reviewer: a batch increment pushed after a lost NOK left the bolt unlocked), held
        too (the pushed one unreadable: not known to be an OK; a new user's trial: the hold
        hid the lock at max_nok, and its release reopened the bolt for its tightening pset
        where the loosen pset was due; an OK entered for it ends the lock)."""
        if self._pending_push is not None:
            return []
        m, acts = self.matcher, []
        owed, self._nok_owed = self._nok_owed, {}
        for bolt, pset in owed.items():
            if m is not None and bolt in m.bolts and bolt in self._nok_last \
                    and bolt not in m.done and bolt not in m.locked:
                acts += self._after_nok(t, bolt, pset, counted=True)
            self._lock_due.pop(bolt, None)
        # the bolts a gap it revealed may own, run down again since: held after its record
        return acts + self._held_after_push(t)

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

    def _lost_enables(self, ev: ResultIn) -> list[_Cut]:
        """The enables that got no result in their window (the operator left the bolt) whose
        result a result fetched late (its push lost: a later one skipped its id, or a
        reconnect's catch-up found it) may be: of its pset, made within that enable and its
        window (or when, not known), its bolt still open and not selected now (of a vehicle
        that has left: whatever it is now, not known here).  The enable whose window's check
        fetched it, whatever its time: the check fetches only what was made since the last
        result heard, and a clock stepped since its last measure (a trial: +60 s) placed
        it outside that enable, the bolt left open to be tightened twice.  A push made
        before the enable owed now (:meth:`_made_before_enable`: the controller held it
        back), or pushed with no enable owed, is late as well: the enables its own time
        places it in (:meth:`_pushed_late_of`; a reviewer: a push held back until the wrench
        rested held nothing, its bolt left open)."""
        r = ev.result
        if not ev.fetched:
            return self._pushed_late_of(ev)
        found: list[_Cut] = []
        checked = self._checked_enable()
        for u in self._unanswered:
            en = u.selection
            if en.pset is None or int(r.pset) != en.pset or not self._still_open(u):
                continue
            if ev.made_at is not None and not u.spans(ev.made_at, CLOCK_SLACK_S) \
                    and en is not checked:
                continue    # made while its tool was off for good: not its own
            found.append(u)
        # a check found nothing made under these: placed by the result's time alone
        return found + [u for u in self._cleared if ev.made_at is not None
                        and u.selection.pset == int(r.pset) and self._still_open(u)
                        and u.spans(ev.made_at, CLOCK_SLACK_S)]

    def _still_open(self, u: _Cut, selected_too: bool = False) -> bool:
        """Whether the bolt of the unanswered enable ``u`` is still open (not selected now,
        done, held, skipped or locked; of a vehicle that has left: not known here, open).
        Selected again while its own enable's check runs, it is: no tool went on since (a
        reviewer: a result the check could not place left it open, its tool went on).
        ``selected_too``: selected now, it is open as well (its tool would go on again)."""
        m, b = self.matcher, u.selection.bolt
        selected = not selected_too and b == self.bolt \
            and u.selection is not self._checked_enable()
        return not (u.selection.vin == self.vin and m is not None and (
            selected or b in m.done or b in m.held or b in m.skipped or b in m.locked))

    def _lost_in_doubt(self, ev: ResultIn, lost: list[_Cut]) -> list[Action]:
        """The result may be that of each of the ``lost`` enables (:meth:`_lost_enables`).
        Never taken for one (other enables came between: the data cannot prove it), never
        left open either (it may be tightened: a quality trial's bolt was tightened twice):
        each such bolt is held for a person, stored so that the hold outlives a restart and
        comes back with its vehicle where that one has left."""
        tid = int(ev.result.tightening_id)
        return self._hold_unanswered(ev.t, lost, lambda u: lost_unknown_note(
            tid, u.selection.pset, u.enabled_at), tid)

    def _hold_unanswered(self, t: float, lost: list[_Cut], note_of: Callable[[_Cut], str],
                         tid: int | None = None) -> list[Action]:
        """Each bolt of the unanswered enables ``lost`` held (its note ``note_of`` it, the
        result it may be ``tid``), stored so that the hold outlives a restart and comes back
        with its vehicle where that one has left.  A bolt once (its first enable's note):
        a bolt enabled again keeps each unanswered enable (:meth:`_unanswered_after`)."""
        acts: list[Action] = []
        done: set[tuple[str, str]] = set()
        for u in lost:
            en, b = u.selection, u.selection.bolt
            if (en.vin, b) in done:
                continue
            done.add((en.vin, b))
            note = note_of(u)
            stored = StoreCutUnknown(en.vin, b, note, en, what=LOST_UNKNOWN, tightening_id=tid)
            if en.vin != self.vin or self.matcher is None:
                self._held_away[(en.vin, b)] = (note, en)
                acts += [stored, Publish(Notice(Said.CUT_UNKNOWN, bolt=b, vin=en.vin, note=note,
                                                t=t))]
            else:
                acts += [stored, *self._hold_unknown(t, b, note, en)]
            self._answered_bolt(en.vin, b)
        return acts

    def _hold_unknown(self, t: float, bolt: str, note: str, en: Selection) -> list[Action]:
        """``bolt`` (of the vehicle at the station) held, its result not known (``note``);
        where it is selected, the selection dropped and its tool off: else its tool went on
        at the next frame (a bolt held by a check as the operator came back to it), or
        stayed on (a link cut's retry, its tool on again, held by a rundown the catch-up
        fetched after: an integrator's trial)."""
        acts = self._hold(t, bolt, note, Notice(Said.CUT_UNKNOWN, bolt=bolt, note=note, t=t),
                          under=en)
        if self.bolt == bolt and (self.state in ON_A_BOLT or self.tool_on):
            acts = self._drop(t, State.TRACKING,
                              StateReason(Because.UNKNOWN_HELD, bolt=bolt)) + acts
        return acts

    def _gap_in_doubt(self, ev: ResultsMissed) -> list[Action]:
        """Tightenings made with the link up, their pushes lost, that the controller does not
        give (a gap): the result of each enable since the last result heard that got none in
        its window may be among them.  Never left open (it may be tightened: the operator
        would tighten it twice): each such bolt held for a person, the one whose tool went on
        again since as well (:meth:`_gap_again`)."""
        ids = id_span(ev.first, ev.last)

        def note(u: _Cut) -> str:
            return lost_gap_note(ids, u.selection.pset, u.enabled_at)

        if not ev.live:
            # a link cut's gap: the catch-up's end settles its enable; but one told only by
            # a push after a refused catch-up may hold results made since the reconnect (a
            # reviewer: the bolt left since, its push lost, was not held)
            def mine(u: _Cut) -> bool:
                return u.enabled_at > self._link_back_at
            acts = self._hold_unanswered(ev.t, [
                u for u in self._unanswered if mine(u) and self._still_open(u)], note)
        else:
            last = self._judged
            since = self._judged_at if last is not None and last[0] == ev.first - 1 \
                else float("-inf")

            def mine(u: _Cut) -> bool:
                return u.enabled_at >= since - CLOCK_SLACK_S
            lost = [u for u in self._unanswered if mine(u) and self._still_open(u)]
            acts = self._hold_unanswered(ev.t, lost, note)
            if self._checking_on and self._checking_owed():
                # told by a check with the tool on: the enable on now decided at its end
                self._gaps_on_check.append((ev.first, ev.last))
        return acts + self._gap_again(ev.t, [u for u in self._again if mine(u)], note)

    def _gap_again(self, t: float, again: list[_Cut], note: Callable[[_Cut], str]
                   ) -> list[Action]:
        """A gap's ids may be the rundown of an enable whose bolt's tool went on again since
        (``again``: run down again now, or selected): never closed as one rundown where it
        may be two (under the loosen strategy a NOK joint tightened again without its
        loosening), each such bolt is held for a person too -- once the pushed result that
        revealed the gap, that bolt's own as a rule, is judged (recorded to it first: a hold
        stored before a rundown ends with it), or now where none is waited for.  Not one
        held or skipped already (a person has it)."""
        m = self.matcher
        for u in again:
            en = u.selection
            if en.vin == self.vin and m is not None and (en.bolt in m.held
                                                         or en.bolt in m.skipped):
                continue
            if all((w.selection.vin, w.selection.bolt) != (en.vin, en.bolt)
                   for w, _ in self._hold_after_push):
                self._hold_after_push.append((u, note(u)))
        return self._held_after_push(t) if self._pending_push is None else []

    def _held_after_push(self, t: float) -> list[Action]:
        """The bolts a gap may own whose tool went on again (:meth:`_gap_again`) held, each
        not held or skipped meanwhile (a person has it already)."""
        owed, self._hold_after_push = self._hold_after_push, []
        m, acts = self.matcher, []
        for u, note in owed:
            en = u.selection
            if en.vin == self.vin and m is not None and (en.bolt in m.held
                                                         or en.bolt in m.skipped):
                continue
            acts += self._hold_unanswered(t, [u], _said(note))
        return acts

    def _fetched_in_doubt(self, ev: ResultIn) -> list[Action]:
        """A result a check with the tool on fetched (:meth:`_check_while_on`) that nothing
        proves made under the enable on now (:meth:`_made_under`), of its pset:
        :meth:`_doubt_while_on`."""
        if not (ev.fetched and ev.live and ev.before is None):
            return []
        tid = int(ev.result.tightening_id)
        return self._doubt_while_on(ev.t, int(ev.result.pset), lambda u: lost_unknown_note(
            tid, u.selection.pset, u.enabled_at), tid)

    def _doubt_while_on(self, t: float, pset: int | None, note_of: Callable[[_Cut], str],
                        tid: int | None = None) -> list[Action]:
        """A check with the tool on found what may be the rundown of the enable on now, and
        cannot place it (a result not proved its own, of its pset; ``pset`` None: ids the
        controller no longer gives).  Never left with its tool on (the operator would run
        it down again), nor open (the window-end check, finding nothing newer, would leave
        it so): the tool off and the bolt held for a person; the enable owes nothing more.
        The tool already off (the operator lifted the wrench as the check ran: the usual
        moment, the rundown over) holds it all the same (a reviewer: left open, the window-end
        check then found the newest already heard and the bolt could be tightened twice)."""
        en, since = self._enabled, self._enabled_at
        if not (self._checking_on and self._checking_owed()) \
                or en is None or since is None or en.vin != self.vin \
                or (pset is not None and en.pset is not None and pset != en.pset):
            return []
        return self._hold_enable(t, en, since, note_of, tid)

    def _hold_enable(self, t: float, en: Selection, since: float,
                     note_of: Callable[[_Cut], str], tid: int | None = None) -> list[Action]:
        """The enable ``en`` (its tool on since ``since``) ends with its bolt held for a
        person (its note ``note_of`` it, the result it may be ``tid``): the tool off where it
        is on, and the enable owes nothing more."""
        acts = self._drop(t, State.TRACKING, StateReason(Because.UNKNOWN_HELD, bolt=en.bolt)) \
            if self.tool_on else []
        acts += self._hold_unanswered(t, [_Cut(en, since, t)], note_of, tid)
        self._enabled, self._off_at = None, None
        return acts

    def _before_enable(self, ev: ResultIn) -> bool:
        """Whether ``ev`` was made before the enable owed now, so never its rundown: its id
        in a gap told before that enable (a later id, or the controller's newest, had
        revealed it: the ids grow with every tightening; a review: after a catch-up that
        timed out, the cut's id stored as a gap and given after all closed the next bolt of
        its pset), its own time while the link was down (:meth:`_made_offline`), or its own
        time before that enable's tool went on (:meth:`_made_before_enable`)."""
        n = self._enable_serial
        return self._made_offline(ev) or self._sent_late_from_cut(ev) \
            or self._made_before_enable(ev) or any(
                told < n for told in self._gaps_holding(int(ev.result.tightening_id)))

    def _made_before_enable(self, ev: ResultIn) -> bool:
        """Whether ``ev``'s own time puts it before the enable owed now, beyond the clock's
        slack, within the span of another bolt's enable of its pset that got no result (or
        whose check found none: :meth:`_pushed_late_of`): a push the controller held back
        (an integrator's trial: 13 s late, of the bolt before, same pset, closed the bolt on
        now), never this enable's rundown.  Its time alone decides nothing (a reviewer: a
        controller clock stepped back since it was measured put every rundown of the bolt
        on before its own enable): only where another enable could have made it."""
        made, at = ev.made_at, self._enabled_at
        if made is None or at is None or made >= at - CLOCK_SLACK_S:
            return False
        en = self._enabled
        mine = None if en is None else (en.vin, en.bolt)
        return any((u.selection.vin, u.selection.bolt) != mine
                   for u in self._pushed_late_of(ev))

    def _pushed_late_of(self, ev: ResultIn) -> list[_Cut]:
        """The enables a result pushed late may be of: of its pset, their bolt still open,
        their span (from the tool on to their late-result window's end) holding its own time:
        those that got no result in their window, and those whose check found nothing made
        (the controller stored and pushed it late).  Its time not known: none."""
        made, pset = ev.made_at, int(ev.result.pset)
        if made is None:
            return []
        return [u for u in (*self._unanswered, *self._cleared)
                if u.selection.pset == pset and self._still_open(u, selected_too=True)
                and u.spans(made, CLOCK_SLACK_S)]

    def _gaps_holding(self, tid: int) -> list[int]:
        """Of the gaps told whose ids hold ``tid``, how many enables had come when each was
        told (none: ``tid`` in no gap told)."""
        return [told for first, last, told in self._gaps_told if first <= tid <= last]

    def _count_restarted(self, ev: ResultIn) -> None:
        """A result pushed under an id at or below the newest judged, in no gap told, and not
        a copy of one recorded (:meth:`_result_read` answered those): the controller's count
        started again (its memory cleared, replaced, restored).  The gaps told are the old
        count's: their ids are new rundowns now, never "made before the enable" (a review: a
        restarted count's rundown in an old gap, stored unattributed, its bolt left open with
        its tool on, to be tightened twice); and so is the newest judged when a catch-up
        did not end complete (:meth:`_sent_late_from_cut`)."""
        tid, last = int(ev.result.tightening_id), self._judged
        if ev.fetched or last is None or tid > last[0] or self._gaps_holding(tid):
            return
        self._gaps_told, self._cut_unsettled = [], None

    def _sent_late_from_cut(self, ev: ResultIn) -> bool:
        """Whether ``ev``, pushed without its own time, may be the rundown of a link cut
        whose catch-up did not end complete (its bolt held), the controller's newest not
        said (:attr:`CaughtUp.unasked`), sent late by the controller:
        the first result after the newest judged then, of that enable's pset, the enable
        owed now made after the link came back.  Nothing tells it from that enable's own
        rundown (a review: recorded to it, the bolt closed by the cut's)."""
        u, r, at = self._cut_unsettled, ev.result, self._enabled_at
        if u is None or ev.fetched or ev.made_at is not None or at is None:
            return False
        sel, judged = u
        return (judged is None or int(r.tightening_id) > judged) and sel.pset is not None \
            and int(r.pset) == sel.pset and at >= self._link_back_at

    def _late_cut_in_doubt(self, ev: ResultIn) -> list[Action]:
        """A result that may be a link cut's rundown sent late (:meth:`_sent_late_from_cut`)
        or that of the enable owed now: never taken for it, and never left with its tool on
        either (were it its own, the operator would run it down again): its bolt held for a
        person, the tool off, the enable owed nothing more (as :meth:`_doubt_while_on`).
        Its vehicle gone (the result within its window after the lift went down), that
        vehicle's bolt is held all the same, stored for when it is back (a review: neither
        recorded nor held, open to be tightened twice at a rework)."""
        en, since = self._enabled, self._enabled_at
        if not self._sent_late_from_cut(ev) or en is None or since is None \
                or not en.vin or self._cut_unsettled is None \
                or (en.pset is not None and int(ev.result.pset) != en.pset):
            return []   # (of another pset than the enable's: the cut's, never its own)
        cut, tid = self._cut_unsettled[0], int(ev.result.tightening_id)
        whose = cut.bolt if cut.vin == en.vin else f"{cut.bolt} of {cut.vin}"
        acts = self._drop(ev.t, State.TRACKING, StateReason(Because.UNKNOWN_HELD, bolt=en.bolt)) \
            if self.tool_on and en.vin == self.vin else []
        acts += self._hold_unanswered(ev.t, [_Cut(en, since, ev.t)], lambda u: cut_unknown_note(
            cut_own_why(tid, f"or {whose}'s, made during the link cut and sent late (the "
                             "controller's clock not known)"), u.selection.pset, u.enabled_at),
            tid)
        self._enabled, self._off_at = None, None
        return acts

    def _made_offline(self, ev: ResultIn) -> bool:
        """Whether ``ev``'s own time puts it while the link was down last (as
        :meth:`_offline` says by a time) and the enable owed now came after the link was
        back: made before that enable."""
        lost, back, at, made = self._link_lost_at, self._link_back_at, self._enabled_at, \
            ev.made_at
        return made is not None and at is not None and back >= lost > float("-inf") \
            and at >= back and lost - CLOCK_SLACK_S <= made <= back - CLOCK_SLACK_S

    def _cut_in_doubt(self, ev: ResultIn) -> list[Action]:
        """A result stored unattributed while a link cut's result is owed, of the pset sent
        then (pushed again by the controller after the reconnect, or fetched and not proved
        by its data): it may be that bolt's, or not.  Never taken for it, and never left
        open either (it may be tightened): the bolt is held for a person.  Of another pset,
        made after the enable (or when, not known): the tool, enabled during the cut, ran
        with another program (one selected on the controller itself) -- as where the link
        is up, held (an integrator's trial: "no tightening made while the link was down:
        open as before", and its tool went on again)."""
        cut, r = self._cut, ev.result
        if cut is None or cut.selection.pset is None:
            return []
        tid, pset = int(r.tightening_id), int(r.pset)
        if pset == cut.selection.pset:
            return self._cut_unknown(ev.t, cut_own_why(tid, "(not proved by the controller's "
                                                         "data)"), tid=tid)
        if ev.made_at is not None and not (
                cut.enabled_at - CLOCK_SLACK_S <= ev.made_at
                <= max(self._link_back_at, cut.cut_at) + CLOCK_SLACK_S):
            return []   # before the enable, or after the link was back: not the cut's
        # (no result named: an outcome entered for the bolt is not another program's)
        return self._cut_unknown(ev.t, other_pset_note(tid, pset, cut.selection.pset))

    def _on_caught_up(self, ev: CaughtUp) -> list[Action]:
        """:meth:`_cut_caught_up`; a pushed result waited for since ids it skipped were told
        is waited for no longer (the reconnect's catch-up fed what the controller has).  A
        complete one fetched what an earlier cut's controller could still send late."""
        if ev.complete:
            self._cut_unsettled = None
        # its catch-up over: what comes now was made since.  One that did not fetch every
        # result after a cut's proved rundown leaves that bolt's not known (the tool may
        # have run again on it: a reviewer, left ending NOK, its retry never fetched)
        closed, self._cut_closed = self._cut_closed, None
        # (one watched again after a stop is not held for it: that catch-up may have ended
        # long before, and each start would hold an old bolt again: a reviewer)
        acts = [] if ev.complete or closed is None or closed[2] is not None \
            or self._cut_watch_held else self._cut_unknown(
                ev.t, f"results after its rundown {closed[1]} not all fetched "
                      f"({ev.reason or 'the catch-up did not end'})", closed[0])
        if ev.restarted:    # the gaps told are the old count's: their ids are new rundowns
            self._gaps_told, self._cut_unsettled = [], None
        return acts + self._end_wait(ev.t) + self._cut_caught_up(ev)

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
            if ev.unasked:
                self._cut_unsettled = (cut.selection,
                                       None if self._judged is None else self._judged[0])
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

    def _cut_unknown(self, t: float, why: str, cut: _Cut | None = None,
                     tid: int | None = None) -> list[Action]:
        """The link cut's bolt held (its result not known: ``why``); the cut ends.  ``cut``:
        one whose rundown was recorded already (:meth:`_cut_closed`), else the one open;
        ``tid``: the result stored unattributed that may be its own (an outcome entered for
        the bolt is that result: a supervisor's trial counted one tightening twice)."""
        cut = cut or self._cut
        assert cut is not None  # noqa: S101 - the callers' guard
        en = cut.selection
        self._answered(en)
        note = cut_unknown_note(why, en.pset, cut.enabled_at)
        stored = StoreCutUnknown(en.vin, en.bolt, note, en, tightening_id=tid)
        if self.matcher is None or self.vin != en.vin or en.bolt not in self.matcher.bolts:
            # held when that vehicle is at the station again
            self._held_away[(en.vin, en.bolt)] = (note, en)
            return [stored, Publish(Notice(Said.CUT_UNKNOWN, bolt=en.bolt, vin=en.vin,
                                           note=note, t=t))]
        return [stored, *self._hold_unknown(t, en.bolt, note, en)]

    def _answered(self, en: Selection) -> None:
        """``en``'s result is in, or settled for a person (held): its enable is owed nothing
        more, and a link cut during it is over."""
        if self._enabled is en:
            self._enabled = None
        if self._cut is not None and self._cut.selection is en:
            self._cut = None

    def _ran_again_of(self, ev: ResultIn) -> tuple[_Cut, int] | None:
        """The link cut whose proved rundown (its id) ``ev`` was fetched after, by the same
        catch-up, made after it: of that enable's vehicle (where it echoes one), a later id,
        not before the enable by its own time (and, watched again after a stop, not after
        that rundown was stored); else None.  See :meth:`ResultRules._ran_again_after_cut`."""
        closed, r = self._cut_closed, ev.result
        if closed is None or not ev.fetched or ev.live:
            return None
        cut, after, by = closed
        en, tid = cut.selection, int(r.tightening_id)
        echoed = str(r.vin or "").strip()
        # (``by``: restored at a start, when the cut's rundown was stored: one made later
        # is not that catch-up's, and one whose time is not known is not known to be: that
        # catch-up may have ended long before, a reviewer's old bolt held at every start)
        if en.pset is None or tid <= after or (echoed and echoed != en.vin) \
                or (ev.made_at is not None and ev.made_at < cut.enabled_at - CLOCK_SLACK_S) \
                or (by is not None and (ev.made_at is None
                                        or ev.made_at > by + CLOCK_SLACK_S)):
            return None
        return cut, after

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
            again = self._ran_again_of(ev)
            if again is not None:   # (a supervisor's trial: "no tool enable left" beside
                # the hold that named it; another vehicle's bolt with its VIN)
                sel = again[0].selection
                return None, Unproved(UnprovedKind.RAN_AGAIN, bolt=sel.bolt if sel.vin ==
                                      self.vin else f"{sel.bolt} of {sel.vin}",
                                      follows=again[1])
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
        went on for it (beyond the clock's slack).  Its time, where known, never before the
        enable or after its tool went off.  Fetched by the check as the enable's window ended
        (:meth:`_checking_owed`) as well as because a later one skipped its id.  A
        supervisor's trial: the operator pulled again at once, the first NOK stored
        unattributed and uncounted (by its time alone, within the slack, never proved)."""
        r, made = ev.result, ev.made_at
        checked = self._checking_owed()
        if not (ev.fetched and ev.live) \
                or not en.vin or self._cut is not None or self._enabled_at is None \
                or self._enabled_at <= self._link_lost_at \
                or not (self._result_owed(ev.t) or checked):
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
        slack).  Its time not known: not proved.  Where the enable before was this bolt's
        own, either enable's rundown is this bolt's (a reviewer: a retry's quick NOK)."""
        if self._same_bolt_before or self._checked_clear == self._enable_serial - 1:
            return True     # (the enable before checked: nothing made in its window)
        off = self._off_before_enable
        return made is not None and (off is None or made > off + CLOCK_SLACK_S)

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


def _said(note: str) -> Callable[[_Cut], str]:
    """A hold's note made already, as :meth:`LostRules._hold_unanswered` takes one."""
    return lambda _: note
