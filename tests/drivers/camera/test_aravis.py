"""The Aravis backend against Aravis's own fake GigE camera on loopback (the real library
path: discovery, GVCP registers, GVSP stream).  The fake's image is known: pixel (x, y) of
frame ``id`` has index ``(x + y + id) % 255`` scaled by ``1 + gain + log10(exposure / 10 ms)``;
Mono8 is that index, RGB8 its colour in a jet colour map, Bayer*8 the mosaic of that colour.
"""

import socket
import time

import numpy as np
import pytest

from drivers.camera import open_camera
from drivers.errors import DeviceTimeoutError, RefusedError

SMALL = "region=0,0,128,96"

#: how long a test waits for a frame it asked for, s: generous (a 20 MB frame of the fake
#: camera on a busy machine); a wait ends with the frame
GRAB_S = 30.0


def _index(frame, scale=1.0):
    h, w = frame.height, frame.width
    y, x = np.mgrid[0:h, 0:w]
    return np.clip(((x + y + frame.frame_id) % 255) * scale, 0, 255).astype(int)


def test_software_trigger_no_frame_without_one_frame_per_trigger(fake):
    with open_camera(fake.url(SMALL)) as cam:
        with pytest.raises(DeviceTimeoutError,
                           match=r"no frame within 0\.3 s after its software trigger"):
            cam.grab(0.3)
        frames = []
        for _ in range(3):
            cam.trigger()
            frames.append(cam.grab(GRAB_S))
            with pytest.raises(DeviceTimeoutError):  # exactly one frame per trigger
                cam.grab(0.15)
    ids = [f.frame_id for f in frames]
    assert ids == [ids[0], ids[0] + 1, ids[0] + 2]
    stamps = [f.timestamp for f in frames]
    assert stamps == sorted(stamps) and abs(stamps[-1] - time.time()) < 2.0
    assert frames[0].camera == fake.url(SMALL) and frames[0].pixel_format == "Mono8"


def _grab_one(url):
    """One frame (these tests are about its pixels): a software trigger the fake camera lost
    on a loaded machine (its GigE packets on loopback) is fired again, and the camera is
    opened anew for the last tries (a whole run once saw no frame for three triggers over
    50 s on one stream); one frame per trigger is tested above."""
    last: DeviceTimeoutError | None = None
    for _ in range(3):
        with open_camera(url) as cam:
            for _ in range(2):
                cam.trigger()
                try:
                    return cam.grab(10.0)
                except DeviceTimeoutError as e:
                    last = e
    assert last is not None
    raise last


def test_mono8_is_the_fakes_ramp_in_three_channels(fake):
    f = _grab_one(fake.url(SMALL + "&pixel_format=Mono8"))
    assert f.image.shape == (96, 128, 3)
    assert np.array_equal(f.image[:, :, 0], _index(f)) and np.ptp(f.image, axis=2).max() == 0


def test_rgb8_becomes_bgr(fake):
    f = _grab_one(fake.url(SMALL + "&pixel_format=RGB8"))
    idx = _index(f)
    b, r = f.image[:, :, 0].astype(int), f.image[:, :, 2].astype(int)
    assert (r[idx >= 230] > b[idx >= 230]).all()  # the jet map ends in red...
    assert (b[idx <= 25] > r[idx <= 25]).all()  # ...and starts in blue
    for i in np.unique(idx)[:20]:  # one colour per index
        assert len(np.unique(f.image[idx == i], axis=0)) == 1


def _colour_table(frame):
    """index -> BGR colour, from an RGB8 frame (checked above)."""
    idx = _index(frame)
    table = np.zeros((256, 3), int)
    table[idx.ravel()] = frame.image.reshape(-1, 3)
    return table


@pytest.mark.parametrize("bayer", ["BayerGB8", "BayerGR8", "BayerRG8", "BayerBG8"])
def test_bayer_is_demosaiced_to_the_fakes_colours(fake, bayer):
    table = _colour_table(_grab_one(fake.url(SMALL + "&pixel_format=RGB8")))
    f = _grab_one(fake.url(SMALL + f"&pixel_format={bayer}"))
    assert f.pixel_format == bayer and f.image.shape == (96, 128, 3)
    idx = _index(f)
    keep = (idx > 3) & (idx < 251)  # the ramp wraps from red to blue: no colour to expect
    keep[:2], keep[-2:], keep[:, :2], keep[:, -2:] = False, False, False, False
    expected = table[idx][keep]
    got = f.image[keep].astype(int)
    err = np.percentile(np.abs(got - expected), 95)
    # Aravis 0.8's fake writes its BayerRG8 mosaic as BG and its BayerBG8 as RG
    # (src/arvfakecamera.c); the driver decodes what the camera says it sends.
    swapped = np.percentile(np.abs(got - expected[:, ::-1]), 95)
    if bayer in ("BayerGB8", "BayerGR8"):
        assert err <= 12, f"{bayer}: 95th percentile error {err}"
    else:
        assert min(err, swapped) <= 12, f"{bayer}: errors {err} / swapped {swapped}"


