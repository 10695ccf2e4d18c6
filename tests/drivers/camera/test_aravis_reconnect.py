"""The camera unplugged and plugged back: a typed error, the link stays down (nothing retries
behind the caller's back), then ``reconnect()`` (what the station's keeper calls) brings it
back configured as before.

Aravis's fake GigE camera is destroyed (the cable pulled: register accesses time out after
Aravis's 2.5 s of GVCP retries) and created again with the same serial (plugged back, with
its power-on defaults: the driver must configure it again).
"""

import time

import pytest

from drivers.camera import open_camera
from drivers.errors import ConnectionLostError, DeviceError

SETTINGS = "region=0,0,64,48&pixel_format=RGB8&exposure_us=20000"


def test_unplugged_then_plugged_back(fake):
    with open_camera(fake.url(SETTINGS)) as cam:
        cam.trigger()
        before = cam.grab()
        fake.stop()
        with pytest.raises(ConnectionLostError, match=r"software trigger: .*timeout .*camera "
                                                      "unplugged, off, or link down"):
            cam.trigger()
        t0 = time.monotonic()
        with pytest.raises(ConnectionLostError, match=r"link down \(software trigger: "):
            cam.grab(5.0)
        assert time.monotonic() - t0 < 1.0            # said at once
        assert "link down" in cam.identity()
        fake.start()
        deadline = time.monotonic() + 10.0
        while True:
            try:
                cam.reconnect()
                break
            except DeviceError:
                assert time.monotonic() < deadline, cam.identity()
                time.sleep(0.1)
        cam.trigger()
        after = cam.grab(1.0)
        assert after.pixel_format == "RGB8" and after.image.shape == before.image.shape
        assert "RGB8 64x48" in cam.identity()
        assert cam.settings.exposure_us == 20000.0  # configured again after the re-plug
    assert not cam.is_open


def test_close_while_the_link_is_down_releases_it(fake):
    """close() releases the failed link.  The fake is plugged back at once so that releasing
    the old objects does not sit in GVCP timeouts: with the camera still gone, close() would
    wait for those (about 7.5 s)."""
    cam = open_camera(fake.url(SETTINGS))
    fake.stop()
    with pytest.raises(ConnectionLostError):
        cam.trigger()
    fake.start()
    start = time.monotonic()
    cam.close()  # the no_leaks fixture checks that nothing is left behind
    assert time.monotonic() - start < 5.0
    with pytest.raises(DeviceError, match="not open"):
        cam.grab()


def test_a_camera_that_dropped_the_station_is_a_lost_link_until_reconnected(fake):
    """A GigE camera that missed the station's heartbeat (a stall of the host longer than its
    heartbeat timeout) ignores the station's commands: no frame would ever come.  The driver
    says so as a lost link, and ``reconnect()`` takes the camera back."""
    with open_camera(fake.url(SETTINGS)) as cam:
        assert fake.heartbeat_ms() == 60000  # as the URL set it
        cam.trigger()
        cam.grab()
        fake.drop_controllers_after(500)
        deadline = time.monotonic() + 15.0
        with pytest.raises(ConnectionLostError, match=r"control of the camera lost: it heard no "
                                                      r"heartbeat .*or another program took it"):
            while time.monotonic() < deadline:  # Aravis notices within its next heartbeats
                cam.trigger()
                cam.grab()
                time.sleep(0.2)
        t0 = time.monotonic()
        with pytest.raises(ConnectionLostError, match=r"link down \(control of the camera lost"):
            cam.grab(5.0)
        assert time.monotonic() - t0 < 1.0  # said at once
        cam.reconnect()
        assert fake.heartbeat_ms() == 60000  # set again
        cam.trigger()
        assert cam.grab().image.shape == (48, 64, 3)


def test_a_camera_another_program_controls_is_refused_at_opening(fake):
    with open_camera(fake.url(SETTINGS)):
        with pytest.raises(DeviceError, match=r"another program controls camera "
                                              r"'Aravis-Fake-STATIOND1'"):
            open_camera(fake.url(SETTINGS))
