"""How the shell's catch-up after a reconnect ends, for the core (``CaughtUp``): complete, or
why not, and on which connection.  Every way it can end tells the core, unless the link went
down again (the next reconnect's catch-up tells), so that a link cut during an enable is
never left open with the tool off for good; and a catch-up of an earlier connection is told
as that connection's (the core then says nothing of a later cut with it).

The controller and the records are stand-ins answering as the driver and the repository do
(the daemon-level tests drive the simulated controller over Open Protocol:
``test_result_types_daemon.py``)."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime
from types import SimpleNamespace
from typing import Any

import pytest

from drivers.errors import ConnectionLostError, ProtocolError, RefusedError
from drivers.wrench.base import TighteningResult, UnreadableResult
from stationd.shell.blocking import Blocking
from stationd.shell.controller import ControllerFeed
from stationd.station.inputs import (
    CaughtUp,
    NewestChecked,
    ResultCopy,
    ResultIn,
    ResultsMissed,
    ResultsSkipped,
    UnreadableIn,
)
from tests.rundowns import rundown


class Controller:
    """A controller's fetches: ``answers`` by tightening id (0: its newest), an exception
    raised as the driver raises it."""

    can_curves, curves_on, clock_offset_s = False, False, 0.0

    def __init__(self, answers: dict[int, Any], can_fetch: bool = True) -> None:
        self.answers, self.can_fetch = answers, can_fetch

    def fetch_result(self, tid: int, timeout: float | None = None) -> Any:
        got = self.answers.get(tid)
        if isinstance(got, Exception):
            raise got
        return got

    def wait_result(self, timeout: float, acknowledge: bool = False) -> Any:
        time.sleep(0.05)
        return None

    def identification(self) -> None:
        return None


def res(tid: int) -> TighteningResult:
    return rundown(tid, 1, code=1)


def catch_up(controller: Controller, last: int | None = 40, comebacks: int = 1,
             on_feed: Any = None, reading: bool = False, stored: bool = False,
             copies: bool = False) -> list[Any]:
    """What the catch-up fed the core after ``comebacks`` reconnects in a row (each while
    the last one's catch-up ran); ``reading``: the results' loop runs beside it;
    ``copies``: every result asked of the records is one recorded already."""
    fed: list[Any] = []
    keeper = SimpleNamespace(device=controller, reconnects=1, losing=False, up=True,
                             lost=lambda exc: None)
    records = SimpleNamespace(repo=SimpleNamespace(read_result_stored=lambda t: stored),
                              last_tightening_id=lambda: last,
                              copy_input=(lambda ev, vin: ResultCopy(ev.t, ev.result, vin,
                                                                      "B1"))
                              if copies else (lambda ev, vin: ev),
                              unreadable_input=lambda ev: ev)
    # the status as the results' loop reads it too (between two waits: its clock check)
    core = SimpleNamespace(missed_since=lambda: time.time() - 60,
                           status=lambda: SimpleNamespace(vin="V", faults={}, tool_on=False,
                                                          bolt=None))

    async def feed(ev: Any) -> None:
        fed.append(ev)
        if on_feed is not None:
            on_feed(ev, keeper)

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = ControllerFeed(core, records, keeper, feed, lambda ev: None,  # type: ignore[arg-type]
                               Blocking(pool))
        loop = None
        if reading:
            loop = asyncio.create_task(_read_forever(feed_, controller))
        feed_.came_back()
        for n in range(2, comebacks + 1):
            await asyncio.sleep(0)      # the running one has started on its connection
            keeper.reconnects = n
            feed_.came_back()
        assert feed_.catching_up is not None
        await feed_.catching_up
        if loop is not None:
            loop.cancel()
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    return fed


async def _read_forever(feed: ControllerFeed, controller: Controller) -> None:
    while True:
        await feed.results(controller)  # type: ignore[arg-type]


def _ends(fed: list[Any]) -> list[tuple[bool, str, int | None]]:
    return [(e.complete, e.reason, e.reconnects) for e in fed if isinstance(e, CaughtUp)]


def test_every_result_since_fetched_is_complete_on_its_connection():
    fed = catch_up(Controller({0: res(42), 41: res(41), 42: res(42)}))
    assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [41, 42]
    assert _ends(fed) == [(True, "", 1)]


def test_a_fetch_that_fails_with_the_link_up_ends_it_incomplete():
    """MID 0064 for 41 answered about tightening 43 (a ProtocolError, the link kept): it
    ended without a word, and the cut it was to end held the tool off for good (a
    reviewer)."""
    fed = catch_up(Controller({0: res(43), 41: ProtocolError(
        "fetch tightening 41: the controller answered with tightening 43")}))
    assert _ends(fed) == [(False, "fetching them failed (fetch tightening 41: the controller "
                                  "answered with tightening 43)", 1)]


def test_a_driver_that_crashes_during_it_ends_it_incomplete(caplog):
    """A reviewer: an exception no driver should raise (a bug) ended the task without a
    word: a cut's watch kept the tool off for every bolt until the next reconnect."""
    fed = catch_up(Controller({0: res(43), 41: KeyError("tightening")}))
    assert _ends(fed) == [(False, "the catch-up failed (KeyError: 'tightening')", 1)]
    assert any("the catch-up crashed" in r.getMessage() for r in caplog.records)


def test_a_link_lost_again_tells_nothing():
    def lose(ev: Any, keeper: Any) -> None:
        keeper.up = False

    fed = catch_up(Controller({0: res(43), 41: res(41), 42: ConnectionLostError("gone")}),
                   on_feed=lose)
    assert not _ends(fed)       # the next reconnect's catch-up tells


def test_results_missing_on_the_controller_end_it_incomplete():
    fed = catch_up(Controller({0: res(42), 42: res(42)}))      # 41: no longer there
    assert _ends(fed) == [(False, "tightening 41 no longer on the controller", 1)]


def test_a_reconnect_while_a_catch_up_runs_gets_its_own_after_it():
    """The catch-up of connection 1 still ran when the link came back as connection 2: one
    for connection 2 follows, each told as its own (the core takes the first for stale
    against a cut made on connection 1)."""
    fed = catch_up(Controller({0: res(41), 41: res(41)}), comebacks=2)
    assert [r for *_, r in _ends(fed)] == [1, 2]


def test_a_register_driven_controller_is_read_once_before_it_is_told():
    """A controller that keeps no results to fetch keeps its last one in its registers: the
    results' loop reads it after the reconnect before the catch-up says it is incomplete
    (a reviewer: told first, the cut's own result, read a moment later, was held)."""
    reads: list[float] = []
    controller = Controller({}, can_fetch=False)
    original = controller.wait_result

    def wait_result(timeout: float, acknowledge: bool = False) -> Any:
        reads.append(time.monotonic())
        return original(timeout, acknowledge)

    controller.wait_result = wait_result
    told: list[float] = []
    fed = catch_up(controller, reading=True,
                   on_feed=lambda ev, k: told.append(time.monotonic())
                   if isinstance(ev, CaughtUp) else None)
    assert _ends(fed) == [(False, "this controller keeps no results to fetch", 1)]
    assert reads and reads[0] < told[0]


def test_a_result_whose_time_does_not_read_is_kept_in_a_first_catch_up():
    """No tightening recorded yet; the controller's newest (3) does not read, its time with
    it; 2 and 1 were made since the link was lost.  Where 3 lies against the cut is not
    known, but it is the controller's record of a tightening: fed to the core (stored, the
    cut's bolt held), and the walk back goes on past it to the results it can place (an
    independent controller's trial: two results made during a cut stored nowhere; a
    reviewer: the ones below the unreadable one were never fetched)."""
    newest = UnreadableResult(raw="0226006500" + "x" * 40, mid=65, revision=2,
                              error="MID 0065 revision 2 torque '00ABCD' is not a number",
                              tightening_id=3, pset=1, fetched=True)
    recent = [SimpleNamespace(**{**vars(res(t)), "timestamp": datetime.now()})
              for t in (1, 2)]
    fed = catch_up(Controller({0: newest, 2: recent[1], 1: recent[0]}), last=None)
    assert [e.unreadable.tightening_id for e in fed if isinstance(e, UnreadableIn)] == [3]
    assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [1, 2]
    assert _ends(fed) == [(True, "", 1)]


def test_with_the_controller_s_clock_unknown_its_newest_is_kept_and_the_rest_unknown():
    """No clock offset (the controller did not tell its time): no result can be placed
    against the cut; the newest is kept (fed) and the catch-up says why it is not complete."""
    controller = Controller({0: res(2), 1: res(1)})
    controller.clock_offset_s = None
    fed = catch_up(controller, last=None)
    assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [2]
    assert _ends(fed) == [(False, "the controller's clock is not known: its results cannot "
                                  "be placed before or after the link was lost", 1)]


def test_a_controller_with_no_results_though_some_were_recorded_does_not_say_none_made():
    """Tightening 40 recorded; the controller has none at all (restarted with its memory
    cleared, or replaced): what it made during the cut is not known (a supervisor's trial:
    "no tightening made while the link was down ... open as before")."""
    fed = catch_up(Controller({0: None}), last=40)
    assert _ends(fed) == [(False, "the controller has no results, though tightening 40 was "
                                  "recorded: cleared (restarted or replaced), what it made "
                                  "before is not known", 1)]
    assert _ends(catch_up(Controller({0: None}), last=None)) == [(True, "", 1)]


def test_a_count_started_again_since_the_link_was_lost_leaves_the_time_before_unknown():
    """Tightening 40 recorded; the controller's count started again and its first results
    (1, 2) were both made since the link was lost: fed, but what it made before its count
    started again is not known.  Where its history reaches back before the link was lost
    (1 made before), every result since was found."""
    recent = {t: SimpleNamespace(**{**vars(res(t)), "timestamp": datetime.now()})
              for t in (1, 2)}
    fed = catch_up(Controller({0: recent[2], **recent}), last=40)
    assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [1, 2]
    assert _ends(fed) == [(False, "its first result since its count started again was made "
                                  "after the link was lost: what it made before is not "
                                  "known", 1)]
    old = SimpleNamespace(**{**vars(res(1)), "timestamp": datetime(2020, 1, 1)})
    fed = catch_up(Controller({0: recent[2], 2: recent[2], 1: old}), last=40)
    assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [2]
    assert _ends(fed) == [(True, "", 1)]


def test_a_catch_up_that_finds_the_ids_started_again_tells_the_core():
    """The controller's results cleared (none, though 40 was recorded) or its count started
    again (its newest below the last recorded): the core is told (``CaughtUp.restarted``),
    the gaps it was told being another count's (tests/station/test_gap_ids_restart.py);
    a catch-up that counts on does not say it."""
    def restarted(fed: list[Any]) -> list[bool]:
        return [e.restarted for e in fed if isinstance(e, CaughtUp)]

    assert restarted(catch_up(Controller({0: None}), last=40)) == [True]
    recent = SimpleNamespace(**{**vars(res(2)), "timestamp": datetime.now()})
    assert restarted(catch_up(Controller({0: recent, 2: recent, 1: None}), last=40)) == [True]
    assert restarted(catch_up(Controller({0: res(42), 41: res(41), 42: res(42)}))) == [False]
    assert restarted(catch_up(Controller({0: None}), last=None)) == [False]


def test_a_replaced_controller_s_newest_recorded_already_is_counted_from_not_restarted(
        caplog):
    """A technician's trial: after a controller was replaced (its ids from 1 again, 1 and 2
    recorded), every reload said "the controller's newest tightening (2) is older than the
    last recorded (5): its ids restarted", the highest id ever recorded being the old
    controller's.  Its newest recorded already (the very same: id, values, its own time):
    counted from it, nothing fetched, nothing said; not recorded, as before."""
    from drivers.wrench.base import ResultType, Status, TighteningResult

    newest = TighteningResult(
        ok=True, torque_nm=25.0, angle_deg=30.0, torque_status=Status.OK,
        angle_status=Status.OK, tightening_id=2, pset=1, vin="", timestamp=datetime.now(),
        torque_min_nm=22.0, torque_max_nm=28.0, torque_target_nm=25.0, angle_min_deg=15.0,
        angle_max_deg=90.0, angle_target_deg=30.0, result_type=ResultType.TIGHTENING,
        result_type_code=1)
    with caplog.at_level(logging.INFO, logger="stationd"):
        fed = catch_up(Controller({0: newest, 2: newest}), last=5, copies=True)
    assert "ids restarted" not in caplog.text
    assert [e.restarted for e in fed if isinstance(e, CaughtUp)] == [False]
    assert not [e for e in fed if isinstance(e, ResultIn)]
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="stationd"):
        fed = catch_up(Controller({0: newest, 2: newest, 1: None}), last=5)
    assert [e.restarted for e in fed if isinstance(e, CaughtUp)] == [True]


