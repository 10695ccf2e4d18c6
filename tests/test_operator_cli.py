"""``stationd operator sign-in|sign-out|status`` without a daemon: bad input is one line and
exit 2 before any login, no daemon answering is one line and exit 3; never a traceback.  (The
daemon's answers: tests/shell/test_operator_daemon.py.)"""

from __future__ import annotations

import io
import socket
import sys

import pytest

from stationd.cli import main


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize(("argv", "message"), [
    (["operator", "sign-in", " "], "user ' '"),
    (["operator", "sign-in", "x" * 65], "the name of a user"),
    (["operator", "sign-in", "olga", "--comment", "y" * 501], "at most 500 characters"),
    (["operator", "sign-in", "olga", "--url", "not a url"], "not a url"),
    (["operator", "status", "--timeout", "-1"], "--timeout"),
])
def test_bad_input_is_one_line_and_exit_2(argv, message, capsys, monkeypatch):
    monkeypatch.setenv("STATIOND_PASSWORD", "whatever-it-is")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("argv", [["operator", "sign-in", "olga"],
                                  ["operator", "sign-out", "--user", "sam"],
                                  ["operator", "status"]])
def test_no_daemon_is_one_line_and_exit_3(argv, capsys, monkeypatch):
    monkeypatch.setenv("STATIOND_PASSWORD", "whatever-it-is")
    url = f"http://127.0.0.1:{_closed_port()}/"
    assert main([*argv, "--url", url, "--timeout", "5"]) == 3
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Errno" not in err, err
    assert f"no daemon answers at {url} (connection refused): is stationd running?" in err


@pytest.mark.parametrize("argv", [["operator", "sign-in", "olga"],
                                  ["skip", "VIN1", "B01", "--user", "sam", "--comment",
                                   "no access"]])
def test_no_password_is_said_so_without_asking_the_daemon(argv, capsys, monkeypatch):
    """Standard input empty (``< /dev/null``) was sent as an empty password, and the daemon's
    answer said "login refused: wrong user or password". The port is closed: had the daemon
    been asked, the command would say that nothing answers (exit 3)."""
    monkeypatch.delenv("STATIOND_PASSWORD", raising=False)
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    url = f"http://127.0.0.1:{_closed_port()}/"
    assert main([*argv, "--url", url, "--timeout", "5"]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [
        "stationd: error: no password given: set STATIOND_PASSWORD, type it at the prompt, "
        "or give it as the first line of standard input"], err


def test_sign_out_names_who_gives_it(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["operator", "sign-out"])
    assert exit_.value.code == 2 and "--user" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["skip", "VIN1", "B01"], ["release", "VIN1", "B01"],
                                     ["loosen", "VIN1", "B01"]])
def test_a_skip_a_release_and_a_loosen_order_need_their_reason(command, capsys):
    """A quality engineer's trial: a bolt locked after three NOKs was released with no word
    of why (an entered outcome needed one).  Refused before any login or password."""
    for comment in ([], ["--comment", "  "]):
        assert main([*command, "--user", "sam", *comment, "--url", "http://127.0.0.1:9/"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--comment: why (a " in err, err
        assert "is kept with its reason" in err
    assert main([*command, "--user", "sam", "--comment", "ok\nFAKE LOG LINE", "--url",
                 "http://127.0.0.1:9/"]) == 2
    assert "--comment: printable characters only" in capsys.readouterr().err
