"""An independent tester's finding (against dustywill/open-protocol-emulator and
pydesai/open-protocol-simulator, both of which refuse MID 0064 at once): the station takes
*any* RefusedError of the catch-up's MID 0064 for "this controller keeps no results"
(``ControllerFeed._refused`` sets ``_no_history``), and then never asks MID 0064 again on
that connection -- neither the check every CHECK_ON_S with the tool on nor the window-end
check.  But the driver raises RefusedError also for a MID 0064 that was merely not answered
within its timeout (``Channel.ask``: "no answer ... taken as refused"), and for a transient
MID 0004 such as error 98 ("controller internal request timeout").  One slow answer at a
reconnect so switches the lost-push check off for the whole connection: a push lost later
leaves its bolt open with the tool on (the new-user trial the check was made for), though
the controller answers MID 0064 perfectly well from then on."""

from __future__ import annotations

import asyncio
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import pytest

from drivers.errors import ConnectionLostError, RefusedError
from stationd.station.inputs import CaughtUp, NewestChecked, ResultIn, ResultsMissed
from tests.shell.test_catch_up import REFUSED, Controller, _feed_of, res


class SlowOnce(Controller):
    """Answers MID 0064 normally, except the first ask, which gets ``first`` (what the
    driver raises for it)."""

    def __init__(self, answers: dict[int, Any], first: RefusedError | None) -> None:
        super().__init__(answers)
        self.first: RefusedError | None = first
        self.asked: list[int] = []

    def fetch_result(self, tid: int, timeout: float | None = None) -> Any:
        self.asked.append(tid)
        if self.first is not None:
            first, self.first = self.first, None
            raise first
        return super().fetch_result(tid, timeout)


# what OpenProtocolWrench.fetch_result raises for each (Channel.ask / Channel.request)
SILENT = RefusedError("fetch tightening (newest): no answer to MID 0064 within 2 s: taken as "
                      "refused (the link kept: its keep-alive tells whether it is alive)")
BUSY = RefusedError("fetch tightening (newest): refused by the controller: error 98 "
                    "(controller internal request timeout)", code=98)


async def _caught_up(feed_: Any) -> None:
    """The link back: the feed's catch-up started and run to its end."""
    feed_.came_back()
    assert feed_.catching_up is not None
    await feed_.catching_up


async def _checked_after_catch_up(controller: SlowOnce, fed: list[Any],
                                  pool: ThreadPoolExecutor) -> Any:
    """A reconnect's catch-up (its MID 0064 as ``controller`` answers it first), 40 the last
    heard on the link; then B1 run down (41, its push lost) and its tool-on check: the feed."""
    feed_ = _feed_of(controller, 40, None, fed, pool)
    await _caught_up(feed_)                  # the one slow MID 0064 (or answered: 40)
    feed_._accounted = 40                    # 40 the last heard on this link (pushed)
    controller.answers = {0: res(41), 41: res(41)}   # B1 run down: 41, its push lost
    core: Any = feed_.core
    core.tool_on, core.checking = True, 1
    feed_.check_newest(1, tool_on=True)      # CHECK_ON_S of tool-on: B1's check
    assert feed_.checking is not None
    await feed_.checking
    return feed_


@pytest.mark.parametrize("first", [None, SILENT, BUSY],
                         ids=["control-answered", "unanswered-once", "error-98-once"])
def test_a_tool_on_check_still_finds_a_lost_push_after_one_slow_catch_up(first):
    # (control-answered passes: the same scenario with the catch-up answered at once)
    # 40 recorded; the controller's newest at the reconnect is 40 (nothing made in the cut),
    # but its answer to the catch-up's MID 0064 is late once (40 then heard pushed again).
    # Then B1's tool goes on, the operator runs B1 down (41), its push is lost; the check
    # with the tool on asks.
    controller = SlowOnce({0: res(40), 40: res(40)}, first)
    fed: list[Any] = []

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = await _checked_after_catch_up(controller, fed, pool)
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    found = [e.result.tightening_id for e in fed if isinstance(e, ResultIn)]
    [checked] = [e for e in fed if isinstance(e, NewestChecked)]
    assert controller.asked.count(0) >= 2 and found == [41], (
        f"after one {'unanswered' if first is SILENT else 'error 98'} MID 0064 at the "
        f"catch-up, the tool-on check asked {controller.asked.count(0) - 1} time(s) and "
        f"found {found} (41's push lost): {checked}")


