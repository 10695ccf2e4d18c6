"""The calibration check's rules in the pure core: pairs start untrusted, a check makes them
trusted or puts one in fault (moved) with its figure, a bolt end only an untrusted pair sees is
refused with its reason, checks are asked at the start, when a vehicle arrives, while idle and
on command; without references nothing changes."""

from __future__ import annotations

import random
from typing import Any

import pytest

from stationd.localize.check import PairCheck, RefMeasure, RefWhy, Verdict
from stationd.reasons import Unchecked, UncheckedKind, Why
from stationd.station.actions import LoadVehicle, Publish, RecordCommand, Reply, SendParams
from stationd.station.commands import CheckCalibration, Issuer, Right
from stationd.station.core import StationCore
from stationd.station.events import Localized, Notice, PairChecked, Said
from stationd.station.inputs import (
    CommandDone,
    CommandIn,
    LiftRead,
    LoadedBolt,
    LocalizedIn,
    Started,
    Tick,
    VehicleLoaded,
    VinSent,
)
from stationd.station.matching import MatchParams
from stationd.station.trust import (
    Asked,
    CheckAsked,
    MeasureReferences,
    PairTrust,
    RecordCheck,
    ReferencesChecked,
    reason_of,
)
from stationd.words import check_asked_words, check_words, notice_words, reason_words

BOLTS = {"B1": LoadedBolt((0.0, 0.0, 0.0), 1), "B2": LoadedBolt((60.0, 0.0, 0.0), 2)}
PARAMS = MatchParams(tolerance_mm=8.0, margin_mm=6.0, stable_frames=2, max_age_s=0.5)
PAIRS = ("pair1", "pair2")
ENGINEER = Issuer("eve", frozenset({Right.CALIBRATE}), "cli")


def ok(pair: str) -> PairCheck:
    return PairCheck(pair, Verdict.OK, (RefMeasure("R1", 0.1, (0.0, 0.0, 0.0)),), "R1", 0.1, 2.0)


def moved(pair: str, off: float = 3.4) -> PairCheck:
    return PairCheck(pair, Verdict.MOVED, (RefMeasure("R1", off, (off, 0.0, 0.0)),), "R1", off,
                     2.0)


def unchecked(pair: str, why: RefWhy = RefWhy.NOT_FOUND) -> PairCheck:
    return PairCheck(pair, Verdict.NOT_CHECKED, (RefMeasure("R1", why=why),), "R1", None, 2.0,
                     why)


def _core(trust: bool = True) -> StationCore:
    return StationCore(PARAMS, leave_frames=2,
                       trust=PairTrust(PAIRS, period_s=600.0) if trust else None)


def _kinds(acts: list[Any], kind: type) -> list[Any]:
    return [a for a in acts if isinstance(a, kind)]


def _events(acts: list[Any], kind: type) -> list[Any]:
    return [a.event for a in acts if isinstance(a, Publish) and isinstance(a.event, kind)]


def _loaded(core: StationCore, t: float = 10.0) -> list[Any]:
    """Started, the lift up, the vehicle loaded and its VIN sent: the actions of the load."""
    core.feed(Started(t))
    acts = core.feed(LiftRead(t + 1, True, True, 7, "VIN1"))
    assert _kinds(acts, LoadVehicle)
    acts = core.feed(VehicleLoaded(t + 2, "VIN1", "M", BOLTS))
    core.feed(VinSent(t + 2, "VIN1"))
    return acts


def _at(core: StationCore, t: float, pairs: tuple[str, ...], x: float = 0.0) -> list[Any]:
    return core.feed(LocalizedIn(t, t - 0.05, (x, 0.0, 0.0), pairs=pairs))


def test_pairs_start_untrusted_and_a_check_is_asked_at_once():
    core = _core()
    acts = core.feed(Started(1.0))
    (ask,) = _kinds(acts, MeasureReferences)
    assert ask.pairs == PAIRS and ask.why == CheckAsked(Asked.STARTED) and ask.request is None
    assert check_asked_words(ask.why) == "station started"
    assert set(core.trust.untrusted()) == set(PAIRS)
    assert all(r.kind is Why.PAIR_UNCHECKED for r in core.trust.untrusted().values())


