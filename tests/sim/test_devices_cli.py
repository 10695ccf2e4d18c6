"""``stationd sim plc`` and ``stationd sim controller``: the simulated devices served on their
real protocols in a process of their own, read by the station's own drivers as a station being
commissioned would; and the VINs of the simulated line."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from drivers.errors import RefusedError
from drivers.lift import open_lift
from drivers.wrench import open_wrench
from stationd.sim.vin import check_digit, is_valid, make_vin

ROOT = Path(__file__).resolve().parents[2]
STATION = ROOT / "config" / "sim" / "station.yaml"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(*argv: str) -> tuple[subprocess.Popen[str], str]:
    """The command, and its first line (where it listens)."""
    p = subprocess.Popen([sys.executable, "-m", "stationd", "sim", *argv], cwd=ROOT,
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert p.stdout is not None
    return p, p.stdout.readline()


def _stop(p: subprocess.Popen[str]) -> int:
    p.send_signal(signal.SIGTERM)
    return p.wait(60)


def test_the_simulated_plc_is_driven_by_commands_and_read_over_modbus() -> None:
    port = _free_port()
    p, first = _start("plc", "--config", str(STATION), "--port", str(port))
    try:
        assert f"127.0.0.1:{port}" in first
        assert p.stdin is not None and p.stdout is not None
        p.stdout.readline()   # the commands' help
        with open_lift(f"modbus-tcp://127.0.0.1:{port}?timeout=1") as lift:
            assert not lift.read_state().at_working_height
            p.stdin.write("vehicle 1 9SDST0018TL000001\nraise\n")
            p.stdin.flush()
            said = p.stdout.readline() + p.stdout.readline()
            s = lift.read_state()
            assert s.at_working_height and s.model_code == 1 and s.vin == "9SDST0018TL000001"
            assert "at working height" in said
            p.stdin.write("frobnicate\nlower\n")
            p.stdin.flush()
            assert "not a command" in p.stdout.readline()
            p.stdout.readline()
            assert not lift.read_state().at_working_height
    finally:
        assert _stop(p) == 0


def test_the_simulated_plc_serves_on_when_its_stdin_ends() -> None:
    """``stationd sim plc </dev/null`` (nohup, a service) ended silently: the station saw
    only "connection refused"."""
    port = _free_port()
    p, first = _start("plc", "--config", str(STATION), "--port", str(port))
    try:
        assert p.stdin is not None and p.stdout is not None and f"127.0.0.1:{port}" in first
        p.stdin.close()
        p.stdout.readline()   # the commands' help
        assert p.stdout.readline().startswith("stdin closed: the PLC serves on")
        with open_lift(f"modbus-tcp://127.0.0.1:{port}?timeout=2") as lift:
            assert not lift.read_state().at_working_height
        assert p.poll() is None
    finally:
        assert _stop(p) == 0


def test_the_simulated_controller_runs_the_station_files_psets_over_open_protocol() -> None:
    port = _free_port()
    p, first = _start("controller", "--config", str(STATION), "--port", str(port))
    try:
        assert f"127.0.0.1:{port}" in first and "psets" in first
        with open_wrench(f"openprotocol://127.0.0.1:{port}", timeout=2.0) as w:
            w.select_pset(1)
            with pytest.raises(RefusedError):
                w.select_pset(99)   # not in the bolt table
    finally:
        assert _stop(p) == 0


def test_a_port_out_of_range_is_one_line_and_exit_2() -> None:
    r = subprocess.run([sys.executable, "-m", "stationd", "sim", "plc", "--port", "70000"],
                       cwd=ROOT, capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "0-65535" in r.stderr


@pytest.mark.parametrize(("argv", "words"), [
    (("plc", "--every", "-1"), "--every -1: seconds"),
    (("plc", "--every", "nan"), "--every nan: seconds"),
    (("plc", "--model-code", "70000"), "holds 0-65535"),
    (("controller", "--trigger-every", "-1"), "--trigger-every -1: seconds"),
    (("controller", "--nok-rate", "2"),
     "stationd: error: --nok-rate 2: the share of NOK results, 0 to 1"),
])
def test_numbers_that_cannot_work_are_refused_at_the_start(argv: tuple[str, ...],
                                                           words: str) -> None:
    """A sweep: these were taken silently (a negative period, NaN) or refused only at the
    first vehicle (a model code that does not fit the register)."""
    r = subprocess.run([sys.executable, "-m", "stationd", "sim", *argv], cwd=ROOT,
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and words in r.stderr, r
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.parametrize("device", ["plc", "controller", "lift", "wrench"])
def test_a_busy_port_is_one_line_for_the_plc_as_for_the_controller(device: str) -> None:
    """A sweep: the PLC on a port in use ended in pymodbus's RuntimeError traceback; then
    both said ``error: cannot listen ...`` with exit 1, not as the station's other commands
    say their errors (``stationd: error: ...``, exit 2).  ``sim lift`` and ``sim wrench``
    are the same simulators under the names ``probe``, ``status`` and the journal use."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = subprocess.run([sys.executable, "-m", "stationd", "sim", device, "--port",
                            str(port)], cwd=ROOT, capture_output=True, text=True, timeout=60,
                           stdin=subprocess.DEVNULL)
    assert r.returncode == 2, r
    assert r.stderr.startswith(f"stationd: error: cannot listen on 127.0.0.1:{port}: the port "
                               "is in use"), r     # in the same words (not "Address ...")
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_vins_have_17_characters_of_the_alphabet_and_their_check_digit() -> None:
    assert check_digit("1M8GDM9AXKP042788") == "X"        # the standard's worked example
    vins = [make_vin(n) for n in (0, 1, 42, 999_999)]
    assert all(len(v) == 17 and is_valid(v) for v in vins)
    assert len(set(vins)) == 4
    assert not is_valid(vins[1][:8] + ("0" if vins[1][8] != "0" else "1") + vins[1][9:])
    assert not is_valid("1M8GDM9AXKP04278")      # 16 characters
    assert not is_valid("IM8GDM9AXKP042788")     # I is not in the alphabet
    with pytest.raises(ValueError):
        make_vin(1_000_000)


