"""The operator signed in at the station, in the pure core: a typed command any configured user
gives for themselves, effective once recorded; every rundown carries who was signed in when
its tool was enabled; ``operator_required`` sends nothing with nobody signed in (a typed
refusal); the idle time-out signs out and is recorded; random sequences keep the invariants."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stationd.reasons import Reason, Why
from stationd.station.actions import (
    DisableTool,
    EnableTool,
    Publish,
    Record,
    RecordCommand,
    SendParams,
)
from stationd.station.commands import Issuer, Right, SignIn, SignOut
from stationd.station.core import StationCore
from stationd.station.events import (
    Because,
    OperatorChange,
    OperatorChanged,
    Refused,
    State,
    StateReason,
)
from stationd.station.inputs import CommandDone, CommandIn, OperatorBack, ResultIn, Started, Tick
from stationd.words import answer_words, comment_words, operator_words, reason_words
from tests.station.test_commands import _answer
from tests.station.test_core import (
    PARAMS,
    Driver,
    _on,
    _ready,
    decode,
    published,
    result,
    seeded_steps,
)

OLGA = Issuer("olga", frozenset(), "screen 10.0.0.7")     # an operator: no rights needed
PIA = Issuer("pia", frozenset({Right.SKIP}), "cli")


def _reply(acts: list[Any]) -> Any:
    """The command's answer: the one Reply among ``acts``."""
    return _answer(acts).answer


def _changes(acts: list[Any]) -> list[OperatorChanged]:
    return published(acts, OperatorChanged)


def _tighten(d: Driver, bolt: int, tid: int, ok: bool = True) -> list[Any]:
    _on(d, bolt)
    d.step(("ack", 0.01, True))
    _on(d, bolt, 1)
    sel = d.core.selection
    assert d.tool and sel is not None, d.core.reason
    return d.feed(ResultIn(d.t, result(tid, sel.pset or 0, ok)))


def test_a_sign_in_is_recorded_then_every_rundown_carries_the_operator():
    d = _ready()
    acts = d.feed(CommandIn(d.t, 1, SignIn(), OLGA))
    assert [type(a).__name__ for a in acts] == ["RecordCommand"] and d.core.operator is None
    acts = d.feed(CommandDone(d.t, 1))           # effective once on disk
    assert d.core.operator == "olga" and _reply(acts).accepted
    change = _changes(acts)[0]
    assert (change.user, change.previous, change.how) == ("olga", None, "signed in")
    assert operator_words(change) == "operator: olga signed in"
    recs = [a for a in _tighten(d, 2, 5) if isinstance(a, Record)]
    assert [r.selection.operator for r in recs] == ["olga"]
    assert answer_words(_reply(acts)).startswith("command sign-in by olga")


def test_nobody_signed_in_records_rundowns_without_a_user_when_not_required():
    d = _ready()
    recs = [a for a in _tighten(d, 1, 3) if isinstance(a, Record)]
    assert [r.selection.operator for r in recs] == [None]


def test_a_sign_out_or_another_operator_ends_it_and_leaves_a_selected_bolt():
    d = _ready()
    d.command(1, SignIn(), OLGA)
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    assert d.tool
    acts = d.command(2, SignIn("shift change"), PIA)     # pia takes over
    assert _reply(acts).accepted and d.core.operator == "pia"
    assert any(isinstance(a, DisableTool) for a in acts) and not d.tool
    assert d.core.state is State.TRACKING and d.core.bolt is None
    assert d.core.reason == StateReason(Because.OPERATOR, how=OperatorChange.SIGNED_IN)
    assert _changes(acts)[0].previous == "olga"
    recs = [a for a in _tighten(d, 2, 6) if isinstance(a, Record)]
    assert [r.selection.operator for r in recs] == ["pia"]
    # a sign-out by another user names who was signed out in the command it records
    acts = d.feed(CommandIn(d.t, 3, SignOut(), OLGA))
    rec = next(a for a in acts if isinstance(a, RecordCommand))
    assert rec.command == SignOut("", "pia")
    acts = d.feed(CommandDone(d.t, 3))
    assert d.core.operator is None and _changes(acts)[0].by == "olga"
    assert operator_words(_changes(acts)[0]) == "operator: pia signed out by olga"


def test_sign_in_and_out_refusals_are_typed_and_change_nothing():
    d = _ready()
    acts = d.feed(CommandIn(d.t, 1, SignOut(), OLGA))
    assert _reply(acts).reason == Reason(Why.NOT_SIGNED_IN)
    d.command(2, SignIn(), OLGA)
    acts = d.feed(CommandIn(d.t, 3, SignIn(), OLGA))
    assert _reply(acts).reason == Reason(Why.SIGNED_IN, user="olga")
    assert not any(isinstance(a, RecordCommand) for a in acts)
    assert reason_words(Reason(Why.SIGNED_IN, user="olga")) == "olga is signed in already"


