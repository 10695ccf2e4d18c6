"""The shell's check of the controller's newest result (``ControllerFeed.check_newest``):
a check chained on an earlier one ends with it at a stop, one the core gave up on asks
nothing, and a controller that refused MID 0064 at the catch-up is told by its next push
(an independent review's scenarios)."""

from __future__ import annotations

import asyncio
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace
from typing import Any

from drivers.wrench.sim.controller import SimController, SimPset, SimWrench
from stationd.shell.blocking import Blocking
from stationd.shell.controller import ControllerFeed
from stationd.station.actions import CheckNewest, DisableTool, EnableTool, Record, SendParams
from stationd.station.core import StationCore
from stationd.station.inputs import NewestChecked, ResultIn, ResultsMissed, Started, Tick
from stationd.station.policy import NokPolicy, NokRule
from tests.shell.test_catch_up import REFUSED, Controller, Pushing, _feed_of, res
from tests.station.test_core import PARAMS, Driver, _on


class Slow(Controller):
    """MID 0064 answered only once ``go`` is set (a controller slow to answer)."""

    def __init__(self) -> None:
        super().__init__({0: res(40)})
        self.go, self.asked = threading.Event(), threading.Event()

    def fetch_result(self, tid: int, timeout: float | None = None) -> Any:
        self.asked.set()
        assert self.go.wait(10)
        return super().fetch_result(tid, timeout)


def test_the_stop_ends_every_check_it_started():
    fed: list[Any] = []
    controller = Slow()

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, fed, pool)
        feed_._accounted = 40
        _core(feed_).checking = 1
        feed_.check_newest(1)            # B1's check: the controller slow to answer
        while not controller.asked.is_set():
            await asyncio.sleep(0.01)
        _core(feed_).checking = 2
        feed_.check_newest(2)            # the core gave up on it (CHECK_WAIT_S): B3's check
        # Station.run's stop: cancels the feed's tasks, gathers them
        tasks = feed_.tasks()
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        n = len(fed)
        controller.go.set()              # the controller answers after the stop
        await asyncio.sleep(0.5)
        pool.shutdown()
        feed_.close()
        after = fed[n:]
        assert not [e for e in after if isinstance(e, NewestChecked)], (
            f"fed to the core after the stop: {after}")

    asyncio.run(main())


def test_a_check_the_core_gave_up_on_fetches_nothing_afterwards():
    """The shell side of tests/station/test_check.py::test_a_check_the_core_gave_up_on
    ...: B1's check (serial 1) waits for a running catch-up; the core gives up on it after
    CHECK_WAIT_S (its enables count moved on: B3 enabled, 41 made).  When the catch-up ends
    the stale check still asks and fetches 41 as a live result (before=None), advancing
    ``_accounted`` so that B3's own check later finds nothing made."""
    fed: list[Any] = []
    controller = Controller({0: res(41), 41: res(41)})

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, fed, pool)
        feed_._accounted = 40
        release = asyncio.Event()
        feed_.catching_up = asyncio.create_task(_until(release))   # a long catch-up
        _core(feed_).checking = 1
        feed_.check_newest(1)
        await asyncio.sleep(0.1)
        # meanwhile (core): B1's check overdue, B3 enabled (enables 0 -> 1) and off again
        core = _core(feed_)
        status = core.status
        core.status = lambda: SimpleNamespace(**{**vars(status()), "enables": 1,
                                                       "checking": None})
        release.set()
        assert feed_.checking is not None
        await feed_.checking
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    got = [(e.result.tightening_id, e.live, e.before) for e in fed if isinstance(e, ResultIn)]
    assert got == [], f"the stale check fetched {got} during B3's window"



def test_the_next_push_tells_of_a_push_lost_after_a_refused_catch_up():
    """The catch-up after a reconnect is refused (MID 0064): 40 the last recorded.  B1 is
    then enabled and tightened (41, its push lost); its window ends, the check asks nothing
    (``_no_history``) and tells the core nothing (B1 left open).  The operator's next
    tightening is pushed (42): the id it skips (41, made long after the catch-up ended, with
    the link up) must reach the core as a live gap -- the only thing that can still hold B1
    (the core's ``_gap_in_doubt`` ignores a gap that is not live, as a link cut's)."""
    fed: list[Any] = []
    controller = Pushing({0: REFUSED}, 42, first=False)

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed_ = _feed_of(controller, 40, None, fed, pool)
        feed_.came_back()
        assert feed_.catching_up is not None
        await feed_.catching_up                      # refused: _no_history
        _core(feed_).checking = 1
        feed_.check_newest(1)                        # B1's window ended
        assert feed_.checking is not None
        await feed_.checking
        await feed_.results(controller)              # 42 pushed: skips 41
        pool.shutdown()
        feed_.close()

    asyncio.run(main())
    [checked] = [e for e in fed if isinstance(e, NewestChecked)]
    assert not checked.nothing_made and not checked.unknown     # B1 not held by the check
    gaps = [(e.first, e.last, e.live) for e in fed if isinstance(e, ResultsMissed)]
    # told as the refused catch-up's gap (the core holds the bolts left since the reconnect:
    # tests/station/test_check.py)
    assert [(f, la) for f, la, _ in gaps] == [(41, 41)], f"the lost push reached the core as {gaps}"