def test_a_bolt_seen_only_by_an_untrusted_pair_is_refused_with_that_reason():
    core = _core()
    acts = _loaded(core)
    # the vehicle's arrival asks for a check; until it answers nothing is trusted
    arrived = _kinds(acts, MeasureReferences)[0].why
    assert arrived == CheckAsked(Asked.ARRIVED, vin="VIN1")
    assert check_asked_words(arrived) == "vehicle VIN1 arrived"
    for k in range(4):
        acts = _at(core, 20.0 + k, ("pair1",))
        assert not _kinds(acts, SendParams)
    (loc,) = _events(acts, Localized)
    assert loc.reason.kind is Why.PAIR_UNCHECKED and loc.reason.pair == "pair1"
    assert "checking for vehicle VIN1" in reason_words(loc.reason)
    acts = core.feed(ReferencesChecked(30.0, (ok("pair1"), moved("pair2"))))
    checked = {e.pair: e for e in _events(acts, PairChecked)}
    assert checked["pair1"].trusted and not checked["pair2"].trusted
    assert checked["pair2"].why.kind is Why.PAIR_MOVED
    assert check_words(checked["pair2"]) == "pair2 moved: reference R1 off by 3.4 mm (> 2 mm)"
    assert [a.check.pair for a in _kinds(acts, RecordCheck)] == ["pair1", "pair2"]
    # the moved pair alone: refused with its figure; the trusted pair selects
    for k in range(3):
        acts = _at(core, 31.0 + k, ("pair2",))
        assert not _kinds(acts, SendParams)
    assert _events(acts, Localized)[0].reason.kind is Why.PAIR_MOVED
    acts = _at(core, 40.0, ("pair1", "pair2"))   # fused with the moved pair: refused too
    assert not _kinds(acts, SendParams)
    sent = [a for k in range(3) for a in _kinds(_at(core, 41.0 + k, ("pair1",)), SendParams)]
    assert [s.bolt for s in sent] == ["B1"]


def test_which_pairs_saw_it_must_be_known():
    core = _core()
    _loaded(core)
    core.feed(ReferencesChecked(15.0, (ok("pair1"), ok("pair2"))))
    acts = [a for k in range(3) for a in _at(core, 20.0 + k, ())]
    assert not _kinds(acts, SendParams)


def test_a_moved_pair_stays_moved_until_a_check_finds_it_in_place():
    core = _core()
    _loaded(core)
    core.feed(ReferencesChecked(15.0, (ok("pair1"), moved("pair2"))))
    # the next vehicle's arrival distrusts the others, not the moved one's fault
    core.trust.distrust(Unchecked(UncheckedKind.ARRIVAL, vin="VIN2"))
    assert core.trust.why["pair2"].kind is Why.PAIR_MOVED
    assert reason_words(core.trust.why["pair1"]) == \
        "pair1 not checked against the references: checking for vehicle VIN2"
    # an unchecked result (the reference covered) does not clear it either
    core.feed(ReferencesChecked(16.0, (ok("pair1"), unchecked("pair2"))))
    assert core.trust.why["pair2"].kind is Why.PAIR_UNCHECKED
    core.feed(ReferencesChecked(17.0, (ok("pair1"), ok("pair2"))))
    assert core.trust.untrusted() == {}


def test_lift_references_away_leave_a_pair_as_it_was():
    core = _core()
    core.feed(Started(1.0))
    core.feed(ReferencesChecked(2.0, (ok("pair1"), ok("pair2"))))
    acts = core.feed(ReferencesChecked(3.0, (ok("pair1"), unchecked("pair2", RefWhy.LIFT_AWAY))))
    assert core.trust.untrusted() == {}
    assert [e.trusted for e in _events(acts, PairChecked)] == [True, True]


