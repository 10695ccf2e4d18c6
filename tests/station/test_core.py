"""The pure station core: every rule on fakes, no device, no clock.

A small driver plays the daemon (answers vehicle loads and VIN sends at once) and keeps the
truth (where the wrench is, what the lift says, which devices are down, what the tool is);
hypothesis feeds it hundreds of random event sequences and the safety invariants are checked
after every event."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.keeper import FaultKind
from stationd.reasons import (
    CoreFault,
    CoreFaultKind,
    Reason,
    Skip,
    SkipKind,
    Unattributed,
    UnattributedKind,
    Why,
)
from stationd.station.actions import (
    Acknowledge,
    CheckNewest,
    CloseVehicle,
    DisableTool,
    EnableTool,
    LoadVehicle,
    Owed,
    Publish,
    Record,
    RecordCommand,
    Selection,
    SendParams,
    SendVin,
    StoreUnattributed,
)
from stationd.station.core import StationCore
from stationd.station.events import (
    Because,
    BoltsChanged,
    BoltSkipped,
    BoltView,
    DeviceHealth,
    Notice,
    OperatorChanged,
    Refused,
    ResultUnattributed,
    Said,
    State,
    StateChanged,
    StateReason,
    ToolDisabled,
    VehicleOpened,
)
from stationd.station.inputs import (
    DATABASE,
    Announce,
    CaughtUp,
    CommandDone,
    CommandIn,
    DeviceBack,
    DeviceFault,
    LiftRead,
    LoadedBolt,
    LocalizedIn,
    NewestChecked,
    ParamsAcked,
    ParamsRefused,
    ResultIn,
    ResultsSkipped,
    Started,
    Tick,
    VehicleLoaded,
    VehicleRejected,
    VinSent,
)
from stationd.station.matching import MatchParams
from stationd.station.state import LATE_RESULT_S
from stationd.words import fault_words, reason_words, state_words, unattributed_words
from tests.rundowns import rundown

BOLTS = {"B1": LoadedBolt((0.0, 0.0, 0.0), 1), "B2": LoadedBolt((60.0, 0.0, 0.0), 2),
         "B3": LoadedBolt((0.0, 60.0, 5.0), 1)}
PARAMS = MatchParams(tolerance_mm=8.0, margin_mm=6.0, stable_frames=2, max_age_s=0.5)


def result(tid: int, pset: int, ok: bool = True) -> Any:
    return rundown(tid, pset, ok)


@dataclass
class Driver:
    """Plays the daemon around a core and checks the invariants on every answer."""

    core: StationCore = field(default_factory=lambda: StationCore(PARAMS, leave_frames=2))
    t: float = 1000.0
    bolts: Mapping[str, LoadedBolt] = field(default_factory=lambda: BOLTS)  # each vehicle's
    ready: bool = False
    at_height: bool = False
    down: set[str] = field(default_factory=set)
    where: str | None = None          # the bolt the wrench is really on (None: none)
    fresh: bool = True                # the last localization's frames were fresh
    tool: bool = False
    tool_bolt: str | None = None
    tool_vin: str | None = None
    pending: str | None = None        # parameters sent, not yet answered
    acked: dict[str, float] = field(default_factory=dict)  # bolt -> ack instant
    sends: list[str] = field(default_factory=list)
    records: dict[int, str] = field(default_factory=dict)
    typed: tuple[str | None, str | None] | None = None   # a typed copy said: its record
    closed_vins: set[str] = field(default_factory=set)
    vin_seq: int = 0
    reconnects: int = 0               # the controller's connections so far (DeviceBack's)
    catching: int | None = None       # the connection whose catch-up has not ended yet
    ids: int = 10_000                 # the last tightening id of the "lost" steps
    #: the shell's check of the controller's newest answers at once, having found nothing
    #: more (False: the test answers it, with what the controller had)
    answer_checks: bool = True
    log: list[Any] = field(default_factory=list)
    #: the loaded vehicle's bolts as a screen holds them: its opening, then the core's
    #: changes (BoltsChanged), folded
    shown: dict[str, BoltView] = field(default_factory=dict)

    def feed(self, ev: Any) -> list[Any]:
        before = self.core.state
        acts = self.core.feed(ev)
        self.log.append((ev, acts))
        self.follow(acts)
        out = list(acts)
        for a in acts:
            self.check(a, before, ev)
            if isinstance(a, LoadVehicle):
                vin = a.vin
                if vin in self.closed_vins and not a.reopen:
                    out += self.feed(VehicleRejected(self.t, vin, "closed", closed=True))
                else:
                    self.closed_vins.discard(vin)
                    out += self.feed(VehicleLoaded(self.t, vin, "M", self.bolts,
                                                   rework=a.reopen))
            elif isinstance(a, SendVin):
                out += self.feed(VinSent(self.t, a.vin))
            elif isinstance(a, CloseVehicle):
                self.closed_vins.add(a.vin)
            elif isinstance(a, CheckNewest) and self.answer_checks:
                out += self.feed(NewestChecked(self.t))
        return out

    def alone(self, ev: Any) -> list[Any]:
        """``ev`` to the core alone: its actions, none carried out (a test looks at them),
        the screen following what it published."""
        acts = self.core.feed(ev)
        self.follow(acts)
        return acts

    def follow(self, acts: list[Any]) -> None:
        """A screen follows the core's bolts by its deltas alone: after every input, what it
        holds is what the core's snapshot says (the core the one writer of a bolt's state)."""
        for e in published(acts, VehicleOpened):
            self.shown = {v.bolt: v for v in e.bolts}
        for e in published(acts, BoltsChanged):
            assert e.vin == self.core.vin and e.bolts, e
            self.shown.update({v.bolt: v for v in e.bolts})
        if self.core.vin is not None:
            now = {v.bolt: v for v in self.core.bolt_views()}   # made afresh
            assert self.shown == now == {v.bolt: v for v in self.core.status().bolts}

    def command(self, request: int, cmd: Any, who: Any) -> list[Any]:
        """``cmd`` given by ``who``; when accepted, recorded (the shell's CommandDone, which
        makes it effective and answers it): the actions of both."""
        acts = self.feed(CommandIn(self.t, request, cmd, who))
        if any(isinstance(a, RecordCommand) for a in acts):
            acts += self.feed(CommandDone(self.t, request))
        return acts

    def check(self, a: Any, before: State, ev: Any) -> None:
        c = self.core
        if isinstance(a, SendParams):
            assert isinstance(ev, LocalizedIn) and before is State.TRACKING
            assert self.ready and not self.down and self.fresh
            assert a.bolt == self.where, (a.bolt, self.where)   # only where the wrench is
            assert ev.t - ev.exposure_t <= PARAMS.max_age_s
            self.pending = a.bolt   # a send before the last one's answer supersedes it
            self.sends.append(a.bolt)
        elif isinstance(a, EnableTool):
            assert isinstance(ev, LocalizedIn), ev        # only a localization enables
            assert a.bolt == self.where == c.bolt and self.fresh
            assert a.bolt in self.acked and ev.exposure_t > self.acked[a.bolt]
            assert self.ready and not self.down
            assert c._cut is None, "the tool enabled while a link cut's result is owed"
            self.tool, self.tool_bolt, self.tool_vin = True, a.bolt, c.vin
        elif isinstance(a, DisableTool):
            self.tool = False
        elif isinstance(a, Publish) and isinstance(a.event, Notice) \
                and a.event.said is Said.TYPED_COPY:
            # its record follows: to the bolt of the enable its untyped copy was fetched for
            # (held then), by the result's own time (ResultRules._typed_copy)
            self.typed = (c.vin, a.event.bolt)
        elif isinstance(a, Record):
            tid = int(a.result.tightening_id)
            assert tid not in self.records, "a result recorded twice"
            # to the bolt the tool was last enabled for, of the vehicle it was enabled on;
            # or that of an earlier enable, said as a typed copy just before
            if (a.vin, a.bolt) != self.typed:
                assert (a.vin, a.bolt) == (self.tool_vin, self.tool_bolt), \
                    (a.vin, a.bolt, self.tool_vin, self.tool_bolt)
            self.typed = None
            self.records[tid] = a.bolt

    # -- the operations hypothesis draws ------------------------------------------------------
    def step(self, op: tuple[Any, ...]) -> None:
        kind = op[0]
        self.t += op[1]
        if kind == "lift":
            self.ready, self.at_height = op[2] and op[3], op[3]
            if op[3] and op[4] is not None:
                self.vin_seq += 1
            if "lift" not in self.down:
                self.feed(LiftRead(self.t, self.ready, self.at_height, 7, op[4]))
        elif kind == "loc":
            for k in range(op[5] if len(op) > 5 else 1):   # the wrench stays a few frames
                self.t += 0.1 * bool(k)
                self.loc(op[2], op[3], op[4])
        elif kind == "ack" and self.pending is not None:
            bolt, self.pending = self.pending, None
            if op[2]:
                self.acked[bolt] = self.t
                self.feed(ParamsAcked(self.t, bolt))
            else:
                self.feed(ParamsRefused(self.t, bolt, "pset unknown"))
        elif kind == "result":
            tid = op[3] if op[4] else 100 + len(self.log)
            pset = BOLTS[self.tool_bolt].pset if self.tool_bolt and op[2] else 9
            self.feed(ResultIn(self.t, result(tid, pset or 0, op[5])))
        elif kind == "fault":
            self.down.add(op[2])
            self.feed(DeviceFault(self.t, op[2], FaultKind.DOWN, f"{op[2]} gone"))
            assert self.core.state is State.FAULT and not self.tool
        elif kind == "back" and self.down:
            device = sorted(self.down)[op[3] % len(self.down)]
            self.down.discard(device)
            if device != "wrench":
                self.feed(DeviceBack(self.t, device, reconnects=op[3]))
            else:
                self.reconnects += 1
                self.feed(DeviceBack(self.t, device, reconnects=self.reconnects))
                # the shell's catch-up then ends (complete now and then not: a refusal), at
                # once or later (a "caught" step: the station goes on meanwhile)
                self.catching = self.reconnects
                if op[3] != 1:
                    self.step(("caught", 0.0, op[3] != 2))
        elif kind == "caught" and self.catching is not None:
            self.feed(CaughtUp(self.t, op[2], "refused", self.catching))
            self.catching = None
        elif kind == "lost":
            # a pushed result skips the id before it (its push lost, the link up): the core is
            # told, the one skipped fetched and fed (made ``op[3]`` s ago), then the pushed one
            self.ids += 2
            pset = BOLTS[self.tool_bolt].pset if self.tool_bolt and op[2] else 9
            self.feed(ResultsSkipped(self.t, self.ids))
            self.feed(ResultIn(self.t, result(self.ids - 1, pset or 0, op[4]), fetched=True,
                               follows=self.ids - 2, made_at=self.t - op[3], live=True,
                               before=self.ids))
            self.feed(ResultIn(self.t, result(self.ids, pset or 0, not op[4])))
        elif kind == "tick":
            self.feed(Tick(self.t))
        if self.down:
            assert self.core.state is State.FAULT

    def loc(self, target: int, age: float, noise: float) -> None:
        """The wrench moves to bolt ``target`` (0: none, 4: between two bolts) and is seen
        by frames exposed ``age`` s ago."""
        names = list(BOLTS)
        if target == 5:      # stays where it is
            target = 0 if self.where is None else names.index(self.where) + 1
        if target == 0:
            p, self.where = None, None
        elif target == 4:
            p, self.where = (30.0, 0.0, 0.0), None
        else:
            self.where = names[target - 1]
            pos = BOLTS[self.where].position
            p = (pos[0] + noise, pos[1] - noise, pos[2])
        self.fresh = age <= PARAMS.max_age_s
        had = self.tool
        self.feed(LocalizedIn(self.t, self.t - age, p, None if p else Reason(
            Why.NOT_LOCALIZED, note="marker not found")))
        if had and not (self.fresh and self.where == self.tool_bolt):
            assert not self.tool, "tool still on a localization after leaving the bolt"
        if self.tool:
            assert self.where == self.tool_bolt and self.fresh


KINDS = ["lift"] * 2 + ["loc"] * 8 + ["ack"] * 2 + ["result"] * 2 + ["fault", "back", "tick",
                                                                    "caught", "lost"]
RAW = st.tuples(st.sampled_from(KINDS), st.sampled_from([0.02, 0.05, 0.1, 0.2, 0.3]),
                st.sampled_from(range(256)), st.sampled_from([-3.0, -1.0, 0.0, 0.5, 2.0, 4.0]),
                st.sampled_from([0.05, 0.05, 0.1, 0.3, 0.6, 2.0]), st.sampled_from([1, 2, 3, 4]))


def decode(raw: tuple[Any, ...]) -> tuple[Any, ...]:
    """A drawn tuple as one of :meth:`Driver.step`'s operations (biased towards a working
    station, so that selections, enables and results happen often)."""
    kind, dt, n, noise, age, rep = raw
    if kind == "lift":
        return ("lift", dt, n % 4 != 0, n % 8 != 1, ["VIN1", "VIN1", "VIN2", None][n // 64])
    if kind == "loc":
        return ("loc", dt, [0, 1, 2, 3, 4, 5, 5, 5][n % 8], age, noise, rep)
    if kind == "ack":
        return ("ack", dt, n % 5 != 0)
    if kind == "result":
        return ("result", dt * (1 + 20 * (n % 3 == 0)), n % 4 != 0, 1 + n % 3, n % 5 == 0,
                n % 7 != 0)
    if kind == "fault":
        return ("fault", dt, ["lift", "wrench", "pair1", "database"][n % 4])
    if kind == "caught":
        return ("caught", dt, n % 3 != 0)
    if kind == "lost":
        return ("lost", dt * 30, n % 4 != 0, [0.5, 1.0, 3.0, 30.0][n % 4], n % 3 != 0)
    if kind == "back":
        return ("back", dt, "", n % 3)
    return ("tick", dt * 20)


OPS = RAW.map(decode)


def seeded_steps(rng: np.random.Generator, kinds: list[str], weights: np.ndarray,
                 n: int) -> list[tuple[Any, ...]]:
    """``n`` raw steps of a seeded walk (kinds by ``weights``, then :func:`decode`'s fields),
    drawn at once: one numpy draw per step and field was most of the walks' time."""
    return list(zip([kinds[k] for k in rng.choice(len(kinds), n, p=weights)],
                    rng.choice([0.02, 0.1, 0.2], n).tolist(),
                    rng.integers(256, size=n).tolist(), rng.normal(0, 1.5, n).tolist(),
                    rng.choice([0.05, 0.05, 0.1, 0.3, 0.6], n).tolist(),
                    rng.integers(1, 5, size=n).tolist(), strict=True))


@settings(max_examples=300, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(OPS, min_size=5, max_size=80))
def test_random_event_sequences_keep_the_safety_invariants(ops):
    d = Driver()
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VIN1"))
    for op in ops:
        d.step(op)


def test_seeded_random_walks_keep_the_safety_invariants_and_get_work_done():
    """Hundreds of longer walks with a realistic mix (numpy, seeded): the invariants hold and
    the walks really select, enable and record (else the invariants were checked on nothing)."""
    rng = np.random.default_rng(12)
    kinds = ["lift", "loc", "ack", "result", "fault", "back", "tick", "caught", "lost"]
    weights = np.array([0.04, 0.58, 0.15, 0.09, 0.02, 0.06, 0.03, 0.01, 0.02])
    totals: dict[str, int] = {"send": 0, "enable": 0, "record": 0}
    for _ in range(300):
        d = Driver()
        d.feed(Started(d.t))
        d.step(("lift", 0.1, True, True, "VIN1"))
        for raw in seeded_steps(rng, kinds, weights, 60):
            d.step(decode(raw))
        totals["send"] += len(d.sends)
        totals["record"] += len(d.records)
        totals["enable"] += sum(isinstance(a, EnableTool) for _, acts in d.log for a in acts)
    assert min(totals.values()) > 30, totals


@settings(max_examples=150, derandomize=True, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 3), st.floats(0.0, 0.2), st.floats(-3, 3)),
                min_size=1, max_size=40), st.integers(1, 3))
