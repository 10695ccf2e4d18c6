"""The NOK policy after a result (retry, lock, loosen, skip), and the outcome a person entered
for a held bolt: what closes a bolt or counts against it, whether measured or read on the
controller's screen."""

from __future__ import annotations

from db.kinds import (
    LOOSENING,
    TIGHTENING,
)
from stationd.station.actions import (
    Action,
    Publish,
    Reply,
)
from stationd.station.commands import Answer, EnterOutcome, Issuer
from stationd.station.events import (
    BoltSkipped,
    Notice,
    ResultRecorded,
    Said,
)
from stationd.station.inputs import (
    CommandDone,
)
from stationd.station.orders import OrderRules
from stationd.station.policy import Strategy
from stationd.station.state import NOK_SKIPPED


class NokRules(OrderRules):
    """A bolt's outcome: the NOK policy after a NOK or a loosening, and an outcome a person
    entered for a held bolt."""

    def _after_loosening(self, t: float, bolt: str, ok: bool,
                         tid: int | None = None) -> list[Action]:
        """A loosening (measured, or its outcome entered by a person) is never the bolt done
        (it undoes a tightening).  OK: the bolt's tightening pset goes next; NOK: it counts as
        a NOK of the bolt (the joint did not come loose: ``max_nok`` of them lock it) and a
        bolt to loosen stays so; one heard late, made after the bolt had locked, is said
        (:meth:`_nok_after_lock`), the lock standing.  ``tid``: its tightening id."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self.matcher.done.discard(bolt)
        self.matcher.counted.discard(bolt)   # undone: no longer counts in its batch
        if ok:
            self._nok_last.discard(bolt)
            self._loosen.discard(bolt)
            return [Publish(Notice(Said.LOOSENED, bolt=bolt, t=t))]
        # its last rundown a NOK (the joint did not come loose), as its records say it
        self._nok_last.add(bolt)
        n = self._noks[bolt] = self._noks.get(bolt, 0) + 1
        if bolt in self.matcher.locked:     # made before the station knew of the lock
            return [self._nok_after_lock(t, bolt, n, tid)]
        rule = self._nok_rule(bolt)
        if n >= rule.max_nok:
            return self._lock(t, bolt, n)
        return [Publish(Notice(Said.LOOSENING_NOK, bolt=bolt, count=n, t=t))]

    def _after_nok(self, t: float, bolt: str, pset: int | None,
                   counted: bool = False, tid: int | None = None) -> list[Action]:
        """The NOK policy: the bolt locks after ``max_nok`` in a row; with ``loosen`` it gets
        its loosen pset next (also once released); with ``skip`` it is marked NOK and skipped
        for this vehicle; with ``repeat`` it is open again.  However its NOKs came (live, or
        heard late: a push lost, fetched later): it locks at the ``max_nok``-th, and a NOK
        made after that, the tool still on as the station did not know yet (``tid``: its
        tightening id), is counted and said, the lock standing as it was made (a supervisor's
        trial: locked after 4 NOK in a row with max_nok 3, not a word of the 4th)."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        n = self._noks[bolt] = self._noks.get(bolt, 0) + (0 if counted else 1)
        due = self._lock_due.pop(bolt, None)
        if bolt in self.matcher.locked:
            return [self._nok_after_lock(t, bolt, n, tid)]
        rule = self._nok_rule(bolt, pset)
        if rule.strategy is Strategy.LOOSEN and rule.loosen_pset is not None:
            self._loosen.add(bolt)
        if rule.count_in_batch:     # the sequence goes on without an OK of this bolt
            self.matcher.counted.add(bolt)
        if due is not None and due < n:   # max_nok reached by a NOK heard late, then this
            return [*self._lock(t, bolt, due), self._nok_after_lock(t, bolt, n, tid)]
        if n >= rule.max_nok:
            return self._lock(t, bolt, n)
        if bolt in self._loosen:
            return [self._to_loosen(t, bolt)]
        if rule.strategy is Strategy.SKIP:
            why = NOK_SKIPPED
            self.matcher.skipped[bolt] = why
            return [Publish(BoltSkipped(bolt, skip=why, t=t))]
        return []

    def _nok_after_lock(self, t: float, bolt: str, n: int, tid: int | None) -> Action:
        """A NOK of ``bolt`` (``n`` in a row now) made after it had reached its max_nok,
        heard only now: recorded (its Record is the caller's), counted, and said; the lock
        stands at the count it was made at."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        return Publish(Notice(Said.NOK_AFTER_LOCK, bolt=bolt, tightening_id=tid, count=n,
                              locked_at=self.matcher.locked.get(bolt), t=t))

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
        self._ran_once(b, cmd.loosening, cmd.ok)
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
            # an OK answers the NOKs before it, as a pushed one does: a lock made while the
            # result was not known (a lost NOK's, judged when the unreadable one came) ends
            m.locked.pop(b, None)
            self._noks.pop(b, None)
            self._loosen.discard(b)
            self._nok_last.discard(b)
            m.counted.discard(b)
        else:
            self._nok_last.add(b)
            acts += self._after_nok(t, b, spec.pset if spec is not None else None)
        m.reset()
        return acts