REFUSED = RefusedError("fetch tightening 0: the controller refused (MID 0004 error 99)",
                       code=99)


class Pushing(Controller):
    """One that pushes tightening ``push`` once; ``first``: it is taken by the results' loop
    before the catch-up asks for the newest (else after)."""

    def __init__(self, answers: dict[int, Any], push: int, first: bool) -> None:
        super().__init__(answers)
        self.push, self.first, self.pushed = push, first, threading.Event()

    def fetch_result(self, tid: int, timeout: float | None = None) -> Any:
        if tid == 0 and self.first:
            assert self.pushed.wait(10)
        return super().fetch_result(tid, timeout)

    def wait_result(self, timeout: float, acknowledge: bool = False) -> Any:
        if self.pushed.is_set():
            return super().wait_result(timeout, acknowledge)
        self.pushed.set()
        return res(self.push)


def _feed_of(controller: Controller, last: int, since: float | None, fed: list[Any],
             pool: ThreadPoolExecutor) -> ControllerFeed:
    """The shell's results feed over ``controller``, the last id recorded ``last``, results
    missed since ``since``: what it feeds the core goes to ``fed``."""
    keeper = SimpleNamespace(device=controller, reconnects=1, losing=False, up=True)
    records = SimpleNamespace(repo=SimpleNamespace(read_result_stored=lambda t: False),
                              last_tightening_id=lambda: last, copy_input=lambda ev, vin: ev)
    core: Any = SimpleNamespace(missed_since=lambda: since, tool_on=False, checking=None)
    core.status = lambda: SimpleNamespace(vin="V", faults={}, tool_on=core.tool_on, enables=0,
                                          checking=core.checking)

    async def feed(ev: Any) -> None:
        fed.append(ev)

    return ControllerFeed(core, records, keeper, feed, lambda ev: None,  # type: ignore[arg-type]
                          Blocking(pool))