def test_operator_required_sends_nothing_with_nobody_signed_in_and_says_why():
    d = _ready(operator_required=True)
    before = len(d.log)
    _on(d, 2, 4)
    acts = [a for _, got in d.log[before:] for a in got]
    assert d.sends == [] and not any(isinstance(a, SendParams) for a in acts)
    refusals = [a.event for a in acts if isinstance(a, Publish)
                and isinstance(a.event, Refused)]
    signin = [r for r in refusals if r.reason.kind is Why.SIGN_IN]
    assert len(signin) == 1 and refusals[-1] is signin[0]     # said once, where it selected
    assert reason_words(signin[0].reason).startswith("sign in to tighten")
    d.command(1, SignIn(), OLGA)
    recs = [a for a in _tighten(d, 2, 7) if isinstance(a, Record)]
    assert d.sends == ["B2"] and recs[0].selection.operator == "olga"
    d.command(2, SignOut(), OLGA)
    before = len(d.sends)
    _on(d, 1, 3)
    assert len(d.sends) == before          # signed out: refused again


def test_the_idle_time_out_signs_out_and_records_it_never_with_the_tool_on():
    d = _ready(operator_idle_s=60.0)
    d.command(1, SignIn(), OLGA)
    _on(d, 1)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    assert d.tool
    d.t += 120
    assert _changes(d.feed(Tick(d.t))) == [] and d.core.operator == "olga"  # the tool is on
    d.feed(ResultIn(d.t, result(4, 1)))
    d.t += 30
    assert _changes(d.feed(Tick(d.t))) == []            # a rundown 30 s ago is work
    d.t += 40
    acts = d.feed(Tick(d.t))
    assert d.core.operator is None and _changes(acts)[0].how == "idle"
    rec = next(a for a in acts if isinstance(a, RecordCommand))
    assert rec.request == 0 and rec.command == SignOut(user="olga", idle_s=60.0)
    assert comment_words(rec.command) == "idle for 60 s"       # the comment recorded
    assert rec.issuer.source == "station (idle)"
    assert d.feed(CommandDone(d.t, 0)) == []            # nobody waits for its answer


def test_an_operator_signed_in_before_a_start_is_still_signed_in_unless_idle_too_long():
    core = StationCore(PARAMS, operator_idle_s=600.0)
    core.feed(OperatorBack(1000.0, "olga", 900.0))
    acts = core.feed(Started(1000.0))
    assert core.operator == "olga"
    assert _changes(acts)[0].user == "olga" and _changes(acts)[0].how == "still signed in"
    core = StationCore(PARAMS, operator_idle_s=60.0)
    core.feed(OperatorBack(1000.0, "olga", 900.0))
    acts = core.feed(Started(1000.0))
    assert core.operator is None and _changes(acts)[0].user is None


@dataclass
class OperatorDriver(Driver):
    """The core's driver with people signing in and out: the invariants of the operator
    checked on every answer besides the safety ones."""

    required: bool = False
    signed: str | None = None            # who the core said is signed in
    enabled_by: str | None = None        # who was signed in when the tool went on
    requests: int = 0
    recorded_by: list[str | None] = field(default_factory=list)

    def check(self, a: Any, before: State, ev: Any) -> None:
        super().check(a, before, ev)
        if isinstance(a, SendParams):
            assert not self.required or self.core.operator is not None
            assert a.selection.operator == self.core.operator
        elif isinstance(a, EnableTool):
            assert a.selection.operator == self.signed
            self.enabled_by = a.selection.operator
        elif isinstance(a, Record):
            # a rundown carries who was signed in when its tool went on: never another
            assert a.selection is not None and a.selection.operator == self.enabled_by
            self.recorded_by.append(a.selection.operator)
        elif isinstance(a, Publish) and isinstance(a.event, OperatorChanged):
            assert not self.tool, "the operator changed with the tool on"
            self.signed = a.event.user

    def person(self, n: int) -> None:
        who = [OLGA, PIA, OLGA, None][n % 4]
        self.requests += 1
        self.command(self.requests, SignOut() if who is None else SignIn(), who or PIA)
        assert self.core.operator == self.signed


def test_seeded_random_sequences_with_people_signing_in_and_out_keep_the_invariants():
    rng = np.random.default_rng(21)
    kinds = ["lift", "loc", "ack", "result", "fault", "back", "tick", "person"]
    weights = np.array([0.02, 0.58, 0.17, 0.12, 0.01, 0.03, 0.04, 0.03])
    recorded: list[str | None] = []
    for walk in range(400):
        required = walk % 2 == 0
        d = OperatorDriver(core=StationCore(PARAMS, leave_frames=2, operator_required=required,
                                            operator_idle_s=120.0), required=required)
        d.feed(Started(d.t))
        d.step(("lift", 0.1, True, True, "VIN1"))
        for raw in seeded_steps(rng, kinds, weights, 80):
            if raw[0] == "person":
                d.t += 0.1
                d.person(raw[2])
                continue
            d.step(decode(raw))
        recorded += d.recorded_by
    # the walks really recorded rundowns, with and without an operator
    nobody = recorded.count(None)
    assert nobody >= 10 and len(recorded) - nobody >= 20, (nobody, len(recorded))
