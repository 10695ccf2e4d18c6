"""A Ctrl-C that lands in the import machinery's own code is not printed and lost.

An exception raised by a signal handler while a module lock's weakref callback runs
(``importlib._bootstrap._get_module_lock``) is printed as "Exception ignored in ..." with a
traceback and swallowed: the user saw a traceback and the command went on.  The handler
defers such an interrupt a moment instead, a bounded number of times, and only there: a
module's own code run by an import is interrupted at once.  The frames are taken from a real
import (a meta path finder), the handler the one :func:`stationd.cli._signals` installs."""

from __future__ import annotations

import importlib.abc
import signal
import sys
import time
import weakref
from types import FrameType, ModuleType

import pytest

from stationd import cli


class _FrameTaker(importlib.abc.MetaPathFinder):
    """Keeps, for one module name, its own frame (code run by an import) and its caller's
    (the import machinery's own)."""

    ours: FrameType | None = None
    machinery: FrameType | None = None

    def find_spec(self, name: str, path: object, target: ModuleType | None = None) -> None:
        if name == "stationd_test_no_such_module":
            self.ours, self.machinery = sys._getframe(), sys._getframe(1)
        return None


@pytest.fixture(autouse=True)
def _sigint_taken():
    """The suite run as a background job (``pytest ... &``, nohup) starts with SIGINT
    ignored, which the CLI rightly leaves ignored: these tests are about the handler it puts
    in, so SIGINT has Python's own handler while they run."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)


def _frames() -> tuple[FrameType, FrameType]:
    taker = _FrameTaker()
    sys.meta_path.insert(0, taker)
    try:
        with pytest.raises(ModuleNotFoundError):
            __import__("stationd_test_no_such_module")
    finally:
        sys.meta_path.remove(taker)
    assert taker.ours is not None and taker.machinery is not None
    return taker.ours, taker.machinery


def test_only_the_import_machinery_s_own_frame_is_told_apart():
    ours, machinery = _frames()
    assert cli._importing(machinery)
    assert not cli._importing(ours)          # code an import runs: interrupted at once
    assert not cli._importing(sys._getframe())
    assert not cli._importing(None)


def test_an_interrupt_in_the_import_machinery_comes_a_moment_later_not_lost():
    _, machinery = _frames()
    with cli._signals(restore=True) as stopped:
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)
        handler(signal.SIGINT, machinery)    # no exception here: it would be printed, lost
        assert stopped.signal == signal.SIGINT
        with pytest.raises(KeyboardInterrupt):
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                time.sleep(0.01)


def test_a_deferred_interrupt_is_deferred_a_bounded_number_of_times():
    _, machinery = _frames()
    with cli._signals(restore=True):
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)
        deferred = 0
        with pytest.raises(KeyboardInterrupt):
            for _ in range(cli.DEFER_TIMES + 1):
                handler(signal.SIGINT, machinery)
                deferred += 1
        assert deferred == cli.DEFER_TIMES
        time.sleep(10 * cli.DEFER_S)      # no timer left to ask again: nothing raised here


def test_an_interrupt_outside_the_import_machinery_stops_at_once():
    ours, _ = _frames()
    for frame in (ours, sys._getframe()):
        with cli._signals(restore=True) as stopped:
            handler = signal.getsignal(signal.SIGINT)
            assert callable(handler)
            with pytest.raises(KeyboardInterrupt):
                handler(signal.SIGINT, frame)
            assert stopped.signal == signal.SIGINT


def test_a_command_that_ends_with_an_interrupt_deferred_says_it_was_interrupted(
        monkeypatch, capsys):
    """A Ctrl-C deferred in the import machinery and a command that ended before it was
    asked again: the command's own code was returned, and the signal then ended the process
    silently.  It ends as interrupted, with its line."""
    _, machinery = _frames()

    def command(argv: object, stopped: object) -> int:
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)
        handler(signal.SIGINT, machinery)
        return 0

    monkeypatch.setattr(cli, "_main", command)
    assert cli.main(["anything"]) == cli.EXIT_SIGINT
    assert capsys.readouterr().err == "stationd: interrupted (Ctrl-C)\n"
    time.sleep(10 * cli.DEFER_S)          # its timer cancelled: nothing raised here


def test_an_interrupt_as_the_handlers_are_put_in_is_the_command_s_not_a_traceback(
        monkeypatch, capsys):
    """A Ctrl-C that came just as ``_signals`` put its handler in (the suite under load: the
    handler, in place, raised inside ``signal.signal``, before ``main`` handled anything)
    printed a traceback.  It is remembered, the other handler put in too, and the command
    ends interrupted with its line, never begun."""
    real = signal.signal
    raised: list[int] = []

    def signal_then_interrupted(signum: int, handler: object) -> object:
        before = real(signum, handler)
        if not raised and callable(handler):
            raised.append(signum)
            handler(signal.SIGINT, sys._getframe())   # the Ctrl-C, as it lands now
        return before

    began: list[object] = []
    monkeypatch.setattr(cli.signal, "signal", signal_then_interrupted)
    monkeypatch.setattr(cli, "_main", lambda argv, stopped: began.append(argv) or 0)
    assert cli.main(["anything"]) == cli.EXIT_SIGINT
    assert capsys.readouterr().err == "stationd: interrupted (Ctrl-C)\n"
    assert raised and began == []
    monkeypatch.undo()
    # the handlers put back as they were (restore: a test's main)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_command_stopped_just_after_its_file_was_put_in_place_names_the_file(
        monkeypatch, capsys, tmp_path):
    """A SIGTERM that landed after tune-color's rename and before its "wrote" line (the
    suite, once) ended it as "stopped" with the whole file there: the user read that nothing
    was written.  The stop line names what the command had already put in place; a command
    stopped before writing anything says only that it stopped."""
    from stationd import outfile

    out = tmp_path / "hsv.yaml"

    def command(argv: object, stopped: object) -> int:
        outfile.write_atomic(out, "# HSV range\n")
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)
        handler(signal.SIGINT, sys._getframe())   # the Ctrl-C, before "wrote" is said
        return 0

    monkeypatch.setattr(cli, "_main", command)
    assert cli.main(["anything"]) == cli.EXIT_SIGINT
    assert capsys.readouterr().err == f"stationd: interrupted (Ctrl-C) after writing {out}\n"
    assert out.read_text() == "# HSV range\n"

    def stopped_early(argv: object, stopped: object) -> int:
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)
        handler(signal.SIGINT, sys._getframe())
        return 0

    monkeypatch.setattr(cli, "_main", stopped_early)
    assert cli.main(["another"]) == cli.EXIT_SIGINT   # the first command's file is not its
    assert capsys.readouterr().err == "stationd: interrupted (Ctrl-C)\n"


class _Dropped:
    """An object whose weakref callback a test runs (as the garbage collector would)."""


def test_an_interrupt_in_a_callback_whose_exceptions_are_ignored_comes_again_not_lost(capsys):
    """A Ctrl-C at the demo's start landed in SQLAlchemy's weakref callback
    (``_collection_gced``): "Exception ignored in ..." and a traceback on stderr, the
    interrupt swallowed (the suite, under load).  Any such callback: not printed, asked
    again a moment later, where it stops the command."""
    with cli._signals(restore=True) as stopped:
        handler = signal.getsignal(signal.SIGINT)
        assert callable(handler)

        def callback(_: object) -> None:
            handler(signal.SIGINT, sys._getframe())   # the signal lands in the callback

        obj = _Dropped()
        ref = weakref.ref(obj, callback)
        del obj                                       # the callback runs, its raise ignored
        assert ref() is None and stopped.signal == signal.SIGINT
        with pytest.raises(KeyboardInterrupt):
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                time.sleep(0.01)
    assert "Exception ignored" not in capsys.readouterr().err
