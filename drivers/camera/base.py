"""A camera as the station sees it: trigger, then grab one BGR frame with its timestamp.

Every backend (Aravis, OpenCV, file replay, simulated world) delivers the same thing -- an
8-bit BGR image, because the marker is found by its colour -- so the vision code never learns
where a frame came from.  The public methods here do the shared work (state checks, argument
checks, timeouts) and call small hooks each backend overrides, like python-can's ``BusABC``.

Trigger semantics, the same for every backend, so that a stereo pair can be driven without
knowing what it is made of:

- ``trigger()`` starts a new frame *now*: frames already waiting (from earlier triggers) are
  dropped and a software trigger is fired.  Backends that cannot be triggered (free-running
  cameras, replays, the simulated world) note the time instead, which becomes the frame's
  timestamp, so two cameras triggered together get matching timestamps.
- ``grab(timeout)`` returns the next frame.  A software-triggered camera delivers nothing
  without a trigger (DeviceTimeoutError); the other backends deliver a frame on every grab.

Timing, the same for every backend, because the station judges a frame's age from it (a
wrench seen 300 ms ago may be on another bolt now): ``Frame.timestamp`` is the instant the
frame was *exposed* (triggered), on the host's ``time.time()`` scale, never when it arrived;
``Frame.arrival`` is the host time ``grab()`` delivered it.  Their difference is the camera's
exposure-to-delivery delay (readout, transfer, queueing, rendering), which the daemon reports.
Each backend documents where its exposure instant comes from.

Classes are named ``CameraDevice`` so they do not clash with the camera *model*
(``stationd.geometry.camera.Camera``: intrinsics and distortion).
"""

from __future__ import annotations

import math
import time
from abc import abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from drivers.errors import DeviceError
from drivers.lifecycle import Device

DEFAULT_TIMEOUT = 2.0  # seconds a grab waits when neither the URL nor the caller says


class UnsupportedError(DeviceError):
    """The camera cannot do this (exposure on a file replay, gain on a camera without it)."""


class FrameError(DeviceError):
    """A frame arrived but cannot be used: an unreadable file, an unsupported pixel format,
    an incomplete buffer.  The camera itself is still usable: grab again."""


class EndOfStreamError(DeviceError):
    """A replay (image files, a video file) has delivered its last frame."""


@dataclass(eq=False)
class Frame:
    """One image: ``image`` is HxWx3 uint8 in BGR order (OpenCV's), ``timestamp`` is
    seconds since the epoch on the host clock (``time.time()`` scale) when the frame was
    exposed (triggered) -- what ages are measured from --, ``frame_id`` counts the camera's
    frames, ``camera`` is the camera's URL, ``pixel_format`` what the camera sent before
    conversion to BGR, ``arrival`` the host time the frame was delivered (``grab()`` sets
    it as it returns; a frame built elsewhere gets its construction time)."""

    image: np.ndarray
    timestamp: float
    frame_id: int
    camera: str
    pixel_format: str = "BGR8"
    arrival: float = field(default_factory=time.time)

    def __post_init__(self) -> None:
        img = self.image
        if not (isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.ndim == 3
                and img.shape[2] == 3 and img.shape[0] > 0 and img.shape[1] > 0):
            shape = getattr(img, "shape", None)
            dtype = getattr(img, "dtype", type(img).__name__)
            raise ValueError(f"a frame is an HxWx3 uint8 BGR image, got {dtype} {shape}")

    @property
    def delay_s(self) -> float:
        """Seconds from exposure to delivery (readout, transfer, queueing, rendering)."""
        return self.arrival - self.timestamp

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        return int(self.image.shape[0])


def positive(text: str) -> float:
    """URL option converter: a finite number > 0 (seconds, microseconds)."""
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(text)
    return value


def flag(text: str) -> bool:
    """URL option converter: 1/0, yes/no, true/false, on/off."""
    low = text.strip().lower()
    if low in ("1", "yes", "true", "on"):
        return True
    if low in ("0", "no", "false", "off"):
        return False
    raise ValueError(text)


def choice(*allowed: str) -> Callable[[str], str]:
    """URL option converter: one of ``allowed``, case-insensitive, returned as spelled there."""
    table = {a.lower(): a for a in allowed}

    def conv(text: str) -> str:
        try:
            return table[text.strip().lower()]
        except KeyError:
            raise ValueError(text) from None
    return conv


