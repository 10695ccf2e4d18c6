"""What an ``aravis://`` URL asks of a camera, and Aravis's error codes as typed errors.

Kept apart from ``aravis.py`` because none of it needs Aravis: it is tested without it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar
from urllib.parse import unquote, urlsplit

from drivers.camera import pixels
from drivers.camera.base import UnsupportedError, choice, positive
from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    DeviceError,
    RefusedError,
)
from drivers.url import OptionError, parse_url

N = TypeVar("N", int, float)
FORM = ("aravis://DEVICE-ID?trigger=software|line0|free&pixel_format=" + "|".join(pixels.FORMATS)
        + "&exposure_us=N&gain_db=N&buffers=4&region=full|X,Y,W,H&frame_rate=HZ&heartbeat_ms=N"
        + "&stream_socket=udp|packet")
DEFAULT_BUFFERS = 4
# ArvDeviceError codes meaning "the camera is gone": not connected, protocol error, transfer
# error, timeout, not found; and the ones meaning "someone else controls it"
LINK_LOST = {2, 3, 4, 5, 6}
NOT_IN_CONTROL = {10, 17, 18}
FEATURE_MISSING = {("arv-device-error-quark", 1), ("arv-gc-error-quark", 0),
                   ("arv-gc-error-quark", 7)}


@dataclass(frozen=True)
class Settings:
    """What the URL asks of the camera."""

    name: str
    trigger: str = "software"
    pixel_format: str | None = None
    exposure_us: float | None = None
    gain_db: float | None = None
    buffers: int = DEFAULT_BUFFERS
    region: tuple[int, int, int, int] | str | None = None
    frame_rate: float | None = None
    heartbeat_ms: int | None = None
    #: how a GigE stream is read: a UDP socket (what the service, without raw sockets, gets),
    #: or Aravis's packet socket (a 32 MB ring, for unpaced bursts; needs CAP_NET_RAW, and
    #: has Aravis 0.8's start-up race: see ``_Link._configure``)
    stream_socket: str = "udp"


def _region(text: str) -> tuple[int, int, int, int] | str:
    if text.lower() == "full":
        return "full"
    x, y, w, h = (int(v) for v in text.split(","))
    if min(x, y) < 0 or min(w, h) <= 0:
        raise ValueError(text)
    return x, y, w, h


def _trigger(text: str) -> str:
    low = text.lower()
    if low in ("software", "free") or (low.startswith("line") and low[4:].isdigit()):
        return low
    raise OptionError("expected software, free or line0, line1... (a hardware trigger input)")


#: plausible settings: outside them a number is a typo or another unit, and the camera would
#: refuse it (or clamp it silently) only once the station runs.  GenICam cameras' analogue
#: gain goes from 0 to 24-48 dB (a linear factor such as 9000 is not dB); an exposure longer
#: than a second blurs a moving wrench into nothing and shorter than 1 us is no camera's
GAIN_DB = (0.0, 48.0)
EXPOSURE_US = (1.0, 1_000_000.0)


#: a GigE Vision camera's heartbeat timeout (bootstrap register 0x0938): below Aravis's
#: heartbeat period (1 s) the camera would drop the station at once; above 10 minutes a
#: station that died would keep its camera locked for that long
HEARTBEAT_MS = (1500, 600_000)


def _bounded(convert: Callable[[str], N], bounds: tuple[N, N], what: str,
             unit: str = "") -> Callable[[str], N]:
    """An option's reader: ``convert`` the text, refused outside ``bounds`` with what a
    value of it is (``what`` LO-HI, ``unit``)."""
    def read(text: str) -> N:
        value = convert(text)
        if not bounds[0] <= value <= bounds[1]:
            raise OptionError(f"{what} is {bounds[0]:g}-{bounds[1]:g}{unit}")
        return value
    return read


_gain_db = _bounded(float, GAIN_DB, "a gain in dB")
_exposure_us = _bounded(float, EXPOSURE_US, "an exposure in microseconds", " (1 s)")
_heartbeat_ms = _bounded(int, HEARTBEAT_MS, "a heartbeat timeout in milliseconds",
                         " (Aravis sends one each second)")


def _buffers(text: str) -> int:
    n = int(text)
    if not 1 <= n <= 64:
        raise ValueError(text)
    return n


def parse_aravis_url(text: str) -> tuple[Settings, dict[str, float | None]]:
    """The camera settings and the timing options of an ``aravis://`` URL.  The device id
    is taken from the URL as written (case kept, percent-decoded)."""
    url = parse_url(text)
    opts = url.typed_options({
        "trigger": (_trigger, "software"), "pixel_format": (choice(*pixels.FORMATS), None),
        "exposure_us": (_exposure_us, None), "gain_db": (_gain_db, None),
        "buffers": (_buffers, None),
        "region": (_region, None), "frame_rate": (positive, None),
        "heartbeat_ms": (_heartbeat_ms, None), "stream_socket": (choice("udp", "packet"), None),
        "timeout": (positive, None)}, FORM)
    name = unquote(urlsplit(text).netloc)
    if url.scheme != "aravis" or not name or url.path not in ("", "/"):
        raise url.error(f"expected {FORM} (the device id is VENDOR-MODEL-SERIAL, as Aravis "
                        "lists it)")
    settings = Settings(name, opts["trigger"], opts["pixel_format"], opts["exposure_us"],
                        opts["gain_db"], opts["buffers"] or DEFAULT_BUFFERS, opts["region"],
                        opts["frame_rate"], opts["heartbeat_ms"], opts["stream_socket"] or "udp")
    return settings, {"timeout": opts["timeout"]}


def translate(exc: Any, what: str, device: str) -> DeviceError:
    """A typed DeviceError for a GLib.Error raised by Aravis while doing ``what``."""
    domain, code = str(getattr(exc, "domain", "")), int(getattr(exc, "code", -1))
    msg = f"{what}: {getattr(exc, 'message', exc)}"
    if domain == "arv-device-error-quark" and code in LINK_LOST:
        return ConnectionLostError(msg + " (camera unplugged, off, or link down?)",
                                   device=device, code=code)
    if domain == "arv-device-error-quark" and code in NOT_IN_CONTROL:
        return ConnectError(msg + " (is another program using the camera?)", device=device,
                            code=code)
    if (domain, code) in FEATURE_MISSING:
        return UnsupportedError(msg, device=device, code=code)
    if domain == "arv-gc-error-quark":
        return RefusedError(msg, device=device, code=code)
    return DeviceError(msg, device=device, code=code)
