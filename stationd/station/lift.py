"""The vehicle and the lift: the station works only at working height with a vehicle
loaded (its VIN with the controller); a vehicle arrives, is rejected, reopened or ends, and
the lift's state is followed."""

from __future__ import annotations

import numpy as np

from db.kinds import LOOSENED, MISSING, NOK, PENDING, SKIPPED, TO_LOOSEN, HeldUnder
from drivers.keeper import FaultKind
from stationd.reasons import CoreFault, CoreFaultKind, FaultWhy
from stationd.station.actions import (
    Action,
    CloseVehicle,
    LoadVehicle,
    NoteLock,
    Publish,
    Record,
    SendVin,
    SettleClosing,
)
from stationd.station.events import (
    Because,
    BoltLocked,
    ClosingSettled,
    Notice,
    OperatorChange,
    OperatorChanged,
    Said,
    State,
    StateReason,
    VehicleClosed,
    VehicleOpened,
)
from stationd.station.faults import FaultRules
from stationd.station.inputs import (
    LIFT,
    VEHICLE,
    WRENCH,
    Event,
    LiftRead,
    Started,
    VehicleEnded,
    VehicleLoaded,
    VehicleRejected,
    VinSent,
    Written,
)
from stationd.station.matching import BoltMatcher, BoltRule
from stationd.station.policy import Strategy
from stationd.station.state import (
    LIFT_FAULT_BIT,
    NO_LOOSEN_PSET,
    NOK_SKIPPED,
    ON_A_BOLT,
    _disable,
)


