"""Devices' faults and their return: the station in FAULT while any device is, the tool
off, a teach point answered; back to waiting or tracking when every device is back."""

from __future__ import annotations

from drivers.keeper import FaultKind
from stationd.reasons import FaultWhy
from stationd.station.actions import Action, Publish
from stationd.station.events import (
    Because,
    DeviceHealth,
    DeviceIdentified,
    LineLinkChanged,
    State,
    StateReason,
)
from stationd.station.inputs import (
    DATABASE,
    LIFT,
    WRENCH,
    DeviceBack,
    DeviceFault,
    DeviceSaid,
    LineLinkIn,
)
from stationd.station.state import _Cut, _disable
from stationd.station.teaching import TeachRules


class FaultRules(TeachRules):
    """Devices' faults and their return."""

    def _on_device_fault(self, ev: DeviceFault) -> list[Action]:
        if ev.device == WRENCH:
            self._vin_pending = False
            self._link_lost_at = ev.t
            if self._enabled is not None and self._enabled_at is not None and self._cut is None \
                    and self._result_owed(ev.t) and ev.kind is not FaultKind.REFUSED:
                # the tool's result may come only after the reconnect: where it belongs is
                # then proved by the controller's own data (:meth:`_made_during_cut`).  A
                # refusal keeps the link (no reconnect, no catch-up): its results come pushed
                self._cut = _Cut(self._enabled, self._enabled_at, ev.t, self._wrench_reconnects)
        if ev.device == DATABASE:
            # the load under way failed (the only database call the core waits for): the
            # vehicle is loaded again once the database is back and the lift still ready
            self._loading = False
        if ev.device == LIFT:
            # the PLC's fault bit is not known while it does not answer: the first read after
            # the outage says it again (kept, the bit still set read as no change was lost
            # with the outage's fault: the lift "ok" everywhere, a review)
            self._plc_fault = False
            self._lift_lost_at = ev.t
        return self._fault(ev.t, ev.device, ev.kind, ev.reason)

    def missed_since(self) -> float | None:
        """Since when results the controller made may have been missed with no tightening id
        to count from (none of this controller's recorded yet): the enable a link cut came
        during (its result is proved by the controller's data), else the last time the link
        was lost (the station's start included); None before the station started.  What the
        controller made before is its history, not this station's."""
        if self._cut is not None:
            return min(self._cut.enabled_at, self._link_lost_at)
        return None if self._link_lost_at == float("-inf") else self._link_lost_at

    def _on_device_back(self, ev: DeviceBack) -> list[Action]:
        if ev.device == WRENCH and ev.reconnects is not None \
                and ev.reconnects != self._wrench_reconnects:
            if self._wrench_reconnects is not None:
                self._wrench_epoch += 1   # a reconnected controller may have lost the VIN
            self._wrench_reconnects = ev.reconnects
        acts: list[Action] = []
        if ev.device == WRENCH and self._link_back_at < self._link_lost_at:
            self._link_back_at = ev.t
        if ev.device == WRENCH and WRENCH in self.faults:
            # the DisableTool sent at the fault may never have arrived: off, whatever it did
            acts += _disable(StateReason(Because.CONTROLLER_BACK), t=ev.t)
        if ev.device == LIFT and self.faults.get(LIFT, (None,))[0] is FaultKind.REPORTED:
            return acts   # the PLC answers with its fault bit set (read first): a read ends it
        return acts + self._back(ev.t, ev.device)

    def _on_device_said(self, ev: DeviceSaid) -> list[Action]:
        """What a device said it is, told once per change (a reconnect says it again; a
        field that changed under the same words is a change too)."""
        plate = ev.nameplate
        if self.identifications.get(ev.device) == plate:
            return []
        self.identifications[ev.device] = plate
        return [Publish(DeviceIdentified(ev.device, ev.identity, plate, t=ev.t))]

    def _on_line_link(self, ev: LineLinkIn) -> list[Action]:
        """The line database's link, kept and told when it changes; never a fault."""
        link = LineLinkChanged(ev.up, ev.reason, ev.alarm, t=ev.t)
        if self.line is not None and (self.line.up, self.line.reason, self.line.alarm) \
                == (link.up, link.reason, link.alarm):
            return []
        self.line = link
        return [Publish(link)]

    def _fault(self, t: float, device: str, kind: FaultKind, reason: FaultWhy) -> list[Action]:
        """``device`` is in fault for ``reason``: a device's own words (a driver's text, kept
        as it came), or a fault of the station's own rules, typed (its words are said at the
        edges: :class:`DeviceHealth` carries it as ``fault``, worded at publication)."""
        acts: list[Action] = []
        if self.faults.get(device) != (kind, reason):
            acts.append(Publish(
                DeviceHealth(device, False, kind, reason, t=t) if isinstance(reason, str)
                else DeviceHealth(device, False, kind, fault=reason, t=t)))
        self.faults[device] = (kind, reason)
        acts += self._drop(t, State.FAULT, self._fault_reason())
        if self._teach is not None and self._teach.measuring is not None:
            # a bolt being taught is measured only without faults: answered now, with them
            acts += self._teach_answered(self._teach, self._fault_refusal())
        return acts

    def _back(self, t: float, device: str) -> list[Action]:
        if device not in self.faults:
            return []
        del self.faults[device]
        acts: list[Action] = [Publish(DeviceHealth(device, True, t=t))]
        if self.state is State.FAULT:
            lift = self._lift
            if self.faults:
                self.reason = self._fault_reason()
            elif self.vin is not None and lift is not None and lift.ready \
                    and lift.t > self._lift_lost_at:
                # the loaded vehicle still at height, the lift read ready since it was last
                # silent: tracking again at once ("waiting for vehicle" until the next read
                # counted a car at the station as one awaited, at every controller link cut)
                self._to(State.TRACKING, StateReason(Because.TRACKING))
            else:
                self._to(State.WAITING_VEHICLE, StateReason(Because.RECOVERED))
        return acts