def test_a_busy_operator_gets_bolts_tightened_and_every_result_recorded(places, shots):
    """Mostly good conditions: the invariants hold and results land on their bolts."""
    d = Driver()
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VINX"))
    for target, age, noise in places:
        for _ in range(4):
            d.step(("loc", 0.1, target, age, noise))
            d.step(("ack", 0.01, True))
        for _ in range(shots):
            d.step(("result", 0.05, True, 1, False, True))
    assert set(d.records.values()) <= set(d.sends)


# -- the rules one by one -----------------------------------------------------------------------
def _ready(vin: str = "VIN1", **core: Any) -> Driver:
    """A driver tracking at height with ``vin`` loaded; ``core`` go to its StationCore."""
    d = Driver(core=StationCore(PARAMS, leave_frames=2, **core))
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, vin))
    assert d.core.state is State.TRACKING and d.core.vin == vin
    return d


def _on(d: Driver, bolt: int, n: int = 2, age: float = 0.05) -> None:
    for _ in range(n):
        d.step(("loc", 0.1, bolt, age, 0.3))


def _kinds(acts: list[Any]) -> list[str]:
    return [type(a).__name__ for a in acts if not isinstance(a, Publish)]


def published(acts: list[Any], kind: type) -> list[Any]:
    """The events of type ``kind`` the core published among ``acts``."""
    return [a.event for a in acts if isinstance(a, Publish) and isinstance(a.event, kind)]


