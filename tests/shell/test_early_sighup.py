"""A SIGHUP that reaches ``stationd run`` as it starts, before its event loop takes the signal
(while it reads and checks the station's files, takes its locks): the daemon ended at once by
the signal's default action, without a line in the journal, and systemd counts SIGHUP as a
clean exit (``Restart=on-failure`` leaves the unit down): the station stayed down after an
engineer's ``kill -HUP`` (the README's reload) landed a moment after a restart.  The signal
is remembered from the command's start and the reload it asks for is done once the daemon
runs: the files are read again, as an engineer who had just changed them expects."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest

from tests.shell.notify import NotifyManager

SIM = Path(__file__).resolve().parents[2] / "config" / "sim"
ROOT = SIM.parents[1]

#: ``stationd run`` whose station check sends the process a SIGHUP first (an engineer's
#: ``kill -HUP`` landing while the daemon reads its files): deterministic, no timing
HUP_AT_CHECK = """
import os, signal, sys
import stationd.stationcheck as check
real = check.validate_station
said = []
def hup_first(*a, **kw):
    if not said:
        said.append(1)
        os.kill(os.getpid(), signal.SIGHUP)
    return real(*a, **kw)
check.validate_station = hup_first
sys.argv = ["stationd", "run", "--config", sys.argv[1]]
from stationd.cli import main
raise SystemExit(main())
"""


@pytest.mark.timeout(120)
def test_a_sighup_as_the_daemon_starts_is_a_reload_not_its_end(tmp_path: Path) -> None:
    tag = uuid.uuid4().hex[:8]
    station = tmp_path / "station.yaml"
    station.write_text(textwrap.dedent(f"""\
        cameras:
          left: {{url: 'aravis://Hup-{tag}-A'}}
          right: {{url: 'aravis://Hup-{tag}-B'}}
        pairs:
          pair1: {{calibration: {SIM}/pair1.yaml, to_vehicle: {SIM}/pair1.vehicle.yaml,
                  left: left, right: right}}
        lift: {{url: 'modbus-tcp://127.0.0.1:1?unit=1'}}
        wrench: {{url: 'openprotocol://127.0.0.1:1'}}
        database: {{url: 'sqlite:///{tmp_path / "station.db"}'}}
        """))
    sock = NotifyManager(tmp_path / "notify")
    p = subprocess.Popen([sys.executable, "-c", HUP_AT_CHECK, str(station)], cwd=ROOT,
                         env={**os.environ, "NOTIFY_SOCKET": str(tmp_path / "notify")},
                         stderr=subprocess.PIPE, text=True)
    def until(needle: str) -> None:
        """``needle`` notified, or the daemon's end said (not waited for to the limit)."""
        for _ in range(600):
            try:
                sock.until(needle, 0.1)
                return
            except AssertionError:
                if p.poll() is not None:
                    raise AssertionError(f"the daemon ended ({p.returncode}) before "
                                         f"{needle}: {p.stderr.read() if p.stderr else ''}"
                                         ) from None
        raise AssertionError(f"{needle} not notified")

    try:
        until("READY=1")
        until("RELOADING=1")    # the reload asked as it started, done
        until("READY=1")
        assert p.poll() is None
        p.send_signal(signal.SIGTERM)
        assert p.wait(30) == 0
        err = p.stderr.read() if p.stderr else ""
        assert "configuration reloaded" in err and "Traceback" not in err, err
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(30)
        sock.close()
