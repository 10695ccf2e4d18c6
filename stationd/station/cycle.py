"""The tightening cycle as a pure state machine: events in, actions out.

The daemon feeds it events (lift state, localizations, controller answers, device faults) and
carries out the actions it returns (send parameters, enable or disable the tool, record).
Keeping the rules here, free of I/O, means every safety rule is testable on its own:

- parameters are sent only from TRACKING, for a bolt the matcher *took* (within tolerance,
  unambiguous, not done, stable for N fresh frames), only while the lift is ready;
- the tool is enabled only after the controller acknowledged that bolt's parameters;
- the tool is disabled when the wrench leaves the bolt before tightening, when the lift is not
  ready, on any fault, and after each result;
- a fault (with its reason) stops everything until the device reports back.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stationd.station.matching import BoltMatcher, Match


class State(enum.Enum):
    STARTING = "starting"
    WAITING_VEHICLE = "waiting for vehicle"
    TRACKING = "tracking"
    BOLT_SELECTED = "bolt selected"
    TIGHTENING = "tightening"
    FAULT = "fault"


@dataclass(frozen=True)
class SendParams:
    bolt: str


@dataclass(frozen=True)
class EnableTool:
    bolt: str


@dataclass(frozen=True)
class DisableTool:
    reason: str


@dataclass(frozen=True)
class Record:
    """Record ``result`` for ``bolt``; where the wrench was is the daemon's selection's."""

    bolt: str
    result: Any  # the controller's TighteningResult


@dataclass(frozen=True)
class Log:
    message: str


Action = SendParams | EnableTool | DisableTool | Record | Log


@dataclass
class Cycle:
    """One station's cycle; ``leave_frames`` localizations off the selected bolt (or refused)
    in a row mean the wrench left it."""

    matcher: BoltMatcher
    leave_frames: int = 3
    state: State = State.STARTING
    reason: str = "starting"
    bolt: str | None = None
    _last_match: Match | None = field(default=None, repr=False)
    _away: int = field(default=0, repr=False)

    @property
    def selected_match(self) -> Match | None:
        """The matcher's verdict that selected the current bolt (None without one)."""
        return self._last_match

    # -- events ----------------------------------------------------------------------------
    def started(self) -> list[Action]:
        return self._to(State.WAITING_VEHICLE, "waiting for the lift")

    def lift(self, ready: bool, why: str = "lift not at working height") -> list[Action]:
        if self.state is State.FAULT:
            return []
        if not ready:
            if self.state in (State.WAITING_VEHICLE, State.STARTING):
                self.reason = why
                return []
            return self._drop(State.WAITING_VEHICLE, why)
        if self.state in (State.WAITING_VEHICLE, State.STARTING):
            return self._to(State.TRACKING, "tracking the wrench")
        return []

    def localized(self, bolt_end_mm: np.ndarray | None, refusal: str | None = None,
                  age_s: float = 0.0) -> list[Action]:
        """A localization (bolt end in the vehicle frame), or why there is none."""
        if bolt_end_mm is None:
            m = self.matcher.refuse(refusal or "no localization")
        else:
            m = self.matcher.update(bolt_end_mm, age_s)
        if self.state is State.TRACKING:
            if m.bolt is None:
                return [Log(f"no bolt: {m.reason}")] if m.reason else []
            self.bolt, self._last_match, self._away = m.bolt, m, 0
            self.matcher.reset()
            self._to(State.BOLT_SELECTED, f"bolt {m.bolt} selected")
            return [SendParams(m.bolt)]
        if self.state in (State.BOLT_SELECTED, State.TIGHTENING):
            on_bolt = m.candidate == self.bolt
            self._away = 0 if on_bolt else self._away + 1
            if self._away >= self.leave_frames:
                return self._drop(State.TRACKING, f"wrench left bolt {self.bolt} "
                                  f"({m.reason or 'elsewhere'})")
        return []

    def params_acknowledged(self, bolt: str) -> list[Action]:
        if self.state is not State.BOLT_SELECTED or bolt != self.bolt:
            # a late acknowledgement for a bolt no longer selected: keep the tool off
            return [DisableTool(f"late acknowledgement for {bolt} ignored"),
                    Log(f"late acknowledgement for {bolt} ignored")]
        self._to(State.TIGHTENING, f"tightening bolt {bolt}")
        return [EnableTool(bolt)]

    def params_refused(self, bolt: str, reason: str) -> list[Action]:
        """A refusal is a fault with its reason; the bolt is then skipped for this vehicle
        (reported missing at the end) so that the same refused parameters are not sent again
        and again once the fault clears."""
        self.matcher.skipped[bolt] = f"controller refused its parameters ({reason})"
        return self.fault(f"controller refused the parameters for {bolt}: {reason}")

    def result(self, bolt: str, result: Any, ok: bool) -> list[Action]:
        if self.state is not State.TIGHTENING or bolt != self.bolt:
            # a late result (the trigger pulled as the wrench left): the bolt is tightened
            # all the same, and an OK one is done (never sent again, order rules move on)
            if ok:
                self.matcher.mark_done(bolt)
            return [Log(f"result for {bolt} outside a tightening: recorded, not matched"),
                    Record(bolt, result), DisableTool("unexpected result")]
        acts: list[Action] = [DisableTool(f"bolt {bolt} tightened"),
                              Record(bolt, result)]
        if ok:
            self.matcher.mark_done(bolt)
        self.bolt = None
        self._to(State.TRACKING, f"bolt {bolt} {'OK' if ok else 'NOK'}; tracking")
        return acts

    def fault(self, reason: str) -> list[Action]:
        acts = self._drop(State.FAULT, reason)
        return [*acts, Log(f"fault: {reason}")]

    def recovered(self) -> list[Action]:
        if self.state is not State.FAULT:
            return []
        return self._to(State.WAITING_VEHICLE, "recovered; waiting for the lift")

    # -- helpers ---------------------------------------------------------------------------
    def _to(self, state: State, reason: str) -> list[Action]:
        self.state, self.reason = state, reason
        return []

    def _drop(self, state: State, reason: str) -> list[Action]:
        """Leave a bolt: the tool goes off first, whatever happens next."""
        had_bolt = self.state in (State.BOLT_SELECTED, State.TIGHTENING)
        self.bolt, self._last_match, self._away = None, None, 0
        self.matcher.reset()
        self._to(state, reason)
        return [DisableTool(reason)] if had_bolt else []