def test_the_simulated_controller_runs_the_nok_policys_loosen_psets(tmp_path: Path) -> None:
    """A station whose NOK policy loosens with pset 4: the standalone controller announced
    psets 1, 2, 3 and refused pset 4 (parameter set not present), every loosening the
    station would ask for (a line engineer's trial); the daemon's own simulator had it."""
    import shutil
    for f in STATION.parent.iterdir():
        shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    station.write_text(station.read_text() + "nok: {max_nok: 2, strategy: loosen, "
                                              "loosen_pset: 4}\n")
    port = _free_port()
    p, first = _start("controller", "--config", str(station), "--port", str(port))
    try:
        assert "psets 1, 2, 3, 4)" in first, first
        with open_wrench(f"openprotocol://127.0.0.1:{port}", timeout=2.0) as w:
            w.select_pset(4)
    finally:
        assert _stop(p) == 0
    # a station whose bolt tables are in its database only: the simulator's own programs,
    # and the policy's loosen pset beside them
    from stationd.sim.devices_cli import _station

    station.write_text(station.read_text().replace("bolts: bolts.yaml\n", ""))
    _, psets, _ = _station(str(station))
    assert psets is not None and 4 in psets and 1 in psets


def test_the_simulated_plc_serves_the_unit_of_the_station_files_lift(tmp_path: Path) -> None:
    """A commissioning engineer's trial: the station file names the real PLC's unit
    (``modbus-tcp://...?unit=5``) and ``stationd sim plc --config`` stands in for it.  The
    simulator took the file's register map but served unit 1 whatever the file said, and had
    no option to say another: the daemon on that file stayed in fault ("Modbus exception 4
    ... a unit id it does not serve").  ``--unit`` says another one."""
    import shutil
    for f in STATION.parent.iterdir():
        shutil.copy(f, tmp_path)
    port = _free_port()
    station = tmp_path / "station.yaml"
    station.write_text(station.read_text().replace(
        "lift: {url: 'sim://lift'}", f"lift: {{url: 'modbus-tcp://127.0.0.1:{port}?unit=5'}}"))
    assert "unit=5" in station.read_text()
    for given, unit in (((), 5), (("--unit", "7"), 7)):   # the file's, then another
        p, first = _start("plc", "--config", str(station), "--port", str(port), *given)
        try:
            assert f"unit {unit})" in first, first
            with open_lift(f"modbus-tcp://127.0.0.1:{port}?unit={unit}&timeout=2") as lift:
                assert not lift.read_state().at_working_height
        finally:
            assert _stop(p) == 0
        port = _free_port()