class SlowThenPushing(SlowOnce):
    """:class:`SlowOnce` whose results' loop takes ``push`` (once, when set)."""

    push: int | None = None

    def wait_result(self, timeout: float, acknowledge: bool = False) -> Any:
        push, self.push = self.push, None
        return res(push) if push is not None else super().wait_result(timeout, acknowledge)


def test_a_result_the_check_fetched_after_a_slow_catch_up_is_not_told_again_as_the_cut_s():
    """After the catch-up's MID 0064 went unanswered once, the ids beyond the last recorded
    wait for the first push beyond it to say the cut (``_refused_after``).  The tool-on check
    fetched 41 meanwhile: the next push (42) skips nothing, and 41 is no gap."""
    controller = SlowThenPushing({0: res(40), 40: res(40)}, SILENT)
    fed: list[Any] = []

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = await _checked_after_catch_up(controller, fed, pool)
        controller.push = 42
        await feed_.results(controller)
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    gaps = [(e.first, e.last) for e in fed if isinstance(e, ResultsMissed)]
    found = [e.result.tightening_id for e in fed if isinstance(e, ResultIn)]
    assert 41 in found and gaps == [], f"41 fetched by the check, then told as {gaps}"


@pytest.mark.parametrize("first", [SILENT, BUSY], ids=["unanswered-once", "error-98-once"])
def test_the_ids_a_slow_catch_up_did_not_fetch_are_asked_for_not_stored_as_refused(first):
    """Weakness A (a review): the catch-up's MID 0064 went unanswered once (or error 98), a
    refusal of the moment (``_no_history`` stays off: the checks ask on).  B1 was run down
    during the cut (41); the controller still has it and gives it.  The first push beyond
    the last recorded (42) told 41 at once as a gap "the controller refused to give them"
    without asking for it: a tightening the controller has was never recorded (the cut's
    bolt held where the controller's data could settle it), the gap's words untrue, and the
    id, counted as accounted for (``last_tightening_id`` counts a gap's end), never asked
    for again.  It is asked for (as the catch-up would have: made while the link was down,
    not with it up), and no gap is told."""
    controller = SlowThenPushing({0: res(42), 41: res(41), 42: res(42)}, first)
    fed: list[Any] = []

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, fed, pool)
        await _caught_up(feed_)                  # the one slow MID 0064: not caught up
        controller.push = 42                     # B2 run down after the reconnect
        await feed_.results(controller)
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    gaps = [(e.first, e.last, e.reason) for e in fed if isinstance(e, ResultsMissed)]
    got = [(e.result.tightening_id, e.fetched, e.live) for e in fed if isinstance(e, ResultIn)]
    assert gaps == [] and got == [(41, True, False), (42, False, False)], (
        f"41, which the controller still has, told as {gaps}; results fed: {got}")


class PushedFirst(SlowThenPushing):
    """:class:`SlowThenPushing` whose catch-up's first MID 0064 is answered (slowly) only
    after the push was taken."""

    def __init__(self, answers: dict[int, Any], first: RefusedError | None) -> None:
        super().__init__(answers, first)
        self.taken = threading.Event()

    def wait_result(self, timeout: float, acknowledge: bool = False) -> Any:
        got = super().wait_result(timeout, acknowledge)
        self.taken.set()
        return got

    def fetch_result(self, tid: int, timeout: float | None = None) -> Any:
        assert self.taken.wait(10)
        return super().fetch_result(tid, timeout)


@pytest.mark.parametrize("first", [SILENT, BUSY], ids=["unanswered-once", "error-98-once"])
def test_a_push_before_a_slow_catch_up_s_refusal_gets_the_cut_s_ids_asked_for_too(first):
    """As above, 42 pushed before the catch-up's MID 0064 went unanswered: the ids between
    the last recorded and it (41) were stored as refused at once (``_refused``); asked for
    instead, after 42 (fed already).  The core is told the newest was not said
    (``CaughtUp.unasked``): what the controller made during the cut may still come."""
    controller = PushedFirst({0: res(42), 41: res(41), 42: res(42)}, first)
    fed: list[Any] = []

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, fed, pool)
        feed_.came_back()
        controller.push = 42
        await feed_.results(controller)          # 42 pushed as the link came back
        assert feed_.catching_up is not None
        await feed_.catching_up                  # then the one slow MID 0064
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    gaps = [(e.first, e.last) for e in fed if isinstance(e, ResultsMissed)]
    got = [(e.result.tightening_id, e.fetched) for e in fed if isinstance(e, ResultIn)]
    assert gaps == [] and got == [(42, False), (41, True)], (gaps, got)
    assert [(c.complete, c.unasked) for c in fed if isinstance(c, CaughtUp)] == [(False, True)]


