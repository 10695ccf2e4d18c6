"""The simulated controller's revisions, old results and link level, checked byte for byte by
a hand-written integrator on a raw socket (not by our client), and its entry point."""

from __future__ import annotations

import io
import os
import queue
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from drivers.wrench import open_wrench
from drivers.wrench.base import TighteningResult
from drivers.wrench.sim import cli as sim_cli
from drivers.wrench.sim.controller import SimController

from ..conftest import FAST, op, read_message, wait_until

ROOT = Path(__file__).resolve().parents[4]


def raw_tcp(sim: SimController) -> socket.socket:
    return socket.create_connection(("127.0.0.1", sim.listen_tcp()), timeout=1.0)


def ask(conn: socket.socket, mid: int, data: bytes = b"", rev: str = "001",
        seq: str = "  ") -> bytes:
    raw = op(mid, data, rev)
    conn.sendall(raw[:16] + seq.encode() + raw[18:])
    return read_message(conn)


def start(c: socket.socket, rev: str = "001") -> bytes:
    return ask(c, 1, rev=rev)


def test_identity_in_revision_6_byte_for_byte(sim):
    with raw_tcp(sim) as c:
        got = start(c, "006")
    # R2.8.0 table 16: revision 6 brings 12-16; the last byte is 221 (client id)
    assert got == (b"02210002006         " + b"010001" + b"0201" + b"03"
                   + b"SimController".ljust(25) + b"04SIM" + b"05" + b"2.8.0".ljust(19)
                   + b"06" + b"stationd-sim 1.0".ljust(19) + b"07" + b"sim tool 1.0".ljust(19)
                   + b"08" + b"simulated RBU".ljust(24) + b"09SIM0000001" + b"10000"
                   + b"11000" + b"120" + b"131" + b"14" + b"1".ljust(10) + b"15"
                   + b"simulated station".ljust(25) + b"161" + b"\x00")
    assert int(got[:4]) == len(got) - 1


def test_refused_revisions_and_the_code(sim):
    sim.refuse_revisions(1, {7, 6})
    sim.refuse_revisions(60, {7})
    sim.revision_refusal_code = 76
    with raw_tcp(sim) as c:
        assert start(c, "007") == b"00260004001         000176\x00"
        assert start(c, "006") == b"00260004001         000176\x00"
        assert start(c, "005")[4:11] == b"0002005"
        assert ask(c, 60, rev="007") == b"00260004001         006076\x00"
        assert ask(c, 60, rev="999") == b"00260004001         006076\x00"   # never served
        assert ask(c, 60, rev="003") == b"00240005001         0060\x00"
        ask(c, 18, b"001")
        ask(c, 43)
        sim.pull_trigger()
        pushed = read_message(c)
    assert pushed[4:11] == b"0061003" and len(pushed) == 419 + 1
    assert pushed[385:387] == b"47"          # revision 3's first tag, after revision 2's 385


def test_old_results_by_id_newest_and_not_found(sim):
    with raw_tcp(sim) as c:
        start(c)
        assert ask(c, 64, b"0000000000") == b"00260004001         006415\x00"
        ask(c, 18, b"002")
        ask(c, 43)
        first, second = sim.pull_trigger(), sim.pull_trigger()
        by_id = ask(c, 64, b"0000000001")
        newest = ask(c, 64, b"0000000000", rev="002")
        assert ask(c, 64, b"12") == b"00260004001         006401\x00"        # invalid data
        sim.forget_results(1)
        assert ask(c, 64, b"0000000001") == b"00260004001         006415\x00"
    assert first is not None and second is not None
    assert by_id[:20] == b"01180065001         " and by_id[20:32] == b"010000000001"
    assert by_id[59:64] == b"03002"                           # pset, at its place
    assert newest[4:11] == b"0065002" and len(newest) == 226 + 1   # table 86: 226 bytes
    assert newest[20:32] == b"010000000002"                 # the tightening id first


def test_link_level_byte_for_byte():
    """Each 9997/9998 names the number its sender expects next: the received one + 1 (the
    specification's figure 8: "MID 0060 seq. 01" -> "MID 9997 seq. 02")."""
    with SimController(seed=1, nok_rate=0.0, link_ack=True) as sim, raw_tcp(sim) as c:
        ident = start(c, "006")
        assert ident[-4:] == b"161\x00" and b"121131" in ident[20:]   # says it does
        c.sendall(op(60, rev="007")[:16] + b"01" + op(60, rev="007")[18:])
        assert read_message(c) == b"00249997001     02  0060\x00"    # its link-level ack
        answer = read_message(c)                                     # numbered: 01
        assert answer == b"00240005001     01  0060\x00"
        c.sendall(b"00249997001     02  0005\x00")                   # our ack of it
        # a repeat of our 0060 (same number): acknowledged again, not handled again
        c.sendall(op(60, rev="007")[:16] + b"01" + op(60, rev="007")[18:])
        assert read_message(c) == b"00249997001     02  0060\x00"
        # a message without a number: link-level error 0003 (invalid sequence number),
        # numbered with the one expected
        c.sendall(op(18, b"001"))
        assert read_message(c) == b"00289998001     02  00180003\x00"
        # nor a number that is neither the next nor a repeat
        assert ask(c, 18, b"001", seq="05") == b"00289998001     02  00180003\x00"
        assert ask(c, 18, b"001", seq="02") == b"00249997001     03  0018\x00"
        assert read_message(c) == b"00240005001     02  0018\x00"
        # an acknowledgement that echoes the number instead of naming the next is not one
        c.sendall(b"00249997001     02  0005\x00")
        assert wait_until(lambda: any("sequence 2, which is not outstanding" in e
                                      for e in sim.errors))
        c.sendall(b"00249997001     03  0005\x00")                   # this one is
        assert ask(c, 18, b"002", seq="03") == b"00249997001     04  0018\x00"
        assert read_message(c) == b"00240005001     03  0018\x00"    # the next number
    assert sim.repeats == 1 and sim.pset == 2


