"""``stationd teach`` whose terminal hangs up (an engineer's SSH session dropped, the laptop's
lid closed): SIGHUP's default action ended the command at once, without its teach stop, and
the station stayed in teach mode (its normal cycle off: nothing tightened) until someone
found out why.  A hang-up stops the command as SIGTERM does: teach mode is ended first, one
line, exit 129.  The daemon is a stand-in here, in this process, that records the commands
(the whole daemon's teach-in is ``test_teach_cli``)."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, ClassVar

import pytest

ROOT = Path(__file__).resolve().parents[1]


class StandIn(BaseHTTPRequestHandler):
    """The daemon's API as ``stationd teach`` uses it; each command's kind kept."""

    kinds: ClassVar[list[str]] = []
    started = threading.Event()
    stopped = threading.Event()
    teaching = False     # teach mode left on by an earlier session: teach-start refused

    def log_message(self, *a: Any) -> None:
        pass

    def _answer(self, doc: Any, status: int = 200) -> None:
        raw = json.dumps(doc).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(raw)))
        self.end_headers()
        self.wfile.write(raw)

    def do_GET(self) -> None:
        if self.path.startswith("/api/status"):
            self._answer({"station": {"id": "ST-07", "config": "/etc/stationd/station.yaml"},
                          "state": "tracking"})
        elif self.path.startswith("/api/nonce"):
            self._answer({"nonce": "n"})
        else:
            self.send_error(404)

    def do_POST(self) -> None:
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])) or b"{}")
        if self.path == "/api/commands":
            StandIn.kinds.append(body["kind"])
            if body["kind"] == "teach-start" and StandIn.teaching:
                words = "command teach-start SIM-1 by ed (cli 127.0.0.1): refused: teach " \
                        "mode is on (teaching SIM-1 (sue): hold the tool on a bolt)"
                self._answer({"accepted": False, "words": words, "kind": "teach-start",
                              "reason": {"kind": "teaching", "words": "teach mode is on"}},
                             409)
                return
            if body["kind"] == "teach-start":
                StandIn.started.set()
            if body["kind"] == "teach-stop":
                StandIn.stopped.set()
                StandIn.teaching = False
        self._answer({"accepted": True, "words": "accepted"})


def _teaching(url: str, tmp_path: Path) -> subprocess.Popen[str]:
    """``stationd teach`` of B01 and B02 against the stand-in at ``url``, once it waits on
    B01 (teach mode started at the station)."""
    p = subprocess.Popen(
        [sys.executable, "-m", "stationd", "teach", "--model", "SIM-1", "--user", "ed",
         "--bolts", "B01,B02", "--out", str(tmp_path / "taught.yaml"), "--url", url],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, env={**os.environ, "STATIOND_PASSWORD": "teach-me-please"})
    assert p.stdout is not None
    while "press Enter" not in (line := p.stdout.readline()):   # waits on B01
        if not line:
            p.kill()
            raise AssertionError(p.communicate(timeout=30))
    assert StandIn.started.is_set()
    return p


@pytest.mark.timeout(120)
def test_a_hang_up_mid_teach_ends_teach_mode_at_the_station(tmp_path: Path) -> None:
    server = ThreadingHTTPServer(("127.0.0.1", 0), StandIn)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    p = _teaching(url, tmp_path)
    try:
        p.send_signal(signal.SIGHUP)           # the terminal hung up
        _, err = p.communicate(timeout=60)
        assert StandIn.stopped.is_set(), (p.returncode, err)   # teach mode ended
        assert p.returncode == 128 + signal.SIGHUP, (p.returncode, err)
        assert err.strip().splitlines()[-1] == "stationd: stopped by SIGHUP (hang-up)", err
        assert "Traceback" not in err and not (tmp_path / "taught.yaml").exists()
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(30)
        server.shutdown()


def _serve() -> tuple[ThreadingHTTPServer, str]:
    StandIn.kinds.clear()
    StandIn.started.clear()
    StandIn.stopped.clear()
    server = ThreadingHTTPServer(("127.0.0.1", 0), StandIn)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/"


def _teach(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "stationd", "teach", *argv], cwd=ROOT,
                          capture_output=True, text=True, timeout=60, input="q\n",
                          env={**os.environ, "STATIOND_PASSWORD": "teach-me-please"})


@pytest.mark.timeout(120)
def test_teach_mode_left_on_is_ended_from_the_command_line(tmp_path: Path) -> None:
    """Teach mode left on by a session that was cut off (a kill -9, a laptop gone) could not
    be ended from the command line: a new ``stationd teach`` was refused ("teach mode is
    on") without a word of what to do, and had no way to stop it; only the commissioning
    screen's Stop.  The refusal says how, and ``stationd teach --stop`` ends it."""
    server, url = _serve()
    StandIn.teaching = True
    try:
        r = _teach("--model", "SIM-1", "--user", "ed", "--bolts", "B01", "--out",
                   str(tmp_path / "t.yaml"), "--url", url)
        assert r.returncode == 1 and "teach mode is on" in r.stderr, r
        assert f"stationd teach --stop --user NAME --url {url}" in r.stderr, r.stderr
        r = _teach("--stop", "--user", "ed", "--url", url)
        assert r.returncode == 0, r
        assert StandIn.kinds[-1] == "teach-stop" and not StandIn.teaching
        assert "teach-start" not in StandIn.kinds[1:]
        # --model and --out stay needed to teach
        r = _teach("--user", "ed", "--bolts", "B01", "--url", url)
        assert r.returncode == 2 and "--model" in r.stderr and "--stop" in r.stderr, r
    finally:
        server.shutdown()


class HangsUpTwice(StandIn):
    """As :class:`StandIn`; the nonce of the teach stop (after the first hang-up) is answered
    only once the command received a second SIGHUP, or gave up the request (at most 10 s):
    a terminal's hang-up reaches the foreground command twice, from the shell that resends
    it to its jobs and from the kernel as that shell (the session leader) exits."""

    pid = 0
    hung_up = threading.Event()

    def do_GET(self) -> None:
        if self.path.startswith("/api/nonce") and HangsUpTwice.hung_up.is_set() \
                and HangsUpTwice.pid:
            pid, HangsUpTwice.pid = HangsUpTwice.pid, 0
            os.kill(pid, signal.SIGHUP)
            select.select([self.connection], [], [], 10)   # the command gone, or waiting
            try:
                self._answer({"nonce": "n"})
            except OSError:
                pass   # it went without waiting for the answer
            return
        super().do_GET()


@pytest.mark.timeout(120)
def test_a_second_hang_up_does_not_cut_the_teach_stop(tmp_path: Path) -> None:
    """The teach stop the first SIGHUP sends is not cut by the second one: the stop was
    interrupted (a KeyboardInterrupt in its request), teach mode left on at the station, as
    with no handling at all."""
    StandIn.kinds.clear()
    StandIn.started.clear()
    StandIn.stopped.clear()
    server = ThreadingHTTPServer(("127.0.0.1", 0), HangsUpTwice)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    p = _teaching(url, tmp_path)
    try:
        HangsUpTwice.pid = p.pid
        HangsUpTwice.hung_up.set()
        p.send_signal(signal.SIGHUP)           # the terminal hung up
        _, err = p.communicate(timeout=60)
        assert StandIn.stopped.is_set(), (p.returncode, err)   # teach mode ended
        assert p.returncode == 128 + signal.SIGHUP, (p.returncode, err)
        assert err.strip().splitlines()[-1] == "stationd: stopped by SIGHUP (hang-up)", err
        assert "Traceback" not in err, err
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(30)
        server.shutdown()