def test_checks_are_asked_while_idle_every_period_and_retried_with_a_vehicle():
    core = _core()
    core.feed(Started(0.0))
    assert not _kinds(core.feed(Tick(5.0)), MeasureReferences)      # one is pending
    core.feed(ReferencesChecked(1.0, (ok("pair1"), ok("pair2"))))
    assert not _kinds(core.feed(Tick(500.0)), MeasureReferences)
    (ask,) = _kinds(core.feed(Tick(601.0)), MeasureReferences)
    assert ask.why == CheckAsked(Asked.PERIODIC) and ask.lift_at_height is False
    assert check_asked_words(ask.why) == "periodic check"
    assert not _kinds(core.feed(Tick(602.0)), MeasureReferences)    # pending
    assert _kinds(core.feed(Tick(700.0)), MeasureReferences)        # lost: asked again
    # with a vehicle, an unchecked pair is checked again every RETRY_S
    core = _core()
    _loaded(core, t=1000.0)
    core.feed(ReferencesChecked(1003.0, (ok("pair1"), unchecked("pair2"))))
    assert not _kinds(core.feed(Tick(1005.0)), MeasureReferences)
    (ask,) = _kinds(core.feed(Tick(1013.5)), MeasureReferences)
    assert ask.lift_at_height is True


def test_a_check_on_command_is_answered_with_each_pairs_verdict():
    core = _core()
    core.feed(Started(0.0))
    nobody = Issuer("op", frozenset({Right.SKIP}), "cli")
    (reply,) = _kinds(core.feed(CommandIn(1.0, 1, CheckCalibration(), nobody)), Reply)
    assert reply.answer.reason.kind is Why.NO_RIGHT and reply.answer.reason.right == "calibrate"
    acts = core.feed(CommandIn(2.0, 2, CheckCalibration("after the crash"), ENGINEER))
    assert _kinds(acts, RecordCommand)
    (ask,) = _kinds(core.feed(CommandDone(2.1, 2)), MeasureReferences)
    assert ask.request == 2 and ask.why == CheckAsked(Asked.COMMAND, user="eve")
    assert check_asked_words(ask.why) == "asked by eve"
    acts = core.feed(ReferencesChecked(2.5, (ok("pair1"), moved("pair2", 4.0)), request=2))
    (reply,) = _kinds(acts, Reply)
    assert reply.answer.accepted and reply.answer.result["pair2"]["verdict"] == "moved"
    assert reply.answer.result["pair2"]["offset_mm"] == pytest.approx(4.0)
    assert reply.answer.result["pair1"]["references"]["R1"]["offset_mm"] == pytest.approx(0.1)


def test_without_references_nothing_changes_and_it_is_said():
    core = _core(trust=False)
    acts = core.feed(Started(0.0))
    assert not _kinds(acts, MeasureReferences)
    assert any("no calibration check configured" in notice_words(e)
               for e in _events(acts, Notice))
    assert [e.said for e in _events(acts, Notice)] == [Said.NO_REFERENCES]
    core.feed(LiftRead(1.0, True, True, 7, "VIN1"))
    assert not _kinds(core.feed(VehicleLoaded(2.0, "VIN1", "M", BOLTS)), MeasureReferences)
    core.feed(VinSent(2.0, "VIN1"))
    sent = [a for k in range(3) for a in _kinds(_at(core, 3.0 + k, ()), SendParams)]
    assert [s.bolt for s in sent] == ["B1"]
    (reply,) = _kinds(core.feed(CommandIn(9.0, 1, CheckCalibration(), ENGINEER)), Reply)
    assert reply.answer.reason.kind is Why.NO_REFERENCES
    assert not _kinds(core.feed(Tick(5000.0)), MeasureReferences)


