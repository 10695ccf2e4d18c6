"""The Open Protocol client against the simulated controller, one contract run over TCP on
127.0.0.1 and over a pty pair (pyserial), plus the URL registry."""

from __future__ import annotations

import threading
import time

import pytest

from drivers.errors import DeviceError, RefusedError, UrlError
from drivers.link import SerialLink, TcpLink
from drivers.url import parse_url
from drivers.wrench import open_wrench
from drivers.wrench.base import Status
from drivers.wrench.openprotocol.client import OpenProtocolWrench
from drivers.wrench.sim.controller import SimWrench

from ..conftest import FAST, connect, reconnect_within, url_for, wait_until

TRANSPORTS = ["tcp", "serial"]


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_session_start_subscribes_and_introduces_the_controller(sim, transport, tmp_path):
    with connect(sim, transport, tmp_path) as w:
        assert w.identity().startswith("SimController (cell 0001, channel 01): supplier "
                                       "SIM, Open Protocol 2.8.0, software stationd-sim 1.0")
        assert [(r.mid, r.revision, r.data) for r in sim.received()] == [
            (1, 6, b""), (60, 7, b""), (80, 1, b"")]            # 0080: the controller's clock
        assert w.revisions == {1: 6, 60: 7} and not w.link_level
        assert w.status().connected and w.wait_connected(0.1)
        # the same MID 0002, typed: the nameplate fields an MES reads over OPC UA
        plate = w.identification()
        assert plate.words == w.identity()
        assert (plate.manufacturer, plate.model, plate.serial_number,
                plate.software_revision) == ("SIM", "SimController (RBU simulated RBU)",
                                             "SIM0000001", "stationd-sim 1.0")
    assert sim.received()[-1].mid == 3                    # communication stop on close


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_commands_reach_the_controller_and_are_acknowledged(sim, transport, tmp_path):
    with connect(sim, transport, tmp_path) as w:
        w.select_pset(2)
        w.send_vin("WVWZZZ1JZ3W386752")
        w.enable_tool()
        assert (sim.pset, sim.vin, sim.tool_enabled) == (2, "WVWZZZ1JZ3W386752", True)
        w.disable_tool(timeout=0.3)
        assert not sim.tool_enabled
    sent = {r.mid: r.data for r in sim.received()}
    assert sent[18] == b"002" and sent[50] == b"WVWZZZ1JZ3W386752        "
    assert sent[42] == sent[43] == b""


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_results_are_parsed_and_each_acknowledged(sim, transport, tmp_path):
    with connect(sim, transport, tmp_path) as w:
        w.select_pset(1)
        w.send_vin("VIN42")
        w.enable_tool()
        assert w.wait_result(0.05) is None
        truth = [sim.pull_trigger() for _ in range(5)]
        got = [w.wait_result(1.0) for _ in truth]
        assert wait_until(lambda: sim.acks == 5)
    for t, r in zip(truth, got, strict=True):
        assert t is not None and r is not None
        assert (r.tightening_id, r.pset, r.ok, r.torque_nm, r.angle_deg, r.vin, r.timestamp) \
            == (t.tightening_id, 1, t.ok, t.torque_nm, t.angle_deg, "VIN42", t.timestamp)
        assert r.torque_status is Status.OK and 22.5 <= r.torque_nm <= 27.5
        assert (r.torque_target_nm, r.angle_min_deg, r.angle_max_deg) == (25.0, 60.0, 120.0)
    assert [r.tightening_id for r in got if r] == [1, 2, 3, 4, 5]


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_refusal_carries_the_code_and_keeps_the_link(sim, transport, tmp_path):
    sim.refuse_pset(3, 3)
    with connect(sim, transport, tmp_path) as w:
        with pytest.raises(RefusedError, match=r"select pset 9: .*error 02 \(parameter set "
                                               r"not present\)") as e:
            w.select_pset(9)
        assert e.value.code == 2
        with pytest.raises(RefusedError, match="error 03") as e:
            w.select_pset(3)
        assert e.value.code == 3 and sim.pset is None
        w.select_pset(1)
        assert w.status().reconnects == 0 and sim.pset == 1


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_keepalive_holds_an_idle_link_open(sim, transport, tmp_path):
    sim.silence_timeout = 0.4                    # the real controller: 15 s, we send at 10 s
    with connect(sim, transport, tmp_path, keepalive=0.1) as w:
        time.sleep(1.0)
        assert w.status() == w.status().__class__(connected=True)
        assert sim.drops == 0 and len(sim.received(9999)) >= 5
        w.select_pset(1)


