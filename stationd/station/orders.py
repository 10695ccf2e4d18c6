"""Commands (people's orders through the screens and ``stationd`` commands): who may give
which, why one is refused, and what each does (skip, release, reopen, loosen, sign in and
out, teach, check), with its record and answer."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from stationd.reasons import Reason, Skip, SkipKind, Why
from stationd.station.actions import Action, Publish, RecordCommand, RecordRefusal, Reply
from stationd.station.commands import (
    KIND,
    RIGHT,
    Answer,
    CheckCalibration,
    Command,
    EnterOutcome,
    Issuer,
    LoosenBolt,
    ReleaseBolt,
    ReopenVehicle,
    Right,
    SignIn,
    SignOut,
    SkipBolt,
    TeachPoint,
    TeachStart,
    TeachStop,
)
from stationd.station.events import (
    Because,
    BoltReleased,
    BoltSkipped,
    BoltToLoosen,
    OperatorChange,
    OperatorChanged,
    State,
    StateReason,
    VehicleReopened,
)
from stationd.station.faults import FaultRules
from stationd.station.inputs import VEHICLE, CommandDone, CommandIn, OperatorBack
from stationd.station.state import ON_A_BOLT

#: the commands whose refusals are kept in the records: those that change a bolt's verdict
#: or a vehicle (a refused falsified OK must show in the trail, not in the journal alone)
AUDITED = (SkipBolt, ReleaseBolt, LoosenBolt, EnterOutcome, ReopenVehicle)


class OrderRules(FaultRules):
    """Commands: who may give which, why one is refused, what each does."""

    def _on_command_in(self, ev: CommandIn) -> list[Action]:
        """A command is checked against the rules now and takes effect once recorded."""
        why = self._refusal(ev.command, ev.issuer, ev.known, ev.meant)
        if why is not None:
            acts: list[Action] = [Reply(Answer(ev.request, ev.command, ev.issuer, why))]
            if isinstance(ev.command, AUDITED):   # would have changed a bolt or a vehicle:
                acts.append(RecordRefusal(ev.command, ev.issuer, why, ev.t))   # the trail
            return acts
        if isinstance(ev.command, SignOut):   # its record names who is signed out
            ev = replace(ev, command=replace(ev.command, user=self.operator))
        if isinstance(ev.command, EnterOutcome):   # its record is the held result's kind
            b = ev.command.bolt
            ev = replace(ev, command=replace(
                ev.command, loosening=b in self._held_loosening,
                loosen_pset=self._held_loosening.get(b)))
        self._commands[ev.request] = ev
        return [RecordCommand(ev.request, ev.command, ev.issuer, ev.t)]

    def _refusal(self, cmd: Command, who: Issuer, known: bool | None = None,
                 meant: str | None = None) -> Reason | None:
        """Why ``cmd`` may not be carried out now, or None (``known``: whether the database
        has the VIN it names, ``meant`` the one it has in another case: :class:`CommandIn`)."""
        right = RIGHT.get(type(cmd))
        if right is not None and right not in who.rights:
            asked = KIND[type(cmd)]
            return Reason(Why.NO_RIGHT, right=right.value,
                          asked=None if asked.startswith(right.value) else asked)
        if isinstance(cmd, SignIn):
            return Reason(Why.SIGNED_IN, user=who.user) if self.operator == who.user else None
        if isinstance(cmd, SignOut):
            return Reason(Why.NOT_SIGNED_IN) if self.operator is None else None
        if isinstance(cmd, CheckCalibration):
            return None if self.trust is not None else Reason(Why.NO_REFERENCES)
        if isinstance(cmd, TeachStart | TeachPoint | TeachStop):
            return self._teach_refusal(cmd)
        if self._teach is not None:
            return self._teach.refusal()
        if isinstance(cmd, ReopenVehicle):
            if cmd.vin == self.vin:
                return Reason(Why.ALREADY_OPEN, vin=cmd.vin)
            return None   # the database knows whether it is closed (CommandDone)
        if self.vin is None or self.matcher is None:
            # a vehicle raised while a device is in fault is not loaded until it is back
            return self._fault_refusal() if self.faults else Reason(Why.NO_VEHICLE)
        if cmd.vin != self.vin:
            # typed in lower case: said, not taken (a command names exactly what it acts on)
            if known is False and cmd.vin.upper() != self.vin:
                # a VIN the database does not know: not "reopen it" (a supervisor's trial)
                return Reason(Why.UNKNOWN_VEHICLE, vin=cmd.vin, other=meant)
            return Reason(Why.OTHER_VEHICLE, vin=cmd.vin,
                          other=self.vin if cmd.vin.upper() == self.vin else None,
                          reopened=True if cmd.vin in self._reopened else None,
                          here=self.vin)
        if cmd.bolt not in self.matcher.bolts:
            alike = [b for b in self.matcher.bolts if b.casefold() == cmd.bolt.casefold()]
            return Reason(Why.UNKNOWN_BOLT, bolt=cmd.bolt, vin=cmd.vin,
                          other=alike[0] if alike else None)
        if isinstance(cmd, LoosenBolt):
            return self._loosen_refusal(cmd)
        if isinstance(cmd, ReleaseBolt):
            return None if cmd.bolt in self.matcher.locked or cmd.bolt in self.matcher.held \
                else Reason(Why.NOT_LOCKED, bolt=cmd.bolt)
        if isinstance(cmd, EnterOutcome):   # what a person read on the controller's screen
            if cmd.bolt not in self.matcher.held:
                # (locked after NOKs: said so, it is released instead: a supervisor's trial)
                return Reason(Why.NOT_HELD, bolt=cmd.bolt,
                              count=self.matcher.locked.get(cmd.bolt))
            return self._entered_outside(cmd)
        if cmd.bolt in self.matcher.done:
            return Reason(Why.DONE, bolt=cmd.bolt)
        if cmd.bolt in self.matcher.skipped:
            return Reason(Why.SKIPPED, bolt=cmd.bolt, skip=self.matcher.skipped[cmd.bolt])
        if isinstance(cmd, SkipBolt) and Right.RELEASE not in who.rights:
            # a skip ends a lock or a hold: only who may release it may (an operator's skip
            # took the lock away, the supervisor never asked)
            if cmd.bolt in self.matcher.held:
                return Reason(Why.HELD, bolt=cmd.bolt, note=self.matcher.held[cmd.bolt])
            if cmd.bolt in self.matcher.locked:
                return Reason(Why.LOCKED, bolt=cmd.bolt, count=self.matcher.locked[cmd.bolt])
        if self.tool_on and self.bolt == cmd.bolt:
            return Reason(Why.TOOL_ON_BOLT, bolt=cmd.bolt)
        return None

    def _entered_outside(self, cmd: EnterOutcome) -> Reason | None:
        """An OK entered with a torque (or angle) outside the bolt's window: a value typed
        wrong (4.974 for 49.74 closed a 45-55 Nm bolt as OK: a supervisor trial), or not this
        bolt's result.  Refused, as the station refuses such an OK from the controller as a
        tightening; a NOK, or a loosening's outcome (its loosen program judges it), is not
        checked against the bolt's window."""
        spec = self._specs.get(cmd.bolt)
        p = spec.parameters if spec is not None else None
        if not cmd.ok or p is None or cmd.bolt in self._held_loosening:
            return None
        out: list[str] = []
        if not p.torque.min <= cmd.torque_nm <= p.torque.max:
            out.append(f"torque {cmd.torque_nm:g} Nm outside {p.torque.min:g}-"
                       f"{p.torque.max:g} Nm")
        if p.angle is not None and not p.angle.min <= cmd.angle_deg <= p.angle.max:
            out.append(f"angle {cmd.angle_deg:g} deg outside {p.angle.min:g}-"
                       f"{p.angle.max:g} deg")
        return Reason(Why.ENTERED_OUTSIDE, bolt=cmd.bolt, note="; ".join(out)) if out else None

    def _loosen_refusal(self, cmd: LoosenBolt) -> Reason | None:
        """A loosen is for a bolt tightened (OK, or NOK last) that a loosen pset applies to,
        not locked, skipped, to be loosened already, or being tightened now."""
        m = self.matcher
        assert m is not None  # noqa: S101 - checked by the caller
        b = cmd.bolt
        loosen_pset = self._nok_rule(b).loosen_pset
        if loosen_pset is None:
            return Reason(Why.NO_LOOSEN_PSET, bolt=b)
        if b in self._loosen:   # (said as the rule, it read as an instruction: a trial)
            return Reason(Why.LOOSEN_ORDERED, bolt=b, pset=loosen_pset)
        if b in m.locked:
            return Reason(Why.LOCKED, bolt=b, count=m.locked[b])
        if b in m.skipped:
            return Reason(Why.SKIPPED, bolt=b, skip=m.skipped[b])
        if self.tool_on and self.bolt == b:
            return Reason(Why.TOOL_ON_BOLT, bolt=b)
        if b not in m.done and b not in self._nok_last:
            return Reason(Why.NOTHING_TO_LOOSEN, bolt=b)
        return None

    def _on_command_done(self, ev: CommandDone) -> list[Action]:
        c = self._commands.pop(ev.request, None)
        if c is None:
            return []
        answer = Answer(ev.request, c.command, c.issuer, ev.reason)
        if ev.reason is not None:
            return [Reply(answer)]
        cmd = c.command
        if isinstance(cmd, CheckCalibration):
            return self._check_asked(ev.t, c)
        if isinstance(cmd, TeachStart | TeachPoint | TeachStop):
            return self._teach_done(ev.t, c)
        if isinstance(cmd, SignIn | SignOut):
            user = c.issuer.user if isinstance(cmd, SignIn) else None
            how = OperatorChange.SIGNED_IN if user is not None else OperatorChange.SIGNED_OUT
            by = c.issuer.user if user is None and c.issuer.user != self.operator else None
            return [*self._operator_is(ev.t, user, how, by), Reply(answer)]
        acts: list[Action] = []
        if isinstance(cmd, SkipBolt):
            acts += self._skip(ev.t, cmd, c.issuer)
        elif isinstance(cmd, ReleaseBolt):
            note = self._unhold(cmd.bolt) if self.matcher is not None \
                and self.vin == cmd.vin else None
            ended: dict[str, Any] = {}   # what the release ended, for its answer
            if note is not None:
                ended["hold"] = note
                acts.append(Publish(BoltReleased(cmd.bolt, c.issuer.user, unknown=True,
                                                 t=ev.t)))
                assert self.matcher is not None  # noqa: S101 - _unhold found a hold
                if cmd.bolt not in self.matcher.done:   # (its OK recorded since: known)
                    self._check_first.add(cmd.bolt)
                else:   # done before its hold (a rundown after its OK held it): stays done
                    ended["done"] = True
                self._loosen_unknown(cmd.bolt)
            locked = self.matcher.locked.pop(cmd.bolt, None) \
                if self.matcher is not None and self.vin == cmd.vin else None
            if locked is not None:
                ended["lock"] = locked
                acts.append(Publish(BoltReleased(cmd.bolt, c.issuer.user, t=ev.t)))
            if ended and cmd.bolt in self._loosen:   # released, still to be loosened first
                acts.append(self._to_loosen(ev.t, cmd.bolt))
                ended["loosen_pset"] = self._nok_rule(cmd.bolt).loosen_pset
            if ended:
                # a release ends the NOKs in a row, a hold's as a lock's: as the records count
                # them at a reload (a supervisor's trial: the live count went on)
                self._noks.pop(cmd.bolt, None)
            # (a supervisor's trial: a second release answered "accepted" alike, having ended
            # a new hold rather than the lock it was meant for)
            answer = replace(answer, result=ended or None)
        elif isinstance(cmd, LoosenBolt):
            acts += self._loosen_ordered(ev.t, cmd, c.issuer)
        elif isinstance(cmd, ReopenVehicle):
            acts.append(Publish(VehicleReopened(cmd.vin, c.issuer.user, t=ev.t)))
            self._reopened.add(cmd.vin)
            if cmd.vin == self._closed_vin and VEHICLE in self.faults:
                # the closed vehicle at height, reopened: its fault clears and the next lift
                # read loads it (open now)
                self._closed_vin, self._loading = None, False
                acts += self._back(ev.t, VEHICLE)
        return [*acts, Reply(answer)]

    def _skip(self, t: float, cmd: SkipBolt, who: Issuer) -> list[Action]:
        """The bolt is not tightened at this station for this vehicle; a selection of it ends
        (the tool goes off)."""
        if self.matcher is None or self.vin != cmd.vin or cmd.bolt not in self.matcher.bolts:
            return []   # the vehicle left while the command was being recorded
        why = Skip(SkipKind.COMMAND, user=who.user, comment=cmd.comment)
        self.matcher.skipped[cmd.bolt] = why
        # a lock or a hold ends with the skip (a user with the release right gave it)
        self.matcher.locked.pop(cmd.bolt, None)
        self._unhold(cmd.bolt)
        self._noks.pop(cmd.bolt, None)
        acts: list[Action] = [Publish(BoltSkipped(cmd.bolt, skip=why, t=t))]
        if self.bolt == cmd.bolt:
            acts += self._drop(t, State.TRACKING,
                               StateReason(Because.SKIPPED, bolt=cmd.bolt, skip=why))
        return acts

    def _loosen_ordered(self, t: float, cmd: LoosenBolt, who: Issuer) -> list[Action]:
        """A recorded loosen command: the bolt is no longer done and gets its loosen pset
        next; a selection of it ends (its tightening pset may have been sent)."""
        if self.matcher is None or self.vin != cmd.vin or cmd.bolt not in self.matcher.bolts:
            return []   # the vehicle left while the command was being recorded
        self.matcher.done.discard(cmd.bolt)
        # its last rundown no longer ends it as a NOK on the report (it says "loosen first",
        # as its records do after a reload); the NOK row it ends stands (a reviewer: the NOK
        # policy owed to a fetched NOK was dropped, no lock at max_nok)
        self._ordered_loosen.add(cmd.bolt)
        self._loosen.add(cmd.bolt)
        acts = [self._to_loosen(t, cmd.bolt, who.user, cmd.comment)]
        if self.bolt == cmd.bolt:
            acts += self._drop(t, State.TRACKING,
                               StateReason(Because.LOOSEN_ORDERED, bolt=cmd.bolt))
        return acts

    def _to_loosen(self, t: float, bolt: str, user: str | None = None,
                   comment: str | None = None) -> Action:
        """``bolt`` gets its loosen pset next: after a NOK (the NOK policy), or by ``user``'s
        loosen command with their ``comment`` (the reason carries both; its words say whose
        command it was)."""
        pset = self._nok_rule(bolt).loosen_pset
        return Publish(BoltToLoosen(bolt, Reason(Why.LOOSEN_FIRST, bolt=bolt, pset=pset,
                                                 user=user, note=comment), user, t=t))

    # -- the operator signed in at the station ---------------------------------------------
    def _on_operator_back(self, ev: OperatorBack) -> list[Action]:
        """Signed in before a start or reload: still signed in (said at :class:`Started`),
        unless idle too long already."""
        if self.operator_idle_s is not None and ev.t - ev.since >= self.operator_idle_s:
            return []
        self.operator, self._operator_seen = ev.user, ev.since
        return []

    def _operator_is(self, t: float, user: str | None, how: OperatorChange,
                     by: str | None = None) -> list[Action]:
        """``user`` (None: nobody) is the operator from now on.  A bolt selected for the last
        one is left (the tool off): its rundown would carry the wrong name."""
        previous, self.operator, self._operator_seen = self.operator, user, t
        acts: list[Action] = []
        if previous != user and (self.state in ON_A_BOLT or self.tool_on):
            acts += self._drop(t, State.TRACKING, StateReason(Because.OPERATOR, how=how))
        self._last_refusal = None   # a refusal to nobody is said again to the next one
        return [*acts, Publish(OperatorChanged(user, self.operator_required, previous, how,
                                               by, t=t))]

    def _operator_idle(self, t: float) -> list[Action]:
        """The operator idle for ``operator_idle_s`` (no selection, no rundown) is signed
        out, and that is recorded as their sign-out by the station (nobody waits for it:
        request 0)."""
        idle, user = self.operator_idle_s, self.operator
        if idle is None or user is None or self.tool_on or self.state in ON_A_BOLT \
                or t - self._operator_seen < idle:
            return []
        out = SignOut(user=user, idle_s=idle)
        return [*self._operator_is(t, None, OperatorChange.IDLE),
                RecordCommand(0, out, Issuer(user, frozenset(), "station (idle)"), t)]
