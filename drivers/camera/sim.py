"""``sim://PAIR/SIDE``: a camera that shows what the simulated world shows through it.

The camera and the world meet through an in-process channel, like python-can's virtual bus:
the world calls ``register_world("pair1", source)`` and every ``sim://pair1/left`` or
``sim://pair1/right`` camera asks ``source(side, seed, at)`` for a BGR image when it is
grabbed, where ``at`` is the trigger instant (host ``time.time()``): the world answers with
what the camera saw *at that instant*, however late the grab and however long the render
(the wrench may have moved since), and the frame's timestamp is ``at``.  So on a loaded
machine a frame arrives later (older, and a station may refuse it as stale) but never shows
another moment than its timestamp says, as with a real camera.  Without a ``trigger()``, the
grab's own start is the trigger.
The world renders with ``stationd.sim.render`` through that camera's calibration, so lighting,
noise and what the marker looks like are the world's business, not the camera's.

The pair is looked up at grab time, not at open: the daemon may open its cameras before the
simulated world has started.  A grab with no world for the pair is a ConnectError that says
what to register.  ``seed`` is the URL's ``seed`` option plus the frame number, the same for
the left and right frames of one stereo grab, so a seeded world renders a reproducible run.

Its serial number is ``SIM-PAIR-SIDE`` unless the URL's ``serial`` option names another (a
test's camera replaced by another unit).

Frames come no faster than the camera it stands for delivers them: ``frame_rate`` Hz, by
default :data:`FRAME_RATE`, the station's 20 MP USB3 camera at full resolution (5472x3648
8-bit Bayer is 20 MB a frame; USB3 Vision carries about 380 MB/s), or the rate
``STATIOND_SIM_FRAME_RATE`` names (a camera set to a lower rate: the test suite runs its
simulated stations at 10 Hz, its tests being about what the station does, not at what
rate).  A trigger (or a grab without one) earlier than a frame period after the last
exposure waits for the sensor, as a real camera's trigger does, and the exposure is then.
Without the cap a station's loop grabs a frame without a marker in a few milliseconds and
spins at a rate no camera of the station reaches, burning the cores it shares with
everything else (a daemon tracking an empty scene used two whole cores).

    sim://pair1/left?seed=100
    sim://pair1/left?serial=SIM-SPARE-1
    sim://pair1/left?frame_rate=10
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from urllib.parse import unquote, urlsplit

import numpy as np

from drivers.camera.base import CameraDevice, Frame, positive
from drivers.errors import ConnectError, ProtocolError
from drivers.url import parse_url

#: ``source(side, seed, at) -> HxWx3 uint8 BGR image`` of the world as of host time ``at``
WorldSource = Callable[[str, int, float], np.ndarray]
SIDES = ("left", "right")
FORM = "sim://PAIR/left|right[?seed=N&serial=TEXT&frame_rate=HZ]"
#: frames per second of the station's camera at full resolution (the USB3 link's limit)
FRAME_RATE = 19.0
#: the environment variable that sets the default rate of cameras whose URL names none
RATE_ENV = "STATIOND_SIM_FRAME_RATE"

_worlds: dict[str, WorldSource] = {}
_lock = threading.Lock()


def register_world(pair: str, source: WorldSource, *, replace: bool = False) -> None:
    """Let ``sim://PAIR/...`` cameras render through ``source``.  A pair is registered once
    (ValueError otherwise, so two worlds never fight over a camera) unless ``replace``."""
    if not pair or "/" in pair:
        raise ValueError(f"a pair name is a non-empty word without '/', got {pair!r}")
    if not callable(source):
        raise TypeError("source must be callable as source(side, seed, at)")
    with _lock:
        if pair in _worlds and not replace:
            raise ValueError(f"a simulated world is already registered for pair {pair!r}")
        _worlds[pair] = source


def unregister_world(pair: str) -> None:
    """Remove the pair's world (nothing if none): its cameras then fail at the next grab."""
    with _lock:
        _worlds.pop(pair, None)


def registered_worlds() -> list[str]:
    """The pairs that have a world, sorted (tests check that none is left behind)."""
    with _lock:
        return sorted(_worlds)


def parse_sim_url(text: str) -> tuple[str, str, int]:
    """(pair, side, seed) of a ``sim://`` URL; the pair keeps its case (hostnames do not)."""
    pair, side, seed, _, _ = _parse(text)
    return pair, side, seed


