"""The NOK policy in the pure core: a bolt locks after max_nok NOKs in a row and only a
release (a user with the right) unlocks it; the skip strategy; overrides per pset and bolt;
the count survives a reload (it comes with the vehicle)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from stationd.errors import ConfigError
from stationd.reasons import Reason, Wait, WaitKind, Why
from stationd.station.actions import NoteLock, Record
from stationd.station.commands import ReleaseBolt, SkipBolt
from stationd.station.core import StationCore
from stationd.station.events import BoltLocked, BoltReleased, BoltSkipped, Refused
from stationd.station.inputs import CommandDone, CommandIn, ResultIn, Started, VehicleLoaded
from stationd.station.policy import NokPolicy, NokRule, table_errors
from stationd.words import reason_words, wait_words
from stationd.yamlio import YamlNode
from tests.station import test_core
from tests.station.test_commands import OPERATOR, SUPERVISOR, _answer
from tests.station.test_core import BOLTS, PARAMS, Driver, _on, published, result


def _tighten(d: Driver, bolt: int, tid: int, ok: bool) -> list[Any]:
    _on(d, bolt)
    d.step(("ack", 0.01, True))
    _on(d, bolt, 1)
    assert d.tool, d.core.reason
    acts = d.feed(ResultIn(d.t, result(tid, BOLTS[f"B{bolt}"].pset or 0, ok)))
    assert any(isinstance(a, Record) for a in acts)
    return acts


def _events(acts: list[Any], kind: type) -> list[Any]:
    return [a.event for a in acts if type(a).__name__ == "Publish" and isinstance(a.event, kind)]


def _driver(policy: NokPolicy) -> Driver:
    d = Driver(core=StationCore(PARAMS, leave_frames=2, nok=policy))
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VIN1"))
    return d


def test_a_bolt_locks_after_max_nok_in_a_row_and_a_release_unlocks_it():
    d = _driver(NokPolicy(NokRule(max_nok=3)))
    _tighten(d, 2, 1, ok=False)
    acts = _tighten(d, 2, 2, ok=False)
    assert not _events(acts, BoltLocked)                 # repeat: open again after two
    acts = _tighten(d, 2, 3, ok=False)
    assert [(e.bolt, e.count) for e in _events(acts, BoltLocked)] == [("B2", 3)]
    sends = len(d.sends)
    _on(d, 2, 4)
    assert len(d.sends) == sends                         # locked: never sent again
    assert "B2" not in d.core.allowed()
    # an operator may not release; a supervisor may, once it is locked
    acts = d.alone(CommandIn(d.t, 1, ReleaseBolt("VIN1", "B2", "checked"), OPERATOR))
    assert _answer(acts).answer.reason == Reason(Why.NO_RIGHT, right="release")
    d.alone(CommandIn(d.t, 2, ReleaseBolt("VIN1", "B2", "thread checked"), SUPERVISOR))
    acts = d.alone(CommandDone(d.t, 2))
    assert _answer(acts).answer.accepted
    # a lock of NOKs (their results known): no "may be tightened already"
    assert [(e.bolt, e.user, e.unknown) for e in _events(acts, BoltReleased)] == \
        [("B2", "sam", False)]
    acts = d.alone(CommandIn(d.t, 3, ReleaseBolt("VIN1", "B2"), SUPERVISOR))
    assert _answer(acts).answer.reason == Reason(Why.NOT_LOCKED, bolt="B2")
    assert reason_words(Reason(Why.NOT_LOCKED, bolt="B2")) == \
        "B2 is neither locked nor held: nothing to release"
    _tighten(d, 2, 4, ok=True)                           # the count starts again
    assert "B2" in d.core.matcher.done


def test_a_locked_bolt_is_skipped_only_by_who_may_release_it_and_the_skip_ends_the_lock():
    """A newcomer's operator skipped a bolt locked after 3 NOK: the lock was gone, nobody
    with the release right had seen it.  An operator's skip is refused as the lock's words
    say; a supervisor's is taken and ends the lock (the bolt skipped, not locked)."""
    d = _driver(NokPolicy(NokRule(max_nok=2)))
    _tighten(d, 2, 1, ok=False)
    _tighten(d, 2, 2, ok=False)
    assert d.core.matcher is not None and d.core.matcher.locked == {"B2": 2}
    acts = d.alone(CommandIn(d.t, 1, SkipBolt("VIN1", "B2", "stuck"), OPERATOR))
    refused = _answer(acts).answer.reason
    assert refused == Reason(Why.LOCKED, bolt="B2", count=2)
    assert "supervisor" in reason_words(refused)
    assert d.core.matcher.locked == {"B2": 2} and "B2" not in d.core.matcher.skipped
    d.alone(CommandIn(d.t, 2, SkipBolt("VIN1", "B2", "to rework"), SUPERVISOR))
    acts = d.alone(CommandDone(d.t, 2))
    assert _answer(acts).answer.accepted
    assert [e.bolt for e in _events(acts, BoltSkipped)] == ["B2"]
    assert d.core.matcher.locked == {} and "B2" in d.core.matcher.skipped
    assert d.core.status().locked == frozenset()
    sends = len(d.sends)
    _on(d, 2, 3)
    assert len(d.sends) == sends                         # skipped: never sent


