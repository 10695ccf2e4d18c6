"""The throw-away PostgreSQL server does not outlive its owner: killed with -9 (a test run or a
demo stopped hard), the owner never calls ``stop()``, and the watcher stops the server and
removes its folder."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.pgserver import PgServer

pytestmark = pytest.mark.skipif(PgServer().missing is not None,
                                reason=PgServer().missing or "")

_OWNER = """
import sys, time
from stationd.pgserver import PgServer
s = PgServer()
s.start()
print(s.port, s.dir, flush=True)
time.sleep(600)
"""


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _until(what, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if what():
            return True
        time.sleep(0.2)
    return bool(what())


def test_a_killed_owner_takes_its_server_and_folder_with_it() -> None:
    root = Path(__file__).resolve().parent.parent
    owner = subprocess.Popen([sys.executable, "-c", _OWNER], stdout=subprocess.PIPE,
                             cwd=root, env={**os.environ, "PYTHONPATH": str(root)})
    try:
        assert owner.stdout is not None
        port_text, folder = owner.stdout.readline().decode().split()
        port = int(port_text)
        assert _listening(port) and Path(folder).is_dir()
        owner.send_signal(signal.SIGKILL)
        owner.wait()
        assert _until(lambda: not _listening(port), 20.0), "the server outlived its owner"
        assert _until(lambda: not Path(folder).exists(), 10.0), "its folder was left behind"
    finally:
        if owner.poll() is None:
            owner.kill()


def test_a_stopped_server_leaves_no_watcher() -> None:
    server = PgServer()
    server.start()
    watcher = server._watcher
    assert watcher is not None and watcher.poll() is None
    server.stop()
    assert watcher.poll() is not None
    assert server.dir is None