def test_default_keepalive_is_10_s_within_the_controllers_15_s():
    w = OpenProtocolWrench(TcpLink("127.0.0.1", 1), device="x")
    assert w._keepalive == 10.0 and 10.0 < SimWrench.from_url(
        parse_url("sim://wrench")).controller.silence_timeout == 15.0


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_commands_from_several_threads_are_serialised(sim, transport, tmp_path):
    errors = []
    with connect(sim, transport, tmp_path) as w:
        def work(n):
            try:
                for i in range(10):
                    w.select_pset(1 + (n + i) % 3)
            except BaseException as e:
                errors.append(e)
        threads = [threading.Thread(target=work, args=(n,)) for n in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert errors == [] and sim.errors == [] and len(sim.received(18)) == 40


def test_a_result_reaches_a_thread_already_waiting(sim, tmp_path):
    got = []
    with connect(sim, "tcp", tmp_path) as w:
        w.select_pset(1)
        w.enable_tool()
        waiter = threading.Thread(target=lambda: got.append(w.wait_result(2.0)))
        waiter.start()
        time.sleep(0.05)
        sim.pull_trigger()
        waiter.join()
    assert got and got[0] is not None and got[0].tightening_id == 1


def test_lifecycle_open_close_idempotent_and_final(sim, tmp_path):
    w = open_wrench(url_for(sim, "tcp", tmp_path), connect=False, **FAST)
    with pytest.raises(DeviceError, match="not open"):
        w.select_pset(1)
    w.close()                                   # before open: nothing to do
    w2 = open_wrench(f"openprotocol://127.0.0.1:{sim.listen_tcp()}", **FAST)
    w2.open()                                   # already open: nothing to do
    w2.close()
    w2.close()
    with pytest.raises(DeviceError, match="closed"):
        w2.select_pset(1)
    with pytest.raises(DeviceError, match="closed; open a new one"):
        w2.open()


def test_arguments_are_checked_before_anything_is_sent(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        for bad in (-1, 1000, 1.0, True):
            with pytest.raises(ValueError, match="pset must be an integer 0-999"):
                w.select_pset(bad)
        with pytest.raises(ValueError, match="at most 25"):
            w.send_vin("X" * 26)
        with pytest.raises(ValueError, match="printable ASCII"):
            w.send_vin("VIN\x03")
    assert sim.received(18) == sim.received(50) == []


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_sim_url_runs_the_real_protocol_and_is_reproducible(transport):
    runs = []
    for _ in range(2):
        with open_wrench(f"sim://wrench?transport={transport}&seed=7&nok_rate=0.5",
                         **FAST) as w:
            assert isinstance(w, SimWrench) and w.controller.received(1)
            w.select_pset(2)
            w.enable_tool()
            results = []
            for _ in range(6):
                w.controller.pull_trigger()
                results.append(w.wait_result(1.0))
            runs.append([(r.torque_nm, r.angle_deg, r.ok) for r in results if r])
    assert runs[0] == runs[1] and len(runs[0]) == 6
    assert {ok for _, _, ok in runs[0]} == {True, False}


def test_urls_pick_the_backend_and_its_options():
    tcp = OpenProtocolWrench.from_url(parse_url("openprotocol://10.0.0.9?timeout=0.7"))
    assert isinstance(tcp._link, TcpLink) and tcp._link.port == 4545 and tcp.timeout == 0.7
    ser = OpenProtocolWrench.from_url(parse_url("openprotocol+serial:///dev/ttyUSB1?baud=9600"))
    assert isinstance(ser._link, SerialLink) and (ser._link.port, ser._link.baudrate) == (
        "/dev/ttyUSB1", 9600)
    w = open_wrench("sim://wrench?transport=serial", connect=False, timeout=0.3, psets={})
    assert isinstance(w, SimWrench) and w.timeout == 0.3 and w.controller.psets == {}


@pytest.mark.parametrize(("url", "words"), [
    ("modbus-udp://10.0.0.1:502", "unknown wrench scheme 'modbus-udp' (accepted: "
                                  "openprotocol://HOST[:4545], openprotocol+serial://"),
    ("openprotocol://10.0.0.1?baud=9600", "unknown option baud (accepted: connect_timeout,"),
    ("openprotocol+serial:///dev/ttyUSB1?parity=E", "unknown option parity"),
    ("openprotocol://10.0.0.1?timeout=-1", "timeout must be > 0"),
    ("openprotocol://10.0.0.1?timeout=fast", "option timeout='fast' is not valid"),
    ("openprotocol:///dev/ttyUSB1", "expected openprotocol://HOST[:PORT]"),
    ("openprotocol+serial://host:4545", "expected a device path"),
    ("sim://lift", "expected sim://wrench"),
    ("sim://wrench?transport=usb", "transport must be tcp or serial"),
    ("sim://wrench?nok_rate=2", "nok_rate must be in [0, 1]"),
    ("wrench", "is not a device URL"),
])
def test_bad_urls_say_what_is_accepted(url, words):
    with pytest.raises(UrlError) as e:
        open_wrench(url)
    assert words in str(e.value)


def test_unknown_keyword_is_a_type_error():
    with pytest.raises(TypeError, match=r"unknown option.*retries"):
        open_wrench("openprotocol://10.0.0.1", retries=3)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_result_is_acknowledged_only_when_the_station_says_it_is_stored(sim, transport,
                                                                          tmp_path):
    with connect(sim, transport, tmp_path) as w:
        w.select_pset(1)
        w.enable_tool()
        first, second = sim.pull_trigger(), sim.pull_trigger()
        r1 = w.wait_result(1.0, acknowledge=False)
        r2 = w.wait_result(1.0, acknowledge=False)
        assert r1 is not None and r2 is not None and first is not None and second is not None
        time.sleep(0.2)
        assert sim.acks == 0 and sim.acked_ids == []      # received, not acknowledged
        w.acknowledge_result(r1)
        assert wait_until(lambda: sim.acked_ids == [first.tightening_id])
        with pytest.raises(ValueError, match="not awaiting acknowledgement"):
            w.acknowledge_result(r1)                      # twice: refused, nothing sent
        w.acknowledge_result(r2)
        assert wait_until(lambda: sim.acked_ids == [1, 2])
        assert sim.acks == 2


def test_an_acknowledgement_never_crosses_to_a_new_session(sim, tmp_path):
    """0062 names no result: after a reconnect it would acknowledge the new session's
    results, so a result from the old link cannot be acknowledged any more."""
    with connect(sim, "tcp", tmp_path) as w:
        w.select_pset(1)
        w.enable_tool()
        sim.pull_trigger()
        r = w.wait_result(1.0, acknowledge=False)
        assert r is not None
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected) and reconnect_within(w)
        with pytest.raises(DeviceError, match=r"acknowledge tightening 1: .*still holds it"):
            w.acknowledge_result(r)
        assert sim.acks == 0


def test_a_controller_that_hangs_while_asked_is_a_lost_link(sim, tmp_path):
    """The controller hangs with its socket open while the station keeps asking for results
    (each unanswered MID 0064 taken as a refusal, the traffic never idle): once it has said
    nothing for the keep-alive's interval, a keep-alive is sent, and unmirrored it is a lost
    link (an integrator's trial: 18 refusals in 45 s, the wrench "ok" throughout).  A
    controller that ignores MID 0064 alone keeps its link: it mirrors the keep-alive."""
    with connect(sim, "tcp", tmp_path, keepalive=0.3, timeout=0.2) as w:
        sim.ignore_mid(64)
        for _ in range(8):                       # 1.6 s of asking, never idle
            with pytest.raises(RefusedError, match="taken as refused"):
                w.fetch_result(0, timeout=0.2)
        assert w.status().connected and sim.received(9999), "a refusal alone is no lost link"
        sim.hang()
        lost = False
        for _ in range(50):
            try:
                w.fetch_result(0, timeout=0.2)
            except RefusedError:
                continue
            except DeviceError:
                lost = True
                break
        assert lost and not w.status().connected
        assert "keep-alive (MID 9999) not mirrored" in str(w.status().reason)
