"""The Aravis backend's trigger modes, errors and lifecycle, against Aravis's fake cameras."""

import socket
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from drivers.camera import UnsupportedError, open_camera
from drivers.errors import ConnectError, DeviceError, DeviceTimeoutError

from .conftest import FAKE_NAME, aravis_or_skip

SMALL = "region=0,0,128,96"


def test_line_trigger_waits_for_the_line(fake):
    """The GigE fake simulates no trigger pulses: on Line0 nothing arrives, and trigger()
    must not fire a software trigger in that mode."""
    with open_camera(fake.url(SMALL + "&trigger=line0")) as cam:
        assert "trigger line0" in cam.identity()
        cam.trigger()
        with pytest.raises(DeviceTimeoutError) as err:
            cam.grab(0.3)
        assert "software trigger" not in str(err.value)


def test_line_trigger_pulses_deliver_frames():
    """Aravis's in-process fake camera ("Fake_1") pulses Line0 at 25 Hz (and ignores
    software triggers): frames arrive without trigger(), and trigger() drops stale ones."""
    aravis_or_skip().enable_interface("Fake")
    with open_camera("aravis://Fake_1?trigger=line0&region=0,0,64,48") as cam:
        a, b = cam.grab(1.0), cam.grab(1.0)
        assert b.frame_id == a.frame_id + 1 and 0.02 < b.timestamp - a.timestamp < 0.08
        time.sleep(0.15)  # frames pile up in the pool
        cam.trigger()
        assert cam.grab(1.0).timestamp > time.time() - 0.06


def test_free_run_delivers_without_trigger(fake):
    with open_camera(fake.url(SMALL + "&trigger=free&frame_rate=50")) as cam:
        a, b = cam.grab(1.0), cam.grab(1.0)
        assert b.frame_id > a.frame_id and a.image.shape == (96, 128, 3)


def test_what_the_camera_does_not_offer(fake):
    with pytest.raises(UnsupportedError, match=r"pixel format BGR8 not offered by the camera "
                                               r"\(it offers: .*RGB8"):
        open_camera(fake.url("pixel_format=BGR8"))
    with pytest.raises(UnsupportedError, match=r"trigger line3 not offered \(sources: Line0, "
                                               r"Software\)"):
        open_camera(fake.url("trigger=line3"))
    with open_camera(fake.url(SMALL)) as cam:  # and the camera is usable after those
        cam.trigger()
        cam.grab()


def test_unknown_device_lists_the_cameras_found(fake):
    with pytest.raises(ConnectError, match=rf"cannot open camera 'Aravis-Fake-NOPE'.*cameras "
                                           rf"found: .*{FAKE_NAME}"):
        open_camera("aravis://Aravis-Fake-NOPE")


def test_lifecycle(fake):
    cam = open_camera(fake.url(SMALL))
    cam.open()  # idempotent
    assert cam.identity().startswith("Aravis Fake S/N STATIOND1 (GigE Vision 127.0.0.1")
    cam.close()
    cam.close()
    with pytest.raises(DeviceError, match="not open"):
        cam.grab()
    assert "closed" in cam.identity()


def test_shutdown_order_at_process_end(aravis_port):
    """A process that exits with a camera still open: the atexit hook closes the stream and
    the camera before Aravis.shutdown(), and the process exits cleanly."""
    aravis_or_skip()
    code = textwrap.dedent("""
        from drivers.camera import open_camera
        from drivers.camera.aravis import load
        arv = load()[0]
        fake = arv.GvFakeCamera.new("127.0.0.1", "STATIOND9")
        cam = open_camera("aravis://Aravis-Fake-STATIOND9?region=0,0,64,48")
        cam.trigger()
        print(cam.grab().image.shape)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0 and r.stdout.strip() == "(48, 64, 3)", r.stderr


def test_a_heartbeat_is_for_gige_cameras():
    """Aravis's in-process fake ("Fake_1") is no GigE camera: it has no heartbeat to set."""
    aravis_or_skip().enable_interface("Fake")
    with pytest.raises(UnsupportedError, match=r"heartbeat_ms is for GigE Vision cameras"):
        open_camera("aravis://Fake_1?heartbeat_ms=5000&region=0,0,64,48")


def test_stray_traffic_while_the_stream_opens_costs_no_frame(fake):
    """Other programs' UDP on the loopback while the camera opens, shaped as the camera's
    stream packets with a frame id 90 ahead of its next one: the stream reads only its own
    port, so every open delivers a frame at once.  (Aravis's packet socket, its default as
    root, took such a packet as its first and then dropped the real frames as late, 90 of
    them, 9 s at 10 Hz: about one open in three failed here.)"""
    stop = threading.Event()
    ahead = [0]
    sent: list[int] = []
    failed: list[BaseException] = []

    def stray() -> None:
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                while not stop.is_set():
                    packet = (b"\x00\x00" + ((ahead[0] + 90) % 65536).to_bytes(2, "big")
                              + b"\x03\x00\x00\x05" + bytes(64))
                    for _ in range(200):
                        s.sendto(packet, ("127.0.0.1", 9))
                    sent.append(200)
                    time.sleep(0)
        except BaseException as exc:    # said by the test, not lost with the thread
            failed.append(exc)

    sender = threading.Thread(target=stray, daemon=True)
    sender.start()
    try:
        for _ in range(12):
            with open_camera(fake.url(SMALL + "&trigger=free&frame_rate=10")) as cam:
                ahead[0] = cam.grab(5.0).frame_id + 2
    finally:
        stop.set()
        sender.join(5)
    assert not failed and sum(sent) > 1000, (failed, sum(sent))   # the traffic was there


def test_the_stream_socket_is_a_gige_option():
    """A USB3 Vision camera (Aravis's in-process fake device) streams over USB: asking it for
    a packet socket is refused, saying so."""
    aravis_or_skip().enable_interface("Fake")
    with pytest.raises(UnsupportedError, match="stream_socket is for GigE Vision cameras"):
        open_camera("aravis://Fake_1?stream_socket=packet&region=0,0,64,48")


def test_what_breaks_a_gige_stream_is_journaled(caplog):
    """A kernel that lets a UDP socket buffer less than a 20 MP frame (its packets dropped
    whenever the host is late), and a packet socket asked where none may be opened (Aravis
    then reads a UDP socket without a word): each said at the camera's opening."""
    import logging
    from pathlib import Path

    from drivers.camera import aravis

    caplog.set_level(logging.WARNING, logger="drivers.camera.aravis")
    allowed = int(Path("/proc/sys/net/core/rmem_max").read_text())
    aravis._say_stream_limits("cam", "udp", 5472 * 3648)
    assert ("net.core.rmem_max" in caplog.text) == (allowed < 8 << 20), caplog.text
    caplog.clear()
    aravis._say_stream_limits("cam", "udp", 128 * 96)     # any buffer holds such a frame
    assert caplog.text == ""
    try:
        socket.socket(socket.AF_PACKET, socket.SOCK_RAW).close()
        raw = True
    except OSError:
        raw = False
    aravis._say_stream_limits("cam", "packet", 5472 * 3648)
    assert ("may not open raw sockets" in caplog.text) == (not raw), caplog.text
