"""The station's decisions, pure: typed input events in, typed actions out.

The daemon only does I/O and timing: it reads the lift, grabs and localizes, talks to the
controller and the database, and feeds what happened to :meth:`StationCore.feed`; it carries out
the actions returned, in order, and feeds their outcome back (an acknowledgement, a refusal, a
fault).  Every rule lives here, so every rule is testable without a device, a clock or a thread:
time comes in with the events (``t``, ``time.time()`` scale; a localization also carries its
frames' *exposure* instant).

The rules are split by subject, each a layer of one class, the lowest first:
:mod:`~stationd.station.state` (the state and its shared transitions) <
:mod:`~stationd.station.teaching` (teach-in, the calibration check) <
:mod:`~stationd.station.faults` < :mod:`~stationd.station.orders` (commands) <
:mod:`~stationd.station.nok` (the NOK policy, entered outcomes) <
:mod:`~stationd.station.lost` (results heard late: lost pushes, link cuts) <
:mod:`~stationd.station.unread` (results not read) <
:mod:`~stationd.station.results` (results: which enable each answers); beside results,
also on faults, :mod:`~stationd.station.lift` (the vehicle and the lift) and
:mod:`~stationd.station.tool` (selection and the tool);
:class:`StationCore` puts them together and dispatches each input (:mod:`~stationd.station.inputs`)
to its handler, answering actions (:mod:`~stationd.station.actions`).

The safety rules, each enforced in exactly one place:

- parameters are sent only from TRACKING, for the bolt the matcher *took*, while the lift is
  ready, a vehicle is loaded (its VIN with the controller) and no device is in fault;
- the tool is enabled only after the controller acknowledged that bolt's parameters AND a
  localization from frames exposed after that acknowledgement still finds the wrench on it;
- the tool goes off at the first localization that does not confirm the bolt (stale, refused,
  elsewhere), when the lift is not ready, on any fault, and after each result; the selection
  itself is dropped after ``leave_frames`` such localizations in a row;
- every result is recorded once, to the bolt the tool was enabled for (also when it arrives
  within ``late_result_s`` after the tool went off: the trigger was pulled as the wrench left);
  any other result is acknowledged unrecorded (the controller keeps its own record);
- faults are kept per device; the station leaves FAULT when every faulty device is back;
- with reference markers configured, a bolt end is used only when every pair that made it is
  trusted: checked against the references since the start and since the vehicle arrived, and
  not moved (:mod:`stationd.station.trust`).
"""

from __future__ import annotations

from typing import assert_never

from stationd.station.actions import Action, Publish
from stationd.station.events import StateChanged, VehicleOpened
from stationd.station.inputs import (
    Announce,
    CaughtUp,
    CommandDone,
    CommandIn,
    DeviceBack,
    DeviceFault,
    DeviceSaid,
    Event,
    LiftRead,
    LineLinkIn,
    LocalizedIn,
    ModelsKnown,
    NewestChecked,
    NotStored,
    OperatorBack,
    ParamsAcked,
    ParamsRefused,
    ResultCopy,
    ResultIn,
    ResultsMissed,
    ResultsSkipped,
    Started,
    Tick,
    ToolOn,
    UnreadableIn,
    VehicleEnded,
    VehicleLoaded,
    VehicleRejected,
    VinSent,
    Written,
)
from stationd.station.lift import LiftRules
from stationd.station.results import ResultRules
from stationd.station.tool import ToolRules
from stationd.station.trust import ReferencesChecked


class StationCore(LiftRules, ToolRules, ResultRules):
    """One station's rules: every subject's handlers, one entry point (:meth:`feed`)."""

    # -- the one entry point ---------------------------------------------------------------
    def feed(self, ev: Event) -> list[Action]:
        """Everything that happened goes in here; what to do comes out, in order."""
        before = (self.state, self.reason)
        acts = self._dispatch(ev)
        acts += self._vin_due()
        acts += self._closing_settled(ev, acts)
        # the bolts as they are now, before the news that says why (a lock, a release, a
        # result): a screen draws a bolt's state from the core's, then takes the news's words
        at = next((i + 1 for i, a in enumerate(acts)     # (after the vehicle's opening)
                   if isinstance(a, Publish) and isinstance(a.event, VehicleOpened)), 0)
        acts[at:at] = self._bolts_changed(ev.t)
        if (self.state, self.reason) != before:  # first: follow-ups may change it again
            acts.insert(0, Publish(StateChanged(self.state, self.reason, t=ev.t)))
        return acts

    def _dispatch(self, ev: Event) -> list[Action]:
        """Each input to its handler, spelled out so that the type checker and a reader can
        follow it (an input of the Event union without a case fails the type check)."""
        match ev:
            case Started():
                return self._on_started(ev)
            case Announce():
                return self._on_announce(ev)
            case LiftRead():
                return self._on_lift_read(ev)
            case VehicleLoaded():
                return self._on_vehicle_loaded(ev)
            case VehicleRejected():
                return self._on_vehicle_rejected(ev)
            case LocalizedIn():
                return self._on_localized_in(ev)
            case ParamsAcked():
                return self._on_params_acked(ev)
            case ToolOn():
                return self._on_tool_on(ev)
            case Written():
                return self._on_written(ev)
            case VehicleEnded():
                return self._on_vehicle_ended(ev)
            case ParamsRefused():
                return self._on_params_refused(ev)
            case ResultIn():
                return self._on_result_in(ev)
            case ResultCopy():
                return self._on_result_copy(ev)
            case NewestChecked():
                return self._on_newest_checked(ev)
            case ResultsSkipped():
                return self._on_results_skipped(ev)
            case UnreadableIn():
                return self._on_unreadable_in(ev)
            case CaughtUp():
                return self._on_caught_up(ev)
            case ResultsMissed():
                return self._on_results_missed(ev)
            case NotStored():
                return self._on_not_stored(ev)
            case CommandIn():
                return self._on_command_in(ev)
            case CommandDone() if self._is_entered_outcome(ev):
                return self._on_entered_outcome_done(ev)
            case CommandDone():
                return self._on_command_done(ev)
            case DeviceFault():
                return self._on_device_fault(ev)
            case DeviceBack():
                return self._on_device_back(ev)
            case DeviceSaid():
                return self._on_device_said(ev)
            case LineLinkIn():
                return self._on_line_link(ev)
            case ModelsKnown():
                return self._on_models_known(ev)
            case VinSent():
                return self._on_vin_sent(ev)
            case Tick():
                return self._on_tick(ev)
            case OperatorBack():
                return self._on_operator_back(ev)
            case ReferencesChecked():
                return self._on_references_checked(ev)
        assert_never(ev)

    def _on_announce(self, ev: Announce) -> list[Action]:
        return [Publish(StateChanged(self.state, self.reason, t=ev.t))]

    def _on_tick(self, ev: Tick) -> list[Action]:
        return self._pending_overdue(ev.t) + self._check_overdue(ev.t) + \
            self._window_over(ev.t) + self._check_while_on(ev.t) + self._teach_overdue(ev.t) + \
            self._check_due(ev.t) + self._operator_idle(ev.t)