def test_the_state_s_reason_and_the_tool_s_are_kinds_with_their_fields():
    """Why the station is in its state, and why the tool went off, are told typed (the words
    are :func:`stationd.words.state_words`'): a start, the lift, a vehicle, a bolt selected,
    acknowledged, tightened and its result; another one the wrench leaves; a fault, back."""
    d = Driver()
    assert d.core.status().reason == StateReason(Because.OPENING)
    d.feed(Started(d.t))
    d.step(("lift", 0.1, False, False, None))
    d.step(("lift", 0.1, True, True, "VIN1"))
    _on(d, 1)
    d.step(("ack", 0.1, True))
    _on(d, 1, 1)
    d.step(("result", 0.1, True, 500, True, True))
    _on(d, 2)
    d.step(("ack", 0.1, True))
    _on(d, 2, 1)
    _on(d, 0, 2)                                       # out of view: the tool off, then left
    d.step(("fault", 0.1, "lift"))
    d.step(("back", 0.1, "", 0))
    told = [e for _, acts in d.log for e in published(acts, StateChanged)]
    assert [(e.state, e.reason) for e in told] == [
        (State.WAITING_VEHICLE, StateReason(Because.WAITING_LIFT)),
        (State.WAITING_VEHICLE, StateReason(Because.LIFT_NOT_READY,
                                            note="lift not at working height")),
        (State.WAITING_VEHICLE, StateReason(Because.LOADING, vin="VIN1")),
        (State.TRACKING, StateReason(Because.TRACKING)),
        (State.BOLT_SELECTED, StateReason(Because.SELECTED, bolt="B1", pset=1)),
        (State.BOLT_SELECTED, StateReason(Because.ACKNOWLEDGED, bolt="B1")),
        (State.TIGHTENING, StateReason(Because.TIGHTENING, bolt="B1")),
        (State.TRACKING, StateReason(Because.RESULT, bolt="B1", ok=True)),
        (State.BOLT_SELECTED, StateReason(Because.SELECTED, bolt="B2", pset=2)),
        (State.BOLT_SELECTED, StateReason(Because.ACKNOWLEDGED, bolt="B2")),
        (State.TIGHTENING, StateReason(Because.TIGHTENING, bolt="B2")),
        (State.BOLT_SELECTED, StateReason(Because.SELECTED_UNCONFIRMED, bolt="B2")),
        (State.TRACKING, StateReason(Because.WRENCH_LEFT, bolt="B2")),
        (State.FAULT, StateReason(Because.FAULT, faults=(("lift", "lift gone"),))),
        (State.WAITING_VEHICLE, StateReason(Because.RECOVERED)),
    ]
    off = [(e.reason, e.bolt, e.why is not None) for _, acts in d.log
           for e in published(acts, ToolDisabled)]
    assert off == [(StateReason(Because.STARTED), None, False),
                   (StateReason(Because.RUNDOWN, bolt="B1", ok=True), "B1", False),
                   (StateReason(Because.NOT_CONFIRMED, bolt="B2"), "B2", True),
                   (StateReason(Because.WRENCH_LEFT, bolt="B2"), "B2", True)]
    # the shell is told the same reason with the action
    assert [a.reason for _, acts in d.log for a in acts if isinstance(a, DisableTool)] == \
        [r for r, _, _ in off]


def test_the_tool_waits_for_a_frame_exposed_after_the_acknowledgement():
    d = _ready()
    _on(d, 1)
    assert d.sends == ["B1"] and d.core.state is State.BOLT_SELECTED
    d.step(("ack", 0.2, True))
    # frames exposed before the ack (older than the 0.2 s since): no tool
    acts = d.feed(LocalizedIn(d.t + 0.01, d.t - 0.1, (0.2, 0.1, 0.0)))
    assert "EnableTool" not in _kinds(acts) and not d.tool
    acts = d.feed(LocalizedIn(d.t + 0.05, d.t + 0.02, (0.2, 0.1, 0.0)))
    assert _kinds(acts) == ["EnableTool"] and d.core.state is State.TIGHTENING


