"""What a device drives is its backend's to say (``Openable.endpoint``), never read from its
scheme's name: every registered backend answers, with its own protocol's rules (default
ports, Modbus units, serial lines, camera indexes), and a simulated twin answers None."""

from __future__ import annotations

from typing import ClassVar

import pytest

from drivers import camera, lift, wrench
from drivers.devices import Kind, backend_class
from drivers.endpoint import (
    AravisEndpoint,
    Endpoint,
    SerialEndpoint,
    TcpEndpoint,
    UrlEndpoint,
    VideoEndpoint,
)
from drivers.errors import UrlError
from drivers.lifecycle import Device
from drivers.modbus_link import DEFAULT_PORT as MODBUS_PORT
from drivers.wrench.openprotocol.options import DEFAULT_PORT as OPEN_PROTOCOL_PORT

REGISTRIES = {Kind.CAMERA: camera.BACKENDS, Kind.LIFT: lift.BACKENDS, Kind.WRENCH: wrench.BACKENDS}

#: one URL of every registered backend, and what it drives
SAMPLES: dict[tuple[Kind, str], tuple[str, Endpoint | None]] = {
    (Kind.CAMERA, "aravis"): ("aravis://Hik-MV-DA1?trigger=line0", AravisEndpoint("Hik-MV-DA1")),
    (Kind.CAMERA, "opencv"): ("opencv://2?width=640", VideoEndpoint("/dev/video2")),
    (Kind.CAMERA, "file"): ("file:///data/left_*.png?loop=1", None),
    (Kind.CAMERA, "sim"): ("sim://pair1/left", None),
    (Kind.LIFT, "modbus-tcp"): ("modbus-tcp://10.0.0.1?unit=3",
                                TcpEndpoint("10.0.0.1", MODBUS_PORT, 3)),
    (Kind.LIFT, "modbus-rtu"): ("modbus-rtu:///dev/ttyUSB0?unit=2", SerialEndpoint("/dev/ttyUSB0")),
    (Kind.LIFT, "sim"): ("sim://lift", None),
    (Kind.WRENCH, "openprotocol"): ("openprotocol://10.0.0.9",
                                    TcpEndpoint("10.0.0.9", OPEN_PROTOCOL_PORT)),
    (Kind.WRENCH, "openprotocol+serial"): ("openprotocol+serial:///dev/ttyUSB1?baud=9600",
                                           SerialEndpoint("/dev/ttyUSB1")),
    (Kind.WRENCH, "sim"): ("sim://wrench", None),
    (Kind.WRENCH, "modbus-tcp"): ("modbus-tcp://10.0.0.1:1502?unit=4",
                                  TcpEndpoint("10.0.0.1", 1502, 4)),
    (Kind.WRENCH, "modbus-rtu"): ("modbus-rtu:///dev/ttyUSB2?unit=1",
                                  SerialEndpoint("/dev/ttyUSB2")),
    (Kind.WRENCH, "sim+modbus"): ("sim+modbus://wrench?transport=rtu", None),
}


def test_every_registered_backend_has_a_sample():
    """A backend added to a registry is added here too, with what it drives."""
    registered = {(kind, scheme) for kind, backends in REGISTRIES.items() for scheme in backends}
    assert registered == set(SAMPLES)


@pytest.mark.parametrize(("kind", "scheme"), sorted(SAMPLES))
def test_every_backend_answers_what_it_drives(kind, scheme):
    url, drives = SAMPLES[kind, scheme]
    backend = backend_class(kind, url)
    assert backend.endpoint(url) == drives
    if backend.simulated:
        assert drives is None   # a twin exists only in this process


@pytest.mark.parametrize("scheme", sorted({s for b in REGISTRIES.values() for s in b
                                           if sum(s in other for other in REGISTRIES.values())
                                           > 1}))