def refused_then_pushed(controller: Pushing, then: int | None = None) -> list[Any]:
    """Fed after a reconnect whose catch-up was refused, and one pushed result (and
    ``then``, pushed after it)."""
    fed: list[Any] = []

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, time.time() - 60, fed, pool)
        feed_.came_back()
        if not controller.first:
            assert feed_.catching_up is not None
            await feed_.catching_up
        await feed_.results(controller)  # type: ignore[arg-type]
        if then is not None:
            controller.pushed.clear()
            controller.push = then
            await feed_.results(controller)  # type: ignore[arg-type]
        assert feed_.catching_up is not None
        await feed_.catching_up
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    return fed


def _gaps(fed: list[Any]) -> list[tuple[int, int, str]]:
    return [(e.first, e.last, e.reason) for e in fed if isinstance(e, ResultsMissed)]


def test_a_refused_catch_up_records_the_ids_before_the_next_pushed_one_as_a_gap():
    """The controller refuses MID 0064 after a reconnect (its newest not said): the ids
    between the last recorded (40) and the first pushed since (43) were made during the cut
    and went nowhere; a gap says so, whether the push comes after the refusal or before it
    (the tightenings made during a cut whose catch-up was refused left no row: a helper's
    trial)."""
    for first in (False, True):
        fed = refused_then_pushed(Pushing({0: REFUSED}, 43, first))
        assert _gaps(fed) == [(41, 42, "the controller refused to give them (MID 0064)")]
        assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [43]
        assert [c.complete for c in fed if isinstance(c, CaughtUp)] == [False]


