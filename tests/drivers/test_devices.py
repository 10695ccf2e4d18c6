"""What a device is, asked of its backend through the one front door (``drivers.devices``),
never read from its scheme's name: whether it is a simulated twin, which view of the
simulated world a camera shows."""

from __future__ import annotations

import pytest

from drivers.devices import Kind, backend_class, simulated, world_view
from drivers.errors import UrlError


@pytest.mark.parametrize(("kind", "url", "twin"), [
    (Kind.CAMERA, "sim://pair1/left", True), (Kind.CAMERA, "aravis://Hik-DA1", False),
    (Kind.CAMERA, "opencv://0", False), (Kind.CAMERA, "file:///data/left_*.png", False),
    (Kind.LIFT, "sim://lift", True), (Kind.LIFT, "modbus-tcp://10.0.0.1?unit=1", False),
    (Kind.WRENCH, "sim://wrench", True), (Kind.WRENCH, "sim+modbus://wrench", True),
    (Kind.WRENCH, "openprotocol://10.0.0.9", False), (Kind.WRENCH, "modbus-rtu:///dev/x", False),
    (Kind.WRENCH, "nonsense://x", False), (Kind.LIFT, "not a url", False)])
def test_a_simulated_twin_is_its_backends_to_say(kind, url, twin):
    """``stationd run`` starts the simulated world beside a station with a twin: asked of
    the backend's class (nothing built, no simulator started); a URL naming no backend is no
    twin (its own check says why)."""
    assert simulated(kind, url) is twin


def test_the_backend_class_is_looked_up_by_kind_and_refused_for_another_kind():
    assert backend_class(Kind.WRENCH, "sim+modbus://wrench").__name__ == "SimModbusWrench"
    assert backend_class(Kind.LIFT, "sim://lift").__name__ == "SimLift"
    with pytest.raises(UrlError, match="unknown lift scheme 'openprotocol'"):
        backend_class(Kind.LIFT, "openprotocol://10.0.0.9")


@pytest.mark.parametrize(("url", "view"), [
    ("sim://pair1/left", ("pair1", "left")), ("sim://Front/right?seed=3", ("Front", "right")),
    ("aravis://Hik-DA1", None), ("opencv://0", None), ("bogus://x", None)])
def test_a_camera_says_which_view_of_the_simulated_world_it_shows(url, view):
    assert world_view(url) == view


def test_a_malformed_simulated_camera_url_is_refused_not_taken_for_a_real_camera():
    with pytest.raises(UrlError, match="expected sim://PAIR/left"):
        world_view("sim://pair1/middle")