def test_the_tool_goes_off_at_the_first_frame_off_the_bolt_and_comes_back_without_a_resend():
    d = _ready()
    _on(d, 1)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    assert d.tool
    d.step(("loc", 0.1, 0, 0.05, 0.0))            # one frame without the marker
    assert not d.tool and d.core.state is State.BOLT_SELECTED
    _on(d, 1, 1)                                   # back on it, same parameters
    assert d.tool and d.sends == ["B1"]
    d.step(("loc", 0.1, 1, 0.9, 0.0))              # a stale frame: off again
    assert not d.tool
    d.step(("loc", 0.1, 2, 0.05, 0.0))
    assert d.core.state is State.TRACKING and d.core.bolt is None   # left after 2 frames


def test_a_result_is_recorded_to_its_bolt_and_the_bolt_is_done():
    d = _ready()
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    acts = d.feed(ResultIn(d.t, result(5, 2)))
    assert _kinds(acts) == ["DisableTool", "Record"] and d.records == {5: "B2"}
    assert d.core.state is State.TRACKING
    _on(d, 2, 4)
    assert d.sends == ["B2"]                       # done: never sent again
    assert _kinds(d.feed(ResultIn(d.t, result(5, 2)))) == ["Acknowledge"]  # resent: once


def test_a_late_result_goes_to_the_bolt_the_tool_was_on_within_the_window_only():
    d = _ready()
    _on(d, 1)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    _on(d, 3, 2)                                   # left B1, now near B3 (same pset)
    assert not d.tool and d.core.bolt is None
    acts = d.feed(ResultIn(d.t + 1.0, result(8, 1)))
    assert next(a for a in acts if isinstance(a, Record)).late
    assert d.records == {8: "B1"}
    acts = d.feed(ResultIn(d.t + 1.5, result(9, 1)))   # a second one: nobody's
    assert _kinds(acts) == ["StoreUnattributed"]
    assert any(isinstance(a, Publish) and isinstance(a.event, ResultUnattributed)
               for a in acts)


@pytest.mark.parametrize("nxt", [3, 2], ids=["same pset", "another pset"])
def test_the_tool_waits_while_the_bolt_it_left_may_still_send_its_result(nxt):
    """B1's tool went off as the wrench left for another bolt, its result not in: that bolt
    is selected and acknowledged, but its tool stays off until B1's result is in (then
    recorded to B1, never to the bolt the wrench is on now) or can no longer come."""
    d = _ready()
    _on(d, 1)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    assert d.tool and d.tool_bolt == "B1"
    _on(d, nxt, 4)                                 # left B1: selected, parameters sent
    name = f"B{nxt}"
    assert d.pending == name
    d.step(("ack", 0.01, True))
    _on(d, nxt, 2)                                 # confirmed: the tool would go on
    assert not d.tool and d.core.state is State.BOLT_SELECTED
    assert d.core.reason == StateReason(Because.RESULT_OWED, bolt=name, owed="B1")
    assert state_words(d.core.reason) == (
        f"bolt {name}: the tool stays off until bolt B1's result is in, or can no longer come")
    d.tool_bolt = "B1"
    acts = d.feed(ResultIn(d.t + 0.3, result(8, 1)))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B1"]
    assert d.records == {8: "B1"}
    _on(d, nxt, 1)
    assert d.tool and d.tool_bolt == name and d.core.state is State.TIGHTENING


def test_the_tool_goes_on_once_the_result_of_the_bolt_left_can_no_longer_come():
    d = _ready()
    _on(d, 1)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    _on(d, 3, 4)
    d.step(("ack", 0.01, True))
    _on(d, 3, 2)
    assert not d.tool and d.core.reason.kind is Because.RESULT_OWED
    d.step(("loc", LATE_RESULT_S, 3, 0.05, 0.3))   # the late-result window passed:
    assert not d.tool      # the controller's newest is asked for (B1's push lost?) first
    d.step(("loc", 0.1, 3, 0.05, 0.3))   # answered (nothing more), the next frame: on
    assert d.tool and d.tool_bolt == "B3"
    acts = d.feed(ResultIn(d.t + 0.3, result(8, 1)))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B3"]


def test_a_result_after_the_window_is_not_attributed():
    d = _ready()
    _on(d, 1)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    d.step(("lift", 0.1, False, True, "VIN1"))     # lift moving: tool off
    assert not d.tool
    assert _kinds(d.feed(ResultIn(d.t + 6.0, result(3, 1)))) == ["StoreUnattributed"]


def test_faults_are_per_device_and_the_station_recovers_when_all_are_back():
    d = _ready()
    d.step(("fault", 0.1, "lift"))
    d.step(("fault", 0.1, "pair1"))
    assert d.core.reason.kind is Because.FAULT
    assert [device for device, _ in d.core.reason.faults] == ["lift", "pair1"]
    d.down.discard("lift")
    d.step(("lift", 0.1, True, True, "VIN1"))       # the lift answers: one fault left
    assert d.core.state is State.FAULT
    assert [device for device, _ in d.core.reason.faults] == ["pair1"]
    d.step(("back", 0.1, "pair1", 0))
    # the lift read ready with VIN1 since its outage: tracking at once, not "waiting for
    # vehicle" until the next read
    assert d.core.state is State.TRACKING
    d.step(("lift", 0.1, True, True, "VIN1"))
    assert d.core.state is State.TRACKING
    health = [a.event for _, acts in d.log for a in acts
              if isinstance(a, Publish) and isinstance(a.event, DeviceHealth)]
    assert [(h.device, h.ok) for h in health] == [("lift", False), ("pair1", False),
                                                  ("lift", True), ("pair1", True)]
    states = [a.event.state for _, acts in d.log for a in acts
              if isinstance(a, Publish) and isinstance(a.event, StateChanged)]
    assert states[-1] == "tracking"


def test_the_vin_is_sent_once_per_vehicle_and_again_after_a_controller_reconnect():
    d = _ready()
    vins = lambda: [a.vin for _, acts in d.log for a in acts if isinstance(a, SendVin)]  # noqa: E731
    assert vins() == ["VIN1"]
    d.feed(DeviceBack(d.t, "wrench", reconnects=0))   # the first count seen: no resend
    assert vins() == ["VIN1"]
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))   # it reconnected behind our back
    assert vins() == ["VIN1", "VIN1"]
    d.step(("fault", 0.1, "wrench"))
    assert vins() == ["VIN1", "VIN1"]                 # not while it is down
    acts = d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    assert _kinds(acts)[0] == "DisableTool"           # whatever the fault left it in
    d.down.discard("wrench")


def test_parameters_wait_for_the_vin():
    d = Driver()
    d.feed(Started(d.t))
    d.alone(LiftRead(d.t, True, True, 7, "VIN9"))   # nobody answers the loads here
    d.alone(VehicleLoaded(d.t, "VIN9", "M", BOLTS))
    assert d.core.state is State.TRACKING
    for k in range(5):
        acts = d.alone(LocalizedIn(d.t + k, d.t + k, (0.0, 0.0, 0.0)))
        assert not any(isinstance(a, SendParams) for a in acts)