def test_a_held_bolt_is_skipped_only_by_who_may_release_it():
    d = _driver(NokPolicy(NokRule(max_nok=3)))
    assert d.core.matcher is not None
    d.core.matcher.held["B3"] = "tightening 7"           # its result could not be read
    acts = d.alone(CommandIn(d.t, 1, SkipBolt("VIN1", "B3"), OPERATOR))
    assert _answer(acts).answer.reason == Reason(Why.HELD, bolt="B3", note="tightening 7")
    d.alone(CommandIn(d.t, 2, SkipBolt("VIN1", "B3"), SUPERVISOR))
    assert _answer(d.alone(CommandDone(d.t, 2))).answer.accepted
    assert "B3" not in d.core.matcher.held and "B3" in d.core.matcher.skipped


def test_an_ok_resets_the_count():
    d = _driver(NokPolicy(NokRule(max_nok=2)))
    _tighten(d, 1, 1, ok=False)
    acts = _tighten(d, 1, 2, ok=True)
    assert not _events(acts, BoltLocked) and "B1" in d.core.matcher.done


def test_the_skip_strategy_marks_the_bolt_and_goes_on():
    d = _driver(NokPolicy(NokRule(max_nok=3, strategy="skip")))
    acts = _tighten(d, 3, 1, ok=False)
    assert [e.bolt for e in _events(acts, BoltSkipped)] == ["B3"]
    sends = len(d.sends)
    _on(d, 3, 3)
    assert len(d.sends) == sends


def test_overrides_per_bolt_win_over_per_pset_over_the_default():
    p = NokPolicy(NokRule(max_nok=3), psets={1: NokRule(max_nok=1)},
                  bolts={"B3": NokRule(max_nok=2)})
    assert p.rule("B1", 1).max_nok == 1 and p.rule("B3", 1).max_nok == 2
    assert p.rule("B2", 2).max_nok == 3
    d = _driver(p)
    acts = _tighten(d, 1, 1, ok=False)                   # pset 1: one NOK locks
    assert [e.count for e in _events(acts, BoltLocked)] == [1]


def test_the_count_comes_back_with_the_vehicle():
    core = StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(max_nok=3)))
    acts = core.feed(VehicleLoaded(1.0, "VIN1", "M", BOLTS, noks={"B1": 3, "B2": 2}))
    assert core.matcher is not None and core.matcher.locked == {"B1": 3}
    # and is said again: after a restart or a reload the screens and status list the lock,
    # for a supervisor to release (a newcomer found it gone from status after a reload)
    assert [(e.bolt, e.count, e.held) for e in _events(acts, BoltLocked)] == [("B1", 3, None)]
    assert core.status().locked == frozenset({"B1"})
    # a bolt skipped after its NOK stays skipped after a reload (a newcomer saw it tightened)
    skip = StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(3), bolts={
        "B3": NokRule(3, "skip")}))
    skip.feed(VehicleLoaded(1.0, "VIN1", "M", BOLTS, noks={"B3": 1}))
    assert skip.matcher is not None and "B3" in skip.matcher.skipped


