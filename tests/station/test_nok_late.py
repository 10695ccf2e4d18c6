"""The NOK policy for NOKs heard late (:mod:`stationd.station.nok`,
:mod:`~stationd.station.results`): a NOK whose push was lost, fetched when a later result
came or by the check of the controller's newest, counts as a live one does.  A supervisor's
trial (the controller keeping its results): a bolt locked after 4 NOKs in a row with
``max_nok`` 3, without a word of the NOK beyond the lock.  The bolt locks at ``max_nok``
however its NOKs arrived; a NOK made after that (the tool still on, the station not
knowing) is recorded and said."""

from __future__ import annotations

from typing import Any

from stationd.station.actions import CheckNewest, NoteLock, Record, SendParams
from stationd.station.events import BoltLocked, Notice, Said
from stationd.station.inputs import NewestChecked, ResultIn, Tick
from stationd.station.policy import NokPolicy, NokRule
from stationd.words import notice_words
from tests.station.test_core import Driver, _on, _ready, published
from tests.station.test_result_types import _enabled, _pulled_twice, res


def _locks(acts: list[Any]) -> list[tuple[str, int]]:
    """The locks published and those noted for the ledger, each (bolt, count)."""
    return [(e.bolt, e.count) for e in published(acts, BoltLocked)] + \
        [(a.bolt, a.count) for a in acts if isinstance(a, NoteLock)]


def _beyond(acts: list[Any]) -> list[Notice]:
    return [n for n in published(acts, Notice) if n.said is Said.NOK_AFTER_LOCK]


def _live_nok(d: Driver, tid: int) -> list[Any]:
    _enabled(d, 1)
    return d.feed(ResultIn(d.t, res(tid, 1, False, 1)))


def test_a_lost_nok_that_reaches_max_nok_locks_there_and_the_pushed_nok_after_it_is_said():
    """The trial: max_nok 3, B1 NOK twice (live); the third NOK's push lost, the operator
    pulls again at once (a fourth NOK, pushed, revealing the third).  B1 locks at 3, the
    third NOK's; the fourth is recorded, counted and said as made beyond the lock (it was:
    4 NOKs in a row, locked at 4, no word of max_nok)."""
    d = _ready(nok=NokPolicy(NokRule(max_nok=3)))
    acts = _live_nok(d, 38) + _live_nok(d, 39)
    assert not _locks(acts)
    d.t += 1.0
    acts = _pulled_twice(d, False, False)             # 41 lost then 42 pushed, both NOK
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 41), ("B1", 42)]
    assert _locks(acts) == [("B1", 3), ("B1", 3)]     # published and noted, once, at 3
    assert d.core.matcher.locked == {"B1": 3}
    [said] = _beyond(acts)
    assert (said.bolt, said.count, said.locked_at, said.tightening_id) == ("B1", 4, 3, 42)
    assert said.level == "warning"
    assert notice_words(said) == (
        "B1: tightening 42, a NOK made after B1 had reached 3 NOK in a row (the push of one "
        "of them lost: the station did not know yet), recorded: 4 NOK in a row; B1 stays "
        "locked for a supervisor")


def test_max_nok_1_a_lost_nok_then_a_pushed_nok_locks_at_1():
    d = _ready(nok=NokPolicy(NokRule(max_nok=1)))
    acts = _pulled_twice(d, False, False)
    assert _locks(acts) == [("B1", 1), ("B1", 1)]
    assert [n.count for n in _beyond(acts)] == [2]


def test_two_nok_fetched_by_the_check_lock_at_the_first_and_say_the_second():
    """B1 enabled, the operator pulls twice (both NOK, both pushes lost) and leaves; the
    check as B1's window ends fetches both: B1 locks at max_nok (1), the first's, and the
    second is said as beyond the lock, not a second lock "after 2 NOK"."""
    d = _ready(nok=NokPolicy(NokRule(max_nok=1)))
    d.answer_checks = False
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 3.0
    _on(d, 2, 3)
    d.t += d.core.late_result_s + 1.0
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    acts = d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                           made_at=enabled_at + 2.5, live=True))
    acts += d.feed(ResultIn(d.t, res(42, 1, False, 1), fetched=True, follows=40,
                            made_at=enabled_at + 2.8, live=True))
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 41), ("B1", 42)]
    assert _locks(acts) == [("B1", 1), ("B1", 1)]
    assert [(n.count, n.tightening_id) for n in _beyond(acts)] == [(2, 42)]
    assert d.core.matcher.locked == {"B1": 1}


def test_a_lost_nok_below_max_nok_then_a_pushed_nok_follows_the_policy_as_before():
    """Neither reaches max_nok early: the pushed NOK locks where it is the max_nok-th, and
    no NOK is said beyond a lock."""
    d = _ready(nok=NokPolicy(NokRule(max_nok=2)))
    acts = _pulled_twice(d, False, False)
    assert _locks(acts) == [("B1", 2), ("B1", 2)] and not _beyond(acts)
    d = _ready(nok=NokPolicy(NokRule(max_nok=3)))
    acts = _pulled_twice(d, False, False)
    assert not _locks(acts) and not _beyond(acts) and d.core._noks["B1"] == 2