def test_a_refusal_skips_the_bolt_and_faults_the_controller_until_it_is_back():
    d = _ready()
    _on(d, 1)
    d.step(("ack", 0.01, False))
    assert d.core.state is State.FAULT
    assert "refused the parameters for B1" in fault_words(dict(d.core.reason.faults)["wrench"])
    # decided typed, with the controller's words; the core writes none of its own (the
    # shell's publication does: tests/shell/test_effects.py)
    refused = [a for _, acts in d.log for a in acts]
    assert [(e.bolt, e.skip, e.reason) for e in published(refused, BoltSkipped)] == [
        ("B1", Skip(SkipKind.REFUSED, reason="pset unknown"), "")]
    assert d.core.matcher.skipped == {"B1": Skip(SkipKind.REFUSED, reason="pset unknown")}
    fault = CoreFault(CoreFaultKind.PARAMS_REFUSED, bolt="B1", note="pset unknown")
    assert [(e.device, e.kind, e.fault, e.reason) for e in published(refused, DeviceHealth)] \
        == [("wrench", FaultKind.REFUSED, fault, "")]
    assert d.core.status().faults == {"wrench": fault}
    d.down.add("wrench")
    d.step(("back", 0.1, "wrench", 0))
    d.step(("lift", 0.1, True, True, "VIN1"))
    _on(d, 1, 5)
    assert d.sends == ["B1"]                         # skipped: not sent again


def test_a_closed_vin_back_is_reopened_as_a_rework_or_a_named_fault():
    d = _ready("VINR")
    d.step(("lift", 0.1, False, False, "VINR"))       # lowered: closed
    assert "VINR" in d.closed_vins and d.core.vin is None
    d.step(("lift", 0.1, True, True, "VINR"))
    assert d.core.vin == "VINR" and d.core.state is State.TRACKING
    loads = [a for _, acts in d.log for a in acts if isinstance(a, LoadVehicle)]
    assert loads[-1].reopen

    d2 = Driver(core=StationCore(PARAMS, rework=False))
    d2.closed_vins.add("VINR")
    d2.feed(Started(d2.t))
    d2.step(("lift", 0.1, True, True, "VINR"))
    assert d2.core.state is State.FAULT
    assert "VIN VINR already closed" in fault_words(dict(d2.core.reason.faults)["vehicle"])
    assert dict(d2.core.reason.faults)["vehicle"] == CoreFault(
        CoreFaultKind.CLOSED, vin="VINR", note="closed")
    d2.step(("lift", 0.1, False, False, None))        # lowering clears it
    assert d2.core.state is State.WAITING_VEHICLE


def test_a_late_acknowledgement_keeps_the_tool_off():
    d = _ready()
    _on(d, 1)
    _on(d, 0, 2)                                      # gone before the ack
    acts = d.feed(ParamsAcked(d.t, "B1"))
    assert _kinds(acts) == ["DisableTool"]
    _on(d, 1, 1)
    assert not d.tool


def test_nothing_is_sent_while_the_lift_is_not_ready_or_on_stale_frames():
    d = Driver()
    d.feed(Started(d.t))
    _on(d, 1, 5)
    d.step(("lift", 0.1, True, True, "VIN1"))
    _on(d, 1, 5, age=0.6)
    assert d.sends == []
    refusals = [a.event.reason for _, acts in d.log for a in acts
                if isinstance(a, Publish) and type(a.event).__name__ == "Refused"]
    assert len(refusals) == 1 and refusals[0].kind is Why.STALE   # once per change


def test_unattributed_results_without_a_vehicle_are_stored_then_acknowledged():
    d = Driver()
    d.feed(Started(d.t))
    acts = d.feed(ResultIn(d.t, result(1, 1)))
    store = [a for a in acts if isinstance(a, StoreUnattributed)]
    assert len(store) == 1 and store[0].vin is None
    assert store[0].why == Unattributed(UnattributedKind.OUTSIDE, 1, 1)
    assert unattributed_words(store[0].why) == "result 1 (pset 1) outside any tightening"
    assert not any(isinstance(a, Record | Acknowledge) for a in acts)


def _owed(bolt: str = "B2", vin: str = "VIN1") -> Selection:
    return Selection(bolt, BOLTS[bolt].pset, BOLTS[bolt].position, 1.0, 0.4, 990.0, 991.0,
                     None, vin, 17)


def test_a_resumed_enable_records_its_result_to_its_bolt_and_vehicle_before_any_load():
    """A reload or restart: the new core takes over the enable the last one owed; its result
    within the window is recorded to that bolt of that vehicle, with that parameter version,
    even before the vehicle is loaded again."""
    core = StationCore(PARAMS, leave_frames=2)
    sel = _owed()
    core.resume(Owed(sel, off_at=1000.0))
    core.feed(Started(1000.1))
    acts = core.feed(ResultIn(1001.0, result(70060, 2, ok=False)))
    rec = [a for a in acts if isinstance(a, Record)]
    assert len(rec) == 1 and rec[0].vin == "VIN1" and rec[0].bolt == "B2" and rec[0].late
    assert rec[0].selection is sel and rec[0].selection.parameters_id == 17
    # sent again by the controller: stored once, acknowledged
    assert _kinds(core.feed(ResultIn(1001.2, result(70060, 2, ok=False)))) == ["Acknowledge"]


def test_a_resumed_enable_is_a_link_cut_the_catch_up_ends():
    """A reload or restart closes and opens the controller's link: the enable the last
    station owed, past its late-result window too, is taken as a cut during it.  Its result
    fetched after the restart is placed by the controller's data; until the catch-up has
    ended it no bolt of that vehicle gets the tool; a complete catch-up without it settles
    the enable (a reviewer: the cut was lost on a reload, another bolt enabled meanwhile)."""
    from stationd.station.actions import SettleEnable
    from stationd.station.inputs import CaughtUp

    core = StationCore(PARAMS, leave_frames=2)
    sel = _owed("B2")
    core.resume(Owed(sel, off_at=1000.0, enabled_at=995.0, in_window=False))
    core.feed(Started(1100.0))
    assert core.missed_since() == 995.0
    fetched = rundown(70061, 2, vin="VIN1")
    acts = core.feed(ResultIn(1101.0, fetched, fetched=True, follows=70060, made_at=998.0))
    assert [(a.bolt, a.late) for a in acts if isinstance(a, Record)] == [("B2", True)]
    assert not core.feed(CaughtUp(1102.0, complete=True))     # the cut had ended
    core = StationCore(PARAMS, leave_frames=2)
    core.resume(Owed(sel, off_at=1000.0, enabled_at=995.0, in_window=False))
    core.feed(Started(1100.0))
    acts = core.feed(CaughtUp(1101.0, complete=True))
    assert [a.selection for a in acts if isinstance(a, SettleEnable)] == [sel]
    assert core.missed_since() == 1100.0


def _reloaded_owing(bolt: str = "B3", done: frozenset[str] = frozenset({"B1"})) -> StationCore:
    """A new core after a reload: it owes ``bolt``'s enable (B3: the pset of B1, done and
    stored before the reload) and has VIN1 loaded again."""
    core = StationCore(PARAMS, leave_frames=2)
    core.resume(Owed(_owed(bolt), off_at=1000.0))
    core.feed(Started(1000.1))
    core.feed(VehicleLoaded(1000.2, "VIN1", "M", BOLTS, done=done))
    return core


