"""The command line's commands when the daemon is slow: a command the daemon took but whose
answer came too late is said as sent and maybe accepted (giving it again blind could skip or
loosen twice), never as "no daemon answers"; a logout that fails does not lose the answer."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import ClassVar

import pytest

#: each test runs the command in a process of its own, as a user does
pytestmark = pytest.mark.system


class _SlowCommands(BaseHTTPRequestHandler):
    """Answers the login and the nonce at once; the command after ``delay`` seconds; the
    logout after ``logout_delay`` (the http layer a slow or loaded daemon shows)."""

    delay = 0.0
    logout_delay = 0.0
    commands: ClassVar[list[dict[str, object]]] = []

    def log_message(self, *args: object) -> None:
        pass

    def _json(self, doc: object) -> None:
        raw = json.dumps(doc).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(raw)))
        self.end_headers()
        self.wfile.write(raw)

    def do_GET(self) -> None:
        self._json({"nonce": "n1"})

    def do_POST(self) -> None:
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])) or b"{}")
        if self.path == "/api/commands":
            type(self).commands.append(body)
            time.sleep(self.delay)
            self._json({"accepted": True, "words": "skip B03: accepted"})
        elif self.path == "/api/logout":
            time.sleep(self.logout_delay)
            self._json({})
        else:
            self._json({"user": body.get("user")})


@pytest.fixture
def slow() -> Iterator[tuple[str, type[_SlowCommands]]]:
    handler = type("Handler", (_SlowCommands,), {"commands": []})
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/", handler
    finally:
        server.shutdown()
        server.server_close()


def _skip(url: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "stationd", "skip", "VIN1", "B03", "--user",
                           "olga", "--comment", "no access", "--url", url, "--timeout", "1"],
                          input="secret-pw\n", capture_output=True, text=True, timeout=60)


def test_a_late_answer_says_sent_and_maybe_accepted(slow) -> None:
    url, handler = slow
    handler.delay = 3.0
    got = _skip(url)
    assert got.returncode == 3, got
    assert "no daemon answers" not in got.stderr
    assert "sent to" in got.stderr and "may have been accepted" in got.stderr
    assert len(got.stderr.strip().splitlines()) == 1 and "Traceback" not in got.stderr
    assert [c["kind"] for c in handler.commands] == ["skip"]


def test_a_failed_logout_keeps_the_answer(slow) -> None:
    url, handler = slow
    handler.logout_delay = 3.0
    got = _skip(url)
    assert got.returncode == 0, got
    # the first line names whoever answered (this stand-in does not say which station)
    assert got.stdout.splitlines() == [f"station at {url}: it does not say which (not a "
                                       "stationd daemon of this version?)",
                                       "skip B03: accepted"]


def test_an_endless_password_line_is_refused_not_read_for_ever() -> None:
    """A sweep: `stationd user hash < /dev/zero` hung (one endless line)."""
    with open("/dev/zero", "rb") as zero:
        got = subprocess.run([sys.executable, "-m", "stationd", "user", "hash"], stdin=zero,
                             capture_output=True, text=True, timeout=60)
    assert got.returncode == 2 and "no end of line within" in got.stderr, got
    assert "Traceback" not in got.stderr and got.stdout == ""


class _NotStationd(BaseHTTPRequestHandler):
    """Another web server on the port: 400 and an empty body to everything."""

    def log_message(self, *args: object) -> None:
        pass

    def _empty(self) -> None:
        self.send_response(400)
        self.send_header("Content-Length", "0")
        self.end_headers()

    def do_GET(self) -> None:
        self._empty()

    def do_POST(self) -> None:
        self._empty()


def test_a_server_that_is_not_stationd_is_said_so() -> None:
    """A sweep: `skip` and `operator status` against a URL that answers HTTP 400 with nothing
    printed "login refused: " and "operator status: " with nothing after them."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), _NotStationd)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    try:
        for argv in (("skip", "VIN1", "B03", "--user", "olga", "--comment", "no access"),
                     ("operator", "status")):
            got = subprocess.run([sys.executable, "-m", "stationd", *argv, "--url", url],
                                 input="secret-pw\n", capture_output=True, text=True,
                                 timeout=60)
            assert got.returncode == 3, got
            assert "not a stationd daemon's screens at this URL (HTTP 400" in got.stderr, got
    finally:
        server.shutdown()
        server.server_close()


def test_the_password_prompt_says_whose(monkeypatch):
    """At a terminal the prompt was ``password:`` alone: whose is said (``sam's
    password:``), as the command names the user."""
    import getpass

    from stationd import command_cli

    asked: list[str] = []
    monkeypatch.delenv("STATIOND_PASSWORD", raising=False)
    monkeypatch.setattr(command_cli.sys.stdin, "isatty", lambda: True, raising=False)
    monkeypatch.setattr(getpass, "getpass", lambda prompt: asked.append(prompt) or "secret")
    assert command_cli.read_password("sam") == "secret"
    assert command_cli.read_password() == "secret"
    assert asked == ["sam's password: ", "password: "]
