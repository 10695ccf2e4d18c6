"""The signals that stop a command, and holding them back for a step that must not be cut.

Why a module of its own: the command line (:mod:`stationd.cli`) turns SIGINT and SIGTERM into
one line and 130 (143) wherever they land, and the few steps that must be whole whatever
comes (a module's import in a C extension, the renames that put a command's files in place)
hold the signals back meanwhile; both need the same list and the same rule, below the
modules that write files.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

#: the signals a command is stopped by
STOPPING = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def held() -> Iterator[None]:
    """SIGINT and SIGTERM held back (blocked, delivered when the body ends) in the main
    thread, the only one Python runs signal handlers in: one that comes meanwhile stops the
    command a moment later, between two lines of ours, instead of in the middle of a step
    that must be whole.  Elsewhere (another thread) nothing to hold."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOPPING)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