def _core(feed: Any) -> Any:
    """The fake core under ``feed`` (tests/shell/test_catch_up.py's ``_feed_of``)."""
    return feed.core


async def _until(event: asyncio.Event) -> None:
    await event.wait()


def test_a_push_lost_with_the_tool_on_is_found_by_the_periodic_check_over_open_protocol():
    """The new-user trial (``lose_push_every``, NOK policy loosen) over Open Protocol to the
    simulated controller on loopback, the real core (tests/station/test_core.py's driver)
    and the shell's results feed: B1 tightened NOK (pushed), loosened (pushed), enabled
    again for its tightening pset; the operator runs it down, the controller loses that
    push and keeps the tool enabled (a second rundown would be made under the same enable).
    The core's periodic check with the tool on asks the controller's newest (MID 0064): the
    rundown is fetched, recorded to B1, the tool goes off on the controller, and the next
    selection of B1 is its loosening."""
    pset = SimPset(12.0, 10.0, 14.0, 30.0, 10.0, 60.0)
    # the controller's clock not said (MID 0080 refused): the order of ids places the result
    ctl = SimController({1: pset, 2: pset, 90: SimPset(20.0, 5.0, 150.0, 90.0, 0.0, 720.0)},
                        seed=5, nok_rate=1.0, refused_mids={80: 99})
    # the core's clock is the station's (the shell stamps what it feeds with time.time())
    d = Driver(core=StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(3, "loosen", 90))))
    d.t, d.answer_checks = time.time(), False
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VIN1"))
    fed: list[Any] = []
    made: list[int] = []

    with SimWrench(ctl, timeout=2.0) as w:
        w.open()

        def apply(acts: list[Any]) -> list[Any]:
            """The core's actions on the controller, as the shell's effects do them."""
            for a in acts:
                if isinstance(a, SendParams):
                    w.select_pset(a.selection.pset)
                elif isinstance(a, EnableTool):
                    w.enable_tool()
                elif isinstance(a, DisableTool):
                    w.disable_tool()
            return acts

        async def feed(ev: Any) -> None:
            fed.append(ev)
            apply(d.feed(ev))

        def enabled(bolt: int) -> SendParams:
            d.t = max(d.t, time.time())
            n = len(d.log)
            _on(d, bolt)
            [sent] = [a for _, aa in d.log[n:] for a in aa if isinstance(a, SendParams)]
            apply([sent])
            d.step(("ack", 0.01, True))
            _on(d, bolt, 1)
            apply([a for _, aa in d.log[n:] for a in aa if isinstance(a, EnableTool)])
            assert d.core.tool_on and ctl.tool_enabled
            return sent

        async def main() -> None:
            pool = ThreadPoolExecutor(2)
            keeper = SimpleNamespace(device=w, reconnects=1, losing=False, up=True)
            # the database as it answers: nothing stored twice
            records = SimpleNamespace(repo=SimpleNamespace(), copy_input=lambda ev, vin: ev)
            feed_ = ControllerFeed(d.core, records, keeper, feed,  # type: ignore[arg-type]
                                   lambda ev: None, Blocking(pool))
            feed_._accounted = 0
            try:
                for code, ok in ((1, False), (2, True)):   # NOK, then its loosening
                    sent = enabled(1)
                    assert sent.loosen == (code == 2)
                    ctl.nok_rate = 0.0 if ok else 1.0
                    shot = ctl.pull_trigger(result_type=code)
                    assert shot is not None
                    await feed_.results(w)
                    assert not d.core.tool_on and not ctl.tool_enabled
                sent = enabled(1)
                assert not sent.loosen and sent.selection.pset == 1
                ctl.nok_rate = 1.0
                ctl.lose_next_push()
                lost = ctl.pull_trigger()                  # its push lost
                assert lost is not None and not lost.ok
                made.append(lost.tightening_id)
                assert ctl.tool_enabled and d.core.tool_on   # nobody heard of it
                d.t += d.core.check_on_s
                [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
                assert check.tool_on
                feed_.check_newest(check.serial, check.tool_on)
                assert feed_.checking is not None
                await feed_.checking
            finally:
                feed_.close()
                pool.shutdown()

        asyncio.run(main())
        recorded = [(a.bolt, int(a.result.tightening_id))
                    for _, aa in d.log for a in aa if isinstance(a, Record)]
        assert recorded == [("B1", 1), ("B1", 2), ("B1", made[0])], recorded
        assert not d.core.tool_on and not ctl.tool_enabled, "the tool left on"
        assert ctl.pull_trigger() is None, "a second rundown under the same enable"
        assert "B1" not in d.core.matcher.held
        n = len(d.log)
        _on(d, 1, 4)
        sent = [a for _, aa in d.log[n:] for a in aa if isinstance(a, SendParams)]
        assert [(s.loosen, s.selection.pset) for s in sent] == [(True, 90)]
