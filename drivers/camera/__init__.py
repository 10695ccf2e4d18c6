"""Cameras, chosen by URL: ``open_camera("aravis://Hikrobot-MV-CS200-10UC-DA1234567")``.

Backends are imported only when their scheme is used (a station of simulated cameras never
imports PyGObject; a typo in the scheme fails before any import), like the lift's registry.
"""

from __future__ import annotations

from typing import Any

from drivers.camera.base import (
    CameraDevice,
    EndOfStreamError,
    Frame,
    FrameError,
    UnsupportedError,
)
from drivers.errors import UrlError
from drivers.url import load_backend, parse_url

#: scheme -> "module:Class"
BACKENDS: dict[str, str] = {
    "aravis": "drivers.camera.aravis:AravisCamera",
    "opencv": "drivers.camera.opencv:OpenCvCamera",
    "file": "drivers.camera.replay:FileReplayCamera",
    "sim": "drivers.camera.sim:SimCamera",
}
FORMS = ("aravis://DEVICE-ID[?trigger=software|line0|free&pixel_format=BayerRG8] | "
         "opencv://INDEX | opencv:///path/video.avi | file:///dir/left_*.png[?loop=1] | "
         "sim://PAIR/left|right")

__all__ = ["BACKENDS", "FORMS", "CameraDevice", "EndOfStreamError", "Frame", "FrameError",
           "UnsupportedError", "camera_class", "check_camera_url", "open_camera"]


def camera_class(url: str) -> type[CameraDevice]:
    """The backend class for ``url``'s scheme; UrlError listing the accepted forms if none."""
    try:
        scheme = parse_url(url).scheme
    except UrlError as exc:
        raise UrlError(f"{exc}; accepted: {FORMS}") from None
    cls: type[CameraDevice] | None = load_backend(BACKENDS, scheme)
    if cls is None:
        raise UrlError(f"unknown camera scheme {scheme!r}; accepted: {FORMS}", device=url)
    return cls


def check_camera_url(url: str, *, sources: bool = False) -> None:
    """Build the camera of ``url`` without opening it: its form and options, with their
    ranges, are checked (UrlError), nothing is connected and no SDK is loaded (the Aravis
    backend parses its URL before it ever imports Aravis).  ``sources``: also check what a
    backend reads that exists now or never (a replay's files: ``check_source``)."""
    cls = camera_class(url)
    try:
        cls(url).close()
    except ValueError as exc:  # a backend's own refusal that is not a UrlError yet
        raise UrlError(str(exc), device=url) from None
    check_source = getattr(cls, "check_source", None)
    if sources and check_source is not None:
        check_source(url)


def open_camera(url: str, **kw: Any) -> CameraDevice:
    """An open camera for ``url``; ``kw`` go to the backend (e.g. ``timeout`` in seconds; the
    URL's own options win).  Close it, or use ``with``."""
    cam = camera_class(url)(url, **kw)
    cam.open()
    return cam