def test_a_result_the_database_had_already_is_said_a_copy_and_published_as_no_new_result():
    """The last guard (the shell's check before the core missed it: a race): the copy of
    B1's result 7 (stored, its acknowledgement lost before a reload) was attributed to B3's
    owed enable (the same pset), and the database says it had it, as B1's.  Nothing was
    stored, no new result is published; the journal names B1, the bolt it is of (it said
    "result 7 of B3"); and B3, never tightened, is not done: it is held for a supervisor
    with why (the tool was enabled for it: its own result may have been lost, so it is not
    simply open again to be tightened twice).  The controller may forget the copy."""
    from stationd.station.events import BoltLocked, Notice, ResultRecorded, Said
    from stationd.station.inputs import Written

    core = _reloaded_owing()
    [rec] = [a for a in core.feed(ResultIn(1001.0, result(7, 1, ok=True)))
             if isinstance(a, Record)]
    assert rec.bolt == "B3"
    acts = core.feed(Written(1001.1, rec, (), again=True, stored_vin="VIN1",
                             stored_bolt="B1"))
    assert _kinds(acts)[-1] == "Acknowledge" and not published(acts, ResultRecorded)
    notices = [(n.said, n.tightening_id, n.bolt, n.vin) for n in published(acts, Notice)]
    assert (Said.SENT_AGAIN, 7, "B1", None) in notices
    assert not any(n[0] is Said.SENT_AGAIN and n[2] == "B3" for n in notices)
    st = core.status()
    assert "B3" not in st.done and "B3" in st.held and "B3" not in core.allowed()
    assert [b.bolt for b in published(acts, BoltLocked)] == ["B3"]
    assert "B1" in st.done
    # a copy of the bolt it was attributed to (the same bolt): said as before, no hold
    core2 = _reloaded_owing("B2", frozenset())
    [rec2] = [a for a in core2.feed(ResultIn(1001.0, result(8, 2, ok=False)))
              if isinstance(a, Record)]
    acts2 = core2.feed(Written(1001.1, rec2, (), again=True, stored_vin="VIN1",
                               stored_bolt="B2"))
    assert _kinds(acts2) == ["Acknowledge"]
    assert [(n.said, n.bolt) for n in published(acts2, Notice)] == [(Said.SENT_AGAIN, "B2")]


def test_a_nok_copy_attributed_to_another_bolt_is_not_counted_against_it():
    """The race's NOK: B1's NOK 7 taken for B3's counted a NOK of B3 (``skip`` skipped it
    for the vehicle, a bolt left untightened); the database's answer takes it back."""
    from stationd.station.inputs import Written
    from stationd.station.policy import NokPolicy, NokRule

    core = StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(3, "skip")))
    core.resume(Owed(_owed("B3"), off_at=1000.0))
    core.feed(Started(1000.1))
    core.feed(VehicleLoaded(1000.2, "VIN1", "M", BOLTS))
    [rec] = [a for a in core.feed(ResultIn(1001.0, result(7, 1, ok=False)))
             if isinstance(a, Record)]
    assert "B3" in core.status().skipped
    core.feed(Written(1001.1, rec, (), again=True, stored_vin="VIN1", stored_bolt="B1"))
    st = core.status()
    assert "B3" not in st.skipped and "B3" not in st.done and "B3" in st.held


def test_a_copy_found_before_the_core_is_never_attributed_to_the_owed_enable():
    """The reviewer's scenario: result 7 of B1 was stored, its acknowledgement lost; B3
    (B1's pset) was enabled; a reload; the controller sends 7 again.  The shell found it
    stored (as B1's) before the core saw it: the core attributes nothing.  B3 stays open,
    its enable still owed (its own result, when it comes, is B3's), the notice names B1, and
    the controller may forget the copy."""
    from stationd.station.events import Notice, ResultRecorded, Said
    from stationd.station.inputs import ResultCopy

    core = _reloaded_owing()
    acts = core.feed(ResultCopy(1001.0, result(7, 1), "VIN1", "B1"))
    assert _kinds(acts) == ["Acknowledge"]
    assert not any(isinstance(a, Record | StoreUnattributed) for a in acts)
    assert not published(acts, ResultRecorded)
    assert [(n.said, n.tightening_id, n.bolt, n.vin) for n in published(acts, Notice)] == [
        (Said.SENT_AGAIN, 7, "B1", None)]
    st = core.status()
    assert "B3" not in st.done and "B3" not in st.held and "B3" in core.allowed()
    # sent again once more: acknowledged, said once
    assert _kinds(core.feed(ResultCopy(1001.1, result(7, 1), "VIN1", "B1"))) == ["Acknowledge"]
    # the tool's own result for B3 still comes within the window: B3's
    [rec] = [a for a in core.feed(ResultIn(1002.0, result(8, 1))) if isinstance(a, Record)]
    assert (rec.vin, rec.bolt, rec.late) == ("VIN1", "B3", True)
    assert "B3" in core.status().done


def test_a_copy_of_another_vehicle_s_result_names_that_vehicle():
    from stationd.station.events import Notice, Said
    from stationd.station.inputs import ResultCopy
    from stationd.words import notice_words

    core = _reloaded_owing()
    acts = core.feed(ResultCopy(1001.0, result(7, 1), "VIN0", "B1"))
    [n] = published(acts, Notice)
    assert (n.said, n.bolt, n.vin) == (Said.SENT_AGAIN, "B1", "VIN0")
    assert notice_words(n) == ("result 7 of B1 of VIN VIN0 sent again by the controller: "
                               "stored once")
    assert "B1" in core.status().done and "B3" not in core.status().done


def test_a_resumed_enable_does_not_take_another_pset_or_a_result_after_its_window():
    core = StationCore(PARAMS, leave_frames=2)
    core.resume(Owed(_owed(), off_at=1000.0))
    core.feed(Started(1000.1))
    assert _kinds(core.feed(ResultIn(1001.0, result(5, 1)))) == ["StoreUnattributed"]
    core.feed(Tick(1005.5))
    acts = core.feed(ResultIn(1005.6, result(6, 2)))
    assert _kinds(acts) == ["StoreUnattributed"]


def test_the_enable_carries_its_selection_with_vehicle_and_parameter_version():
    bolts = {k: LoadedBolt(b.position, b.pset, parameters_id=40 + i)
             for i, (k, b) in enumerate(BOLTS.items())}
    d = _ready()
    d.alone(VehicleLoaded(d.t, "VIN1", "M", bolts))
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    en = [a for _, acts in d.log for a in acts if isinstance(a, EnableTool)]
    assert en and en[-1].selection.vin == "VIN1" and en[-1].selection.parameters_id == 41


