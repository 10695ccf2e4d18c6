"""Blocking calls from the daemon's event loop, typed.

The drivers and the database block; the daemon runs them in its executor threads.  A bare
``run_in_executor`` answers ``Any``, which would leave every device and database join of the
shell unchecked: :class:`Blocking` keeps the called function's return type.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from concurrent.futures import Executor
from typing import Any, TypeVar

T = TypeVar("T")


class Blocking:
    """Runs ``fn(*args)`` in ``executor`` and answers what it returns."""

    def __init__(self, executor: Executor) -> None:
        self.executor = executor

    async def __call__(self, fn: Callable[..., T], *args: Any) -> T:
        return await asyncio.get_running_loop().run_in_executor(self.executor, fn, *args)