def test_a_refused_catch_up_with_nothing_made_during_the_cut_records_no_gap():
    fed = refused_then_pushed(Pushing({0: REFUSED}, 41, first=False))
    assert not _gaps(fed)


def test_a_fetch_refused_part_way_records_it_and_the_ones_after_it_as_a_gap():
    """The controller said its newest (44) and gave 41, then refused 42: 42-43 are a gap,
    and 44, which it gave already, is fed (a reviewer: it was thrown away as missed)."""
    fed = catch_up(Controller({0: res(44), 41: res(41), 42: REFUSED}))
    assert [(e.result.tightening_id, e.follows) for e in fed if isinstance(e, ResultIn)] == [
        (41, 40), (44, None)]
    assert _gaps(fed) == [(42, 43, "the controller refused to give them (MID 0064)")]
    assert [c.complete for c in fed if isinstance(c, CaughtUp)] == [False]


def test_a_refused_check_of_the_last_id_recorded_counts_on():
    """Whether the controller's ids restarted is asked by fetching the last one recorded
    (40); refused, it is not known and the ids after it are fetched as before (a reviewer:
    the refusal ended the catch-up with 41-43 neither fetched nor a gap)."""
    controller = Controller({0: res(43), 40: REFUSED, 41: res(41), 42: res(42)})
    fed = catch_up(controller, stored=True)
    assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [41, 42, 43]
    assert _ends(fed) == [(True, "", 1)]


