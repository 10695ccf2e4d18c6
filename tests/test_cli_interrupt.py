"""A Ctrl-C that lands inside the import machinery is not printed and lost.

An exception raised by a signal handler while a module lock's weakref callback runs
(``importlib._bootstrap._get_module_lock``) is printed as "Exception ignored in ..." with a
traceback and swallowed: the user saw a traceback and the command went on.  The handler
defers such an interrupt a moment instead.  The frame is taken from inside a real import (a
meta path finder), the handler the one :func:`stationd.cli._signals` installs."""

from __future__ import annotations

import importlib.abc
import signal
import sys
import time
from types import FrameType, ModuleType

import pytest

from stationd import cli


class _FrameTaker(importlib.abc.MetaPathFinder):
    """Keeps the frame of its ``find_spec`` for one module name: a frame in the import."""

    frame: FrameType | None = None

    def find_spec(self, name: str, path: object, target: ModuleType | None = None) -> None:
        if name == "stationd_test_no_such_module":
            self.frame = sys._getframe()
        return None


def _import_frame() -> FrameType:
    taker = _FrameTaker()
    sys.meta_path.insert(0, taker)
    try:
        with pytest.raises(ModuleNotFoundError):
            __import__("stationd_test_no_such_module")
    finally:
        sys.meta_path.remove(taker)
    assert taker.frame is not None
    return taker.frame


def test_a_frame_of_the_import_machinery_is_told_from_ours():
    assert cli._importing(_import_frame())
    assert not cli._importing(sys._getframe())
    assert not cli._importing(None)


def test_an_interrupt_inside_an_import_comes_a_moment_later_not_lost():
    frame = _import_frame()
    with cli._signals(restore=True) as stopped:
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)
        handler(signal.SIGINT, frame)        # no exception here: it would be printed and lost
        assert stopped.signal == signal.SIGINT
        with pytest.raises(KeyboardInterrupt):
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                time.sleep(0.01)


def test_an_interrupt_outside_an_import_stops_at_once():
    with cli._signals(restore=True) as stopped:
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)
        with pytest.raises(KeyboardInterrupt):
            handler(signal.SIGINT, sys._getframe())
        assert stopped.signal == signal.SIGINT
