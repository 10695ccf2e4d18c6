"""``stationd probe``: real protocols on loopback, exit codes 0 / 1 / 2."""

import json
import shutil
import socket
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers.lift.sim import SimulatedPlc
from stationd.cli import main
from stationd.outfile import DRAWING_STAMP, FRAME_STAMP, kind_of, stamp_png

SIM = Path(__file__).resolve().parents[1] / "config" / "sim"


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_probe_lift_reads_a_real_modbus_server(capsys):
    with SimulatedPlc() as plc:
        port = plc.start_tcp()
        plc.set_vehicle(7, "WVWZZZ1JZXW000001")
        plc.set_height(1800.0)
        code = main(["probe", "lift", f"modbus-tcp://127.0.0.1:{port}?unit=1", "--json"])
    obj = json.loads(capsys.readouterr().out)
    assert code == 0 and obj["ok"] is True
    assert obj["state"]["model_code"] == 7 and obj["state"]["vin"] == "WVWZZZ1JZXW000001"
    assert abs(obj["state"]["height_mm"] - 1800.0) < 0.1


def test_the_lift_s_and_the_controller_s_ports_swapped_are_said_as_another_device_s(capsys):
    """A technician's trial: the lift's URL on the controller's port and the controller's on
    the PLC's read "the device closed the connection without an answer" and "no answer to
    MID 0001", with no hint of a port of another device."""
    from drivers.wrench.sim.controller import SimController

    with SimController(seed=3) as ctl, SimulatedPlc() as plc:
        op_port, mb_port = ctl.listen_tcp(), plc.start_tcp()
        assert main(["probe", "lift", f"modbus-tcp://127.0.0.1:{op_port}?unit=1",
                     "--timeout", "2"]) == 1
        err = capsys.readouterr().err
        assert "another device's port?" in err and err.count("\n") == 1, err
        assert main(["probe", "wrench", f"openprotocol://127.0.0.1:{mb_port}",
                     "--timeout", "2"]) == 1
        err = capsys.readouterr().err
        assert "no answer to MID 0001" in err and "not an Open Protocol controller's: " \
            "another device's port" in err and err.count("\n") == 1, err


def test_probe_lift_nothing_listening_exits_1(capsys):
    code = main(["probe", "lift", f"modbus-tcp://127.0.0.1:{_free_port()}?unit=1",
                 "--timeout", "0.5"])
    err = capsys.readouterr().err
    assert code == 1 and "refused" in err and err.count("\n") == 1


def test_probe_lift_at_an_http_server_says_garbage_and_what_it_heard(capsys):
    """Pointed at a web server that answers and hangs up: it said ``_HeardTcp ... unbounded
    read``; now as ``probe wrench`` says it."""
    import threading

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def serve() -> None:
        conn, _ = server.accept()
        with conn:
            conn.recv(256)
            conn.sendall(b"HTTP/1.0 400 Bad Request\r\nContent-Type: text/html\r\n\r\n")

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        code = main(["probe", "lift", f"modbus-tcp://127.0.0.1:{server.getsockname()[1]}",
                     "--timeout", "1"])
    finally:
        thread.join(5.0)
        server.close()
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1, err
    assert "garbage reading holding registers 0-11 of unit 1: the device answered something " \
           "that is not Modbus TCP (b'HTTP/1.0 400 Bad Request\\r\\nConten'...)" in err, err


@pytest.mark.parametrize("url,needle", [("bogus://x", "unknown lift scheme"),
                                        ("modbus-tcp://127.0.0.1:502?unti=1", "unknown option")])
def test_probe_lift_bad_url_exits_2(capsys, url, needle):
    code = main(["probe", "lift", url])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and err.count("\n") == 1


def test_station_config_lift_register_map(tmp_path):
    from stationd.config import load_station_config
    from stationd.errors import ConfigError

    cfg = tmp_path / "s.yaml"
    cfg.write_text("lift:\n  url: modbus-tcp://10.0.0.2:502?unit=3\n  registers:\n"
                   "    height: {address: 100}\n")
    lift = load_station_config(cfg).lift
    assert lift.url.startswith("modbus-tcp://") and lift.registers.height.address == 100
    cfg.write_text("lift:\n  registers:\n    heigth: {address: 100}\n")
    with pytest.raises(ConfigError, match=r"s.yaml:3: lift.registers.heigth: unknown key"):
        load_station_config(cfg)


