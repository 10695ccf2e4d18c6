"""``stationd run`` as systemd runs it: READY over NOTIFY_SOCKET, SIGHUP with a bad config
keeps the running one, SIGTERM closes everything and exits 0."""

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.shell.notify import NotifyManager

SIM = Path(__file__).resolve().parents[2] / "config" / "sim"


def _ended(p: subprocess.Popen[str]) -> str:
    """The daemon killed if a failed assertion left it running; what it wrote on stderr."""
    if p.poll() is None:
        p.kill()
    return p.stderr.read() if p.stderr else ""


def _recv_until(manager: NotifyManager, needle: str, timeout: float) -> list[str]:
    return manager.until(needle, timeout)


@pytest.mark.timeout(180)
def test_ready_reload_refused_and_clean_stop(tmp_path):
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    sock = NotifyManager(tmp_path / "notify")
    env = {**os.environ, "NOTIFY_SOCKET": str(tmp_path / "notify")}
    p = subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config", "station.yaml"],
                         cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    try:
        _recv_until(sock, "READY=1", 90)
        _recv_until(sock, "waiting for vehicle", 30)
        (tmp_path / "station.yaml").write_text("vision:\n  centre_methd: paper\n")
        p.send_signal(signal.SIGHUP)
        _recv_until(sock, "reload refused", 60)
        assert p.poll() is None  # still running on the old configuration
        # 300 levels of block mappings: a newcomer's reload killed the daemon (RecursionError)
        (tmp_path / "station.yaml").write_text(_deep_block(300))
        p.send_signal(signal.SIGHUP)
        _recv_until(sock, "reload refused", 60)
        assert p.poll() is None
        # a bolt table the daemon cannot reach (a name too long here; a folder closed to its
        # user alike): refused in one line, where the journal got a traceback
        (tmp_path / "station.yaml").write_text((SIM / "station.yaml").read_text().replace(
            "bolts: bolts.yaml", f"bolts: {tmp_path / ('a' * 300)}/bolts.yaml"))
        p.send_signal(signal.SIGHUP)
        _recv_until(sock, "reload refused", 60)
        assert p.poll() is None
        shutil.copy(SIM / "station.yaml", tmp_path / "station.yaml")  # a valid one again
        p.send_signal(signal.SIGHUP)
        # a reload is RELOADING=1 then READY=1, never STOPPING=1 (systemd would stop the
        # unit and kill the daemon at TimeoutStopSec; a newcomer read it in systemd's source)
        got = _recv_until(sock, "READY=1", 90)   # the station came back up on the new file
        reloading = [m for m in got if "RELOADING=1" in m]
        assert len(reloading) == 1 and "MONOTONIC_USEC=" in reloading[0], got
        assert not any("STOPPING=1" in m for m in got), got
        # a bolt no pair sees (typed in metres): a reload taken says it; the same file in a
        # reload then refused (its database file removed) does not (a review: said before
        # the refusal, it read as the new table running)
        bolts = tmp_path / "bolts.yaml"
        bolts.write_text(bolts.read_text().replace("[1489.8, -529.3, -44.3]",
                                                   "[1.4898, -0.5293, -0.0443]"))
        p.send_signal(signal.SIGHUP)
        _recv_until(sock, "READY=1", 90)
        (tmp_path / "stationd-sim.db").unlink()
        p.send_signal(signal.SIGHUP)
        _recv_until(sock, "reload refused", 60)
        assert p.poll() is None
        p.send_signal(signal.SIGTERM)
        _recv_until(sock, "STOPPING=1", 60)
        assert p.wait(timeout=60) == 0
    finally:
        err = _ended(p)
        sock.close()
    assert "reload refused" in err and "centre_methd: unknown key" in err
    # the first error, and how many more the check lists (the sections missing too)
    assert "(and 4 more errors: stationd config check --config station.yaml lists them)" \
        in err
    assert "configuration reloaded" in err
    assert "bolts.yaml: cannot be reached (file name too long)" in err
    assert err.count("seen by no registered pair") == 1
    assert "reload: " in err.split("seen by no registered pair")[0].splitlines()[-1]
    assert "was removed while the daemon ran" in err
    assert "Traceback" not in err
    # one readable line per event (the unreachable bolt table's is as long as its name)
    assert all(len(line) < 400 or "a" * 300 in line for line in err.splitlines())