def test_a_copy_sent_again_first_does_not_take_the_refused_catch_up_s_gap():
    """After a refused catch-up the controller sends the last recorded result (40) again
    first, then 43: the gap is 41-42, said as made while the link was down, once (a
    reviewer: the copy took it, and 41-42 were fetched as a live gap, refused, said "with
    the link up")."""
    controller = Pushing({0: REFUSED}, 40, first=False)
    fed = refused_then_pushed(controller, then=43)
    gaps = [(e.first, e.last, e.live) for e in fed if isinstance(e, ResultsMissed)]
    assert gaps == [(41, 42, False)]


def _pushed(controller: Controller, push: int, accounted: int) -> list[Any]:
    """What the results' loop fed for one pushed result ``push``, ``accounted`` the last id
    accounted for on the link."""
    fed: list[Any] = []
    sent = threading.Event()

    def wait_result(timeout: float, acknowledge: bool = False) -> Any:
        if sent.is_set():
            return None
        sent.set()
        return res(push)

    controller.wait_result = wait_result  # type: ignore[method-assign]

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, accounted, None, fed, pool)
        feed_._accounted = accounted
        await feed_.results(controller)  # type: ignore[arg-type]
        assert not feed_.received
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    return fed


def _order(fed: list[Any]) -> list[tuple[str, int, bool, int | None]]:
    return [(type(e).__name__, e.tightening_id, False, None) if isinstance(e, ResultsSkipped)
            else (type(e).__name__, e.result.tightening_id, e.fetched, e.before)
            for e in fed if isinstance(e, ResultIn | ResultsSkipped)]


def test_a_push_that_skips_ids_is_told_first_and_fed_after_the_ones_it_skipped():
    """43 pushed after 40: the core is told first (the tool goes off), 41 and 42 are fetched
    and fed, each naming 43, then 43 itself: the results in the order made (a supervisor's
    trial: a NOK fetched after a later one went uncounted; a reviewer: the tool stayed on
    through the fetches).  A fetch that fails still feeds the pushed one."""
    fed = _pushed(Controller({41: res(41), 42: res(42)}), 43, 40)
    assert _order(fed) == [("ResultsSkipped", 43, False, None), ("ResultIn", 41, True, 43),
                           ("ResultIn", 42, True, 43), ("ResultIn", 43, False, None)]
    fed = _pushed(Controller({41: ProtocolError("fetch tightening 41: garbled")}), 43, 40)
    assert _order(fed) == [("ResultsSkipped", 43, False, None), ("ResultIn", 43, False, None)]
    fed = _pushed(Controller({}), 41, 40)          # nothing skipped: nothing told
    assert _order(fed) == [("ResultIn", 41, False, None)]