def _probe_while_pulling(ctl, pulls, *probe_args: str) -> int:
    """``stationd probe wrench`` on ``ctl`` (pset 1) while an operator thread, once the
    probe has enabled the tool, calls ``pulls()``: the probe's exit code."""
    import threading
    import time

    port = ctl.listen_tcp()

    def operator():
        for _ in range(300):
            if ctl.tool_enabled and ctl.pset == 1:
                pulls()
                return
            time.sleep(0.01)

    t = threading.Thread(target=operator)
    t.start()
    code = main(["probe", "wrench", f"openprotocol://127.0.0.1:{port}", "--pset", "1",
                 *probe_args])
    t.join()
    return code


def test_probe_wrench_selects_a_pset_and_reports_one_result(capsys):
    from drivers.wrench.sim.controller import SimController

    with SimController(seed=3) as ctl:
        code = _probe_while_pulling(ctl, ctl.pull_trigger, "--wait-result", "3", "--json")
        assert not ctl.tool_enabled  # the probe leaves the tool disabled
    obj = json.loads(capsys.readouterr().out)
    assert code == 0 and obj["acknowledged"] is True and obj["error"] is None
    assert obj["ok"] is True            # as the lift's object and every failure's say it
    r = obj["result"]
    assert r["pset"] == 1 and r["torque_nm"] > 0 and isinstance(r["ok"], bool)
    assert {"angle_deg", "torque_status", "angle_status", "tightening_id", "vin"} <= set(r)


def test_probe_wrench_says_the_controller_s_clock(capsys):
    """A technician checking a controller swapped in could not see its clock (an INFO line
    of the daemon's journal said it): the probe says it, text and JSON."""
    from drivers.wrench.sim.controller import SimController
    from stationd.probe import clock_words

    with SimController(seed=3, clock_offset_s=-7200.0) as ctl:
        port = ctl.listen_tcp()
        assert main(["probe", "wrench", f"openprotocol://127.0.0.1:{port}"]) == 0
        assert "  clock: -7200 s from this machine's: set the controller's clock" in \
            capsys.readouterr().out.splitlines()
        assert main(["probe", "wrench", f"openprotocol://127.0.0.1:{port}", "--json"]) == 0
        assert -7202 < json.loads(capsys.readouterr().out)["clock_offset_s"] < -7198
    assert clock_words(None).startswith("not known")
    assert clock_words(-0.4) == "agrees with this machine's (within 1 s)"
    # whole seconds as the daemon's journal says them (the controller's clock cut down to
    # its second: 12.2 s measured is +13 s)
    assert clock_words(12.2) == "+13 s from this machine's"


def test_probe_wrench_says_what_is_not_a_tightening_and_waits_for_one(capsys):
    """A batch increment, a loosening, a type nobody knows and a message that does not read
    came before the tightening: each printed as what it is (they printed as "result: OK
    torque 0.00 Nm"), the tightening last, with its type."""
    from drivers.wrench.sim.controller import SimController

    with SimController(seed=3) as ctl:
        def pulls():
            ctl.press(3)
            ctl.pull_trigger(2)
            ctl.pull_trigger(9)
            ctl.garble_next_result("value")
            ctl.pull_trigger()
            ctl.pull_trigger()
        code = _probe_while_pulling(ctl, pulls, "--wait-result", "5")
    out = capsys.readouterr().out
    lines = [x.strip() for x in out.splitlines()]
    assert code == 0
    said = [x for x in lines if x.startswith("not a tightening: ")]
    assert [x.split(":")[1].split(",")[0].strip() for x in said] == [
        "batch increment", "loosening", "result type 9 (unknown)",
        "a result that could not be read"], said
    assert all(x.endswith("still waiting for a tightening") for x in said)
    [result] = [x for x in lines if x.startswith("result: ")]
    assert result.startswith("result: tightening OK") or result.startswith("result: tightening NOK")


def test_probe_wrench_refused_pset_exits_1_with_the_code(capsys):
    from drivers.wrench.sim.controller import SimController

    with SimController(refusals={5: 2}) as ctl:
        port = ctl.listen_tcp()
        code = main(["probe", "wrench", f"openprotocol://127.0.0.1:{port}", "--pset", "5",
                     "--json"])
    obj = json.loads(capsys.readouterr().out)
    assert code == 1 and obj["acknowledged"] is False and obj["error"]["code"] == 2
    assert obj["ok"] is False
    with SimController(refusals={5: 2}) as ctl:   # in words: the refusal said once
        port = ctl.listen_tcp()
        code = main(["probe", "wrench", f"openprotocol://127.0.0.1:{port}", "--pset", "5"])
    out, err = capsys.readouterr()
    assert code == 1 and out.splitlines()[-1] == "  pset 5: REFUSED"
    assert err.count("\n") == 1 and err.startswith("stationd: wrench: ")