def test_a_refusal_is_published_per_bolt_and_reason_not_per_measurement():
    """The wrench moved from one done bolt to another: the screens and the journal must say
    which (a refusal's key keeps bolt ids; only measurements such as ages are folded)."""
    d = _ready()
    for k, tid in ((1, 5), (2, 6)):
        _on(d, k)
        d.step(("ack", 0.01, True))
        _on(d, k, 1)
        d.feed(ResultIn(d.t, result(tid, BOLTS[f"B{k}"].pset or 0)))
    start = len(d.log)
    for k in (1, 1, 2, 2, 1):
        _on(d, k, 2)
    refused = [a.event for _, acts in d.log[start:] for a in acts
               if isinstance(a, Publish) and isinstance(a.event, Refused)]
    assert [(e.bolt, reason_words(e.reason)) for e in refused] == [
        ("B1", "B1 is already done"), ("B2", "B2 is already done"),
        ("B1", "B1 is already done")]
    stale = len(d.log)
    for age in (0.8, 0.9, 1.3):
        _on(d, 1, 1, age=age)
    ages = [a.event.reason for _, acts in d.log[stale:] for a in acts
            if isinstance(a, Publish) and isinstance(a.event, Refused)]
    assert len(ages) == 1 and ages[0].kind is Why.STALE   # one refusal, not one per frame's age


def test_frames_exposed_before_a_rundown_ended_never_select_after_it():
    """Seen in bench station once selections took 30 ms: a NOK rundown on B2 ends, the
    operator moves on, and frames exposed while the wrench was still on B2 (in flight) made a
    new streak and sent B2's parameters with the wrench already elsewhere.  A selection after
    a rundown needs ``stable_frames`` frames exposed after it."""
    d = _ready()
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    assert d.tool
    end = d.t + 0.05
    acts = d.feed(ResultIn(end, result(5, 2, ok=False)))     # NOK: B2 may be tightened again
    assert _kinds(acts) == ["DisableTool", "Record"] and d.core.state is State.TRACKING
    pos = BOLTS["B2"].position
    sends = []
    for k in range(4):   # processed after the rundown, exposed before it: B2 in the picture
        t = end + 0.03 * (k + 1)
        sends += [a for a in d.alone(LocalizedIn(t, end - 0.02, pos, None))
                  if isinstance(a, SendParams)]
    assert sends == [] and d.core.state is State.TRACKING
    for k in range(PARAMS.stable_frames):   # frames exposed after it: the wrench still there
        t = end + 0.2 + 0.03 * k
        sends += [a for a in d.alone(LocalizedIn(t, t - 0.02, pos, None))
                  if isinstance(a, SendParams)]
    assert [a.bolt for a in sends] == ["B2"]


def test_a_database_fault_during_a_load_loads_the_vehicle_again_once_it_is_back():
    """The load's answer was the database's fault: nothing is tracked, and once the database
    is back and the lift still ready the vehicle is loaded again (it was never loaded again:
    the load stayed "under way")."""
    c = StationCore(PARAMS, leave_frames=2)
    c.feed(Started(1.0))
    first = c.feed(LiftRead(1.1, True, True, 7, "VINDB"))
    assert [a for a in first if isinstance(a, LoadVehicle)]
    c.feed(DeviceFault(1.2, "database", FaultKind.DOWN, "disk I/O error"))
    assert c.state is State.FAULT
    assert c.reason == StateReason(Because.FAULT, faults=(("database", "disk I/O error"),))
    assert not [a for a in c.feed(LiftRead(1.3, True, True, 7, "VINDB"))
                if isinstance(a, LoadVehicle)]                     # in fault: no load
    c.feed(DeviceBack(1.4, "database"))
    again = c.feed(LiftRead(1.5, True, True, 7, "VINDB"))
    assert [a.vin for a in again if isinstance(a, LoadVehicle)] == ["VINDB"]
    c.feed(VehicleLoaded(1.6, "VINDB", "M", BOLTS))
    assert c.vin == "VINDB" and c.state is State.TRACKING


def test_a_vehicle_that_changes_at_height_is_a_fault_until_the_lift_goes_down():
    """Newcomer trial (independent PLC): a VIN or model code changing while the lift stayed at
    height was ignored and the old vehicle's parameters went out.  Now: a vehicle fault
    (tool off, nothing sent) until the lift goes down, which closes the loaded vehicle; the
    next raise loads the new one."""
    for changed in (LiftRead(1.3, True, True, 7, "VINOTHER"), LiftRead(1.3, True, True, 9, "VINA")):
        c = StationCore(PARAMS, leave_frames=2)
        c.feed(Started(1.0))
        c.feed(LiftRead(1.1, True, True, 7, "VINA"))
        c.feed(VehicleLoaded(1.2, "VINA", "M", BOLTS))
        assert c.state is State.TRACKING
        acts = c.feed(changed)
        assert c.state is State.FAULT
        assert "lower the lift" in fault_words(dict(c.reason.faults)["vehicle"])
        assert dict(c.reason.faults)["vehicle"] == (
            CoreFault(CoreFaultKind.VIN_CHANGED, vin="VINA", plc_vin="VINOTHER")
            if changed.vin == "VINOTHER" else
            CoreFault(CoreFaultKind.MODEL_CHANGED, vin="VINA", code=7, plc_code=9))
        assert any(isinstance(a, DisableTool) for a in acts) or not c.tool_on
        pos = np.asarray(BOLTS["B1"].position, dtype=np.float64)
        sends = [a for k in range(6) for a in c.feed(LocalizedIn(1.4 + 0.05 * k,
                                                                  1.39 + 0.05 * k, pos, None))
                 if isinstance(a, SendParams)]
        assert sends == []
        down = c.feed(LiftRead(2.0, False, False, changed.model_code, changed.vin))
        assert [a.vin for a in down if isinstance(a, CloseVehicle)] == ["VINA"]
        assert "vehicle" not in c.faults
        up = c.feed(LiftRead(2.5, True, True, changed.model_code, changed.vin))
        assert [(a.model_code, a.vin) for a in up if isinstance(a, LoadVehicle)] == \
            [(changed.model_code, changed.vin)]


def test_a_vehicle_closed_by_the_first_read_after_a_lift_outage_is_said_so():
    """A maintenance trial restarted the lift PLC: it came back saying the lift down and the
    vehicle closed with 50 bolts missing, nothing tying the close to the outage.  The close
    says it came with the PLC's return (the journal then says how to reopen); a lift lowered
    while the PLC answers is an ordinary close."""
    for outage in (True, False):
        c = StationCore(PARAMS, leave_frames=2)
        c.feed(Started(1.0))
        c.feed(LiftRead(1.1, True, True, 7, "VINA"))
        c.feed(VehicleLoaded(1.2, "VINA", "M", BOLTS))
        if outage:
            c.feed(DeviceFault(1.5, "lift", FaultKind.DOWN, "connection refused"))
        down = c.feed(LiftRead(2.0, False, False, 0, None))
        assert [(a.vin, a.after_lift_outage) for a in down if isinstance(a, CloseVehicle)] \
            == [("VINA", outage)]