def test_the_cut_s_ids_asked_for_as_the_link_drops_again_are_not_lost():
    """Weakness A's shell fix, a reconnect during it: after the catch-up's MID 0064 went
    unanswered once, the first push beyond the last recorded (42) has the cut's ids (41)
    asked for (``_cut_ids``).  The link drops as 41 is asked (``ConnectionLostError``):
    ``_cut_ids`` logs "not fetched yet" and tells nothing; 42 is fed and recorded.  At the
    next reconnect the catch-up counts from the last recorded, 42 (``last_tightening_id``
    is the newest accounted for): 41 -- a rundown made during the cut, which the
    controller still has -- is never asked for again, never recorded, not even a gap.
    Before the fix (f69787d) it was at least told as a gap at the push."""
    controller = SlowThenPushing({0: res(42), 41: ConnectionLostError("link lost"),
                                  42: res(42)}, SILENT)
    fed: list[Any] = []

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, fed, pool)
        await _caught_up(feed_)                  # the one slow MID 0064: not caught up
        controller.push = 42                     # B2 run down after the reconnect
        await feed_.results(controller)          # 41 asked for: the link drops
        # the link back: 42 recorded, the controller gives 41 now
        feed_.records.last_tightening_id = lambda: 42    # type: ignore[method-assign]
        controller.answers = {0: res(42), 41: res(41), 42: res(42)}
        await _caught_up(feed_)
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    got = [e.result.tightening_id for e in fed if isinstance(e, ResultIn)]
    gaps = [(e.first, e.last) for e in fed if isinstance(e, ResultsMissed)]
    assert 41 in got or any(first <= 41 <= last for first, last in gaps), (
        f"41, made during the cut, never fed nor told as a gap: results {got}, gaps {gaps}")


@pytest.mark.parametrize("drop_at, then", [(41, "given"), (42, "given"), (41, "refused")],
                         ids=["drop-at-41", "drop-at-42", "drop-at-41-then-refused"])
def test_the_ids_a_push_skipped_asked_for_as_the_link_drops_are_not_lost(drop_at, then):
    """The same hole in the link-up gap (a review): 43 pushed after 40 with the link up
    skips 41-42 (their pushes lost); they are asked for (``_live_gap_alone``) and the link
    drops as ``drop_at`` is asked (``ConnectionLostError``): "not fetched yet", nothing
    told, and 43 is fed and recorded.  The next catch-up counts from the last recorded, 43:
    the ids not fetched -- rundowns made with the link up, which the controller still has,
    a bolt's own as a rule -- were never asked for again, never recorded, not even a gap
    (the bolt they belong to never held: tightened twice).  The next catch-up asks for them
    first, each fed as it would have been (fetched with the link up, before 43: the core
    never takes one for a result made during the cut), once; refused, a gap told with the
    link up (the core holds the bolts whose result it may be)."""
    answers: dict[int, Any] = {0: res(43), 41: res(41), 42: res(42), 43: res(43)}
    controller = SlowThenPushing({**answers, drop_at: ConnectionLostError("link lost")}, None)
    fed: list[Any] = []

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, fed, pool)
        feed_._accounted = 40                    # 40 the last heard on this link
        controller.push = 43                     # 41, 42: their pushes lost
        await feed_.results(controller)          # 41-42 asked for: the link drops
        # the link back: 43 recorded; the controller gives 41-42 now (or refuses them)
        feed_.records.last_tightening_id = lambda: 43    # type: ignore[method-assign]
        controller.answers = dict(answers)
        if then == "refused":
            controller.answers[drop_at] = REFUSED
        await _caught_up(feed_)
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    got = [(e.result.tightening_id, e.fetched, e.live, e.before)
           for e in fed if isinstance(e, ResultIn)]
    gaps = [(e.first, e.last, e.live) for e in fed if isinstance(e, ResultsMissed)]
    before = [(41, True, True, 43)] if drop_at == 42 else []
    if then == "given":
        assert got == [*before, (43, False, False, None), *[
            (t, True, True, 43) for t in range(drop_at, 43)]] and gaps == [], (
            f"41-42, made with the link up, skipped by 43: results {got}, gaps {gaps}")
    else:
        assert got == [(43, False, False, None)] and gaps == [(41, 42, True)], (
            f"41-42, made with the link up, refused: results {got}, gaps {gaps}")