def test_probe_wrench_no_result_in_time_exits_1(capsys):
    code = main(["probe", "wrench", "sim://wrench", "--pset", "1", "--wait-result", "0.3"])
    out, err = capsys.readouterr()
    assert code == 1 and "no tightening result" in err
    assert "no tightening result" not in out         # said once, on stderr


def test_probe_plc_and_controller_are_the_lift_and_the_wrench(capsys):
    """``sim plc`` and ``sim controller`` start the simulators ``probe lift`` and ``probe
    wrench`` read: either name reaches the same probe (a maintenance trial typed both)."""
    assert main(["probe", "plc", "sim://lift", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["kind"] == "lift"
    assert main(["probe", "controller", "sim://wrench", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["kind"] == "wrench"


def test_probe_wrench_bad_input_exits_2(capsys):
    assert main(["probe", "wrench", "ftp://x"]) == 2
    assert main(["probe", "wrench", "sim://wrench", "--pset", "1000"]) == 2
    assert capsys.readouterr().err.count("\n") == 2


def test_probe_camera_sim_url_renders_the_simulated_station(capsys, tmp_path):
    from drivers.camera.sim import registered_worlds

    frame = tmp_path / "f.png"
    code = main(["probe", "camera", "sim://pair1/left", "--timeout", "30", "--json",
                 "--save", str(frame)])
    out, err = capsys.readouterr()
    obj = json.loads(out)
    assert code == 0 and err == "" and obj["ok"] is True
    assert (obj["width"], obj["height"]) == (5472, 3648) and frame.stat().st_size > 0
    assert registered_worlds() == []  # the probe's world is gone with the probe
    assert kind_of(frame) == "frame"   # stamped as the probe's own: the next may replace it


def test_probe_camera_save_never_writes_through_a_link_or_over_another_file(capsys, tmp_path):
    """``--save`` by the one output rule (stationd/outfile.py), refused before the camera is
    opened: a link (to the station file) and a file of another kind are left as they were;
    an earlier frame of the probe may be replaced."""
    shutil.copy(SIM / "station.yaml", tmp_path)
    (tmp_path / "link.png").symlink_to(tmp_path / "station.yaml")
    png = cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))[1].tobytes()
    (tmp_path / "photo.png").write_bytes(png)
    (tmp_path / "photo.jpg").write_bytes(cv2.imencode(".jpg", np.zeros((4, 4, 3),
                                                                        np.uint8))[1].tobytes())
    (tmp_path / "drawing.png").write_bytes(stamp_png(png, DRAWING_STAMP))
    (tmp_path / "station.png").write_text((SIM / "station.yaml").read_text())
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for name, needle in [
        ("link.png", f"link.png: is a symbolic link to {tmp_path / 'station.yaml'}, a station "
                     "file; an output is never written through or over a link"),
        ("photo.png", "photo.png: is a PNG image that this program did not write; writing "
                      "the frame would replace it (give another --save)"),
        ("photo.jpg", "photo.jpg: is an image; writing the frame would replace it"),
        ("drawing.png", "drawing.png: is an earlier drawing of detect --draw"),
        ("station.png", "station.png: is a station file"),
    ]:
        code = main(["probe", "camera", "sim://pair1/left", "--save", str(tmp_path / name)])
        err = capsys.readouterr().err
        assert code == 2 and needle in err and err.count("\n") == 1, err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    assert (tmp_path / "link.png").is_symlink()
    earlier = tmp_path / "frame.png"
    earlier.write_bytes(stamp_png(png, FRAME_STAMP))
    # past the --save check: the next refusal is the URL's (a pair the station lacks)
    code = main(["probe", "camera", "sim://pair9/left", "--save", str(earlier)])
    err = capsys.readouterr().err
    assert code == 2 and "pair9" in err and "--save" not in err


def test_probe_camera_sim_url_of_an_unknown_pair_exits_2(capsys):
    code = main(["probe", "camera", "sim://pair9/left"])
    err = capsys.readouterr().err
    assert code == 2 and "pair9" in err and err.count("\n") == 1
    # the station named whole, and how to name one's own (a line engineer probed their own
    # station's sim://front/left and was told of config/sim's "station.yaml")
    assert str(SIM / "station.yaml") in err and "--config" in err


def test_probe_camera_sim_url_renders_the_station_given(capsys, tmp_path):
    """``--config``: the simulated world of the user's own station (pairs named as theirs)."""
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    station.write_text(station.read_text().replace("pair1", "front"))
    for f in tmp_path.glob("pair1*.yaml"):
        f.rename(f.with_name(f.name.replace("pair1", "front")))
    code = main(["probe", "camera", "sim://front/left", "--config", str(station),
                 "--timeout", "30", "--json"])
    out, err = capsys.readouterr()
    assert code == 0 and json.loads(out)["ok"] is True, err


def test_probe_url_that_urllib_cannot_split_exits_2(capsys):
    assert main(["probe", "lift", "modbus-tcp://[::1"]) == 2  # found by tests/test_cli_fuzz
    err = capsys.readouterr().err
    assert "not a valid URL" in err and err.count("\n") == 1


def _hold(devices, what=None):
    """Another process holding device locks in the machine's shared folder, as a running
    daemon does (``what``: a probe's own lock instead), until its stdin closes."""
    import subprocess
    import sys
    import textwrap

    code = (f"""
        from stationd.devicekey import device_key, lock_dir
        from stationd.lock import DeviceLock
        locks = [DeviceLock(device_key(u), {what!r}, u, lock_dir()) for _, u in {devices!r}]
        for lock in locks:
            lock.acquire()""" if what else f"""
        from stationd.lock import StationLocks
        locks = StationLocks()
        locks.hold("sqlite:///:memory:", devices={devices!r})""")
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(code + """
        import sys
        print("held", flush=True)
        sys.stdin.readline()
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
    return holder


def _let_go(holder):
    holder.stdin.close()
    holder.wait(10)


def test_probe_of_a_device_a_daemon_drives_is_refused_before_touching_it(capsys):
    """The daemon holds its devices' locks (named by endpoint: ``localhost`` there,
    127.0.0.1 here); the probe takes the same lock and is refused, naming the daemon's pid,
    without a word to the PLC; once the daemon is gone the probe reads it."""
    import uuid

    with SimulatedPlc() as plc:
        port = plc.start_tcp()
        plc.set_height(1500.0)
        tag = uuid.uuid4().hex[:8]
        holder = _hold([("lift", f"modbus-tcp://localhost:{port}?timeout=2"),
                        ("wrench", f"openprotocol://127.0.0.1:{_free_port()}"),
                        ("camera left", f"aravis://Probe-{tag}")])
        try:
            url = f"modbus-tcp://127.0.0.1:{port}?unit=1"
            code = main(["probe", "lift", url])
            err = capsys.readouterr().err
            assert code == 2 and err == (f"stationd: error: lift {url}: the station daemon (pid "
                                         f"{holder.pid}) is driving this device; stop it or "
                                         "use its screens\n"), err
            code = main(["probe", "camera", f"aravis://Probe-{tag}?trigger=software"])
            err = capsys.readouterr().err
            assert code == 2 and f"the station daemon (pid {holder.pid})" in err, err
            assert err.count("\n") == 1
            # a script reading --json gets its one object, the refusal in it, and exit 2
            code = main(["probe", "lift", url, "--json"])
            out, err = capsys.readouterr()
            obj = json.loads(out)
            assert code == 2 and obj["ok"] is False and obj["kind"] == "lift", out
            assert f"(pid {holder.pid}) is driving this device" in obj["error"], obj
            assert err.count("\n") == 1 and obj["error"] in err, err
        finally:
            _let_go(holder)
        code = main(["probe", "lift", f"modbus-tcp://127.0.0.1:{port}?unit=1", "--json"])
    obj = json.loads(capsys.readouterr().out)
    assert code == 0 and abs(obj["state"]["height_mm"] - 1500.0) < 0.1


def test_probe_of_a_device_another_probe_holds_says_so(capsys):
    url = f"openprotocol://127.0.0.1:{_free_port()}"
    holder = _hold([("wrench", url)], what="probe wrench")
    try:
        code = main(["probe", "wrench", url, "--timeout", "0.5"])
    finally:
        _let_go(holder)
    err = capsys.readouterr().err
    assert code == 2 and err == (f"stationd: error: wrench {url}: another stationd probe (pid "
                                 f"{holder.pid}) is using this device; wait for it to end\n")
