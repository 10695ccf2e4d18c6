"""Selection and the tool: a localization selects a bolt, its parameters are sent, the tool
is enabled only once a localization exposed after the acknowledgement still finds the wrench
on that bolt, and off at the first one that does not."""

from __future__ import annotations

import numpy as np

from db.bolts import Parameters
from drivers.keeper import FaultKind
from stationd.reasons import CoreFault, CoreFaultKind, Reason, Skip, SkipKind, Why
from stationd.station.actions import (
    Action,
    CheckNewest,
    EnableTool,
    Publish,
    Selection,
    SendParams,
    torque_window,
)
from stationd.station.events import (
    Because,
    BoltSelected,
    BoltSkipped,
    Localized,
    Notice,
    ParamsRefusedEvent,
    ParamsSent,
    Refused,
    Said,
    State,
    StateReason,
    ToolEnabled,
)
from stationd.station.faults import FaultRules
from stationd.station.inputs import WRENCH, LocalizedIn, ParamsAcked, ParamsRefused, ToolOn
from stationd.station.matching import Match
from stationd.station.state import LOCALIZING, LOOSEN_TARGETS, _disable


class ToolRules(FaultRules):
    """Selection and the tool: parameters sent, the tool enabled only on a confirmed bolt."""

    def _on_localized_in(self, ev: LocalizedIn) -> list[Action]:
        ev = self._trusted(ev)
        if self._teach is not None:
            return self._taught(ev, self._teach)
        if self.state not in LOCALIZING or self.matcher is None:
            return []
        if self.state is State.TRACKING and ev.exposure_t <= self._not_before:
            return []   # exposed before the last rundown ended: where the wrench *was*
        age = ev.t - ev.exposure_t
        m = self.matcher.update(np.asarray(ev.point_mm), age) if ev.point_mm is not None \
            else self.matcher.refuse(ev.reason or Reason(Why.NOT_LOCALIZED))
        acts: list[Action] = [Publish(Localized(
            ev.point_mm, ev.tilt_deg if ev.point_mm is not None else None, m.reason,
            m.candidate, m.distance_mm, age * 1e3, self.allowed(), t=ev.t))]
        if self.state is State.TRACKING:
            return acts + self._track(ev, m)
        on_bolt = m.candidate == self.bolt and age <= self.params.max_age_s
        if on_bolt:
            self._away = 0
            if self.state is State.BOLT_SELECTED and self._acked_at is not None \
                    and ev.exposure_t > self._acked_at and self.bolt is not None:
                sel = self._selection
                assert sel is not None  # noqa: S101 - a bolt is selected
                # (also of a car that left: a reviewer); and while the catch-up that proved
                # a cut's rundown still fetches (a rundown made after it may hold that bolt:
                # a reviewer, the tool went on for the retry and it was run down twice)
                cut = self._cut or (self._cut_closed[0] if self._cut_closed else None)
                if cut is not None:
                    self.reason = StateReason(Because.CUT_OWED, bolt=self.bolt,
                                              owed=self._named(cut.selection))
                    return acts
                acts += self._window_over(ev.t)
                owed = self._owed_elsewhere(ev.t)
                if owed is not None:
                    self.reason = StateReason(Because.RESULT_OWED, bolt=self.bolt, owed=owed)
                    return acts
                self._to(State.TIGHTENING, StateReason(Because.TIGHTENING, bolt=self.bolt,
                                                       loosen=sel.loosen))
                self._unanswered_before(sel)
                self.tool_on, self._enabled, self._off_at = True, sel, None
                self._enable_serial += 1
                self._off_before_enable = self._last_off_at
                self._same_bolt_before = self._last_enabled_bolt == (sel.vin, sel.bolt)
                self._last_enabled_bolt = (sel.vin, sel.bolt)
                self._enabled_at = ev.t
                acts.append(EnableTool(self.bolt, sel))
            return acts
        self._away += 1
        # why not on it: the refusal, or the bolt it is on instead (a reason of its own kind)
        why = m.reason or Reason(Why.ELSEWHERE, bolt=m.candidate)
        if self.tool_on:
            acts += self._tool_off(ev.t, StateReason(Because.NOT_CONFIRMED, bolt=self.bolt), why)
            self._to(State.BOLT_SELECTED,
                     StateReason(Because.SELECTED_UNCONFIRMED, bolt=self.bolt))
        if self._away >= self.leave_frames:
            acts += self._drop(ev.t, State.TRACKING,
                               StateReason(Because.WRENCH_LEFT, bolt=self.bolt), why)
        return acts

    def _track(self, ev: LocalizedIn, m: Match) -> list[Action]:
        assert self.matcher is not None  # noqa: S101 - tracking has a vehicle
        if m.bolt is None:
            # once per change of kind and bolts: "stale (812 ms)" and "(790 ms)" are one
            if m.reason is not None and m.reason.key() != self._last_refusal:
                self._last_refusal = m.reason.key()
                return [Publish(Refused(m.reason, m.candidate, t=ev.t))]
            return []
        ready = self._lift is not None and self._lift.ready
        if self.faults or not ready or self.vin is None \
                or self._vin_for != (self.vin, self._wrench_epoch) or ev.point_mm is None:
            self.matcher.reset()   # never reached: TRACKING implies all of these; belt and braces
            return []
        if self.operator_required and self.operator is None:
            # the station requires an operator: nothing is sent for anybody's tool (the
            # streak is kept: a sign-in selects at the next frame of a wrench held still)
            why = Reason(Why.SIGN_IN, bolt=m.bolt)
            if why.key() != self._last_refusal:
                self._last_refusal = why.key()
                return [Publish(Refused(why, m.bolt, t=ev.t))]
            return []
        spec = self._specs[m.bolt]
        pset, params, loosen = spec.pset, spec.parameters, m.bolt in self._loosen
        if loosen:   # the loosen strategy: its loosen pset, never the tightening one, first
            pset = self.nok.rule(m.bolt, spec.pset).loosen_pset
            if pset is None:    # never: a bolt is to loosen only with a loosen pset
                self.matcher.reset()
                return []
            params = Parameters(pset, LOOSEN_TARGETS)
        sel = Selection(m.bolt, pset, ev.point_mm, ev.tilt_deg, float(m.distance_mm or 0.0),
                        ev.exposure_t, ev.t, ev.evidence, self.vin, spec.parameters_id, loosen,
                        self.operator, torque_window(spec.parameters))
        self._operator_seen = ev.t
        self.bolt, self._selection, self._acked_at, self._away = m.bolt, sel, None, 0
        self._last_refusal = None
        self.matcher.reset()
        self._to(State.BOLT_SELECTED,
                 StateReason(Because.SELECTED, bolt=m.bolt, pset=pset, loosen=loosen))
        return [Publish(BoltSelected(m.bolt, pset, ev.point_mm, sel.distance_mm,
                                     ev.tilt_deg, loosen, t=ev.t)),
                SendParams(m.bolt, sel, params, loosen)]

    # A link cut during an enable (``_cut``) keeps the tool off for every bolt, its own
    # included, until the catch-up has ended it (:meth:`_on_caught_up`): that bolt may have
    # been tightened meanwhile, and its result, fetched later, is placed only by the
    # controller's data -- an enable made before it comes would take it, or tighten the bolt
    # twice.

    def _window_over(self, t: float) -> list[Action]:
        """The owed enable's late-result window is over (at the first tick or localization
        after it: a trial found the next bolt's tool on 30 ms after the window's end, before
        the tick that was to check): with no result, it is unanswered and the controller is
        asked for its newest (its push lost?); the enable stays owed until the answer
        (:class:`~stationd.station.inputs.NewestChecked`), and no tool goes on meanwhile."""
        if self._off_at is None or t - self._off_at < self.late_result_s \
                or self._pending_push is not None or self._checking is not None:
            return []
        if self._unanswered_after():
            self._checking, self._checking_on = (t, self._enable_serial), False
            return [CheckNewest(self._enable_serial)]
        self._enabled, self._off_at = None, None
        return []

    def _check_while_on(self, t: float) -> list[Action]:
        """The tool on for :data:`~stationd.station.state.CHECK_ON_S` (since the enable or
        the last such check) and its enable without a result: the controller is asked for its
        newest (:class:`CheckNewest` ``tool_on``).  A rundown whose push was lost (a new-user
        trial: the tool stayed on, the NOK bolt run down again without its loosening) is
        fetched, recorded to the bolt as made under this enable (:meth:`_made_under`) and the
        tool goes off as for a pushed result.  Not while another check, a pushed result
        waited for, a link cut's enable or a wrench fault: one at a time, never more often."""
        en, since = self._enabled, self._enabled_at
        if self.check_on_s is None or not self.tool_on or en is None or since is None \
                or self._checking is not None or self._pending_push is not None \
                or self._cut is not None or WRENCH in self.faults \
                or t - max(since, self._checked_on_at) < self.check_on_s:
            return []
        self._checking, self._checking_on = (t, self._enable_serial), True
        self._checked_on_at = t
        return [CheckNewest(self._enable_serial, tool_on=True)]

    def _owed_elsewhere(self, t: float) -> str | None:
        """The bolt whose result may still come (its tool went off less than the late-result
        window ago, and its result is not in) where it is another bolt than the one selected;
        else None.  The tool is not enabled for the selected bolt meanwhile: a result is
        placed by the enable it came under, and a late one of that bolt would otherwise be
        taken for this one's (the same pset), or lost to its own (another pset).  The same
        across vehicles: the last car's bolt, its result owed as that car left, named with
        its VIN."""
        en = self._enabled
        if en is not None and self._checking is not None:
            return self._named(en)   # (its own bolt too: what the check finds is that one's)
        if en is None or not self._result_owed(t) or (
                (en.vin, en.bolt) == (self.vin, self.bolt) and self._pending_push is None):
            return None     # (its own bolt too while results skipped are fetched)
        return self._named(en)

    def _named(self, sel: Selection) -> str:
        """The bolt of ``sel`` as the state's reason names it: with its VIN where that is not
        the vehicle at the station (the last car's, as it left)."""
        return sel.bolt if sel.vin == self.vin else f"{sel.bolt} of {sel.vin}"

    def _on_params_acked(self, ev: ParamsAcked) -> list[Action]:
        acts: list[Action] = [Publish(ParamsSent(ev.bolt, ev.pset, dict(ev.latency_ms),
                                                 t=ev.t))]
        if self.state is State.BOLT_SELECTED and ev.bolt == self.bolt and self._acked_at is None:
            self._acked_at = ev.t   # the tool waits for a frame exposed after this
            self.reason = StateReason(Because.ACKNOWLEDGED, bolt=ev.bolt)
            return acts
        return [*acts, *_disable(StateReason(Because.LATE_ACK, bolt=ev.bolt), ev.bolt, t=ev.t),
                Publish(Notice(Said.LATE_ACK, bolt=ev.bolt, t=ev.t))]

    def _on_tool_on(self, ev: ToolOn) -> list[Action]:
        return [Publish(ToolEnabled(ev.bolt, t=ev.t))]

    def _on_params_refused(self, ev: ParamsRefused) -> list[Action]:
        """The bolt is skipped for this vehicle (reported missing) so that the same refused
        parameters are not sent again and again; the controller is in fault until it answers.
        Both typed, with the controller's own words (:mod:`stationd.words` says them)."""
        why = Skip(SkipKind.REFUSED, reason=ev.reason)
        acts: list[Action] = [Publish(ParamsRefusedEvent(ev.bolt, ev.reason, t=ev.t))]
        if self.matcher is not None and ev.bolt in self.matcher.bolts:
            self.matcher.skipped[ev.bolt] = why
            acts.append(Publish(BoltSkipped(ev.bolt, skip=why, t=ev.t)))
        return acts + self._fault(ev.t, WRENCH, FaultKind.REFUSED, CoreFault(
            CoreFaultKind.PARAMS_REFUSED, bolt=ev.bolt, note=ev.reason))
