"""Which device a URL drives, as its lock's key: one key per endpoint, whatever the text."""

import os

import pytest

from drivers.devices import Kind
from drivers.endpoint import (
    AravisEndpoint,
    SerialEndpoint,
    TcpEndpoint,
    UrlEndpoint,
    VideoEndpoint,
)
from stationd.devicekey import RUN_LOCK_DIR, device_key, endpoint_key, key_file, lock_dir


@pytest.mark.parametrize(("a", "b"), [
    ("modbus-tcp://PLC:502?unit=1", "modbus-tcp://plc?unit=1&timeout=2"),
    ("modbus-tcp://localhost:1502", "modbus-tcp://127.0.0.1:1502?unit=1"),
    ("openprotocol://10.0.0.5", "openprotocol://10.0.0.5:4545?link_ack=1"),
    ("openprotocol://[::ffff:10.0.0.5]:4545", "openprotocol://10.0.0.5"),
    ("aravis://Hik-MV-1?trigger=line0", "aravis://Hik-MV-1"),
    ("opencv://0?width=640", "opencv:///dev/video0"),
])
def test_one_endpoint_one_key(a, b):
    assert device_key(a) == device_key(b) is not None


@pytest.mark.parametrize(("a", "b"), [
    ("modbus-tcp://plc:502?unit=1", "modbus-tcp://plc:502?unit=2"),  # a gateway's two units
    ("modbus-tcp://plc:502", "modbus-tcp://plc:1502"),
    ("aravis://Hik-MV-1", "aravis://hik-mv-1"),   # Aravis ids keep their case
])
def test_other_endpoints_other_keys(a, b):
    assert device_key(a) != device_key(b)


def test_a_serial_line_is_one_device_whatever_the_unit_or_the_link(tmp_path):
    """``/dev/serial/by-id/...`` links to the ``/dev/ttyUSB0`` another daemon may name."""
    port = tmp_path / "ttyUSB0"
    port.touch()
    link = tmp_path / "usb-FTDI-if00"
    link.symlink_to(port)
    assert device_key(f"modbus-rtu://{link}?unit=3") == device_key(f"modbus-rtu://{port}?unit=1") \
        == device_key(f"openprotocol+serial://{port}") == f"serial {port}"


@pytest.mark.parametrize("url", ["sim://lift", "sim://wrench", "sim+modbus://wrench",
                                 "sim://pair1/left", "file:///data/left_*.png",
                                 "opencv:///data/run.avi"])
def test_simulated_devices_and_files_need_no_lock(url):
    assert device_key(url) is None


def test_key_files_are_one_readable_name_per_key():
    names = {key_file(device_key(u) or "") for u in
             ("modbus-tcp://plc:502?unit=1", "modbus-tcp://plc:502?unit=2",
              "modbus-rtu:///dev/ttyUSB0", "aravis://A/B")}
    assert len(names) == 4 and all("/" not in n and n.endswith(".lock") for n in names)


def test_the_lock_folder_is_run_lock_when_writable():
    writable = os.access(RUN_LOCK_DIR if RUN_LOCK_DIR.is_dir() else RUN_LOCK_DIR.parent,
                         os.W_OK | os.X_OK) and RUN_LOCK_DIR.parent.is_dir()
    assert (lock_dir() == RUN_LOCK_DIR) == writable


def test_a_host_name_and_its_address_are_one_device():
    """``tcp://plc.local:502`` and ``tcp://192.168.0.10:502`` written in two station files
    reach one PLC: the name is resolved when the key is made (this machine's own name, which
    resolves without a name server)."""
    import socket

    name = socket.gethostname()
    try:
        address = socket.getaddrinfo(name, None, socket.AF_INET, socket.SOCK_STREAM)[0][4][0]
    except OSError:
        pytest.skip(f"this machine's name {name!r} does not resolve")
    assert device_key(f"modbus-tcp://{name}:1502?unit=1") \
        == device_key(f"modbus-tcp://{address}:1502") == f"tcp {address}:1502 unit 1"
    assert device_key(f"openprotocol://{name.upper()}") == f"tcp {address}:4545"


def test_a_name_that_does_not_resolve_in_time_keeps_its_name(monkeypatch):
    """A name server that does not answer must not hold the daemon's start: the look-up is
    given up after RESOLVE_TIMEOUT_S and the name is the key; a name that does not exist is
    the key at once."""
    import socket
    import threading
    import time

    from stationd import devicekey

    release = threading.Event()
    real = socket.getaddrinfo

    def silent(host, *args, **kwargs):
        if host == "plc.slow":
            release.wait(10)
            raise socket.gaierror(socket.EAI_AGAIN, "Temporary failure in name resolution")
        return real(host, *args, **kwargs)

    monkeypatch.setattr(socket, "getaddrinfo", silent)
    monkeypatch.setattr(devicekey, "RESOLVE_TIMEOUT_S", 0.3)
    try:
        t0 = time.monotonic()
        assert device_key("modbus-tcp://PLC.slow:502") == "tcp plc.slow:502 unit 1"
        assert time.monotonic() - t0 < 2.0
    finally:
        release.set()
    assert device_key("openprotocol://no-such-host.invalid") == "tcp no-such-host.invalid:4545"


@pytest.mark.parametrize(("endpoint", "key"), [
    (TcpEndpoint("PLC.invalid", 502, 1), "tcp plc.invalid:502 unit 1"),
    (TcpEndpoint("::ffff:10.0.0.5", 4545), "tcp 10.0.0.5:4545"),
    (TcpEndpoint("::1", 4545), "tcp [::1]:4545"),
    (TcpEndpoint("localhost", 1502, 0), "tcp 127.0.0.1:1502 unit 0"),
    (SerialEndpoint("/dev/ttyUSB0"), "serial /dev/ttyUSB0"),
    (VideoEndpoint("/dev/video0"), "video /dev/video0"),
    (AravisEndpoint("Hik-MV-1"), "aravis Hik-MV-1"),
    (UrlEndpoint("x://y"), "url x://y"),
    (None, None),
])
def test_the_key_of_what_a_backend_drives_is_this_machines_view_of_it(endpoint, key):
    """The backend says what it drives; the key is the text of today's locks, with host
    names as their addresses (a name that does not resolve: lower case)."""
    assert endpoint_key(endpoint) == key


def test_a_video_devices_key_follows_its_links(tmp_path):
    device = tmp_path / "video0"
    device.touch()
    (tmp_path / "usb-cam").symlink_to(device)
    assert endpoint_key(VideoEndpoint(str(tmp_path / "usb-cam"))) == f"video {device}"


@pytest.mark.parametrize(("url", "kind", "key"), [
    ("modbus-tcp://127.0.0.1?unit=2", Kind.LIFT, "tcp 127.0.0.1:502 unit 2"),
    ("modbus-tcp://127.0.0.1?unit=2", Kind.WRENCH, "tcp 127.0.0.1:502 unit 2"),
    ("openprotocol://127.0.0.1", Kind.WRENCH, "tcp 127.0.0.1:4545"),
    ("sim://lift", Kind.LIFT, None),
    # a URL naming no backend of its kind, or one its backend refuses, is its own key
    ("openprotocol://127.0.0.1", Kind.LIFT, "url openprotocol://127.0.0.1"),
    ("modbus-tcp://127.0.0.1?unit=300", Kind.LIFT, "url modbus-tcp://127.0.0.1?unit=300"),
    ("bogus://x", None, "url bogus://x"),
    ("not a url", Kind.CAMERA, "url not a url"),
])
def test_the_key_is_asked_of_the_backend_of_the_devices_kind(url, kind, key):
    assert device_key(url, kind) == key