def test_a_lock_is_recorded_and_stands_whatever_max_nok_a_reload_brings():
    """An operator trial: B11 locked after 3 NOKs, the station file's ``max_nok`` raised to 5
    and reloaded, and the operator tightened B11 twice more, no one having released it (the
    lock was read back from the streak against the new rule).  The lock is recorded when it
    happens (:class:`NoteLock`) and comes back as a lock until a person ends it."""
    d = _driver(NokPolicy(NokRule(max_nok=3)))
    for tid in (1, 2):
        acts = _tighten(d, 2, tid, ok=False)
        assert not [a for a in acts if isinstance(a, NoteLock)]
    acts = _tighten(d, 2, 3, ok=False)
    assert [a for a in acts if isinstance(a, NoteLock)] == [NoteLock("VIN1", "B2", 3, d.t)]
    # read back under max_nok 5: locked, as recorded (no second record of it)
    raised = StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(max_nok=5)))
    acts = raised.feed(VehicleLoaded(1.0, "VIN1", "M", BOLTS, noks={"B2": 3},
                                     locked=frozenset({"B2"})))
    assert raised.status().locked == frozenset({"B2"})
    assert not [a for a in acts if isinstance(a, NoteLock)]
    # the streak alone under 5 locks nothing (a lock released since is not in ``locked``)
    alone = StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(max_nok=5)))
    alone.feed(VehicleLoaded(1.0, "VIN1", "M", BOLTS, noks={"B2": 3}))
    assert alone.status().locked == frozenset()
    # a lowered max_nok locks a bolt at its streak when the vehicle comes back: recorded too
    lowered = StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(max_nok=2)))
    acts = lowered.feed(VehicleLoaded(1.0, "VIN1", "M", BOLTS, noks={"B1": 2, "B3": 1}))
    assert lowered.status().locked == frozenset({"B1"})
    assert [a for a in acts if isinstance(a, NoteLock)] == [NoteLock("VIN1", "B1", 2, 1.0)]


def test_the_section_is_checked_with_its_line():
    p = NokPolicy.from_node(YamlNode.parse(
        "max_nok: 2\nstrategy: skip\npsets: {125: {max_nok: 1}}\nbolts: {B07: {strategy: "
        "repeat}}\n"))
    assert p.default == NokRule(2, "skip") and p.psets == {125: NokRule(1, "skip")}
    assert p.bolts == {"B07": NokRule(2, "repeat")}
    for text, message in (("max_nok: 0\n", "out of range"), ("strategy: undo\n", "not one of"),
                          ("psets: {abc: {max_nok: 1}}\n", "a pset number"),
                          ("bolts: [B1]\n", "mapping of names")):
        with pytest.raises(ConfigError, match=message):
            NokPolicy.from_node(YamlNode.parse(text, "station.yaml"))


def test_the_loosen_strategy_needs_a_loosen_pset_refused_with_its_line():
    p = NokPolicy.from_node(YamlNode.parse(
        "strategy: loosen\nloosen_pset: 90\nbolts: {B07: {loosen_pset: 91}, B08: {strategy: "
        "repeat}}\n"))
    assert p.default == NokRule(3, "loosen", 90) and p.bolts["B07"].loosen_pset == 91
    assert p.rule("B08", None) == NokRule(3, "repeat", 90)   # may still be loosened
    for text, line, message in (
            ("max_nok: 2\nstrategy: loosen\n", 2, "loosen needs a loosen_pset"),
            ("psets:\n  125: {strategy: loosen}\n", 2, "loosen needs a loosen_pset"),
            ("loosen_pset: 90\npsets:\n  90: {strategy: loosen}\n", 3, "the pset itself"),
            ("loosen_pset: 0\n", 1, "out of range")):
        with pytest.raises(ConfigError, match=message) as err:
            NokPolicy.from_node(YamlNode.parse(text, "station.yaml"))
        assert (err.value.path, err.value.line) == ("station.yaml", line), text