def test_random_sequences_never_send_for_a_bolt_end_of_an_untrusted_pair():
    """Random checks (ok, moved, unchecked, lift away), vehicles and localizations by random
    pairs: every parameters sent follow only localizations whose pairs were all trusted by
    the last checks (the driver's own bookkeeping, not the core's)."""
    rng = random.Random(21)
    sends = 0
    for _ in range(30):
        core = _core()
        core.feed(Started(0.0))
        trusted: dict[str, bool] = dict.fromkeys(PAIRS, False)
        t, vin = 1.0, 0
        streak_ok: list[bool] = []
        for _step in range(120):
            t += 0.1
            roll = rng.random()
            if roll < 0.1:
                checks = []
                for p in PAIRS:
                    c = rng.choice([ok, moved, unchecked,
                                    lambda q: unchecked(q, RefWhy.LIFT_AWAY)])(p)
                    checks.append(c)
                    if c.verdict is Verdict.OK:
                        trusted[p] = True
                    elif c.why is not RefWhy.LIFT_AWAY:
                        trusted[p] = False
                core.feed(ReferencesChecked(t, tuple(checks)))
            elif roll < 0.15:
                vin += 1
                core.feed(LiftRead(t, False, False, 7, None))
                core.feed(LiftRead(t, True, True, 7, f"VIN{vin}"))
                core.feed(VehicleLoaded(t, f"VIN{vin}", "M", BOLTS))
                core.feed(VinSent(t, f"VIN{vin}"))
                for p in PAIRS:   # an arrival distrusts every pair until checked
                    trusted[p] = False
            else:
                pairs = tuple(p for p in PAIRS if rng.random() < 0.6)
                acts = _at(core, t, pairs, rng.choice([0.0, 60.0]))
                streak_ok.append(bool(pairs) and all(trusted[p] for p in pairs))
                if _kinds(acts, SendParams):
                    # the matcher's stable frames: the last two localizations chose it
                    assert all(streak_ok[-PARAMS.stable_frames:]), streak_ok[-3:]
                    sends += 1
    assert sends >= 10   # the rule was exercised, not vacuous


def test_a_check_asked_before_the_vehicle_arrived_trusts_no_pair_for_it():
    """The start check's grabs may still run when a vehicle arrives: their frames may predate
    the vehicle, so their "in place" trusts nothing; a pair they found moved is moved."""
    core = _core()
    (start_ask,) = _kinds(core.feed(Started(1.0)), MeasureReferences)
    core.feed(LiftRead(2.0, True, True, 7, "VIN1"))
    acts = core.feed(VehicleLoaded(3.0, "VIN1", "M", BOLTS))
    (arrival_ask,) = _kinds(acts, MeasureReferences)
    assert start_ask.t == 1.0 and arrival_ask.t == 3.0
    acts = core.feed(ReferencesChecked(4.0, (ok("pair1"), moved("pair2")), None, start_ask.t))
    checked = {e.pair: e for e in _events(acts, PairChecked)}
    assert not checked["pair1"].trusted and checked["pair1"].why.kind is Why.PAIR_UNCHECKED
    assert checked["pair2"].why.kind is Why.PAIR_MOVED
    assert core.trust is not None and core.trust.asked_t == 3.0    # the arrival's still asked
    acts = core.feed(ReferencesChecked(5.0, (ok("pair1"), ok("pair2")), None, arrival_ask.t))
    assert all(e.trusted for e in _events(acts, PairChecked))
    assert not core.trust.untrusted()


def test_a_pair_not_measured_is_unchecked_with_the_check_s_own_why_typed():
    """The check's verdict, typed in the refusal (the worst reference, its why as the check
    said it, the check's own note); its words are the ones the core wrote before."""
    r = reason_of(unchecked("pair2"))
    assert r is not None and r.reference == "R1" and r.unchecked == Unchecked(
        UncheckedKind.NOT_MEASURED, reference="R1", measure="not found")
    assert reason_words(r) == "pair2 not checked against the references: reference R1 not found"
    down = PairCheck("pair1", Verdict.NOT_CHECKED, (), None, None, 2.0, None, "the pair is down")
    assert reason_words(reason_of(down)) == \
        "pair1 not checked against the references: nothing measured (the pair is down)"
