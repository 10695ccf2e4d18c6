"""stationd.progress: bars on stderr for a person, nothing in logs, pipes or with --quiet."""

import io

import pytest

from stationd import progress
from stationd.cli import build_parser


class _Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.fixture(autouse=True)
def _reset():
    yield
    progress.configure(quiet=False)


def test_a_bar_is_drawn_on_a_terminal(monkeypatch):
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    progress.configure(quiet=False)
    assert list(progress.track(range(3), "views", unit="pair")) == [0, 1, 2]
    assert "views" in term.getvalue() and "0/3" in term.getvalue()  # redrawn at most 10/s


@pytest.mark.parametrize("quiet,stream", [(True, _Terminal), (False, io.StringIO)])
def test_no_bar_when_quiet_or_not_a_terminal(monkeypatch, quiet, stream):
    err = stream()
    monkeypatch.setattr("sys.stderr", err)
    progress.configure(quiet=quiet)
    assert list(progress.track(iter("abc"), "views")) == ["a", "b", "c"]
    progress.note("starting")
    assert err.getvalue() == ""


@pytest.mark.parametrize("argv", [["--quiet", "demo"], ["demo", "--quiet"], ["demo", "-q"],
                                  ["-q", "bench", "vision", "--quick"],
                                  ["calibrate", "camera", "x.png", "--board", "b", "-q"]])
def test_quiet_is_accepted_before_and_after_the_command(argv):
    assert build_parser().parse_args(argv).quiet is True


def test_not_quiet_by_default():
    assert build_parser().parse_args(["demo"]).quiet is False