def _deep_block(levels: int) -> str:
    return "".join("  " * i + f"k{i}:\n" for i in range(levels)) + "  " * levels + "v: 1\n"


@pytest.mark.parametrize(("text", "said"), [("lift: [\n", "malformed YAML"),
                                            (_deep_block(300), "nested more than")])
def test_invalid_config_at_start_is_one_line_and_exit_2(tmp_path, text, said):
    (tmp_path / "bad.yaml").write_text(text)
    r = subprocess.run([sys.executable, "-m", "stationd", "run", "--config",
                        str(tmp_path / "bad.yaml")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and said in r.stderr


@pytest.mark.timeout(180)
def test_a_second_daemon_on_the_same_database_exits_2_naming_the_first(tmp_path):
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    station.write_text(station.read_text().replace("http: {listen: '127.0.0.1:8080'}", ""))
    sock = NotifyManager(tmp_path / "notify")
    env = {**os.environ, "NOTIFY_SOCKET": str(tmp_path / "notify")}
    first = subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config",
                              "station.yaml"], cwd=tmp_path, env=env,
                             stderr=subprocess.DEVNULL)
    try:
        _recv_until(sock, "READY=1", 90)
        second = subprocess.run([sys.executable, "-m", "stationd", "run", "--config",
                                 str(station)], capture_output=True, text=True, timeout=60,
                                env={k: v for k, v in os.environ.items()
                                     if k != "NOTIFY_SOCKET"})
        assert second.returncode == 2 and second.stderr.count("\n") == 1, second.stderr
        assert f"already run by pid {first.pid}" in second.stderr
        assert first.poll() is None   # the first one is untouched
        first.send_signal(signal.SIGTERM)
        assert first.wait(timeout=60) == 0
    finally:
        if first.poll() is None:
            first.kill()
        sock.close()


def _sim_copy(tmp_path, **replace):
    for f in SIM.iterdir():
        if f.is_file() and not f.name.startswith("stationd-sim.db"):
            shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    text = station.read_text().replace("http: {listen: '127.0.0.1:8080'}", "")
    for old, new in replace.items():
        text = text.replace(old, new)
    station.write_text(text)
    return station


