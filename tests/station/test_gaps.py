"""No gap in the results: the ids between the last recorded and the controller's newest are
fetched after a reconnect (the pure rule; through the daemon over Open Protocol:
``tests/shell/test_gaps_daemon.py``)."""

from __future__ import annotations

from stationd.station.gaps import GapPlan, NoFetch, plan
from stationd.words import gap_plan_words


def test_the_ids_between_the_last_recorded_and_the_newest_are_fetched():
    assert plan(10, 13) == GapPlan((11, 12, 13))
    assert plan(10, 10) == GapPlan()
    assert plan(None, 500) == GapPlan(why=NoFetch.NOTHING_RECORDED, newest=500)
    assert gap_plan_words(plan(None, 500)) == \
        "no tightening recorded yet: counting from the controller's newest, 500"
    assert plan(800, 12) == GapPlan(why=NoFetch.IDS_RESTARTED, newest=12, last_recorded=800)
    assert gap_plan_words(plan(800, 12)) == ("the controller's newest tightening (12) is older "
                                             "than the last recorded (800): its ids restarted")
    assert gap_plan_words(plan(10, 13)) == ""
    far = plan(10, 1000, most=5)
    assert far.fetch == (996, 997, 998, 999, 1000) and far.gap == (11, 995)
