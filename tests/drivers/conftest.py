"""Fixtures for every driver test: a check that nothing leaks.

Drivers run reconnect threads, servers, pty copiers and sockets; a test that leaves any of them
behind would make a later one flaky, so each test is checked on its own.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest


def _fds() -> int:
    return len(os.listdir("/proc/self/fd"))


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail a test that leaves threads (a server, reconnect or pty thread), sockets, ptys or
    files open.  What ends on its own is given 2 s."""
    before, fds = set(threading.enumerate()), _fds()
    yield
    deadline = time.monotonic() + 2.0
    while True:
        extra = [t for t in threading.enumerate() if t not in before and t.is_alive()]
        if (not extra and threading.active_count() <= len(before) and _fds() <= fds) \
                or time.monotonic() > deadline:
            break
        time.sleep(0.01)
    assert not extra, f"leaked threads: {[t.name for t in extra]}"
    assert threading.active_count() == len(before), [t.name for t in threading.enumerate()]
    assert _fds() <= fds, f"{_fds() - fds} file descriptor(s) leaked"
