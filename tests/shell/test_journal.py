"""The journal's refusals: each written once, then counted (a wrench held still between two
bolts alternated two refusals, a line a second)."""

from __future__ import annotations

from stationd.reasons import Reason, Why
from stationd.shell.journal import RefusalJournal

TILTED = Reason(Why.TILTED, angle_deg=12.5, limit=10.0)
UNSTABLE = Reason(Why.NOT_STABLE, bolt="B21", count=1, needed=3)


def test_two_refusals_alternating_are_written_once_each_then_counted():
    j = RefusalJournal(quiet_s=60.0)
    lines = [j.refused(TILTED if k % 2 == 0 else UNSTABLE, 100.0 + k) for k in range(40)]
    written = [x for x in lines if x is not None]
    assert written == ["no bolt: wrench tilted 12.5 deg (> 10 deg)",
                       "no bolt: B21: hold the wrench still on it (1 of 3 frames)"]
    # a bolt selected (a change of state): the episode's counts, one line each
    assert j.ended(140.0) == [
        "no bolt: wrench tilted 12.5 deg (> 10 deg): again 19 times in 40 s",
        "no bolt: B21: hold the wrench still on it (1 of 3 frames): again 19 times in 39 s"]
    assert j.ended(141.0) == []                       # said once
    assert j.refused(TILTED, 142.0) == "no bolt: wrench tilted 12.5 deg (> 10 deg)"


def test_a_refusal_that_lasts_is_written_again_after_the_quiet_time_with_its_count():
    j = RefusalJournal(quiet_s=60.0)
    assert j.refused(TILTED, 0.0) is not None
    assert [j.refused(TILTED, float(t)) for t in range(1, 60)] == [None] * 59
    # the measurement changed (13.9 deg), the refusal did not: its key is kind and bolts
    again = j.refused(Reason(Why.TILTED, angle_deg=13.9, limit=10.0), 61.0)
    assert again == ("no bolt: wrench tilted 13.9 deg (> 10 deg) "
                     "(again 59 times in the 61 s before)")
    assert j.ended(62.0) == []


def test_another_bolt_is_another_refusal():
    j = RefusalJournal()
    assert j.refused(Reason(Why.DONE, bolt="B18"), 0.0) == "no bolt: B18 is already done"
    assert j.refused(Reason(Why.DONE, bolt="B01"), 1.0) == "no bolt: B01 is already done"
    assert j.refused(Reason(Why.DONE, bolt="B18"), 2.0) is None


def test_the_count_reads_in_words():
    for n, said in ((1, "again once in 10 s"), (2, "again 2 times in 10 s")):
        j = RefusalJournal()
        j.refused(TILTED, 0.0)
        for k in range(n):
            j.refused(TILTED, 1.0 + k)
        (line,) = j.ended(10.0)
        assert line.endswith(said), line