def test_two_loosening_nok_fetched_by_the_check_lock_once():
    """Under ``loosen`` (max_nok 2): B1's NOK (live) sends its loosen pset next; the operator
    pulls it twice, both loosenings NOK, both pushes lost; the check fetches both.  B1 locks
    at 2 (the first loosening NOK's), and the second is said beyond the lock."""
    d = _ready(nok=NokPolicy(NokRule(max_nok=2, strategy="loosen", loosen_pset=91)))
    _live_nok(d, 38)
    d.answer_checks = False
    sent = _enabled(d, 1)
    assert sent.loosen and sent.selection.pset == 91
    enabled_at = d.t
    d.t += 3.0
    _on(d, 2, 3)
    d.t += d.core.late_result_s + 1.0
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    acts = d.feed(ResultIn(d.t, res(41, 91, False, 2), fetched=True, follows=40,
                           made_at=enabled_at + 2.5, live=True))
    acts += d.feed(ResultIn(d.t, res(42, 91, False, 2), fetched=True, follows=40,
                            made_at=enabled_at + 2.8, live=True))
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    assert [int(a.result.tightening_id) for a in acts if isinstance(a, Record)] == [41, 42]
    assert _locks(acts) == [("B1", 2), ("B1", 2)]
    assert [(n.count, n.locked_at, n.tightening_id) for n in _beyond(acts)] == [(3, 2, 42)]


def test_a_lost_nok_at_max_nok_answered_by_an_unreadable_result_locks_and_its_release_loosens():
    """A new user's trial (the loosen policy, max_nok 3): B1 NOK, loosened, NOK, loosened, a
    third NOK whose push was lost, then an unreadable result pushed (revealing the third).
    The bolt was held, not locked, and releasing the hold reopened it for its tightening
    pset: a NOK joint tightened again without the loosen step.  It locks at 3 (the held
    result, whatever it was, came after the third NOK) and is held; the release ends both
    and its loosen pset goes first."""
    from stationd.station.commands import ReleaseBolt
    from stationd.station.events import BoltToLoosen
    from stationd.station.inputs import ResultsSkipped, UnreadableIn
    from tests.station.test_commands import SUPERVISOR, _answer
    from tests.station.test_loosen import POLICY, _rundown
    from tests.station.test_result_types import unreadable

    d = _ready(nok=POLICY)
    _rundown(d, 1, 16, ok=False)
    _rundown(d, 1, 17, ok=True, rtype=2)
    _rundown(d, 1, 18, ok=False)
    _rundown(d, 1, 19, ok=True, rtype=2)
    sent = _enabled(d, 1)
    assert not sent.loosen                           # the tightening pset, after a loosening
    enabled_at = d.t
    d.t += 5.0
    acts = d.feed(ResultsSkipped(d.t, 21))
    acts += d.feed(ResultIn(d.t, res(20, 1, False, 1), fetched=True, follows=19,
                            made_at=enabled_at + 3.0, live=True, before=21))
    acts += d.feed(UnreadableIn(d.t, unreadable(21, 1)))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 20)]
    assert ("B1", 3) in _locks(acts) and d.core.matcher.locked == {"B1": 3}
    assert "B1" in d.core.matcher.held
    acts = d.command(1, ReleaseBolt("VIN1", "B1", "checked"), SUPERVISOR)
    assert _answer(acts).answer.accepted
    assert "B1" not in d.core.matcher.locked and "B1" not in d.core.matcher.held
    assert [e.bolt for e in published(acts, BoltToLoosen)] == ["B1"]
    n = len(d.log)
    _on(d, 1, 3)
    [again] = [a for _, acts in d.log[n:] for a in acts if isinstance(a, SendParams)]
    assert again.loosen                              # the loosen pset first


def _nok_fetched_push_awaited(policy: NokPolicy) -> Driver:
    """B1 enabled; 42 pushed skips 41, B1's NOK whose push was lost, fetched: its NOK policy
    owed until 42 is judged."""
    from stationd.station.inputs import ResultsSkipped

    d = _ready(nok=policy)
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 5.0
    d.feed(ResultsSkipped(d.t, 42))
    d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                    made_at=enabled_at + 3.0, live=True, before=42))
    return d


def test_a_loosen_command_between_a_lost_nok_and_its_pushed_result_keeps_the_lock_due():
    """A reviewer: a person's loosen command landing while a fetched NOK's policy waits for
    the pushed result after it dropped that policy (its lock at max_nok): the command ended
    the bolt's "NOK last", which the owed policy reads.  The lock comes, as without the
    command and as the records say at a reload (a loosen command ends no NOK row)."""
    from stationd.station.commands import LoosenBolt
    from tests.station.test_commands import SUPERVISOR

    d = _nok_fetched_push_awaited(NokPolicy(NokRule(max_nok=1, strategy="repeat",
                                                    loosen_pset=90)))
    assert d.core._lock_due == {"B1": 1} and "B1" not in d.core.matcher.locked
    acts = d.command(1, LoosenBolt("VIN1", "B1", "rework"), SUPERVISOR)
    assert "B1" in d.core._loosen, acts
    d.feed(ResultIn(d.t, res(42, 1, True, 3)))   # a batch increment pushed: judged
    assert d.core.matcher.locked.get("B1") == 1, d.core.matcher.locked


def test_an_ok_entered_for_the_unreadable_result_after_a_lost_nok_ends_its_lock():
    """As above, max_nok 1: locked and held; the supervisor reads OK on the controller and
    enters it: the bolt is done, neither locked nor held (an OK answers the NOKs before it,
    as a pushed OK does)."""
    from stationd.station.commands import EnterOutcome
    from stationd.station.inputs import UnreadableIn
    from tests.station.test_commands import SUPERVISOR, _answer
    from tests.station.test_result_types import unreadable

    d = _nok_fetched_push_awaited(NokPolicy(NokRule(max_nok=1)))
    d.feed(UnreadableIn(d.t, unreadable(42, 1)))
    assert d.core.matcher.locked == {"B1": 1} and "B1" in d.core.matcher.held
    acts = d.command(1, EnterOutcome("VIN1", "B1", True, 50.1, 31.0, "read on the controller"),
                     SUPERVISOR)
    assert _answer(acts).answer.accepted
    m = d.core.matcher
    assert "B1" in m.done and "B1" not in m.locked and "B1" not in m.held
