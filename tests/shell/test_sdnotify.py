import os
import socket

import pytest

from stationd.shell.sdnotify import Notifier


@pytest.fixture(params=["path", "abstract"])
def manager(request, tmp_path):
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    if request.param == "path":
        addr = str(tmp_path / "notify.sock")
        s.bind(addr)
        env_addr = addr
    else:
        name = f"stationd-test-{os.getpid()}-{id(s)}"
        s.bind(b"\0" + name.encode())
        env_addr = "@" + name
    s.settimeout(2.0)
    yield s, env_addr
    s.close()


def test_ready_status_watchdog_stopping(manager):
    sock, addr = manager
    n = Notifier({"NOTIFY_SOCKET": addr, "WATCHDOG_USEC": "10000000",
                  "WATCHDOG_PID": str(os.getpid())})
    assert n.enabled and n.watchdog_s == 5.0
    assert n.ready("waiting for vehicle")
    assert sock.recv(4096) == b"READY=1\nSTATUS=waiting for vehicle"
    n.status("tracking\nbolt B3")
    assert sock.recv(4096) == b"STATUS=tracking bolt B3"
    n.watchdog()
    assert sock.recv(4096) == b"WATCHDOG=1"
    n.stopping()
    assert sock.recv(4096) == b"STOPPING=1"
    n.close()


def test_no_manager_is_a_no_op():
    n = Notifier({})
    assert not n.enabled and n.watchdog_s is None and n.ready() is False


def test_watchdog_for_another_pid_or_garbage_is_ignored(tmp_path):
    assert Notifier({"WATCHDOG_USEC": "1000000", "WATCHDOG_PID": "1"}).watchdog_s is None
    assert Notifier({"WATCHDOG_USEC": "ten"}).watchdog_s is None


def test_a_vanished_manager_does_not_raise(tmp_path):
    n = Notifier({"NOTIFY_SOCKET": str(tmp_path / "gone.sock")})
    assert n.ready() is False


def test_a_manager_that_does_not_read_never_blocks_the_daemon(manager):
    """A full queue (the manager busy, or stopped reading) drops datagrams at once instead
    of blocking the event loop (it did: the daemon stopped reading its lift and ignored
    SIGTERM); once the manager reads again, notifications arrive again."""
    import time

    sock, addr = manager
    n = Notifier({"NOTIFY_SOCKET": addr})
    t0 = time.monotonic()
    sent = [n.status(f"state {k}") for k in range(200)]
    assert time.monotonic() - t0 < 1.0
    assert sent[0] and not sent[-1] and n.dropped == sent.count(False) > 0
    got = []
    sock.settimeout(0.2)
    try:
        while True:
            got.append(sock.recv(4096))
    except TimeoutError:
        pass
    assert got[0] == b"STATUS=state 0" and len(got) == sent.count(True)
    assert n.status("tracking") and sock.recv(4096) == b"STATUS=tracking"
    n.close()