def test_the_lifts_own_fault_bit_is_a_fault_of_the_station_the_vehicle_kept():
    """A maintenance trial set the PLC's fault bit: the state said "waiting for vehicle (the
    lift PLC reports a fault)" and the lift "ok" everywhere else; then an operator trial saw
    "waiting for vehicle" beside the loaded VIN under a red FAULT headline.  The lift's
    health says it (once per change, and again after the PLC's own outage), the snapshot has
    the lift among the devices in fault, the station is in FAULT (the tool off) with the
    vehicle kept, and back to tracking once the PLC clears it."""
    def healths(acts: list[Any]) -> list[tuple[bool, str, Any]]:
        return [(a.event.ok, a.event.kind, a.event.fault) for a in acts
                if isinstance(a, Publish) and isinstance(a.event, DeviceHealth)
                and a.event.device == "lift"]

    bit = CoreFault(CoreFaultKind.LIFT_REPORTS_FAULT)
    c = StationCore(PARAMS, leave_frames=2)
    c.feed(Started(1.0))
    c.feed(LiftRead(1.1, True, True, 7, "VINA"))
    c.feed(VehicleLoaded(1.2, "VINA", "M", BOLTS))
    faulty = LiftRead(1.5, False, True, 7, "VINA", "the lift PLC reports a fault", True)
    assert healths(c.feed(faulty)) == [(False, "reported", bit)]
    assert c.state is State.FAULT and c.vin == "VINA" and not c.tool_on
    assert c.reason == StateReason(Because.FAULT, faults=(("lift", bit),))
    assert c.status().faults == {"lift": bit} and c.status().fault_kinds == {"lift": "reported"}
    assert healths(c.feed(dataclasses.replace(faulty, t=1.6))) == []       # said once
    c.feed(DeviceFault(1.7, "lift", FaultKind.DOWN, "connection refused"))
    assert healths(c.feed(dataclasses.replace(faulty, t=2.0))) == [
        (True, "", None), (False, "reported", bit)]          # back, and still in fault
    assert c.state is State.FAULT and c.vin == "VINA"
    assert healths(c.feed(LiftRead(2.5, True, True, 7, "VINA"))) == [(True, "", None)]
    assert c.status().faults == {} and c.state is State.TRACKING
    # an outage with the bit set, the keeper's DeviceBack before or after the first read (a
    # review: the bit was lost, the lift "ok" everywhere and the state waiting)
    for back_first in (True, False):
        c.feed(dataclasses.replace(faulty, t=3.0))
        c.feed(DeviceFault(3.1, "lift", FaultKind.DOWN, "connection refused"))
        steps = [DeviceBack(3.2, "lift"), dataclasses.replace(faulty, t=3.3)]
        for step in steps if back_first else steps[::-1]:
            c.feed(step)
        assert c.status().faults == {"lift": bit} and c.state is State.FAULT, back_first
        assert c.status().fault_kinds == {"lift": "reported"}
        c.feed(LiftRead(3.5, True, True, 7, "VINA"))
        assert c.status().faults == {} and c.state is State.TRACKING
    assert "nothing is tightened until it is cleared" in fault_words(bit)


def test_a_fault_heard_before_the_start_does_not_skip_the_start():
    """The database down at boot reaches the core before its loop runs (the serve loop's
    retry): the core is in fault and says so; once it is back and the loop starts, Started
    still does what a start does (the tool off, who is signed in said), once."""
    core = StationCore()
    down = core.feed(DeviceFault(1.0, DATABASE, FaultKind.DOWN, "unable to open database"))
    assert [e.state for e in published(down, StateChanged)] == [State.FAULT]
    assert [h.ok for h in published(down, DeviceHealth)] == [False]
    assert core.status().faults == {DATABASE: "unable to open database"}
    back = core.feed(DeviceBack(2.0, DATABASE))
    assert [h.ok for h in published(back, DeviceHealth)] == [True]
    assert core.status().faults == {} and core.status().state is State.WAITING_VEHICLE
    start = core.feed(Started(3.0))
    assert any(isinstance(a, DisableTool) for a in start)
    assert published(start, OperatorChanged)
    assert core.feed(Started(4.0)) == []           # once


def test_what_the_shell_could_not_do_is_said_by_the_core():
    """A gap the controller cannot fill and a record the database refused reach the core as
    inputs: it decides what is stored and said (the one writer of the station's notices)."""
    from stationd.station.actions import StoreGap
    from stationd.station.events import Notice, Said
    from stationd.station.inputs import NotStored, ResultsMissed
    from stationd.words import notice_words

    core = StationCore()
    core.vin = "VIN1"
    acts = core.feed(ResultsMissed(1.0, 70061, 70062, "the controller no longer has it"))
    assert StoreGap(70061, 70062, "VIN1", "the controller no longer has it") in acts
    (said,) = published(acts, Notice)
    assert (said.said, said.tightening_id, said.last_id, said.link_up, said.note) == (
        Said.GAP, 70061, 70062, False, "the controller no longer has it")
    assert said.level == "warning" and notice_words(said).startswith(
        "tightening 70061-70062 missed while the link was down: a gap")
    acts = core.feed(NotStored(2.0, 7, "B03", "disk I/O error"))
    (said,) = published(acts, Notice)
    assert (said.said, said.tightening_id, said.bolt) == (Said.NOT_STORED, 7, "B03")
    assert said.level == "error" and "tightening 7 of B03 not stored: disk I/O error" == \
        notice_words(said)
    assert not [a for a in acts if not isinstance(a, Publish)]


def test_a_new_station_announces_its_state_as_the_core_decided_it():
    """A new station (a start, a reload) tells its state before it opens anything: the core
    publishes it, once per announcement, and nothing else changes."""
    core = StationCore()
    [told] = published(core.feed(Announce(1.0)), StateChanged)
    assert (told.state, told.reason, told.t) == (State.STARTING, core.status().reason, 1.0)
    core.feed(DeviceFault(2.0, DATABASE, FaultKind.DOWN, "unable to open database"))
    acts = core.feed(Announce(3.0))
    assert [(e.state, e.reason) for e in published(acts, StateChanged)] == \
        [(State.FAULT, core.status().reason)]
    assert all(isinstance(a, Publish) for a in acts)
    assert core.status().faults == {DATABASE: "unable to open database"}


@pytest.mark.parametrize("device", ["wrench", "pair1", "database"])
def test_a_device_back_with_the_vehicle_at_height_tracks_again_not_waiting_for_the_lift(
        device):
    """An MES subscribed to the station's State (OPC UA ``JS/State``) saw every controller
    link cut with a car at height go fault, then "waiting for vehicle: recovered; waiting
    for the lift", then tracking at the next lift read: a car at the station counted as a
    station starved of cars.  A device other than the lift back, the lift read ready with
    the loaded vehicle: tracking at once.  The lift's own outage still waits for its read."""
    d = _ready()
    start = len(d.log)
    d.step(("fault", 0.1, device))
    d.step(("back", 0.1, "", 0))
    told = [(e.state, e.reason) for _, acts in d.log[start:]
            for e in published(acts, StateChanged)]
    assert told[-1] == (State.TRACKING, StateReason(Because.TRACKING)), told
    assert all(s is not State.WAITING_VEHICLE for s, _ in told), told
    assert d.core.state is State.TRACKING
    # the lift itself back: its state is not known until it is read again
    d.step(("fault", 0.1, "lift"))
    d.step(("back", 0.1, "", 0))
    assert (d.core.state, d.core.reason) == (State.WAITING_VEHICLE,
                                             StateReason(Because.RECOVERED))
    d.step(("lift", 0.1, True, True, "VIN1"))
    assert d.core.state is State.TRACKING
