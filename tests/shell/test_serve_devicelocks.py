"""Two ``stationd run`` with different databases and one device: the second is refused at its
start naming the first's pid and the device; a reload moves a device's lock (the new one first,
refused if another daemon holds it, the running station kept); the locks go with the daemon.

The devices are real endpoints nobody answers on (the daemons run in fault, holding their
locks: a lock is the daemon's, not the device's state), named uniquely per test so that tests
run beside each other never share one."""

import os
import signal
import socket
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest

from tests.shell.notify import NotifyManager

SIM = Path(__file__).resolve().parents[2] / "config" / "sim"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _station(path: Path, db: str, lift: str, wrench: str, cams: tuple[str, str]) -> Path:
    path.write_text(textwrap.dedent(f"""\
        cameras:
          left: {{url: '{cams[0]}'}}
          right: {{url: '{cams[1]}'}}
        pairs:
          pair1: {{calibration: {SIM}/pair1.yaml, to_vehicle: {SIM}/pair1.vehicle.yaml,
                  left: left, right: right}}
        lift: {{url: '{lift}'}}
        wrench: {{url: '{wrench}'}}
        database: {{url: 'sqlite:///{db}'}}
        """))
    return path


def _devices():
    tag = uuid.uuid4().hex[:8]
    return (f"modbus-tcp://127.0.0.1:{_free_port()}?unit=1",
            f"openprotocol://127.0.0.1:{_free_port()}",
            (f"aravis://Test-{tag}-A", f"aravis://Test-{tag}-B"))


def _run(config: Path, **kw) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "stationd", "run", "--config", str(config)],
                          capture_output=True, text=True, timeout=60,
                          env={k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"},
                          **kw)


def _start(config: Path, notify: Path) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config", str(config)],
                            env={**os.environ, "NOTIFY_SOCKET": str(notify)},
                            stderr=subprocess.PIPE, text=True)


def _stop(p: subprocess.Popen[str]) -> str:
    if p.poll() is None:
        p.send_signal(signal.SIGTERM)
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
    return p.stderr.read() if p.stderr else ""


@pytest.mark.timeout(120)
def test_a_second_daemon_on_the_first_ones_devices_exits_2_naming_pid_and_device(tmp_path):
    lift, wrench, cams = _devices()
    other_lift, other_wrench, other_cams = _devices()
    first = _station(tmp_path / "a.yaml", str(tmp_path / "a.db"), lift, wrench, cams)
    sock = NotifyManager(tmp_path / "notify")
    a = _start(first, tmp_path / "notify")
    try:
        sock.until("READY=1", 60)
        for i, (dev, second) in enumerate([
                (f"lift {lift}", (lift, other_wrench, other_cams)),
                (f"wrench {wrench}", (other_lift, wrench, other_cams)),
                (f"camera right {cams[1]}", (other_lift, other_wrench, (other_cams[0], cams[1])))]):
            r = _run(_station(tmp_path / f"b{i}.yaml", str(tmp_path / f"b{i}.db"), *second))
            assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
            assert f"{dev}: the device is already driven by pid {a.pid}" in r.stderr
            assert "Traceback" not in r.stderr
        # a probe of a device the daemon drives is refused before it touches it
        r = subprocess.run([sys.executable, "-m", "stationd", "probe", "wrench", wrench,
                            "--timeout", "1"], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        assert f"wrench {wrench}: the station daemon (pid {a.pid}) is driving this device; " \
               "stop it or use its screens" in r.stderr
        assert a.poll() is None                   # the first one is untouched
        a.send_signal(signal.SIGTERM)
        assert a.wait(timeout=30) == 0
        # gone with the first daemon: the second starts on those devices now
        b = _start(_station(tmp_path / "b.yaml", str(tmp_path / "b.db"), lift, wrench, cams),
                   tmp_path / "notify")
        try:
            sock.until("READY=1", 60)
            assert b.poll() is None
        finally:
            assert "Traceback" not in _stop(b)
    finally:
        _stop(a)
        sock.close()


@pytest.mark.timeout(120)
def test_a_reload_onto_a_held_device_is_refused_and_the_old_one_is_let_go_after(tmp_path):
    lift, wrench, cams = _devices()
    lift2 = f"modbus-tcp://127.0.0.1:{_free_port()}?unit=1"
    config = _station(tmp_path / "a.yaml", str(tmp_path / "a.db"), lift, wrench, cams)
    holder = subprocess.Popen(   # another daemon's lock on lift2
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys
            from stationd.lock import StationLocks
            locks = StationLocks()
            locks.hold("sqlite:///:memory:", devices=[("lift", {lift2!r})])
            print("held", flush=True)
            sys.stdin.readline()
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    sock = NotifyManager(tmp_path / "notify")
    a = _start(config, tmp_path / "notify")
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        sock.until("READY=1", 60)
        _station(config, str(tmp_path / "a.db"), lift2, wrench, cams)
        a.send_signal(signal.SIGHUP)
        got = sock.until("reload refused", 30)
        assert f"lift {lift2}: the device is already driven by pid {holder.pid}" in got[-1]
        assert a.poll() is None
        _, other_wrench, other_cams = _devices()
        b = _station(tmp_path / "b.yaml", str(tmp_path / "b.db"), lift, other_wrench, other_cams)
        r = _run(b)                                     # a still drives the first lift
        assert r.returncode == 2 and f"already driven by pid {a.pid}" in r.stderr, r.stderr
        assert holder.stdin is not None
        holder.stdin.close()
        holder.wait(10)
        a.send_signal(signal.SIGHUP)                    # lift2 is free now: a moves to it
        sock.until("READY=1", 60)                       # (the locks moved before it)
        b_sock = NotifyManager(tmp_path / "notify-b")   # ... and the first lift is free
        p = _start(b, tmp_path / "notify-b")
        try:
            b_sock.until("READY=1", 60)
            assert p.poll() is None
        finally:
            assert "Traceback" not in _stop(p)
            b_sock.close()
        a.send_signal(signal.SIGTERM)
        assert a.wait(timeout=30) == 0
    finally:
        if holder.poll() is None:
            holder.kill()
        err = _stop(a)
        sock.close()
    assert "configuration reloaded" in err and "Traceback" not in err
