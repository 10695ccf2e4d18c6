"""Commands find their station's daemon from its station file and act on no other (issue 30,
item 3): with station A's daemon on port P and station B's daemon configured for P too (so it
runs without its screens), ``stationd status|skip --config B.yaml`` reached A and acted there.

Two real daemons (``stationd run``) on station files whose devices do not answer (a lift and
a controller on closed ports, cameras on files that do not exist): each runs in fault and
serves its screens, and is light enough to run two at once.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from stationd.access import hash_password
from stationd.command_cli import DEFAULT_CONFIG, same_station, station_words

#: the tests that run daemons and commands in processes of their own are marked
#: ``system``; the pure ones (which station a daemon's answer names) are fast

SIM = Path(__file__).resolve().parents[1] / "config" / "sim"
PASSWORD = "sam-password-1"  # noqa: S105 - a test user's


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _station(folder: Path, http_port: int, extra: str = "") -> Path:
    """A station file in ``folder`` (its own database) listening on ``http_port``."""
    folder.mkdir()
    path = folder / "station.yaml"
    path.write_text(f"""\
cameras:
  left: {{url: 'file://{folder}/none/left_*.png'}}
  right: {{url: 'file://{folder}/none/right_*.png'}}
pairs:
  pair1: {{calibration: {SIM}/pair1.yaml, to_vehicle: {SIM}/pair1.vehicle.yaml,
          left: left, right: right}}
