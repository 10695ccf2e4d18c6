"""``opencv://INDEX``: a camera OpenCV's VideoCapture can open (UVC webcams through V4L2), or
``opencv:///path/video.avi``: a recorded video.

For bench work and commissioning, not the station's GenICam cameras (the pip OpenCV wheel has
no Aravis backend; see ``aravis.py``).  ``trigger()`` calls ``VideoCapture.grab()`` and
``grab()`` then ``retrieve()``: OpenCV's documented way to take frames from several cameras
as close together in time as possible.  Without a trigger, ``grab()`` reads the next frame.

    opencv://0?width=1920&height=1080&fps=30&fourcc=MJPG&api=v4l2
    opencv:///data/run1/left.avi

A device that stops delivering (unplugged) raises ConnectionLostError and stays down until
``reconnect()`` reopens it (the station's keeper decides when); a video file that ends raises
EndOfStreamError.  Exposure and gain are not offered: their units differ per
OpenCV backend and per driver, so a number set here would mean nothing reliable.
"""

from __future__ import annotations

import logging
from typing import Any, NoReturn

import cv2
import numpy as np

from drivers.camera.base import CameraDevice, EndOfStreamError, Frame, choice, positive
from drivers.counting import counted
from drivers.endpoint import Endpoint, VideoEndpoint
from drivers.errors import ConnectError, ConnectionLostError
from drivers.url import DeviceUrl, parse_url

log = logging.getLogger(__name__)
FORM = "opencv://INDEX[?width=W&height=H&fps=F&fourcc=MJPG&api=v4l2] | opencv:///path/video.avi"
APIS = {"any": cv2.CAP_ANY, "v4l2": cv2.CAP_V4L2, "ffmpeg": cv2.CAP_FFMPEG,
        "gstreamer": cv2.CAP_GSTREAMER, "images": cv2.CAP_IMAGES}
#: the highest camera index: Linux numbers video devices /dev/video0-255 (VIDEO_NUM_DEVICES)
MAX_INDEX = 255


def _fourcc(text: str) -> str:
    if len(text) != 4 or not text.isascii():
        raise ValueError(text)
    return text


def _size(text: str) -> int:
    value = int(text)
    if not 0 < value <= 65535:
        raise ValueError(text)
    return value


def _source(parsed: DeviceUrl) -> int | str:
    """What VideoCapture opens: a camera index (``opencv://0``) or a path (a video file, or
    a device such as ``opencv:///dev/video2``); a UrlError for any other form."""
    if parsed.path and parsed.path != "/" and not parsed.host:
        return parsed.path
    if parsed.host and parsed.host.isdigit() and parsed.path in ("", "/"):
        index = int(parsed.host)
        if index > MAX_INDEX:   # OpenCV fails such an index with a C++ exception
            raise parsed.error(f"the camera index {index} is not a /dev/videoN "
                               f"number (0-{MAX_INDEX})")
        return index
    raise parsed.error(f"expected a camera index or a file path: {FORM}")