@pytest.mark.parametrize("old, new, said", [
    ("lift: {url: 'sim://lift'}", "lift: {url: 'ftp://127.0.0.1:15020'}",
     "unknown lift scheme 'ftp'"),
    ("wrench: {url: 'sim://wrench'}", "wrench: {url: 'openprotocl://10.0.0.5:4545'}",
     "unknown wrench scheme 'openprotocl'"),
    ("database: {url: 'sqlite:///stationd-sim.db'}", "database: {url: 'bogus://x'}",
     "database URL 'bogus://x'"),
])
def test_a_url_typo_at_start_is_one_line_and_exit_2_not_a_fault_forever(tmp_path, old, new,
                                                                        said):
    station = _sim_copy(tmp_path, **{old: new})
    assert new in station.read_text()
    r = subprocess.run([sys.executable, "-m", "stationd", "run", "--config", str(station)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and said in r.stderr and "Traceback" not in r.stderr


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes any folder: needs a normal user")
def test_a_database_folder_the_user_cannot_write_is_one_line_and_exit_2(tmp_path):
    locked = tmp_path / "ro"
    locked.mkdir()
    locked.chmod(0o500)
    station = _sim_copy(tmp_path, **{"sqlite:///stationd-sim.db": f"sqlite:///{locked}/x.db"})
    r = subprocess.run([sys.executable, "-m", "stationd", "run", "--config", str(station)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "cannot create the station's lock" in r.stderr


def test_a_database_folder_that_cannot_be_created_is_one_line_and_exit_2(tmp_path):
    """Even root cannot make a folder under /proc: the same one line as a permission error."""
    station = _sim_copy(tmp_path, **{"sqlite:///stationd-sim.db": "sqlite:////proc/stationd/x.db"})
    r = subprocess.run([sys.executable, "-m", "stationd", "run", "--config", str(station)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    # issue 19: the station file's check refuses a missing database folder before the lock
    # would create it (as whichever user runs the daemon)
    assert "folder /proc/stationd does not exist: create it" in r.stderr
    assert "Traceback" not in r.stderr


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _get(url: str) -> tuple[int, str]:
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(url, timeout=5) as r:  # noqa: S310 - loopback
            return r.status, r.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


@pytest.mark.timeout(180)
def test_a_database_unusable_at_start_is_served_as_a_fault_then_the_results_come(tmp_path):
    """A database file that is not a database at the first start: the daemon does not exit,
    its screens and /healthz say "fault: database" meanwhile (monitoring must not see "no
    daemon"), and once the file is usable the station runs and the results pages answer."""
    import json

    port = _free_port()
    station = _sim_copy(tmp_path, **{"database: {url: 'sqlite:///stationd-sim.db'}":
                                     "database: {url: 'sqlite:///stationd-sim.db'}\n"
                                     f"http: {{listen: '127.0.0.1:{port}'}}"})
    assert f"127.0.0.1:{port}" in station.read_text()
    db = tmp_path / "stationd-sim.db"
    db.write_text("this is not a database\n" * 100)
    sock = NotifyManager(tmp_path / "notify")
    # a 2 s watchdog: systemd would kill a daemon that stops pinging while it waits for its
    # database (second newcomer trial: no WATCHDOG=1 at all meanwhile, killed every ~12 s)
    env = {**os.environ, "NOTIFY_SOCKET": str(tmp_path / "notify"), "WATCHDOG_USEC": "2000000"}
    env.pop("WATCHDOG_PID", None)
    p = subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config", "station.yaml"],
                         cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    base = f"http://127.0.0.1:{port}"
    try:
        _recv_until(sock, "fault: database", 90)
        for _ in range(3):                      # pinged on, in fault, every second
            _recv_until(sock, "WATCHDOG=1", 30)
        end = time.monotonic() + 30
        while True:
            try:
                code, body = _get(base + "/healthz")
                break
            except OSError:
                assert time.monotonic() < end, "the screens never answered"
                time.sleep(0.2)
        assert code == 503 and body.strip() == "fault"    # details: /api/status (token)
        status = json.loads(_get(base + "/api/status")[1])
        assert status["state"] == "fault" and "database" in status["reason"]
        assert _get(base + "/api/vehicles")[0] == 503      # no results yet, said so
        db.unlink()                                     # the disk is fixed: a new database
        _recv_until(sock, "waiting for vehicle", 90)
        end = time.monotonic() + 30
        while _get(base + "/healthz")[0] != 200:
            assert time.monotonic() < end, "healthz stayed in fault"
            time.sleep(0.2)
        assert _get(base + "/api/vehicles")[0] == 200
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=60) == 0
    finally:
        err = _ended(p)
        sock.close()
    assert "Traceback" not in err


@pytest.mark.timeout(240)
def test_a_reload_onto_another_database_moves_the_lock_or_is_refused(tmp_path):
    """One daemon per database across reloads: onto a new database the lock moves (the old one
    is free for another daemon, the new one refused to a second daemon); onto a database
    another daemon runs, the reload is refused and the running station kept."""
    station = _sim_copy(tmp_path)
    text = station.read_text()
    old_db = "database: {url: 'sqlite:///stationd-sim.db'}"
    assert old_db in text
    a2 = tmp_path / "a2.yaml"
    a2.write_text(text.replace(old_db, "database: {url: 'sqlite:///a2.db'}"))
    other = tmp_path / "other"                 # b's station, on a's first database
    other.mkdir()
    for f in tmp_path.iterdir():
        if f.is_file() and f.suffix == ".yaml":
            shutil.copy(f, other)
    first_db = f"database: {{url: 'sqlite:///{tmp_path}/stationd-sim.db'}}"
    (other / "station.yaml").write_text(text.replace(old_db, first_db))
    sock = NotifyManager(tmp_path / "notify")
    env = {**os.environ, "NOTIFY_SOCKET": str(tmp_path / "notify")}
    quiet = {k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"}

    def second(config: Path) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "stationd", "run", "--config",
                               str(config)], capture_output=True, text=True, timeout=60,
                              env=quiet)

    a = subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config", "station.yaml"],
                         cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    b: subprocess.Popen[bytes] | None = None
    b_sock: NotifyManager | None = None
    try:
        _recv_until(sock, "READY=1", 90)
        station.write_text(a2.read_text())
        a.send_signal(signal.SIGHUP)
        _recv_until(sock, "READY=1", 90)                      # running on a2.db now
        r = second(a2)
        assert r.returncode == 2 and f"already run by pid {a.pid}" in r.stderr, r.stderr
        # a's first database is free: another daemon runs on it
        b_sock = NotifyManager(tmp_path / "notify-b")
        b = subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config",
                              "station.yaml"], cwd=other,
                             env={**quiet, "NOTIFY_SOCKET": str(tmp_path / "notify-b")},
                             stderr=subprocess.DEVNULL)
        _recv_until(b_sock, "READY=1", 90)             # b holds the database now
        assert b.poll() is None
        # a reload of a back onto it is refused: a keeps a2.db and runs on
        station.write_text(text.replace(old_db, first_db))
        a.send_signal(signal.SIGHUP)
        _recv_until(sock, "reload refused", 60)
        assert a.poll() is None
        r = second(a2)
        assert r.returncode == 2 and f"already run by pid {a.pid}" in r.stderr, r.stderr
        a.send_signal(signal.SIGTERM)
        assert a.wait(timeout=60) == 0
    finally:
        for p in (a, b):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    p.kill()
        sock.close()
        if b_sock is not None:
            b_sock.close()
    err = a.stderr.read() if a.stderr else ""
    assert b is not None and f"already run by pid {b.pid}" in err and "Traceback" not in err


@pytest.mark.timeout(180)
def test_a_reload_moving_the_screens_onto_a_port_in_use_is_refused(tmp_path):
    """The screens are where the operators look: a reload that would move them to a port
    another program holds is refused, and they stay served where they are (it was accepted
    and the screens were gone, the journal saying so once).  Their own port on another
    host (opened to the line's network) is no port in use: that reload goes through."""
    import urllib.request

    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    here = _free_port()
    while (taken := _free_port()) == here:
        pass
    text = (SIM / "station.yaml").read_text()
    assert "127.0.0.1:8080" in text
    (tmp_path / "station.yaml").write_text(text.replace("127.0.0.1:8080", f"127.0.0.1:{here}"))
    sock = NotifyManager(tmp_path / "notify")
    env = {**os.environ, "NOTIFY_SOCKET": str(tmp_path / "notify")}
    p = subprocess.Popen([sys.executable, "-m", "stationd", "run", "--config", "station.yaml"],
                         cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    holder = socket.socket()
    try:
        _recv_until(sock, "READY=1", 90)
        (tmp_path / "station.yaml").write_text(text.replace(
            "'127.0.0.1:8080'}", f"'0.0.0.0:{here}', token: 'line-network-token-1'}}"))
        p.send_signal(signal.SIGHUP)
        reloaded = _recv_until(sock, "READY=1", 90)
        assert not any("reload refused" in m for m in reloaded), reloaded
        holder.bind(("127.0.0.1", taken))
        holder.listen()
        (tmp_path / "station.yaml").write_text(text.replace("127.0.0.1:8080",
                                                            f"127.0.0.1:{taken}"))
        p.send_signal(signal.SIGHUP)
        refused = _recv_until(sock, "reload refused", 60)
        with urllib.request.urlopen(f"http://127.0.0.1:{here}/healthz", timeout=30) as answer:
            assert answer.status in (200, 503)        # served where it was
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=60) == 0
    finally:
        holder.close()
        err = _ended(p)
        sock.close()
    assert any(f"127.0.0.1:{taken}: the port is in use" in m for m in refused), refused
    assert (f"reload refused, keeping the running configuration: http.listen 127.0.0.1:{taken}: "
            f"the port is in use") in err, err
    assert f"the screens stay on 0.0.0.0:{here}" in err
