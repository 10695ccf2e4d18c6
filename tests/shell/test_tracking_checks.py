"""The vision loop's side of the calibration check: checks asked while one waits are merged (a
person's command keeps its answer), two commands are each answered, and a check is answered
even with every pair down ("not checked: the pair is down"), never left waiting."""

from __future__ import annotations

import asyncio
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from stationd.bus import EventBus
from stationd.config import load_station_config
from stationd.localize.check import RefWhy, Verdict
from stationd.shell.blocking import Blocking
from stationd.shell.tracking import Tracker
from stationd.station.core import StationCore
from stationd.station.trust import (
    Asked,
    CheckAsked,
    MeasureReferences,
    PairTrust,
    ReferencesChecked,
)
from tests.shell.refstation import station_dir

PAIRS = ("pair1", "pair2")


EVE = CheckAsked(Asked.COMMAND, user="eve")   # a check asked by a person


def _answers(tmp_path: Any, asked: list[MeasureReferences]) -> list[ReferencesChecked]:
    """The loop's answers to ``asked`` (given in that order before it runs), every pair
    down (no keeper: no grabber)."""
    cfg = load_station_config(station_dir(tmp_path, PAIRS))
    core = StationCore(cfg.matching, trust=PairTrust(PAIRS, 600.0))
    fed: list[ReferencesChecked] = []

    async def main() -> None:
        stop = asyncio.Event()

        async def feed(ev: Any) -> None:
            fed.append(ev)

        with ThreadPoolExecutor(1) as pool:
            tracker = Tracker(cfg, core, {}, EventBus(), feed, Blocking(pool))
            for a in asked:
                tracker.request_check(a)
            task = asyncio.create_task(tracker.loop(stop))
            for _ in range(100):
                await asyncio.sleep(0.02)
                if len(fed) >= len(asked):
                    break
            await asyncio.sleep(0.1)   # nothing more comes
            stop.set()
            await task

    asyncio.run(main())
    return fed


def test_a_check_asked_while_one_waits_is_merged_and_keeps_the_commands_request(tmp_path):
    fed = _answers(tmp_path, [MeasureReferences(PAIRS, False, CheckAsked(Asked.STARTED)),
                              MeasureReferences(PAIRS, True, EVE, request=7),
                              MeasureReferences(PAIRS, True,
                                                CheckAsked(Asked.ARRIVED, vin="V1"))])
    assert [f.request for f in fed] == [7]
    (answer,) = fed
    assert [c.pair for c in answer.checks] == list(PAIRS)
    # every pair down: answered at once, not checked, with why
    assert all(c.verdict is Verdict.NOT_CHECKED and c.why is RefWhy.NO_FRAMES
               and c.note == "the pair is down" for c in answer.checks)


def test_two_commands_waiting_are_each_answered(tmp_path):
    fed = _answers(tmp_path, [MeasureReferences(PAIRS, False, EVE, request=1),
                              MeasureReferences(PAIRS, False,
                                                CheckAsked(Asked.COMMAND, user="max"),
                                                request=2)])
    assert [f.request for f in fed] == [1, 2]