class LiftRules(FaultRules):
    """The vehicle and lift rules: arrivals, rejections, the lift followed, the VIN sent."""

    def _on_started(self, ev: Started) -> list[Action]:
        if self._started:   # once: a device's fault may have come first (down at boot)
            return []
        self._started = True
        self._link_lost_at = ev.t
        self._to(State.FAULT if self.faults else State.WAITING_VEHICLE,
                 self._fault_reason() if self.faults else StateReason(Because.WAITING_LIFT))
        # the last station may have been killed with the tool on: off until a bolt is confirmed
        return [*_disable(StateReason(Because.STARTED), t=ev.t), *self._check_at_start(ev.t),
                Publish(OperatorChanged(self.operator, self.operator_required,
                                        how=OperatorChange.STILL_SIGNED_IN if self.operator
                                        else OperatorChange.NOBODY, t=ev.t))]

    def _on_lift_read(self, ev: LiftRead) -> list[Action]:
        acts: list[Action] = []
        self._lift = ev
        # a read is the PLC back from an outage (its fault bit is no outage: the PLC answers)
        back = LIFT in self.faults and self.faults[LIFT][0] is not FaultKind.REPORTED
        if back:
            acts += self._back(ev.t, LIFT)
            self._plc_fault = False      # its health was just said ok: said again if not
        if ev.plc_fault != self._plc_fault:
            # the lift itself in fault (its PLC answers and sets its fault bit): a fault of
            # the station as a device down is (the state FAULT, the tool off, the lift's
            # health in fault everywhere), until the PLC clears it; the vehicle stays
            # loaded (an operator trial: "waiting for vehicle" beside the loaded VIN and a
            # red FAULT headline)
            self._plc_fault = ev.plc_fault
            acts += self._fault(ev.t, LIFT, FaultKind.REPORTED, LIFT_FAULT_BIT) \
                if ev.plc_fault else self._back(ev.t, LIFT)
        if VEHICLE in self.faults and not ev.at_height:
            self._closed_vin = None
            acts += self._back(ev.t, VEHICLE)   # a vehicle fault lasts while that vehicle is up
        not_ready = StateReason(Because.LIFT_NOT_READY, note=ev.why)
        if self.vin is not None and not ev.at_height:
            acts += self._drop(ev.t, State.WAITING_VEHICLE, not_ready)
            # a bolt whose result may still come is neither missing nor NOK yet: said due,
            # its verdict follows it (a supervisor's trial: "ending NOK" as the lift went
            # down, its OK recorded a moment later)
            due = tuple(sorted(b for v, b in self._results_due() if v == self.vin))
            if due:
                self._closing[self.vin] = set(due)
            acts.append(CloseVehicle(self.vin, after_lift_outage=back, due=due))
            self._forget_vehicle()
        changed = self._vehicle_changed(ev)
        if changed is not None and VEHICLE not in self.faults:
            # the PLC now names another vehicle (or model) with the lift still at height:
            # the loaded bolts are not this car's; nothing more is sent until the lift goes
            # down (which closes the loaded vehicle and clears this fault)
            acts += self._fault(ev.t, VEHICLE, FaultKind.CHANGED, changed)
        if self.state in (State.STARTING, State.FAULT):
            return acts
        if not ev.ready:
            if self.state in ON_A_BOLT or self.state is State.TRACKING:
                acts += self._drop(ev.t, State.WAITING_VEHICLE, not_ready)
            else:
                self._to(State.WAITING_VEHICLE, not_ready)
            return acts
        if self.vin is None:
            if not self._loading:
                self._loading = True
                vin = ev.vin or f"SEQ-{int(ev.t)}"
                self._load_code = ev.model_code
                acts.append(LoadVehicle(ev.model_code, vin))
                self._to(State.WAITING_VEHICLE, StateReason(Because.LOADING, vin=vin))
            return acts
        if self.state is State.WAITING_VEHICLE:
            self._to(State.TRACKING, StateReason(Because.TRACKING))
        return acts

    def _vehicle_changed(self, ev: LiftRead) -> CoreFault | None:
        """Why the vehicle at height is not the one loaded (its VIN or model code changed),
        typed, else None."""
        if self.vin is None or not ev.at_height:
            return None
        if ev.vin and ev.vin != self.vin:
            return CoreFault(CoreFaultKind.VIN_CHANGED, vin=self.vin, plc_vin=ev.vin)
        if self._load_code is not None and ev.model_code != self._load_code:
            return CoreFault(CoreFaultKind.MODEL_CHANGED, vin=self.vin, code=self._load_code,
                             plc_code=ev.model_code)
        return None

    def _on_vehicle_loaded(self, ev: VehicleLoaded) -> list[Action]:
        self._loading = False
        self._closing.pop(ev.vin, None)   # open again (a rework): its close owes nothing
        self._reopened.discard(ev.vin)     # back at the station
        self.vin, self.model = ev.vin, ev.model
        self._specs = dict(ev.bolts)
        self._recorded = {}
        self.matcher = BoltMatcher(
            {k: np.asarray(b.position, dtype=np.float64) for k, b in ev.bolts.items()},
            self.params, set(ev.done), dict(ev.skipped),
            rules={k: BoltRule(b.order, b.batch) for k, b in ev.bolts.items()})
        self._noks = {k: n for k, n in ev.noks.items() if k in ev.bolts and n > 0}
        newly: list[Action] = []
        for k, n in self._noks.items():   # the NOK policy's state comes back with the vehicle
            rule = self.nok.rule(k, ev.bolts[k].pset)
            if k in ev.locked:      # locked then: until a person releases it, whatever
                self.matcher.locked[k] = n           # max_nok a reload brought
            elif n >= rule.max_nok:  # locked now by a lowered max_nok: recorded as such
                self.matcher.locked[k] = n
                newly.append(NoteLock(ev.vin, k, n, ev.t))
            elif rule.strategy is Strategy.SKIP:
                self.matcher.skipped.setdefault(k, NOK_SKIPPED)
        self._loosen_back(ev)
        self._holds_back(ev)
        # what its records say of each bolt's rundowns: one at all, loosened last, released
        # from a hold and not run down since (its result not known)
        ran = {k for k, st in ev.status.items() if st not in (PENDING, MISSING, SKIPPED)}
        self._ran = ran & ev.bolts.keys()
        self._loosened = {k for k in self._ran if ev.status[k] == LOOSENED}
        self._check_first = {k for k in ev.released if k in ev.bolts and k not in ev.done}
        self._ordered_loosen = set()   # (its records say "loosen first": no NOK last)
        # drawn as the station treats it now (:meth:`_bolt_view`)
        opened = VehicleOpened(ev.vin, ev.model, self.bolt_views(), rework=ev.rework, t=ev.t)
        self._shown, self._shown_key = {v.bolt: v for v in opened.bolts}, self._bolts_key()
        if self.state is State.WAITING_VEHICLE and self._lift is not None and self._lift.ready:
            self._to(State.TRACKING, StateReason(Because.TRACKING))
        # what waits for a supervisor comes back with the vehicle (a restart, a reload): the
        # screens and status list it again, to be released
        waiting = [Publish(BoltLocked(k, n, t=ev.t)) for k, n in self.matcher.locked.items()]
        waiting += [Publish(BoltLocked(k, 0, held=note, t=ev.t))
                    for k, note in self.matcher.held.items()]
        return [*newly, Publish(opened), *waiting, *self._check_on_arrival(ev.t, ev.vin)]

    def _holds_back(self, ev: VehicleLoaded) -> None:
        """The holds come back with the vehicle, each a loosening's where its result came
        under the bolt's loosen pset (:func:`held_a_loosening`): its note says so, and an
        outcome entered for it is a loosening's.  After :meth:`_loosen_back`."""
        assert self.matcher is not None  # noqa: S101 - loaded just now
        self._held_loosening = {}
        self.matcher.held = {}
        for k, note in ev.held.items():
            if k not in ev.bolts:
                continue
            under, pset = ev.held_under.get(k, HeldUnder()), ev.bolts[k].pset
            loosening = held_a_loosening(under, pset, k in self._loosen)
            sent = under.pset if under.pset is not None else self.nok.rule(k, pset).loosen_pset
            self._held(k, note, loosening, sent)
        # a hold this core decided while the vehicle was not loaded, its store raced by the
        # load's read: held all the same (the store makes it the database's too)
        away, self._held_away = self._held_away, {}
        for (vin, k), (note, en) in away.items():
            if vin == ev.vin and k in ev.bolts and k not in self.matcher.held \
                    and k not in self.matcher.skipped:
                self._held(k, note, en.loosen, en.pset)

    def _loosen_back(self, ev: VehicleLoaded) -> None:
        """The loosen strategy's state comes back with the vehicle: a bolt whose last rundown
        is a NOK under ``loosen`` (also a NOK loosening), or with a loosen command since its
        last rundown, gets its loosen pset next; one that no loosen pset applies to any more
        is skipped (its tightening pset would hit a tightened joint again)."""
        assert self.matcher is not None  # noqa: S101 - loaded just now
        self._loosen, self._nok_last = set(), set()
        for k, status in ev.status.items():
            if k not in ev.bolts:
                continue
            rule = self.nok.rule(k, ev.bolts[k].pset)
            if status == NOK:
                self._nok_last.add(k)
                if rule.count_in_batch:   # the NOK counts in its batch (the policy's choice)
                    self.matcher.counted.add(k)
            # to be loosened: a loosen command since its last rundown, a NOK under the loosen
            # strategy, or a loosening that did not come loose under any strategy (a loosen
            # command's: live, its loosen pset goes again; after a reload its tightening pset
            # went onto a joint still tight)
            if status == TO_LOOSEN or (status == NOK and (rule.strategy is Strategy.LOOSEN
                                                          or k in ev.loosen_nok)):
                if rule.loosen_pset is None:
                    self.matcher.skipped.setdefault(k, NO_LOOSEN_PSET)
                else:
                    self._loosen.add(k)
        for k in ev.released:    # a released hold, not run down since: loosened first as
            if k in ev.bolts:    # at its release (its result not known: it may be a NOK)
                self._loosen_unknown(k)

    def _on_vehicle_rejected(self, ev: VehicleRejected) -> list[Action]:
        if ev.closed and self.rework and ev.vin is not None and self._lift is not None:
            return [Publish(Notice(Said.REWORK_REOPENED, vin=ev.vin, t=ev.t)),
                    LoadVehicle(self._lift.model_code, ev.vin, reopen=True)]
        self._loading = False
        self._closed_vin = ev.vin if ev.closed else None
        # why: the shell's own words, or (a closed VIN) the station's rework rule, typed
        why: FaultWhy = CoreFault(CoreFaultKind.CLOSED, vin=ev.vin, note=ev.reason) \
            if ev.closed else ev.reason
        return self._fault(ev.t, VEHICLE, FaultKind.REJECTED, why)

    def _on_vehicle_ended(self, ev: VehicleEnded) -> list[Action]:
        if ev.settled:
            return [Publish(ClosingSettled(ev.vin, ev.missing, ev.nok, ev.due, ev.settled,
                                           t=ev.t))]
        return [Publish(VehicleClosed(ev.vin, ev.missing, ev.nok, ev.due, t=ev.t))]

    def _closing_settled(self, ev: Event, acts: list[Action]) -> list[Action]:
        """After each input: the results on their way to the database followed (a Record
        out, its Written in: which may come much later, after a database outage); a vehicle
        closed with results due (:attr:`_closing`) gets its verdict again once they are
        settled: in its records, or no longer to come (:meth:`_results_due`: its window and
        check over with nothing found, or its bolt held).  A vehicle back at the station (a
        rework) is open again: nothing more is owed to its close."""
        if isinstance(ev, Written):
            key = (ev.record.vin, ev.record.bolt)
            if self._flying.get(key, 0) > 1:
                self._flying[key] -= 1
            else:
                self._flying.pop(key, None)
        for a in acts:
            if isinstance(a, Record):
                self._flying[(a.vin, a.bolt)] = self._flying.get((a.vin, a.bolt), 0) + 1
        if not self._closing:
            return []
        due = self._results_due()
        out: list[Action] = []
        for vin, bolts in list(self._closing.items()):
            settled = tuple(sorted(b for b in bolts if (vin, b) not in due))
            if settled:
                bolts.difference_update(settled)
                out.append(SettleClosing(vin, settled, tuple(sorted(bolts))))
            if not bolts:
                del self._closing[vin]
        return out

    def _on_vin_sent(self, ev: VinSent) -> list[Action]:
        self._vin_pending = False
        if ev.vin == self.vin:
            self._vin_for = (ev.vin, self._wrench_epoch)
        return []

    # -- the VIN with the controller ------------------------------------------------------
    def _vin_due(self) -> list[Action]:
        """The controller tags its results with the VIN: sent once per vehicle and again after
        the controller reconnected (a power cycle forgets it)."""
        if self.vin is None or WRENCH in self.faults or self._vin_pending:
            return []
        if self._vin_for == (self.vin, self._wrench_epoch):
            return []
        self._vin_pending = True
        return [SendVin(self.vin)]


def held_a_loosening(under: HeldUnder, pset: int | None, to_loosen: bool) -> bool:
    """Whether a hold read back from the records (a reload, a restart) is a loosening's: its
    result came under the bolt's loosen pset.  The records tell it where they have the tool
    enable it answered (``under.loosen``).  Where they cannot (no enable found): a pset it
    came under that is not the bolt's tightening pset ``pset`` cannot have tightened it, and
    is taken for a loosening (in doubt a loosening: its entered OK only sends the bolt to its
    tightening pset again, where a tightening's would close a bolt perhaps only loosened);
    with no pset known, the pset the station would send the bolt now decides, as it decided
    the selection then (``to_loosen``: its loosen pset first, the NOK policy's state read
    back from the same records)."""
    if under.loosen is not None:
        return under.loosen
    if under.pset is not None and pset is not None:
        return under.pset != pset
    return to_loosen