lift: {{url: 'modbus-tcp://127.0.0.1:{_port()}'}}
wrench: {{url: 'openprotocol://127.0.0.1:{_port()}'}}
database: {{url: 'sqlite:///station.db'}}
http: {{listen: '127.0.0.1:{http_port}'}}
access:
  users:
    sam: {{role: supervisor, password: "{hash_password(PASSWORD)}"}}
{extra}""")
    return path


class _Daemon:
    """``stationd run --config PATH`` in a process of its own, its journal in a file."""

    def __init__(self, config: Path) -> None:
        self.journal = config.with_name("journal.log")
        self._out = self.journal.open("w")
        self.proc = subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config",
                                      str(config)], stdout=self._out, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL)

    def log(self) -> str:
        return self.journal.read_text()

    def wait_log(self, needle: str) -> None:
        while needle not in self.log():
            assert self.proc.poll() is None, self.log()
            time.sleep(0.05)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(60)
        self._out.close()


def _serves(port: int, daemon: _Daemon) -> None:
    """Wait until something answers ``/api/status`` on ``port`` (``daemon`` running)."""
    while True:
        assert daemon.proc.poll() is None, daemon.log()
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=5):
                return
        except OSError:
            time.sleep(0.05)


def _cli(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "stationd", *argv], capture_output=True,
                          text=True, timeout=120, stdin=subprocess.DEVNULL,
                          env={**os.environ, "STATIOND_PASSWORD": PASSWORD})


@pytest.fixture
def two(tmp_path: Path) -> Iterator[tuple[Path, Path, int, _Daemon]]:
    """Station A's daemon serving on a port; station B's, configured for the same port,
    running without its screens."""
    port = _port()
    a, b = _station(tmp_path / "a", port), _station(tmp_path / "b", port)
    da = _Daemon(a)
    db = None
    try:
        _serves(port, da)
        db = _Daemon(b)
        db.wait_log("screens not served on")
        yield a, b, port, da
    finally:
        for d in (da, db):
            if d is not None:
                d.stop()


@pytest.mark.system
def test_a_command_for_station_b_is_refused_by_station_a(two) -> None:
    a, b, port, da = two
    url = f"http://127.0.0.1:{port}/"
    got = _cli("status", "--config", str(b))
    assert got.returncode == 3 and got.stdout == "", got
    assert got.stderr.splitlines() == [
        f"stationd: status: station at {url}: {a.resolve()} (it has no station id: set "
        "line.station_id or opcua.station_id in its station file to name it), "
        f"not the station of {b.resolve()} (--config {b}): nothing "
        "done; is that station's daemon running, and serving its screens at its "
        "http.listen? (--url to say where)"]
    got = _cli("skip", "VIN00000000000001", "B01", "--user", "sam", "--comment", "no access",
               "--config", str(b))
    assert got.returncode == 3 and got.stdout == "" and "nothing done" in got.stderr, got
    assert "skip" not in da.log().lower()     # A heard no login, no command
    # --url does not get around it: the station file names the station
    got = _cli("skip", "VIN00000000000001", "B01", "--user", "sam", "--comment", "no access",
               "--config", str(b),
               "--url", url)
    assert got.returncode == 3 and "nothing done" in got.stderr, got
    assert "skip" not in da.log().lower()

    # station A's own file reaches it, and the first line names it
    got = _cli("status", "--config", str(a))
    assert got.returncode == 1, got      # its devices do not answer: in fault
    first, *rest = got.stdout.splitlines()
    assert first == f"station at {url}: {a.resolve()} (it has no station id: set " \
                    "line.station_id or opcua.station_id in its station file to name it)"
    assert rest[0].startswith("state:    fault")
    got = _cli("skip", "VIN00000000000001", "B01", "--user", "sam", "--comment", "no access",
               "--config", str(a))
    assert got.returncode == 1, got      # taken to the station, which refuses it
    # named as status names it, without how to give it an id (status says that)
    named = first.split(" (it has no station id")[0]
    assert got.stdout.splitlines()[0] == named
    da.wait_log("skip")                  # A's journal has it: the negative above can fail

    # --url alone: whoever answers there, named
    got = _cli("operator", "status", "--url", url)
    assert got.returncode == 0 and got.stdout.splitlines()[0] == named, got


@pytest.mark.system
def test_the_station_id_names_it_in_the_first_line_and_json_keeps_stdout_clean(
        tmp_path: Path) -> None:
    """A station with an id (its OPC UA JoiningSystem's) is named by it; a copy of its file
    elsewhere (an engineer's PC) reaches it by that id; ``--json`` keeps stdout one object."""
    port, ua = _port(), _port()
    a = _station(tmp_path / "a", port,
                 f"opcua: {{endpoint: 'opc.tcp://127.0.0.1:{ua}', station_id: ST-07,\n"
                 "        security: [none]}\n")
    copy = tmp_path / "copy.yaml"
    copy.write_text(a.read_text())
    d = _Daemon(a)
    try:
        _serves(port, d)
        url = f"http://127.0.0.1:{port}/"
        got = _cli("status", "--config", str(copy), "--json")
        assert got.returncode == 1, got
        assert json.loads(got.stdout)["station"] == {"id": "ST-07", "config": str(a.resolve())}
        assert got.stderr.splitlines() == [f"station ST-07 at {url} ({a.resolve()})"]
    finally:
        d.stop()


@pytest.mark.system
def test_no_station_named_is_bad_input_saying_what_to_give() -> None:
    if DEFAULT_CONFIG.exists():
        pytest.skip(f"{DEFAULT_CONFIG} exists on this machine: it is the default station")
    got = _cli("status")
    assert got.returncode == 2 and got.stdout == "", got
    assert got.stderr.splitlines() == [
        f"stationd: error: which station: no {DEFAULT_CONFIG} here (the station file the "
        "daemon runs); give --config STATION.yaml, or --url http://HOST:PORT/ of its "
        "screens"]


@pytest.mark.parametrize(("expected", "answered", "same"), [
    ({"id": None, "config": "/a.yaml"}, {"id": None, "config": "/a.yaml"}, True),
    ({"id": None, "config": "/b.yaml"}, {"id": None, "config": "/a.yaml"}, False),
    ({"id": "ST-07", "config": "/home/ed/st07.yaml"}, {"id": "ST-07", "config": "/a.yaml"},
     True),
    ({"id": "ST-08", "config": "/b.yaml"}, {"id": "ST-07", "config": "/a.yaml"}, False),
    ({"id": None, "config": "/b.yaml"}, None, False),     # a daemon that does not say
    ({"id": None, "config": "/b.yaml"}, "text", False),
])
def test_same_station(expected, answered, same) -> None:
    assert same_station(expected, answered) is same


def test_station_words_of_a_daemon_that_does_not_say() -> None:
    assert station_words("http://h:1/", None) == (
        "station at http://h:1/: it does not say which (not a stationd daemon of this "
        "version?)")