def test_exposure_and_gain_reach_the_sensor(fake):
    with open_camera(fake.url(SMALL + "&exposure_us=100000")) as cam:
        cam.trigger()
        f = cam.grab()
        assert np.array_equal(f.image[:, :, 0], _index(f, 2.0))  # 1 + log10(10)
        assert cam.set_exposure_us(1000) == 1000.0  # 1 + log10(0.1) = 0: black
        cam.trigger()
        assert cam.grab().image.max() == 0
        cam.set_exposure_us(10000)
        assert cam.set_gain_db(1) == 1.0
        cam.trigger()
        f = cam.grab()
        assert np.array_equal(f.image[:, :, 0], _index(f, 2.0))
        with pytest.raises(RefusedError, match="outside the camera's range 10-1e\\+07 us"):
            cam.set_exposure_us(2e7)
        with pytest.raises(RefusedError, match="gain 50 dB is outside"):
            cam.set_gain_db(50)


def test_pool_for_full_size_20mp_frames(fake):
    """The station's 5472x3648 frames: the pool is sized from the camera's payload and
    recycled (more frames than buffers).  The fake camera sends a 20 MB frame in one
    unpaced burst, more than a UDP socket's buffer holds (a real GigE camera paces it at
    the wire's speed): read through Aravis's packet socket's 32 MB ring, which needs raw
    sockets.  On a loaded machine a frame can still be lost whole (seen in CI): its trigger
    is fired again, twice at most, as in :func:`_grab_one`; and the packet socket's start-up
    race (another test's packet taken for the first frame: every frame after it dropped as
    late) is met by opening the camera again, twice at most."""
    try:
        socket.socket(socket.AF_PACKET, socket.SOCK_RAW).close()
    except PermissionError:
        pytest.skip("a 20 MB unpaced burst needs Aravis's packet socket: raw sockets "
                    "(CAP_NET_RAW, e.g. root)")
    url = fake.url("region=0,0,5472,3648&pixel_format=BayerRG8&buffers=2&stream_socket=packet")
    for opening in range(3):
        with open_camera(url) as cam:
            assert cam.buffer_count == 2 and cam.payload_bytes == 5472 * 3648
            assert "BayerRG8 5472x3648, pool 2 x 19.96 MB" in cam.identity()
            try:
                ids = [_grab_20mp(cam) for _ in range(3)]
                break
            except DeviceTimeoutError:
                if opening == 2:
                    raise
    assert len(set(ids)) == 3      # three frames through a pool of two buffers


def _grab_20mp(cam) -> int:
    """One full frame's id, its trigger fired again twice at most."""
    for attempt in range(3):
        cam.trigger()
        try:
            f = cam.grab(GRAB_S / 3)
            break
        except DeviceTimeoutError:
            if attempt == 2:
                raise
    assert f.image.shape == (3648, 5472, 3)
    return int(f.frame_id)


def test_a_software_triggered_frame_is_stamped_between_trigger_and_arrival(fake):
    """Exposure time, not arrival: never before the trigger was sent, never after the frame
    reached the host (until the camera's clock is verified, the trigger time itself)."""
    with open_camera(fake.url(SMALL)) as cam:
        for _ in range(2):
            t0 = time.time()
            cam.trigger()
            f = cam.grab(GRAB_S)
            assert t0 <= f.timestamp <= f.arrival and f.delay_s >= 0


def test_frames_that_came_broken_are_said_as_packets_lost_not_a_trigger_missed():
    """A technician's trial: a triggered camera whose frames came in pieces was told as
    "no frame within 1 s (software trigger: call trigger() before grab()); 1 broken buffer:
    timeout", a developer's hint that sent him to the trigger."""
    from drivers.camera.aravis import no_frame_words

    said = no_frame_words(1.0, "software", "1 broken buffer: timeout")
    assert said.startswith("no whole frame within 1 s: 1 broken buffer: timeout (")
    assert "packets lost" in said and "trigger" not in said
    assert no_frame_words(0.5, "free", "") == "no frame within 0.5 s"


def test_the_camera_says_its_serial_number(fake):
    """The serial number a pair's calibration is pinned to (GenICam DeviceSerialNumber, as
    Aravis reads it), the one the journal names; none while the link is down."""
    with open_camera(fake.url(SMALL)) as cam:
        serial = cam.serial_number()
        assert serial and f"S/N {serial} " in cam.identity()
    assert cam.serial_number() is None
