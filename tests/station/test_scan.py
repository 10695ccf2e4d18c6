"""The scan plan: pairs that see the marker every cycle, the others every n-th, all of them
as soon as a watched pair loses it."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stationd.station.scan import ScanPlan

PAIRS = ["pair1", "pair2", "pair3", "pair4"]


def test_with_nothing_seen_every_pair_every_cycle():
    plan = ScanPlan(every=4)
    for _ in range(5):
        assert plan.choose(PAIRS) == PAIRS
        plan.saw({n: False for n in PAIRS})


def test_a_pair_that_sees_the_marker_is_watched_and_the_others_scanned_every_fourth():
    plan = ScanPlan(every=4)
    assert plan.choose(PAIRS) == PAIRS
    plan.saw({"pair1": False, "pair2": True, "pair3": False, "pair4": False})
    chosen = []
    for _ in range(8):
        c = plan.choose(PAIRS)
        chosen.append(c)
        plan.saw({n: n == "pair2" for n in c})
    assert chosen == [["pair2"], ["pair2"], ["pair2"], PAIRS] * 2


def test_losing_the_marker_in_a_watched_pair_scans_all_next_cycle():
    plan = ScanPlan(every=4)
    plan.choose(PAIRS)
    plan.saw({"pair1": True, "pair2": True, "pair3": False, "pair4": False})
    assert plan.choose(PAIRS) == ["pair1", "pair2"]
    plan.saw({"pair1": True, "pair2": False})       # it left pair2's view: where is it now?
    assert plan.choose(PAIRS) == PAIRS


def test_a_full_scan_that_finds_it_in_another_pair_adds_that_pair():
    plan = ScanPlan(every=2)
    plan.choose(PAIRS)
    plan.saw({"pair1": True, "pair2": False, "pair3": False, "pair4": False})
    assert plan.choose(PAIRS) == ["pair1"]
    plan.saw({"pair1": True})
    assert plan.choose(PAIRS) == PAIRS                # the every-2nd full scan
    plan.saw({"pair1": True, "pair2": False, "pair3": True, "pair4": False})
    assert plan.choose(PAIRS) == ["pair1", "pair3"]


def test_every_must_be_positive():
    with pytest.raises(ValueError):
        ScanPlan(every=0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.dictionaries(st.sampled_from(PAIRS), st.booleans()), max_size=30),
       st.integers(1, 6))
def test_no_pair_waits_more_than_every_cycles_and_a_lost_marker_means_a_full_scan(seq, every):
    """Whatever the pairs see, each pair is localized at least once in any ``every``
    consecutive cycles, and the cycle after a watched pair stops seeing it is a full scan."""
    plan = ScanPlan(every=every)
    last = dict.fromkeys(PAIRS, -1)
    lost = False
    for k, seen in enumerate(seq):
        watched = plan.watching
        chosen = plan.choose(PAIRS)
        if lost:
            assert chosen == PAIRS
        for n in chosen:
            last[n] = k
        assert all(k - last[n] < every for n in PAIRS)
        result = {n: seen.get(n, False) for n in chosen}
        lost = any(not result.get(n, True) for n in watched & set(chosen))
        plan.saw(result)