def test_overrides_naming_what_no_bolt_table_has_are_refused_with_their_lines():
    from db.bolts import BoltSpec, BoltTable, ModelSpec, Parameters, Pset, Window

    w = Window(20.0, 18.0, 22.0)
    table = BoltTable((ModelSpec("M", (BoltSpec("B1", "b", (0, 0, 0), Parameters(1, w)),
                                       BoltSpec("B2", "b", (60, 0, 0), Parameters(2, w)))),),
                      psets=(Pset(5, None, w),))
    node = YamlNode.parse("loosen_pset: 90\npsets:\n  2: {max_nok: 1}\n  5: {max_nok: 2}\n"
                          "  7: {max_nok: 1}\nbolts:\n  B1: {loosen_pset: 2}\n  B9: {}\n",
                          "station.yaml")
    NokPolicy.from_node(node)
    errors = table_errors(node, table, "bolts.yaml")
    assert [e.line for e in errors] == [5, 8, 7]
    for e, words in zip(errors, ("pset 7: no bolt of bolts.yaml is tightened with it",
                                 "bolt B9: no model of bolts.yaml has it",
                                 "loosen_pset 2 tightens B2 (M) in bolts.yaml"), strict=True):
        assert words in str(e), e


#: B1 and B2 one batch, B3 another (at B3's place in BOLTS)
BATCHED = {k: replace(b, batch="A" if k != "B3" else "C") for k, b in BOLTS.items()}


def _batched(policy: NokPolicy, monkeypatch: pytest.MonkeyPatch) -> Driver:
    monkeypatch.setattr(test_core, "BOLTS", BATCHED)   # what the driver's vehicle loads
    return _driver(policy)


@pytest.mark.parametrize("counts", [False, True])
def test_a_nok_counts_in_its_batch_only_when_the_policy_says_so(counts, monkeypatch):
    """B1 OK and B2 NOK (skipped for the vehicle): batch A is finished only if a NOK counts
    in a batch; else B3 (batch C) waits for it, with the reason."""
    d = _batched(NokPolicy(NokRule(strategy="skip", count_in_batch=counts)), monkeypatch)
    _tighten(d, 1, 1, ok=True)
    _tighten(d, 2, 2, ok=False)
    assert ("B2" in d.core.matcher.counted) is counts
    sends = len(d.sends)
    _on(d, 3)
    if counts:
        assert d.sends[sends:] == ["B3"]
    else:
        assert len(d.sends) == sends
        # the order rule's own words, and the refusal the operator reads names the skip
        wait = d.core.matcher.why_blocked("B3")
        assert wait == Wait(WaitKind.BATCH, batches=(("A", ("B2",)),))
        assert wait_words(wait) == "finish batch A first: B2 remaining"
        refused = [e.reason for _, acts in d.log for e in published(acts, Refused)]
        assert reason_words(refused[-1]) == (
            "B3 must wait: finish batch A first: B2 remaining; B2 was skipped: NOK, skipped "
            "by the NOK policy")
    # an OK of the bolt later (a rework) clears it; so does its state coming back with the
    # vehicle after a restart (its last rundown a NOK)
    core = StationCore(PARAMS, leave_frames=2, nok=d.core.nok)
    core.feed(Started(d.t))
    core.feed(VehicleLoaded(d.t, "VIN1", "M", BATCHED, done=frozenset({"B1"}),
                            status={"B1": "ok", "B2": "nok"}, noks={"B2": 1}))
    assert core.matcher is not None
    assert ("B2" in core.matcher.counted) is counts
    assert (core.matcher.why_blocked("B3") is None) is counts


def test_count_in_batch_is_a_flag_per_rule_refused_with_its_line():
    p = NokPolicy.from_node(YamlNode.parse("count_in_batch: true\npsets:\n"
                                           "  2: {count_in_batch: false}\n", "station.yaml"))
    assert p.rule("B1", 1).count_in_batch and not p.rule("B2", 2).count_in_batch
    with pytest.raises(ConfigError, match=r"station.yaml:1.*true or false"):
        NokPolicy.from_node(YamlNode.parse("count_in_batch: sometimes\n", "station.yaml"))