class OpenCvCamera(CameraDevice):
    """A VideoCapture source as a camera: free-running, no exposure or gain control."""

    def __init__(self, url: str, *, timeout: float | None = None) -> None:
        parsed = parse_url(url)
        opts = parsed.typed_options({
            "width": (_size, None), "height": (_size, None), "fps": (positive, None),
            "fourcc": (_fourcc, None), "api": (choice(*APIS), "any"),
            "timeout": (positive, None)}, FORM)
        super().__init__(url, timeout=opts["timeout"] or timeout)
        self.source: int | str = _source(parsed)
        self.is_file = isinstance(self.source, str)
        self.opts = opts
        self._cap: Any = None
        self._grabbed: float | None = None
        self._count = 0
        self._backend = ""

    @classmethod
    def _endpoint(cls, url: str) -> Endpoint | None:
        """A camera index is the ``/dev/videoN`` Linux numbers it as (V4L2, what OpenCV opens
        on Linux), a path under /dev the video device itself; any other path is a video
        file, read by any number of processes (None)."""
        source = _source(parse_url(url))
        if isinstance(source, int):
            return VideoEndpoint(f"/dev/video{source}")
        return VideoEndpoint(source) if source.startswith("/dev/") else None

    def identity(self) -> str:
        what = f"video file {self.source}" if self.is_file else f"camera index {self.source}"
        cap = self._cap
        size = ""
        if cap is not None:
            w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
            size = f", {w}x{h}"
        return f"OpenCV {cv2.__version__} {self._backend or 'VideoCapture'}: {what}{size}"

    def _connect(self) -> Any:
        """A VideoCapture with the URL's settings; ConnectError if OpenCV cannot open it.
        OpenCV's own warnings are silenced meanwhile: the error says it in one line."""
        params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, int(self.timeout * 1000),
                  cv2.CAP_PROP_READ_TIMEOUT_MSEC, int(self.timeout * 1000)]
        old = cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        try:
            cap = cv2.VideoCapture(self.source, APIS[self.opts["api"]], params)
            if not cap.isOpened():
                cap.release()
                cap = cv2.VideoCapture(self.source, APIS[self.opts["api"]])
        except cv2.error as exc:    # OpenCV's C++ refusal: a device fault, not a crash
            why = (exc.err or str(exc)).strip("> \n").splitlines()
            raise ConnectError(f"OpenCV cannot open {self.source!r}: "
                               f"{why[0] if why else 'refused'}", device=self.url) from None
        finally:
            cv2.utils.logging.setLogLevel(old)
        if not cap.isOpened():
            cap.release()
            hint = "no such file or not a video OpenCV can decode" if self.is_file else \
                "no such camera, or it is in use (ls /dev/video*)"
            raise ConnectError(f"OpenCV cannot open {self.source!r}: {hint}", device=self.url)
        if self.opts["fourcc"]:
            cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*self.opts["fourcc"]))
        for prop, name in ((cv2.CAP_PROP_FRAME_WIDTH, "width"),
                           (cv2.CAP_PROP_FRAME_HEIGHT, "height"), (cv2.CAP_PROP_FPS, "fps")):
            if self.opts[name] is not None:
                cap.set(prop, float(self.opts[name]))
        self._backend = cap.getBackendName()
        return cap

    def _open(self) -> None:
        self._cap = self._connect()
        self._grabbed = None
        self._count = 0

    def _close(self) -> None:
        if self._cap is not None:
            self._cap.release()
        self._cap = None
        self._grabbed = None

    def _ensure(self) -> Any:
        """The capture; ConnectionLostError while it is lost (until ``reconnect()``)."""
        if self._cap is None:
            raise ConnectionLostError("the camera stopped delivering frames; not reopened "
                                      "yet", device=self.url)
        return self._cap

    def _failed(self, what: str) -> NoReturn:
        """End of a file, or a device that stopped: typed error, and forget the capture."""
        if self.is_file:
            raise EndOfStreamError(f"end of video after {counted(self._count, 'frame')}",
                                   device=self.url)
        if self._cap is not None:
            self._cap.release()
        self._cap = None
        raise ConnectionLostError(f"{what} failed: the camera stopped delivering frames",
                                  device=self.url)

    def _trigger(self) -> None:
        cap = self._ensure()
        if not cap.grab():
            self._grabbed = None
            self._failed("grab")
        self._grabbed = self._take_trigger_time()

    def _grab(self, timeout: float) -> Frame:
        cap = self._ensure()
        if self._grabbed is not None:
            timestamp, self._grabbed = self._grabbed, None
            ok, image = cap.retrieve()
        else:
            timestamp = self._take_trigger_time()
            ok, image = cap.read()
        if not ok or image is None:
            self._failed("read")
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        elif image.shape[2] == 4:
            image = np.ascontiguousarray(image[:, :, :3])
        if image.dtype != np.uint8:
            image = cv2.convertScaleAbs(image, alpha=255.0 / 65535.0)
        frame = Frame(image=image, timestamp=timestamp, frame_id=self._count, camera=self.url)
        self._count += 1
        return frame
