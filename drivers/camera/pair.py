"""Two cameras of a stereo pair, grabbed on one trigger, refused when out of step.

Triangulating a marker that moved between the left and the right exposure puts it where it
never was, and nothing downstream can tell: so a pair of frames whose *exposure* timestamps
(``Frame.timestamp``) differ by more than ``max_skew_s`` is refused here with a typed error
instead of being returned.  Arrival times (``Frame.arrival``) may differ by much more (one
camera's transfer queued behind the other's) without harm: the images were taken together.
With software triggers both cameras are triggered back to back (each ``trigger()`` also drops
stale frames, so one refused pair does not shift the next); with a shared hardware trigger
line, ``trigger()`` only drops stale frames and the line starts both exposures.

The grabber does not own the cameras: open and close them yourself.
"""

from __future__ import annotations

import math
import time

from drivers.camera.base import CameraDevice, Frame
from drivers.errors import DeviceError

SIDES = ("left", "right")


class StereoError(DeviceError):
    """A stereo grab that yields no usable pair."""


class StereoSkewError(StereoError):
    """Both frames arrived but were not exposed together; ``skew_s`` says by how much, and
    ``frames`` holds them (left, right) for logging."""

    def __init__(self, message: str, *, device: str | None, skew_s: float,
                 frames: tuple[Frame, Frame]) -> None:
        super().__init__(message, device=device)
        self.skew_s = skew_s
        self.frames = frames


class FrameMissingError(StereoError):
    """One or both cameras gave no frame; ``errors`` maps the side to its camera's error
    (DeviceTimeoutError, ConnectionLostError, ...)."""

    def __init__(self, message: str, *, device: str | None,
                 errors: dict[str, DeviceError]) -> None:
        super().__init__(message, device=device)
        self.errors = errors


def _bare(exc: DeviceError) -> str:
    """A camera's error without the URL it begins with (said after it instead)."""
    text = str(exc)
    prefix = f"{exc.device}: " if exc.device else ""
    return text[len(prefix):] if prefix and text.startswith(prefix) else text


class StereoGrabber:
    """Grab (left, right) frames taken on one trigger, at most ``max_skew_s`` apart."""

    def __init__(self, left: CameraDevice, right: CameraDevice, max_skew_s: float, *,
                 name: str | None = None) -> None:
        if not (math.isfinite(max_skew_s) and max_skew_s >= 0):
            raise ValueError(f"max_skew_s must be >= 0, got {max_skew_s}")
        if left is right:
            raise ValueError("a stereo pair needs two different cameras")
        self.left = left
        self.right = right
        self.max_skew_s = float(max_skew_s)
        #: what its errors begin with: the pair's name, or both URLs; "" for none (the
        #: station names the pair itself before the reason: "p1: no frame from left ...")
        self.name = f"stereo {left.url} + {right.url}" if name is None else name

    def grab(self, timeout: float | None = None) -> tuple[Frame, Frame]:
        """Trigger both cameras, then wait (``timeout`` seconds in all, default the slower
        camera's) for one frame from each.  FrameMissingError names the side(s) that gave
        nothing; StereoSkewError when the timestamps differ by more than ``max_skew_s``."""
        if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
            raise ValueError(f"timeout must be > 0, got {timeout}")
        total = timeout or max(self.left.timeout, self.right.timeout)
        deadline = time.monotonic() + total
        cams = dict(zip(SIDES, (self.left, self.right), strict=True))
        errors: dict[str, DeviceError] = {}
        for side, cam in cams.items():
            try:
                cam.trigger()
            except DeviceError as exc:
                errors[side] = exc
        frames: dict[str, Frame] = {}
        for side, cam in cams.items():
            if side in errors:
                continue
            try:
                frames[side] = cam.grab(max(deadline - time.monotonic(), 1e-3))
            except DeviceError as exc:
                errors[side] = exc
        if errors:
            # why first, then which camera (a technician's trial: the headline, cut at 160
            # characters, showed both URLs and no reason); each camera's URL after its words
            detail = "; ".join(f"{side}: {_bare(exc)} ({cams[side].url})"
                               for side, exc in errors.items())
            raise FrameMissingError(f"no frame from {' and '.join(errors)} within {total:g} s: "
                                    f"{detail}", device=self.name or None, errors=errors)
        left, right = frames["left"], frames["right"]
        skew = abs(left.timestamp - right.timestamp)
        if skew > self.max_skew_s:
            raise StereoSkewError(
                f"frames {left.frame_id} (left) and {right.frame_id} (right) were taken "
                f"{skew * 1000:.1f} ms apart, more than the {self.max_skew_s * 1000:.1f} ms "
                "allowed", device=self.name, skew_s=skew, frames=(left, right))
        return left, right
