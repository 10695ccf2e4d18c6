"""A result fetched without its type (MID 0065 at a revision that has none), its bolt held,
then pushed with its type (:meth:`stationd.station.results.ResultRules._typed_copy`): where
its own time puts it under the enable it was fetched for, it is that enable's rundown,
recorded to its bolt and counted once, its hold ended.  An integrator's trial: the typed
push was taken for a copy "stored once", B11's second NOK never counted, B47's OK left held,
released and tightened twice (found with the diagnosis of a helper session)."""

from __future__ import annotations

from datetime import datetime
from typing import Any

import pytest

from drivers.wrench import UnreadableResult
from stationd.station.actions import CheckNewest, Publish, Record
from stationd.station.events import Notice, Said
from stationd.station.inputs import NewestChecked, ResultCopy, ResultIn, Tick, UnreadableIn
from stationd.words import notice_words
from tests.station.test_core import _ready
from tests.station.test_result_types import _enabled, res

WHEN = datetime(2026, 11, 29, 8, 0, 0)


def _untyped_fetch(tid: int, pset: int) -> UnreadableResult:
    """MID 0065 revision 1 as the driver hands it while the pushes carry a type."""
    return UnreadableResult(
        raw=f"01180065001         01{tid:010d}0300{pset}" + "x" * 60, mid=65, revision=1,
        error="MID 0065 revision 1 carries no result type", tightening_id=tid, pset=pset,
        timestamp=WHEN, fetched=True, laid_out_as=1, header_len=20)


def _held_by_an_untyped_copy(retry: bool) -> tuple[Any, float]:
    """B1 on (after its own NOK 40: a retry; else after B2's enable), the check with the tool
    on fetches 41 without a type: B1 held.  The driver, and when B1's tool went on."""
    d = _ready()
    d.answer_checks = False
    if retry:
        _enabled(d, 1)
        d.feed(ResultIn(d.t, res(40, 1, False, 1)))       # B1's first NOK: tool off
    else:
        _enabled(d, 2)
        d.feed(ResultIn(d.t, res(40, 2, True, 1)))        # B2 OK
    _enabled(d, 1)
    on_at = d.t
    d.t += float(d.core.check_on_s or 0.0) + 0.1
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    d.feed(UnreadableIn(d.t, _untyped_fetch(41, 1)))
    d.feed(NewestChecked(d.t, serial=check.serial))
    assert d.core.matcher is not None and "B1" in d.core.matcher.held
    return d, on_at


@pytest.mark.parametrize("via", ["pushed", "a copy by the records"])
@pytest.mark.parametrize("ok", [False, True], ids=["nok", "ok"])
def test_the_typed_push_of_a_held_untyped_copy_is_its_bolts_rundown(ok, via):
    d, on_at = _held_by_an_untyped_copy(retry=True)
    d.t = on_at + 7.0                                     # the typed push, late
    pushed = res(41, 1, ok, 1, when=WHEN)
    came = ResultIn(d.t, pushed, made_at=on_at + 0.1)
    acts = d.feed(came if via == "pushed" else ResultCopy(d.t, pushed, "VIN1", "B1", came))
    recorded = [(a.bolt, int(a.result.tightening_id), bool(a.result.ok))
                for a in acts if isinstance(a, Record)]
    assert recorded == [("B1", 41, ok)], recorded
    assert "B1" not in d.core.matcher.held
    said = [a.event for a in acts if isinstance(a, Publish) and isinstance(a.event, Notice)]
    assert [n.said for n in said if n.said is Said.TYPED_COPY] == [Said.TYPED_COPY]
    assert "recorded to B1, its hold ended" in notice_words(
        next(n for n in said if n.said is Said.TYPED_COPY))
    if ok:
        assert "B1" in d.core.matcher.done
    else:
        assert d.core._noks.get("B1") == 2, "the second NOK counted for the NOK policy"
    again = d.feed(ResultIn(d.t + 1.0, pushed, made_at=on_at + 0.1))   # sent once more
    assert not [a for a in again if isinstance(a, Record)]


@pytest.mark.parametrize(("after", "recorded"), [(3.0, True), (0.5, False), (None, False)],
                         ids=["made after the tool went on", "within the slack", "no time"])
def test_after_another_bolt_it_must_be_made_beyond_the_slack(after, recorded):
    """The enable before was another bolt's (B2): a rundown made within the clock's slack of
    B1's tool going on may be B2's, one whose time is not known is not placed: B1 stays
    held, as before."""
    d, on_at = _held_by_an_untyped_copy(retry=False)
    d.t = on_at + 7.0
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1, when=WHEN),
                           made_at=None if after is None else on_at + after))
    assert bool([a for a in acts if isinstance(a, Record)]) is recorded
    assert ("B1" in d.core.matcher.held) is not recorded


def test_a_hold_released_meanwhile_stays_as_the_person_decided():
    """B1 released by a supervisor before the typed push came: the push is a copy of the
    stored result (the person decided on the controller's data): nothing recorded again."""
    from stationd.station.commands import ReleaseBolt
    from tests.station.test_commands import SUPERVISOR, _answer

    d, on_at = _held_by_an_untyped_copy(retry=True)
    reply = _answer(d.command(1, ReleaseBolt("VIN1", "B1", comment="checked"), SUPERVISOR))
    assert reply.answer.accepted and "B1" not in d.core.matcher.held
    acts = d.feed(ResultIn(on_at + 7.0, res(41, 1, True, 1, when=WHEN), made_at=on_at + 0.1))
    assert not [a for a in acts if isinstance(a, Record)]


def test_a_typed_copy_says_nothing_of_the_order_for_the_enable_on_now():
    """B1's copy held it; B3 (same pset) enabled; the typed copy of 41 comes and is recorded
    to B1.  It was made under B1's enable: the id order must not take it as judged during
    B3's, or 42, fetched live and made within the slack of B1's tool-off (perhaps B1's
    rundown begun as its disable was sent), would be recorded to B3 by that order alone (a
    reviewer)."""
    d, on_at = _held_by_an_untyped_copy(retry=True)
    d.t = on_at + 3.0
    _enabled(d, 3)
    assert d.core._enabled is not None
    b3_on = d.core._enabled_at
    d.t += 0.3
    pushed = res(41, 1, True, 1, when=WHEN)
    came = ResultIn(d.t, pushed, made_at=on_at + 0.1)
    acts = d.feed(ResultCopy(d.t, pushed, "VIN1", "B1", came))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts
            if isinstance(a, Record)] == [("B1", 41)]
    assert d.core.tool_on and d.core.bolt == "B3"          # B3's tool untouched
    d.t += 0.2
    acts = d.feed(ResultIn(d.t, res(42, 1, True, 1, when=WHEN), made_at=b3_on + 0.5,
                           fetched=True, live=True))
    assert not [a for a in acts if isinstance(a, Record) and a.bolt == "B3"]