def test_link_level_resends_then_drops():
    with SimController(seed=1, link_ack=True) as sim, raw_tcp(sim) as c:
        sim.link_timeout = 0.1
        start(c, "006")
        c.sendall(op(60)[:16] + b"01" + op(60)[18:])
        read_message(c)                                               # 9997
        copies = [read_message(c) for _ in range(4)]                  # never acknowledged
        c.settimeout(2.0)
        assert c.recv(100) == b""                                      # dropped
    assert len(set(copies)) == 1 and copies[0][16:18] == b"01"
    assert (sim.resent, sim.link_drops) == (3, 1)


@pytest.mark.system     # another Python process (tests/system.py)
def test_the_entry_point_serves_an_integrator(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "drivers.wrench.sim", "--port", "0", "--link-ack",
         "--refuse", "1:6", "--refuse", "60:7,6", "--nok-rate", "0", "--trigger-every",
         "0.1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        cwd=ROOT)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("listening on 127.0.0.1:"), proc.stderr.read() \
            if proc.stderr else line
        port = int(line.rsplit(":", 1)[1])
        with open_wrench(f"openprotocol://127.0.0.1:{port}", **FAST) as w:
            assert w.revisions == {1: 5, 60: 5} and not w.link_level   # rev 5: no flag
        with open_wrench(f"openprotocol://127.0.0.1:{port}?link_ack=1", **FAST) as w:
            assert w.link_level
            w.select_pset(1)
            w.enable_tool()
            result = w.wait_result(5.0)
            assert result is not None and result.ok and result.revision == 5
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err


@pytest.mark.system     # another Python process (tests/system.py)
def test_the_entry_point_says_what_is_wrong():
    done = subprocess.run([sys.executable, "-m", "drivers.wrench.sim", "--refuse", "x:y"],
                          capture_output=True, text=True, cwd=ROOT, timeout=30, check=False)
    assert done.returncode == 2 and "expected MID:REV[,REV...], not 'x:y'" in done.stderr


def test_a_busy_port_is_a_listen_error_for_its_command_to_say():
    """``serve`` printed its own "error: cannot listen" and returned 1: ``stationd sim
    controller`` could not say it in the station's words (``stationd: error:``, exit 2)."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        out = io.StringIO()
        with pytest.raises(sim_cli.ListenError, match=rf"^cannot listen on 127\.0\.0\.1:{port}: "):
            sim_cli.serve(SimController(), "127.0.0.1", port, 0.0, threading.Event(),
                          lambda p: f"listening on {p}", out=out)
    assert out.getvalue() == ""


@pytest.mark.parametrize("bad", [{"torque_unit": 9}, {"store_size": 0}])
def test_bad_controller_settings(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        SimController(**bad)


def test_the_behaviour_options_in_process(tmp_path):
    """``--result-types``, ``--mislabel`` and ``--clock-offset`` (shared with ``stationd sim
    controller``), served by ``sim_cli.serve`` in this process."""
    args = sim_cli.parser().parse_args(["--port", "0", "--nok-rate", "0", "--trigger-every",
                                        "0.05", "--result-types", "3,1", "--mislabel", "3",
                                        "--clock-offset", "120"])
    assert (args.result_types, args.mislabel, args.clock_offset) == ([3, 1], 3, 120.0)
    sim = SimController(nok_rate=args.nok_rate, **sim_cli.behaviour(args))
    stop, ports = threading.Event(), queue.SimpleQueue()
    server = threading.Thread(target=sim_cli.serve, args=(
        sim, "127.0.0.1", 0, args.trigger_every, stop, lambda p: ports.put(p) or ""),
        kwargs={"out": io.StringIO(), "types": args.result_types})
    server.start()
    try:
        port = ports.get(timeout=5)
        with open_wrench(f"openprotocol://127.0.0.1:{port}", **FAST) as w:
            offset = w.clock_offset_s
            assert offset is not None and 118 < offset < 122
            w.select_pset(1)
            w.enable_tool()
            got = [w.wait_result(2.0) for _ in range(4)]
            w.disable_tool()
    finally:
        stop.set()
        server.join(timeout=10)
    codes = [g.result_type_code for g in got if isinstance(g, TighteningResult)]
    assert codes == [3, 1, 3, 1]
    assert all(g is not None and g.revision == 3 for g in got)
    with pytest.raises(SystemExit):
        sim_cli.parser().parse_args(["--result-types", "1,100"])