def _parse(text: str) -> tuple[str, str, int, str, float]:
    """(pair, side, seed, serial number, frame rate) of a ``sim://`` URL."""
    url = parse_url(text)
    opts = url.typed_options({"seed": (int, 0), "serial": (str, ""),
                              "frame_rate": (positive, None)}, FORM)
    parts = urlsplit(text)
    pair = unquote(parts.netloc)
    side = unquote(parts.path).strip("/")
    if url.scheme != "sim" or not pair or side not in SIDES:
        raise url.error(f"expected {FORM}")
    if opts["seed"] < 0:
        raise url.error("option seed must be >= 0")
    try:
        rate = opts["frame_rate"] or default_rate()
    except ValueError as exc:
        raise url.error(str(exc)) from None
    return pair, side, int(opts["seed"]), opts["serial"].strip() or f"SIM-{pair}-{side}", rate


def default_rate() -> float:
    """The rate of a camera whose URL names none: ``STATIOND_SIM_FRAME_RATE`` if set (a
    ValueError naming it when it is not a number > 0), else :data:`FRAME_RATE`."""
    text = os.environ.get(RATE_ENV, "").strip()
    if not text:
        return FRAME_RATE
    try:
        return positive(text)
    except ValueError:
        raise ValueError(f"{RATE_ENV}={text!r} is not a frame rate (a number of Hz > 0)") \
            from None


class SimCamera(CameraDevice):
    """A camera of the simulated station.  It has no exposure or gain: the world decides how
    bright the image is.  Frames are rendered when grabbed, of the world as of the trigger
    instant, which is also their timestamp: a stereo pair triggered together shows no skew
    and no motion between its frames however long rendering takes."""

    simulated = True

    def __init__(self, url: str, *, timeout: float | None = None) -> None:
        super().__init__(url, timeout=timeout)
        self.pair, self.side, self.seed, self._serial, rate = _parse(url)
        self.frame_period_s = 1.0 / rate
        self._count = 0
        self._next_exposure = 0.0      # time.monotonic() when the sensor takes a trigger again

    @classmethod
    def world_view(cls, url: str) -> tuple[str, str] | None:
        """``sim://PAIR/SIDE``'s pair and side (a UrlError when the URL is malformed)."""
        pair, side, _ = parse_sim_url(url)
        return pair, side

    def identity(self) -> str:
        with _lock:
            world = "world registered" if self.pair in _worlds else "no world registered yet"
        return f"simulated camera {self.pair}/{self.side} S/N {self._serial} ({world})"

    def serial_number(self) -> str | None:
        return self._serial

    def _open(self) -> None:
        self._count = 0
        self._next_exposure = 0.0

    def _trigger(self) -> None:
        self._ready()
        self._triggered_at = time.time()   # the exposure starts once the sensor is ready

    def _ready(self) -> None:
        """Wait until the sensor can expose again (a frame period after the last exposure
        started), and count the new exposure."""
        wait = self._next_exposure - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        self._next_exposure = time.monotonic() + self.frame_period_s

    def _close(self) -> None:
        pass

    def _grab(self, timeout: float) -> Frame:
        """Render one frame of the world as of the trigger (synchronously: ``timeout`` does
        not cut a render short)."""
        with _lock:
            source = _worlds.get(self.pair)
            known = sorted(_worlds)
        if source is None:
            others = f" (registered: {', '.join(known)})" if known else " (none registered)"
            raise ConnectError(f"no simulated world for pair {self.pair!r}{others}; the world "
                               f"must call drivers.camera.sim.register_world({self.pair!r}, "
                               "source) first", device=self.url)
        if self._triggered_at is None:    # a grab without a trigger exposes now
            self._ready()
        timestamp = self._take_trigger_time()
        frame_id = self._count
        self._count += 1
        image = source(self.side, self.seed + frame_id, timestamp)
        if not (isinstance(image, np.ndarray) and image.dtype == np.uint8 and image.ndim == 3
                and image.shape[2] == 3 and image.size > 0):
            what = f"{getattr(image, 'dtype', type(image).__name__)} " \
                   f"{getattr(image, 'shape', '')}".strip()
            raise ProtocolError(f"the simulated world returned {what}, not an HxWx3 uint8 "
                                "BGR image", device=self.url)
        return Frame(image=image, timestamp=timestamp, frame_id=frame_id, camera=self.url)
