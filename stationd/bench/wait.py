"""Waiting on the simulated station from a benchmark's coroutine."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable


async def until(pred: Callable[[], object], timeout: float, poll_s: float = 0.005) -> bool:
    """Whether ``pred()`` became true within ``timeout`` s, checked every ``poll_s`` (the
    station's loop runs meanwhile: the benchmarks share it)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        await asyncio.sleep(poll_s)
    return False