class CameraDevice(Device):
    """One camera.  ``open()`` and ``close()`` are idempotent and the camera is a context
    manager (``drivers.lifecycle.Device``); backends implement ``_open`` (connect and start
    acquisition) / ``_close`` / ``_grab`` (and ``_trigger``, ``_set_exposure_us``,
    ``_set_gain_db`` where they can) and this class does the rest."""

    def __init__(self, url: str, *, timeout: float | None = None) -> None:
        if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
            raise ValueError(f"timeout must be > 0, got {timeout}")
        super().__init__()
        self.url = url
        self.timeout = timeout or DEFAULT_TIMEOUT
        self._triggered_at: float | None = None

    @classmethod
    def world_view(cls, url: str) -> tuple[str, str] | None:
        """The pair and side of the simulated world a camera of this backend at ``url``
        shows (None: a camera of the real world, which shows what is there)."""
        return None

    def close(self) -> None:
        """Stop acquisition and background work, release the camera; safe to call twice."""
        self._triggered_at = None  # a pending trigger does not outlive the acquisition
        super().close()

    def _check_open(self) -> None:
        if not self._is_open:
            raise DeviceError("the camera is not open", device=self.url)

    def trigger(self) -> None:
        """Start a new frame now (software trigger); frames already waiting are dropped."""
        self._check_open()
        self._triggered_at = time.time()
        self._trigger()

    def grab(self, timeout: float | None = None) -> Frame:
        """The next frame, waiting at most ``timeout`` seconds (default: the camera's).
        DeviceTimeoutError if none arrives (a software-triggered camera needs ``trigger()``
        first), ConnectionLostError if the camera went away (it stays down until
        ``reconnect()``), FrameError for a frame that arrived broken."""
        self._check_open()
        if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
            raise ValueError(f"timeout must be > 0, got {timeout}")
        frame = self._grab(timeout or self.timeout)
        frame.arrival = time.time()
        return frame

    def set_exposure_us(self, exposure_us: float) -> float:
        """Set the exposure time in microseconds; returns the value the camera applied
        (cameras round to their step).  UnsupportedError where there is no such control."""
        self._check_open()
        if not (math.isfinite(exposure_us) and exposure_us > 0):
            raise ValueError(f"exposure must be > 0 us, got {exposure_us}")
        return self._set_exposure_us(float(exposure_us))

    def set_gain_db(self, gain_db: float) -> float:
        """Set the analogue gain in dB; returns the value the camera applied."""
        self._check_open()
        if not math.isfinite(gain_db):
            raise ValueError(f"gain must be finite, got {gain_db}")
        return self._set_gain_db(float(gain_db))

    def _take_trigger_time(self) -> float:
        """The time of the pending ``trigger()`` (consumed), else now: the exposure instant
        of backends that produce the frame when grabbed (taken before the frame is read or
        rendered, so reading time never makes a frame look younger than it is)."""
        t, self._triggered_at = self._triggered_at, None
        return t if t is not None else time.time()

    def serial_number(self) -> str | None:
        """The camera's serial number as it reports it; None where the backend cannot tell
        one unit from another.  The station pins a pair's calibration to the serials it was
        first used with, so that a camera replaced without calibrating the pair again is
        refused rather than trusted (``db.cameras``)."""
        return None

    # -- hooks --------------------------------------------------------------------------
    @abstractmethod
    def identity(self) -> str:
        """A one-line description of the camera and its link, for logs and ``stationd probe``."""

    @abstractmethod
    def _grab(self, timeout: float) -> Frame:
        """The next frame within ``timeout`` seconds (> 0), or a typed DeviceError."""

    def _trigger(self) -> None:  # free-running backends only note the time
        """Fire the trigger; by default nothing to do (the base class noted the time)."""

    def _set_exposure_us(self, exposure_us: float) -> float:
        raise UnsupportedError(f"{type(self).__name__} has no exposure control",
                               device=self.url)

    def _set_gain_db(self, gain_db: float) -> float:
        raise UnsupportedError(f"{type(self).__name__} has no gain control", device=self.url)