def test_a_scheme_several_kinds_share_drives_one_endpoint_in_each(scheme):
    """``sim``, ``modbus-tcp``, ``modbus-rtu``: one transport in each kind, so a lift and a
    controller at one Modbus unit are one device, and a URL alone (no kind) has one key."""
    url = next(u for (_, s), (u, _) in SAMPLES.items() if s == scheme)
    answers = {backend_class(kind, url).endpoint(url)
               for kind, backends in REGISTRIES.items() if scheme in backends}
    assert len(answers) == 1


@pytest.mark.parametrize(("kind", "url", "parent"), [
    (Kind.WRENCH, "sim://wrench", "OpenProtocolWrench"),
    (Kind.WRENCH, "sim+modbus://wrench", "ModbusWrench"),
])
def test_a_simulated_twin_of_a_real_backend_drives_nothing(kind, url, parent):
    """``sim://wrench`` is the Open Protocol client talking to its own simulator: its
    parent would read ``wrench`` as a host, the twin answers None."""
    backend = backend_class(kind, url)
    real = next(c for c in backend.__mro__ if c.__name__ == parent)
    assert backend.simulated and not real.simulated
    assert backend.endpoint(url) is None


def test_the_default_ports_are_the_protocols():
    """Where a URL without a port connects, and so what it drives: one constant each."""
    assert (MODBUS_PORT, OPEN_PROTOCOL_PORT) == (502, 4545)


@pytest.mark.parametrize(("kind", "url", "drives"), [
    # the protocols' default ports, the drivers' own constants
    (Kind.LIFT, "modbus-tcp://PLC", TcpEndpoint("plc", 502, 1)),       # unit 1 by default
    (Kind.WRENCH, "openprotocol://ctl.local:4546", TcpEndpoint("ctl.local", 4546)),
    (Kind.WRENCH, "openprotocol://[::1]", TcpEndpoint("::1", 4545)),
    # a serial line is one device whatever the unit on it
    (Kind.LIFT, "modbus-rtu:///dev/ttyUSB0?unit=7&baud=9600", SerialEndpoint("/dev/ttyUSB0")),
    # an OpenCV index is the /dev/videoN Linux numbers it; a /dev path is the device; any
    # other path a video file anyone may read
    (Kind.CAMERA, "opencv://0", VideoEndpoint("/dev/video0")),
    (Kind.CAMERA, "opencv:///dev/v4l/by-id/usb-cam", VideoEndpoint("/dev/v4l/by-id/usb-cam")),
    (Kind.CAMERA, "opencv:///data/run.avi", None),
    # an Aravis id keeps its case, percent-decoded as the camera is opened
    (Kind.CAMERA, "aravis://hik-MV%20DA1", AravisEndpoint("hik-MV DA1")),
])
def test_the_drivers_rules(kind, url, drives):
    assert backend_class(kind, url).endpoint(url) == drives


@pytest.mark.parametrize(("kind", "url"), [
    (Kind.LIFT, "modbus-tcp://plc?unit=300"), (Kind.LIFT, "modbus-rtu://host/x"),
    (Kind.WRENCH, "openprotocol:///dev/ttyUSB0"), (Kind.CAMERA, "opencv://999"),
    (Kind.CAMERA, "aravis://A/B"),
])
def test_a_url_the_backend_refuses_has_no_endpoint(kind, url):
    """The same rules as opening it: a URL the driver would refuse drives nothing."""
    with pytest.raises(UrlError):
        backend_class(kind, url).endpoint(url)


def test_a_backend_that_does_not_say_is_its_urls_text_and_a_twin_is_nothing():
    """The default is never 'no device' for a real backend: one device per URL text."""

    class Quiet(Device):
        def _open(self) -> None: ...
        def _close(self) -> None: ...

    class QuietTwin(Quiet):
        simulated: ClassVar[bool] = True

    assert Quiet.endpoint("quiet://x") == UrlEndpoint("quiet://x")
    assert QuietTwin.endpoint("quiet://x") is None
