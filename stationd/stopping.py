"""The signals that stop a command, and holding them back for a step that must not be cut.

Why a module of its own: the command line (:mod:`stationd.cli`) turns SIGINT and SIGTERM into
one line and 130 (143) wherever they land, and the few steps that must be whole whatever
comes (a module's import in a C extension, the renames that put a command's files in place)
hold the signals back meanwhile; both need the same list and the same rule, below the
modules that write files.

Why a flag and not the thread's signal mask: a process with threads (an export's progress
bar, a command's asyncio executor, pytest-xdist's workers) has the kernel deliver a signal to
any thread that does not block it, and Python then runs its handler in the main thread at
once: blocking it in the main thread alone held nothing back.  The handler the command line
puts in asks :func:`deferred` first, so a signal that comes during a hold is raised again as
the hold ends, whichever thread received it.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager

#: the signals a command is stopped by: SIGHUP too, its terminal hanging up (an SSH session
#: dropped): its default action ended a command without its last step (``stationd teach``
#: left the station in teach mode); ``stationd run`` takes it as a reload
STOPPING = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class _Hold:
    """How many holds are open, and the signal that came meanwhile (None: none)."""

    depth = 0
    pending: int | None = None


@contextmanager
def held() -> Iterator[None]:
    """SIGINT and SIGTERM held back while the body runs (holds nest): one that comes
    meanwhile is raised again as the last hold ends, and stops the command there, between
    two lines of ours, instead of in the middle of a step that must be whole."""
    _Hold.depth += 1
    try:
        yield
    finally:
        _Hold.depth -= 1
        if _Hold.depth == 0 and _Hold.pending is not None:
            signum, _Hold.pending = _Hold.pending, None
            signal.raise_signal(signum)


def deferred(signum: int) -> bool:
    """Whether ``signum``, just received, waits for a hold's end (remembered, raised again
    then); a handler that gets True does nothing more now."""
    if _Hold.depth == 0:
        return False
    if _Hold.pending is None:
        _Hold.pending = signum
    return True


class _Reload:
    """A SIGHUP that came before the daemon's event loop took the signal."""

    asked = False


def take_reloads() -> None:
    """``stationd run``, at its start: a SIGHUP from now on is remembered
    (:func:`reload_asked`) until the daemon's event loop takes the signal itself.  Why: the
    signal's default action ended a daemon that was still reading its files, without a line
    in the journal, and systemd counts an end by SIGHUP as a clean exit (``Restart=
    on-failure`` left the station down after a ``kill -HUP`` a moment after its restart)."""
    def on_hup(signum: int, frame: object) -> None:
        _Reload.asked = True

    signal.signal(signal.SIGHUP, on_hup)


def reload_asked() -> bool:
    """Whether a SIGHUP came since :func:`take_reloads` (and not asked since): its reload is
    the daemon's to do once it runs."""
    asked, _Reload.asked = _Reload.asked, False
    return asked