def test_a_stop_while_skipped_ids_are_fetched_ends_and_keeps_the_pushed_one():
    """The daemon stops (or reloads) while a pushed result's skipped ids are fetched: the
    stop holds the station's lock, cancels the results' task and waits for it (Station.run).
    It ends at once, the pushed result left in ``received`` for the stop's drain (a
    reviewer: feeding it on the way out waited for the lock the stop held, the daemon hung)."""
    fetching, release = threading.Event(), threading.Event()

    class Slow(Controller):
        def fetch_result(self, tid: int, timeout: float | None = None) -> Any:
            fetching.set()
            release.wait(2.0)       # a slow MID 0064 round trip
            return res(tid)

    controller = Slow({})
    sent = threading.Event()

    def wait_result(timeout: float, acknowledge: bool = False) -> Any:
        if sent.is_set():
            return None
        sent.set()
        return res(43)

    controller.wait_result = wait_result

    async def main() -> tuple[bool, list[Any]]:
        lock = asyncio.Lock()

        async def feed(ev: Any) -> None:       # Station.feed: under the station's lock
            async with lock:
                pass

        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, [], pool)
        feed_._feed = feed
        feed_._accounted = 40
        task = asyncio.create_task(feed_.results(controller))
        while not fetching.is_set():
            await asyncio.sleep(0.01)
        async with lock:                       # Station.run's stop
            task.cancel()
            done, _ = await asyncio.wait({task}, timeout=30)
        release.set()
        pool.shutdown()
        feed_.close()
        return bool(done), [r.tightening_id for r in feed_.received]

    ended, kept = asyncio.run(main())
    assert ended and kept == [43]


def test_the_controller_s_newest_asked_for_fetches_what_was_never_heard(caplog):
    """The core asks (an enable's window ended without its result): the controller's newest
    (42) is after the last one heard (40): 41 and 42 are fetched and fed, with the link up,
    as results whose push was lost; a newest already heard fetches nothing.  The core is
    told the check ended, last, whatever it found (the enable it was for owed no more, the
    tool free to go on)."""
    def asked(answers: dict[int, Any], heard: int, tool_on: bool = False,
              asked_on: bool = False) -> list[Any]:
        fed: list[Any] = []

        async def main() -> None:
            with ThreadPoolExecutor(2) as pool:
                feed_ = _feed_of(Controller(answers), heard, None, fed, pool)
                feed_.core.tool_on = tool_on
                feed_._accounted = heard
                feed_.check_newest(None, asked_on)
                await asyncio.gather(*(t for t in (feed_.checking,) if t is not None))
                feed_.close()

        asyncio.run(main())
        return fed

    with caplog.at_level(logging.INFO, logger="stationd"):
        fed = asked({0: res(42), 41: res(41), 42: res(42)}, 40)
    # said as what it was: no later one came (a trial)
    said = [r.getMessage() for r in caplog.records if "fetched" in r.getMessage()]
    assert "tightening 41 fetched as an enable's late-result window ended (the link up)" \
        in said and not [m for m in said if "after a later one came" in m], said
    assert [(e.result.tightening_id, e.fetched, e.live, e.before) for e in fed
            if isinstance(e, ResultIn)] == [(41, True, True, None), (42, True, True, None)]
    assert isinstance(fed[-1], NewestChecked)
    assert not fed[-1].nothing_made
    told = [NewestChecked]
    [nothing] = asked({0: res(40)}, 40)          # the newest the last one heard: none made
    assert isinstance(nothing, NewestChecked) and nothing.nothing_made
    # refused: said in the journal, nothing fetched, nothing known
    [refused] = asked({0: REFUSED}, 40)
    assert isinstance(refused, NewestChecked) and not refused.nothing_made
    # a tool on: its own rundown may be the newest (fetched before its push: a reviewer)
    assert [type(e) for e in asked({0: res(42), 41: res(41), 42: res(42)}, 40,
                                   tool_on=True)] == told
    # the core's check with the tool on: its fetches said so, not as a window's end (a
    # supervisor's trial read both causes for one result)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="stationd"):
        fed = asked({0: res(41), 41: res(41)}, 40, tool_on=True, asked_on=True)
    said = [r.getMessage() for r in caplog.records if "fetched" in r.getMessage()]
    assert said == ["tightening 41 fetched by a check of the controller's newest with the "
                    "tool on (the link up)"], said
    assert [e.result.tightening_id for e in fed if isinstance(e, ResultIn)] == [41]


