"""The scan plan: pairs that see the marker decide every cycle, the others are scouted every
n-th cycle after the decision, all of them decide as soon as a watched pair loses it."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stationd.station.scan import Cycle, ScanPlan

PAIRS = ["pair1", "pair2", "pair3", "pair4"]


def test_with_nothing_seen_every_pair_decides_every_cycle():
    plan = ScanPlan(every=4)
    for _ in range(5):
        assert plan.choose(PAIRS) == Cycle(PAIRS, [])
        plan.saw({n: False for n in PAIRS})


def test_a_pair_that_sees_the_marker_is_watched_and_the_others_scouted_every_fourth():
    plan = ScanPlan(every=4)
    assert plan.choose(PAIRS) == Cycle(PAIRS, [])
    plan.saw({"pair1": False, "pair2": True, "pair3": False, "pair4": False})
    cycles = []
    for _ in range(8):
        c = plan.choose(PAIRS)
        cycles.append(c)
        plan.saw({n: n == "pair2" for n in c.decide + c.scout})
    others = ["pair1", "pair3", "pair4"]
    assert cycles == [Cycle(["pair2"], []), Cycle(["pair2"], []), Cycle(["pair2"], []),
                      Cycle(["pair2"], others)] * 2


def test_losing_the_marker_in_a_watched_pair_makes_every_pair_decide_next():
    plan = ScanPlan(every=4)
    plan.choose(PAIRS)
    plan.saw({"pair1": True, "pair2": True, "pair3": False, "pair4": False})
    assert plan.choose(PAIRS) == Cycle(["pair1", "pair2"], [])
    plan.saw({"pair1": True, "pair2": False})       # it left pair2's view: where is it now?
    assert plan.choose(PAIRS) == Cycle(PAIRS, [])


def test_a_scout_that_finds_it_in_another_pair_adds_that_pair_to_the_decision():
    plan = ScanPlan(every=2)
    plan.choose(PAIRS)
    plan.saw({"pair1": True, "pair2": False, "pair3": False, "pair4": False})
    assert plan.choose(PAIRS) == Cycle(["pair1"], [])
    plan.saw({"pair1": True})
    c = plan.choose(PAIRS)
    assert c == Cycle(["pair1"], ["pair2", "pair3", "pair4"])
    plan.saw({"pair1": True})                                   # the decision's pairs
    plan.saw({"pair2": False, "pair3": True, "pair4": False})   # then the scout's
    assert plan.choose(PAIRS).decide == ["pair1", "pair3"]


def test_every_must_be_positive():
    with pytest.raises(ValueError):
        ScanPlan(every=0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.dictionaries(st.sampled_from(PAIRS), st.booleans()), max_size=30),
       st.integers(1, 6))
def test_no_pair_waits_more_than_every_cycles_and_a_lost_marker_means_all_decide(seq, every):
    """Whatever the pairs see, each pair is localized (deciding or scouted) at least once in
    any ``every`` consecutive cycles; the watched pairs always decide; and the cycle after a
    watched pair stops seeing the marker, every pair decides."""
    plan = ScanPlan(every=every)
    last = dict.fromkeys(PAIRS, -1)
    lost = False
    for k, seen in enumerate(seq):
        watched = plan.watching
        c = plan.choose(PAIRS)
        assert sorted(c.decide + c.scout) == sorted(set(c.decide + c.scout))
        assert watched <= set(c.decide)
        if lost:
            assert c == Cycle(PAIRS, [])
        for n in c.decide + c.scout:
            last[n] = k
        assert all(k - last[n] < every for n in PAIRS)
        decided = {n: seen.get(n, False) for n in c.decide}
        lost = any(not decided.get(n, True) for n in watched)
        plan.saw(decided)
        if c.scout and not lost:
            plan.saw({n: seen.get(n, False) for n in c.scout})
