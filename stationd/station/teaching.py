"""Teach-in and the calibration check: a bolt end taught from steady localizations, the
reference markers measured at the start, on a vehicle's arrival and when due, and which pairs'
localizations are trusted meanwhile.

The lowest of the subjects: the lift, the tool, the commands and the faults each start or
answer a teach or a check."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from stationd.reasons import Reason, Unchecked, UncheckedKind, Why
from stationd.station.actions import Action, Publish, Reply
from stationd.station.commands import (
    Answer,
    TeachPoint,
    TeachStart,
    TeachStop,
)
from stationd.station.events import (
    Because,
    Localized,
    Notice,
    PairChecked,
    PairsUnchecked,
    Said,
    State,
    StateReason,
)
from stationd.station.inputs import CommandIn, LocalizedIn, ModelsKnown
from stationd.station.state import ON_A_BOLT, CoreState, _Teach
from stationd.station.trust import (
    Asked,
    CheckAsked,
    MeasureReferences,
    RecordCheck,
    ReferencesChecked,
)
from stationd.station.trust import answer as check_answer

#: steady localizations averaged for one taught bolt, and how many may be tried for them
TEACH_FRAMES, TEACH_TRIES = 10, 60
#: a taught bolt end whose localizations spread farther than this was not held still, mm
TEACH_STEADY_MM = 2.0
#: a teach point is answered within this long, s, measured or not (``stationd teach`` waits
#: 15 s for an answer: past it, it could only blame the connection)
TEACH_WAIT_S = 10.0


class TeachRules(CoreState):
    """Teach-in and the calibration check."""

    def _on_models_known(self, ev: ModelsKnown) -> list[Action]:
        self.models = frozenset(ev.models)
        return []

    def _taught(self, ev: LocalizedIn, teach: _Teach) -> list[Action]:
        """Teach mode: fresh localizations of the bolt being measured are collected; after
        ``TEACH_FRAMES`` of them its mean and dispersion are the answer."""
        age = ev.t - ev.exposure_t
        acts: list[Action] = [Publish(Localized(ev.point_mm, ev.tilt_deg, ev.reason, None,
                                                None, age * 1e3, (), t=ev.t))]
        c = teach.measuring
        if c is None or self.faults:
            return acts
        if ev.exposure_t <= teach.since:
            return acts   # exposed before the engineer asked: the tool may have been moving
        teach.frames += 1
        if ev.point_mm is not None and age <= self.params.max_age_s:
            teach.points.append(ev.point_mm)
        else:
            teach.tries += 1
            teach.missed = ev.reason if ev.reason is not None else \
                Reason(Why.STALE, age_ms=age * 1e3, limit=self.params.max_age_s * 1e3)
        if len(teach.points) >= TEACH_FRAMES:
            p = np.asarray(teach.points, dtype=np.float64)
            mean = p.mean(axis=0)
            spread = float(np.linalg.norm(p - mean, axis=1).max())
            teach.measuring, teach.points, teach.tries, teach.missed = None, [], 0, None
            self.reason = teach.reason()
            if spread > TEACH_STEADY_MM:   # moved while measured: not a position
                return [*acts, Reply(Answer(c.request, c.command, c.issuer, Reason(
                    Why.NOT_STEADY, distance_mm=spread, limit=TEACH_STEADY_MM)))]
            # the matching tolerance: what the edges compare the taught bolt with CAD against
            result = {"position_mm": [float(v) for v in mean], "dispersion_mm": spread,
                      "frames": TEACH_FRAMES, "tolerance_mm": self.params.tolerance_mm}
            return [*acts, Reply(Answer(c.request, c.command, c.issuer, result=result))]
        if teach.tries >= TEACH_TRIES:
            why = Reason(Why.NOT_STEADY, count=len(teach.points), needed=TEACH_FRAMES,
                         cause=teach.missed, limit=teach.tries)
            teach.measuring, teach.points, teach.tries, teach.missed = None, [], 0, None
            self.reason = teach.reason()
            return [*acts, Reply(Answer(c.request, c.command, c.issuer, why))]
        return acts

    def _teach_refusal(self, cmd: TeachStart | TeachPoint | TeachStop) -> Reason | None:
        t = self._teach
        if isinstance(cmd, TeachStart):
            if t is not None:
                return t.refusal()
            if self.models is not None and cmd.model not in self.models:
                return Reason(Why.UNKNOWN_MODEL, note=cmd.model)
            if self.tool_on:
                return Reason(Why.TOOL_ON_BOLT, bolt=self.bolt)
            return None
        if t is None:
            return Reason(Why.NOT_TEACHING)
        if isinstance(cmd, TeachPoint) and t.measuring is not None:
            return t.refusal()
        if isinstance(cmd, TeachPoint) and self.faults:   # no frames would come: said now
            return self._fault_refusal()
        return None

    def _teach_done(self, t: float, c: CommandIn) -> list[Action]:
        """A recorded teach command takes effect: the mode on (the tool off, the selection
        dropped), a bolt's measuring started (answered once measured), or the mode off."""
        cmd = c.command
        if isinstance(cmd, TeachStart):
            acts = self._drop(t, State.TEACHING, StateReason(Because.TEACH_MODE))
            self._teach = _Teach(cmd.model, c.issuer.user)
            self._to(State.TEACHING, self._teach.reason())
            return [*acts, Reply(Answer(c.request, cmd, c.issuer))]
        if self._teach is None:
            return [Reply(Answer(c.request, cmd, c.issuer, Reason(Why.NOT_TEACHING)))]
        if isinstance(cmd, TeachPoint):
            self._teach.measuring, self._teach.points, self._teach.tries = c, [], 0
            self._teach.since, self._teach.frames = c.t, 0
            self.reason = self._teach.reason()
            return []
        self._teach = None
        if self.vin is not None and self._lift is not None and self._lift.ready:
            # the vehicle at height works on at once (a process engineer's trial: "teach mode
            # ended; waiting for the lift" with the car on the lift, until its next read)
            self._to(State.TRACKING, StateReason(Because.TEACH_ENDED_TRACKING))
        else:
            self._to(State.WAITING_VEHICLE, StateReason(Because.TEACH_ENDED))
        return [Reply(Answer(c.request, cmd, c.issuer))]

    def _teach_overdue(self, t: float) -> list[Action]:
        """A teach point not measured in :data:`TEACH_WAIT_S` is answered with what happened:
        no localization at all, or too few steady ones (the engineer is waiting)."""
        teach = self._teach
        if teach is None or teach.measuring is None or t - teach.since < TEACH_WAIT_S:
            return []
        why = Reason(Why.NO_FRAMES, limit=TEACH_WAIT_S) if teach.frames == 0 else \
            Reason(Why.NOT_STEADY, count=len(teach.points), needed=TEACH_FRAMES,
                   cause=teach.missed, limit=teach.tries)
        return self._teach_answered(teach, why)

    def _teach_answered(self, teach: _Teach, why: Reason) -> list[Action]:
        """The bolt being measured is answered with ``why`` (not taught); teach mode stays."""
        c = teach.measuring
        teach.measuring, teach.points, teach.tries, teach.frames = None, [], 0, 0
        teach.missed = None
        if c is None:
            return []
        if self.state is State.TEACHING:
            self.reason = teach.reason()
        return [Reply(Answer(c.request, c.command, c.issuer, why))]

    # -- the calibration check (the rules: stationd.station.trust) -------------------------
    def _measure(self, t: float, why: CheckAsked, request: int | None = None) -> list[Action]:
        assert self.trust is not None  # noqa: S101 - only called with references
        self.trust.asked(t)
        at_height = self._lift is not None and self._lift.at_height
        return [MeasureReferences(self.trust.pairs, at_height, why, request, t)]

    def _check_at_start(self, t: float) -> list[Action]:
        """No pair is trusted until checked: a check at once (without references: said)."""
        if self.trust is None:
            return [Publish(Notice(Said.NO_REFERENCES, t=t))]
        return [*self._unchecked(t), *self._measure(t, CheckAsked(Asked.STARTED))]

    def _check_on_arrival(self, t: float, vin: str) -> list[Action]:
        """A vehicle arrives: its pairs are trusted again only once checked for it."""
        if self.trust is None:
            return []
        self.trust.distrust(Unchecked(UncheckedKind.ARRIVAL, vin=vin), t)
        return [*self._unchecked(t), *self._measure(t, CheckAsked(Asked.ARRIVED, vin=vin))]

    def _unchecked(self, t: float) -> list[Action]:
        """The screens told which pairs wait for a check, and why."""
        assert self.trust is not None  # noqa: S101 - only called with references
        reasons = tuple(r for r in self.trust.why.values()
                        if r is not None and r.kind is Why.PAIR_UNCHECKED)
        return [Publish(PairsUnchecked(reasons, t=t))] if reasons else []

    def _check_due(self, t: float) -> list[Action]:
        if self.trust is None or self.state is State.STARTING:
            return []
        idle = not self.tool_on and self.state not in ON_A_BOLT and self._teach is None
        if self.trust.due(t, idle=idle, vehicle=self.vin is not None):
            return self._measure(t, CheckAsked(Asked.PERIODIC))
        return []

    def _check_asked(self, t: float, c: CommandIn) -> list[Action]:
        """A person asked for a check (recorded): measured now, answered with the verdicts."""
        assert self.trust is not None  # noqa: S101 - refused without references
        self.trust.requests.append(c.request)
        self._commands[c.request] = c   # kept for the answer
        return self._measure(t, CheckAsked(Asked.COMMAND, user=c.issuer.user), c.request)

    def _trusted(self, ev: LocalizedIn) -> LocalizedIn:
        """A bolt end made by a pair that is not trusted is a refusal with that pair's reason
        (the localization leaves such pairs out already: this is the rule itself)."""
        if self.trust is None or ev.point_mm is None:
            return ev
        why = self.trust.refusal(ev.pairs)
        return ev if why is None else replace(ev, point_mm=None, reason=why)

    def _on_references_checked(self, ev: ReferencesChecked) -> list[Action]:
        if self.trust is None:
            return []
        acts: list[Action] = []
        for check, before, after in self.trust.answered(ev.t, ev.checks, ev.asked_t):
            acts.append(Publish(PairChecked(
                check.pair, check.verdict.value, check.reference, check.offset_mm,
                check.tolerance_mm, {m.name: m.offset_mm for m in check.measures},
                after is None, after, t=ev.t)))
            acts.append(RecordCheck(check, ev.t))
            if after is not None and self.bolt is not None and self.tool_on \
                    and before is None:
                # the tool stays on only on a confirmed bolt: the next localization decides,
                # and one made by this pair is refused now
                acts.append(Publish(Notice(Said.PAIR_DISTRUSTED, pair=check.pair,
                                           bolt=self.bolt, t=ev.t)))
        waiting = [ev.request] if ev.request is not None else []
        for request in waiting:
            if request in self.trust.requests:
                self.trust.requests.remove(request)
            c = self._commands.pop(request, None)
            if c is not None:
                acts.append(Reply(Answer(request, c.command, c.issuer,
                                         result=check_answer(ev.checks))))
        return acts