def test_a_register_driven_controller_s_queued_results_are_all_read_before_it_is_told():
    """A register-driven controller publishes the next result only once the last is
    acknowledged (``drivers.wrench.modbus``): the tool, still enabled on it during the cut,
    ran twice (41, 42), and both come one after the other after the reconnect.  Each is read
    before the catch-up says it is incomplete, while the tool stays off for the cut: told
    after the first only, 42 came once an enable was possible again, and was taken for the
    next bolt of its pset (a review of the register-driven cut)."""
    queued = [res(41), res(42)]
    controller = Controller({}, can_fetch=False)

    def wait_result(timeout: float, acknowledge: bool = False) -> Any:
        time.sleep(0.05)
        return queued.pop(0) if queued else None

    controller.wait_result = wait_result
    fed = catch_up(controller, reading=True)
    order = [e.result.tightening_id if isinstance(e, ResultIn) else type(e).__name__
             for e in fed if isinstance(e, ResultIn | CaughtUp)]
    assert order == [41, 42, "CaughtUp"], order


class PushesAfter(Controller):
    """A controller that pushes ``pushes`` in turn (then nothing) besides its fetches."""

    def __init__(self, answers: dict[int, Any], pushes: list[Any]) -> None:
        super().__init__(answers)
        self.pushes = pushes

    def wait_result(self, timeout: float, acknowledge: bool = False) -> Any:
        return self.pushes.pop(0) if self.pushes else None


def pushed_after_catch_up(controller: PushesAfter, last: int | None) -> list[Any]:
    """What was fed after a catch-up (``last`` the last id recorded) and then one read of
    the controller's push."""
    fed: list[Any] = []
    keeper = SimpleNamespace(device=controller, reconnects=1, losing=False, up=True,
                             lost=lambda exc: None)
    records = SimpleNamespace(repo=SimpleNamespace(read_result_stored=lambda t: False),
                              last_tightening_id=lambda: last,
                              copy_input=lambda ev, vin: ev, unreadable_input=lambda ev: ev)
    core = SimpleNamespace(missed_since=lambda: time.time() - 60,
                           status=lambda: SimpleNamespace(vin="V", faults={}, tool_on=False,
                                                          bolt=None))

    async def feed(ev: Any) -> None:
        fed.append(ev)

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = ControllerFeed(core, records, keeper, feed, lambda ev: None,  # type: ignore[arg-type]
                               Blocking(pool))
        feed_.came_back()
        assert feed_.catching_up is not None
        await feed_.catching_up
        await feed_.results(controller)  # type: ignore[arg-type]
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    return fed


@pytest.mark.parametrize("last", [5, None], ids=["controller restarted", "fresh database"])
def test_ids_before_the_first_push_of_a_controller_found_empty_are_asked_for(last):
    """The catch-up finds the controller with no result (restarted with ids from 1, or new);
    then 1 is made, its push lost, and 2 is pushed: 1 is asked for and fed before 2 (an
    integrator's trial: 2 and 3 stored, 1 never asked for, nothing said)."""
    fed = pushed_after_catch_up(PushesAfter({1: res(1), 2: res(2)}, [res(2)]), last)
    assert [(type(e).__name__, getattr(e, "tightening_id", None)
             or e.result.tightening_id) for e in fed
            if isinstance(e, (ResultIn, ResultsSkipped))] == [
        ("ResultsSkipped", 2), ("ResultIn", 1), ("ResultIn", 2)]


def test_a_controller_found_empty_that_counts_on_has_no_gap_below_its_first_push():
    """The controller cleared its results but counts on: 499 made (its push lost), 500
    pushed; it has no tightening 1.  Its count did not begin again: no gap of 1-499 (a
    reviewer: the id before alone took it for one, every open bolt held)."""
    fed = pushed_after_catch_up(PushesAfter({499: res(499), 500: res(500)}, [res(500)]), 40)
    assert [type(e).__name__ for e in fed if not isinstance(e, CaughtUp)] == ["ResultIn"]
