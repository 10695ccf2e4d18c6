"""The controller's clock measured again on a link that stays up (days, drifting), by the
shell's results loop between two waits, with the tool off; over Open Protocol to the
simulated controller on loopback.  The core and the records are stand-ins answering as they
do (the clock is the driver's and the shell's business: the core takes each result's time as
the shell gives it)."""

from __future__ import annotations

import asyncio
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace
from typing import Any

import pytest

from drivers.wrench import open_wrench
from drivers.wrench.sim.controller import SimWrench
from stationd.shell import controller as shell_controller
from stationd.shell.blocking import Blocking
from stationd.shell.controller import ControllerFeed


def _reads(wrench: Any, tool_on: bool, n: int = 2) -> None:
    """``n`` turns of the results' loop on ``wrench``, the core's tool as ``tool_on``."""
    keeper = SimpleNamespace(device=wrench, reconnects=1, losing=False, up=True)
    records = SimpleNamespace(repo=None)
    core = SimpleNamespace(status=lambda: SimpleNamespace(vin="V", faults={}, tool_on=tool_on,
                                                          bolt="B1" if tool_on else None))

    async def fed(ev: Any) -> None:
        pass

    async def main() -> None:
        pool = ThreadPoolExecutor(2)
        feed = ControllerFeed(core, records, keeper, fed, lambda ev: None,  # type: ignore[arg-type]
                              Blocking(pool))
        try:
            for _ in range(n):
                await feed.results(wrench)
        finally:
            feed.close()
            pool.shutdown()

    asyncio.run(main())


def test_the_results_loop_measures_the_controller_s_clock_again_with_the_tool_off(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shell_controller, "CLOCK_CHECK_S", 0.0)   # every turn, not every 10 min
    monkeypatch.setattr(shell_controller, "CLOCK_IDLE_S", 0.0)    # idle at once
    with open_wrench("sim://wrench?nok_rate=0", clock_offset_s=0.0, timeout=1.0) as w:
        assert isinstance(w, SimWrench)
        before = w.clock_offset_s
        assert before is not None and -2 < before < 1
        w.controller.clock_offset_s = 30.0           # the controller's clock drifted
        _reads(w, tool_on=True)                      # the tool on, a bolt selected: not now
        assert w.clock_offset_s == before
        _reads(w, tool_on=False)
        after = w.clock_offset_s
        assert after is not None and 28 < after < 32
