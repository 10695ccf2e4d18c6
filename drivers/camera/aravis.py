"""``aravis://DEVICE-ID``: GenICam cameras (USB3 Vision, GigE Vision) through Aravis 0.8.

The only module that talks to Aravis.  PyGObject has no type stubs, so ``gi`` is imported
through importlib and typed ``Any``, when the first ``aravis://`` camera opens.

    aravis://Hikrobot-MV-CS200-10UC-DA1234567?trigger=software&pixel_format=BayerRG8
        &exposure_us=20000&gain_db=0&buffers=4&region=full&timeout=2

- ``trigger``: ``software`` (default: no frame without ``trigger()``), ``line0``, ``line1``...
  (hardware trigger, rising edge) or ``free`` (free-running).
- ``pixel_format``: Mono8, Bayer{RG,GB,GR,BG}8 (demosaiced on the host), RGB8, BGR8; default
  the camera's current one if supported, else the first of those it offers.
- ``buffers``: the stream's pool, each buffer the camera's own payload (20 MB for 5472x3648
  Bayer8, 60 MB for RGB8), allocated once per connection.  ``region``: ``full`` or X,Y,W,H.
  ``frame_rate``: the free-running rate in Hz.  ``heartbeat_ms``: a GigE Vision camera's
  heartbeat timeout (default the camera's own, 3000 ms in the standard).
- A frame's timestamp is its exposure instant on the host's ``time.time()`` scale: the
  buffer's own timestamp (the camera's clock at the start of the frame) mapped onto host
  time by ``clock.ClockMap`` from the buffer's system timestamp (host time of its first
  packet, an upper bound) and the software trigger's send time (a lower bound).  Until the
  map is verified (2 s of frames at the host's rate: Hikrobot cameras report their clock in
  a wrong unit, Aravis's ``src/arv-test.cfg``), or when the camera gives no timestamp, the
  software trigger's send time is the timestamp; with a line or free-running trigger and no
  usable camera clock, the system timestamp is (late by readout and transfer: the one case
  where a frame looks younger than it is, logged once).  Chunk data is not used.

Aravis quirks handled here:
- ``update_device_list()`` (about 1 s: GigE discovery) runs before ``Camera.new`` when the
  device is not listed yet and before every ``reconnect()``.  Without it ``Camera.new``
  finds a GigE device through whichever interface answers a broadcast first: with an Ethernet
  port present, the fake camera on 127.0.0.1 then streams to the Ethernet address and no
  frame ever arrives.
- A vanished GigE camera makes each register access fail after 2.5 s (500 ms x 5 GVCP
  retries, fixed in 0.8).  The ``control-lost`` signal is not used: it comes from Aravis's
  heartbeat thread, where a Python callback leaves a ``threading._DummyThread`` behind for
  good.  Loss is seen in the errors of ``trigger()`` and of a register read after a grab
  times out; the link then stays down (calls say so at once) and the failed link is released
  by the next ``reconnect()`` (the station keeper's thread), not by the caller that saw it.
- A GigE camera that heard no heartbeat within its timeout (the host stalled that long, or
  another program took the camera) drops the station's control: it still answers reads but
  ignores commands, and no frame comes again.  Aravis's heartbeat thread notices within a
  second; ``trigger()`` and a grab that timed out then say so as a lost link, which the
  keeper's ``reconnect()`` takes back, rather than timing out for good.  A camera another
  program controls at opening is refused at once with that reason.
- Shutdown order: stream, then camera, then ``Aravis.shutdown()``, the last only at process
  end (``shutdown()`` below is registered with atexit when Aravis is first loaded).
"""

from __future__ import annotations

import atexit
import importlib
import logging
import socket
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

from drivers.camera import pixels
from drivers.camera.aravis_config import Settings, parse_aravis_url, translate
from drivers.camera.base import CameraDevice, Frame, FrameError, UnsupportedError
from drivers.camera.clock import ClockMap
from drivers.counting import counted
from drivers.endpoint import AravisEndpoint, Endpoint
from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    RefusedError,
)

log = logging.getLogger(__name__)
T = TypeVar("T")
HEARTBEAT_TIMEOUT_REGISTER = 0x0938  # GigE Vision bootstrap register, in milliseconds
_load_lock = threading.Lock()
_system_lock = threading.Lock()  # Aravis's device list is one per process
_modules: tuple[Any, Any] | None = None
_open_cameras: weakref.WeakSet[AravisCamera] = weakref.WeakSet()


def load() -> tuple[Any, Any]:
    """(Aravis, GLib) from PyGObject; ConnectError with what to install if unavailable."""
    global _modules
    with _load_lock:
        if _modules is None:
            try:
                gi = importlib.import_module("gi")
                gi.require_version("Aravis", "0.8")
                arv = importlib.import_module("gi.repository.Aravis")
                glib = importlib.import_module("gi.repository.GLib")
            except (ImportError, ValueError) as exc:
                raise ConnectError(f"Aravis is not available ({exc}): apt-get install "
                                   "gir1.2-aravis-0.8, and pip install 'PyGObject<3.51'"
                                   ) from None
            _modules = (arv, glib)
            atexit.register(shutdown)
        return _modules


def available() -> str | None:
    """None if Aravis can be used here, else the reason (for skipping tests)."""
    try:
        load()
    except ConnectError as exc:
        return str(exc)
    return None


def shutdown() -> None:
    """Close every open Aravis camera (stream first, then camera), then ``Aravis.shutdown()``,
    the order Aravis needs.  Runs at exit; call it earlier only if no camera opens again."""
    for cam in list(_open_cameras):
        cam.close()
    if _modules is not None:
        with _system_lock:
            _modules[0].shutdown()


def _say_stream_limits(device: str, stream_socket: str, payload: int) -> None:
    """Journal what will break a GigE camera's frames, once per opening: a packet socket
    asked where none may be opened (Aravis then reads a UDP socket, silently), or a kernel
    that lets a UDP socket buffer less than a frame's 8 MB or its payload (its packets are
    then dropped whenever the host is late: broken frames)."""
    if stream_socket == "packet":
        try:
            socket.socket(socket.AF_PACKET, socket.SOCK_RAW).close()
        except OSError:
            log.warning("%s: stream_socket=packet, but this process may not open raw "
                        "sockets (CAP_NET_RAW): the stream is read from a UDP socket", device)
        return
    try:
        allowed = int(Path("/proc/sys/net/core/rmem_max").read_text())
    except (OSError, ValueError):
        return
    if allowed < min(payload, 8 << 20):
        log.warning("%s: a UDP socket may buffer %.1f MB (net.core.rmem_max), a frame is "
                    "%.1f MB: frames break whenever the host is late; raise it (sysctl -w "
                    "net.core.rmem_max=8388608)", device, allowed / 1e6, payload / 1e6)


def no_frame_words(timeout: float, trigger: str, broken: str) -> str:
    """Why a grab got no frame, for the journal and ``probe``: frames that came broken
    (``broken``: "2 broken buffers: timeout") are packets lost on the way, not a trigger
    missed (a technician's trial read "call trigger() before grab()", a developer's hint, of
    a camera that was triggered and sent its frame in pieces); no frame at all after a
    software trigger is a trigger not taken."""
    if broken:
        return (f"no whole frame within {timeout:g} s: {broken} (frames arrive incomplete: "
                "packets lost on the link; a GigE camera's packet size or the receive buffer "
                "net.core.rmem_max, a USB3 port's bandwidth shared with another camera)")
    hint = " after its software trigger (not taken, or the camera busy)" \
        if trigger == "software" else ""
    return f"no frame within {timeout:g} s{hint}"


class _Link:
    """One opened camera, configured and acquiring into its buffer pool."""

    def __init__(self, settings: Settings, device: str) -> None:
        self.settings = settings
        self.device = device
        self.arv, self.glib = load()
        self.cam: Any = None
        self.stream: Any = None
        self.payload = 0
        self.pixel_format = ""
        self.clock = ClockMap()  # a new connection may bring a reset camera clock
        self.triggered_at: float | None = None  # host time the last software trigger was sent
        self._warned_clock = False

    def _call(self, what: str, fn: Any, *args: Any) -> Any:
        try:
            return fn(*args)
        except self.glib.Error as exc:
            error = translate(exc, what, self.device)
        raise error

    def connect(self, refresh: bool) -> None:
        """Find, configure and start the camera; typed errors, nothing left open on failure."""
        arv, name = self.arv, self.settings.name
        with _system_lock:
            listed = {arv.get_device_id(i) for i in range(arv.get_n_devices())}
            if refresh or name not in listed:
                arv.update_device_list()
                listed = {arv.get_device_id(i) for i in range(arv.get_n_devices())}
            try:
                self.cam = arv.Camera.new(name)
            except self.glib.Error as exc:
                found = ", ".join(sorted(listed)) or "none"
                raise ConnectError(f"cannot open camera {name!r}: {exc.message} (cameras "
                                   f"found: {found})", device=self.device) from None
        try:
            if not self.in_control():
                raise ConnectError(f"another program controls camera {name!r} (its GigE "
                                   "control channel is taken): close that program, or wait "
                                   "for its heartbeat timeout", device=self.device)
            self._configure()
        except BaseException:
            self.close(lost=True)
            raise

    def in_control(self) -> bool:
        """Whether the station still controls the camera: a GigE camera drops a controller
        whose heartbeat it missed (Aravis notices at its next heartbeat, within a second);
        USB3 Vision has no such channel."""
        return not self.cam.is_gv_device() or bool(self.cam.get_device().is_controller())

    def _check_control(self) -> None:
        if not self.in_control():
            raise ConnectionLostError(
                "control of the camera lost: it heard no heartbeat within its timeout (the "
                "host stalled that long) or another program took it", device=self.device)

    def _configure(self) -> None:
        s, cam, call = self.settings, self.cam, self._call
        if s.stream_socket != "udp" and not cam.is_gv_device():   # before anything is set
            raise UnsupportedError("stream_socket is for GigE Vision cameras (USB3 Vision "
                                   "streams over USB)", device=self.device)
        call("stop acquisition", cam.stop_acquisition)  # a crashed run may have left it on
        if s.heartbeat_ms is not None:
            if not cam.is_gv_device():
                raise UnsupportedError("heartbeat_ms is for GigE Vision cameras (USB3 Vision "
                                       "has no heartbeat)", device=self.device)
            call(f"set heartbeat timeout {s.heartbeat_ms} ms", cam.get_device().write_register,
                 HEARTBEAT_TIMEOUT_REGISTER, s.heartbeat_ms)
        available = call("list pixel formats", cam.dup_available_pixel_formats_as_strings)
        current = call("read pixel format", cam.get_pixel_format_as_string)
        pf = s.pixel_format or (current if current in pixels.FORMATS else next(
            (f for f in pixels.PREFERENCE if f in available), None))
        if pf is None or pf not in available:
            raise UnsupportedError(f"pixel format {pf or 'Mono8/Bayer*8/RGB8'} not offered by "
                                   f"the camera (it offers: {', '.join(available)})",
                                   device=self.device)
        call(f"set pixel format {pf}", cam.set_pixel_format_from_string, pf)
        self.pixel_format = pf
        if s.region is not None:
            full = call("read sensor size", cam.get_sensor_size)
            x, y, w, h = s.region if isinstance(s.region, tuple) else (0, 0, *full)
            call(f"set region {x},{y},{w},{h}", cam.set_region, x, y, w, h)
        if s.trigger == "free":
            call("clear triggers", cam.clear_triggers)
        else:
            sources = call("list trigger sources", cam.dup_available_trigger_sources)
            source = next((t for t in sources if t.lower() == s.trigger), None)
            if source is None:
                raise UnsupportedError(f"trigger {s.trigger} not offered (sources: "
                                       f"{', '.join(sources)})", device=self.device)
            call(f"set trigger {source}", cam.set_trigger, source)
        call("set acquisition mode", cam.set_acquisition_mode,
             self.arv.AcquisitionMode.CONTINUOUS)
        if s.frame_rate is not None:  # free-run rate (cameras may cap it by exposure)
            call(f"set frame rate {s.frame_rate:g} Hz", cam.set_frame_rate, s.frame_rate)
        if s.exposure_us is not None:
            self.set_exposure(s.exposure_us)
        if s.gain_db is not None:
            self.set_gain(s.gain_db)
        self.payload = int(call("read payload size", cam.get_payload))
        if cam.is_gv_device():
            if s.stream_socket == "udp":
                # a UDP socket unless asked, not Aravis's packet socket (its default where
                # raw sockets may be opened, as root): the service has no such right, and
                # Aravis 0.8's packet socket takes any IP packet on the interface until its
                # filter is attached (bind, then _set_socket_filter), reads the first one's
                # bytes as a frame id, then drops the camera's frames as late, up to 100
                cam.get_device().set_stream_options(
                    self.arv.GvStreamOption.PACKET_SOCKET_DISABLED)
            _say_stream_limits(self.device, s.stream_socket, self.payload)
        self.stream = call("create stream", cam.create_stream, None, None)
        if self.stream is None:
            raise ConnectError("the camera gave no stream", device=self.device)
        for _ in range(s.buffers):
            self.stream.push_buffer(self.arv.Buffer.new_allocate(self.payload))
        call("start acquisition", cam.start_acquisition)

    def identity(self) -> str:
        cam = self.cam
        kind = "USB3 Vision" if cam.is_uv_device() else "GigE Vision"
        if cam.is_gv_device():
            kind += f" {cam.get_device().get_device_address().to_string()}"
        region = cam.get_region()
        return (f"{cam.get_vendor_name()} {cam.get_model_name()} S/N "
                f"{cam.get_device_serial_number()} ({kind}; Aravis 0.8): trigger "
                f"{self.settings.trigger}, {self.pixel_format} {region.width}x{region.height}, "
                f"pool {self.settings.buffers} x {self.payload / 1e6:.2f} MB")

    def serial_number(self) -> str | None:
        serial = self.cam.get_device_serial_number()
        return None if serial is None else (str(serial).strip() or None)

    def set_exposure(self, us: float) -> float:
        cam, call = self.cam, self._call
        if not call("check exposure", cam.is_exposure_time_available):
            raise UnsupportedError("the camera has no exposure time control", device=self.device)
        lo, hi = call("read exposure bounds", cam.get_exposure_time_bounds)
        if not lo <= us <= hi:
            raise RefusedError(f"exposure {us:g} us is outside the camera's range "
                               f"{lo:g}-{hi:g} us", device=self.device)
        if call("check auto exposure", cam.is_exposure_auto_available):
            call("turn auto exposure off", cam.set_exposure_time_auto, self.arv.Auto.OFF)
        call(f"set exposure {us:g} us", cam.set_exposure_time, us)
        return float(call("read exposure", cam.get_exposure_time))

    def set_gain(self, db: float) -> float:
        cam, call = self.cam, self._call
        if not call("check gain", cam.is_gain_available):
            raise UnsupportedError("the camera has no gain control", device=self.device)
        lo, hi = call("read gain bounds", cam.get_gain_bounds)
        if not lo <= db <= hi:
            raise RefusedError(f"gain {db:g} dB is outside the camera's range {lo:g}-{hi:g} dB",
                               device=self.device)
        if call("check auto gain", cam.is_gain_auto_available):
            call("turn auto gain off", cam.set_gain_auto, self.arv.Auto.OFF)
        call(f"set gain {db:g} dB", cam.set_gain, db)
        return float(call("read gain", cam.get_gain))

    def trigger(self) -> int:
        """Drop waiting frames, then fire a software trigger (if in that mode): the dropped
        count."""
        dropped = 0
        while (buf := self.stream.try_pop_buffer()) is not None:
            self.stream.push_buffer(buf)
            dropped += 1
        self._check_control()
        if self.settings.trigger == "software":
            self.triggered_at = time.time()  # the exposure cannot start before this
            self._call("software trigger", self.cam.software_trigger)
        return dropped

    def grab(self, deadline: float) -> Frame | str:
        """The next good frame before ``deadline`` (monotonic), else why not (a string)."""
        bad: list[str] = []
        while (left := deadline - time.monotonic()) > 0:
            # in slices of a heartbeat period: a camera that dropped the station is said
            # within a second, not at the end of a long timeout
            buf = self.stream.timeout_pop_buffer(max(1, int(min(left, 1.0) * 1e6)))
            if buf is None:
                self._check_control()
                continue
            try:
                status = buf.get_status()
                if status != self.arv.BufferStatus.SUCCESS:
                    bad.append(status.value_nick)
                    continue
                return self._frame(buf)
            finally:
                self.stream.push_buffer(buf)
        self._call("check the camera", self.cam.get_payload)  # ConnectionLostError if gone
        self._check_control()
        return f"{counted(len(bad), 'broken buffer')}: {', '.join(sorted(set(bad)))}" if bad else ""

    def _frame(self, buf: Any) -> Frame:
        w, h = buf.get_image_width(), buf.get_image_height()
        name = pixels.format_name(buf.get_image_pixel_format())
        fmt = pixels.FORMATS.get(name)
        pad = buf.get_image_padding()
        stride = w * (fmt.bytes_per_pixel if fmt else 1) + int(pad[0])
        try:
            image = pixels.to_bgr(buf.get_image_data(), w, h, name, stride)
        except ValueError as exc:
            raise FrameError(str(exc), device=self.device) from None
        return Frame(image=image, timestamp=self._exposure_time(buf),
                     frame_id=int(buf.get_frame_id()), camera=self.device, pixel_format=name)

    def _exposure_time(self, buf: Any) -> float:
        """The buffer's exposure instant on host time (see the module's docstring).  A frame
        the verified clock places wholly before the pending software trigger is one of an
        earlier trigger that was still in transit: it keeps its own (older) time, and the
        trigger waits for its own frame."""
        system_ns = int(buf.get_system_timestamp())
        system_s = system_ns / 1e9 if system_ns else time.time()
        device_s = int(buf.get_timestamp()) / 1e9
        trigger_s = self.triggered_at
        span = self.clock.interval(device_s)
        if trigger_s is not None and span is not None and span[1] < trigger_s:
            trigger_s = None  # not this frame's trigger
        else:
            self.triggered_at = None
        self.clock.add(device_s, system_s, trigger_s)
        mapped = self.clock.host_time(device_s)
        if mapped is not None:
            return min(mapped, system_s)  # never after the host saw it (drift, rounding)
        if trigger_s is not None:
            return trigger_s
        if not self._warned_clock and not self.clock.checking:
            self._warned_clock = True
            log.warning("%s: exposure times unknown (%s): frames are stamped when they reach "
                        "the host", self.device, self.clock.reason)
        return system_s

    def close(self, lost: bool = False) -> None:
        """Stop (unless the camera is gone: that costs GVCP timeouts), then drop the stream,
        then the camera -- Aravis's order.  Never raises."""
        if self.cam is not None and self.stream is not None and not lost:
            try:
                self.cam.stop_acquisition()
            except self.glib.Error as exc:
                log.debug("%s: stop acquisition: %s", self.device, exc.message)
        self.stream = None
        self.cam = None


def _released(exc: DeviceError) -> DeviceError:
    """``exc`` without its traceback and context, to raise from the caller's frame.  Those
    hold the frames of the failed calls, whose locals hold the Aravis camera: an exception
    kept by the caller (a log record, ``pytest.raises``) would keep a dropped camera alive,
    heartbeating, in control of the device, and the reconnect would fail against it."""
    exc.__traceback__ = None
    exc.__context__ = exc.__cause__ = None
    return exc


class AravisCamera(CameraDevice):
    """A GenICam camera through Aravis; a lost link stays down until ``reconnect()``."""

    def __init__(self, url: str, *, timeout: float | None = None,
                 buffers: int | None = None) -> None:
        settings, timing = parse_aravis_url(url)
        super().__init__(url, timeout=timing["timeout"] or timeout)
        if buffers is not None and "buffers=" not in url:
            settings = replace(settings, buffers=int(buffers))
        self.settings = settings
        self._io = threading.Lock()  # one trigger/grab/setting at a time; guards the links
        self._link: _Link | None = None
        self._failed: _Link | None = None   # lost, released at the next reconnect or close
        self._down = "not connected"

    @classmethod
    def _endpoint(cls, url: str) -> Endpoint:
        """The camera by its device id, read as opening it reads it (case kept)."""
        settings, _ = parse_aravis_url(url)
        return AravisEndpoint(settings.name)

    @property
    def buffer_count(self) -> int:
        return self.settings.buffers

    @property
    def payload_bytes(self) -> int:
        """The size of each pool buffer: the camera's payload (0 while disconnected)."""
        link = self._link
        return link.payload if link is not None else 0

    def _connect(self, refresh: bool) -> _Link:
        link = _Link(self.settings, self.url)
        try:
            link.connect(refresh)
        except DeviceError as exc:
            raise _released(exc) from None
        return link

    def identity(self) -> str:
        link = self._link
        if link is None:
            state = f"link down ({self._down})" if self.is_open else "closed"
            return f"Aravis camera {self.settings.name}: {state}"
        with self._io:
            try:
                return link.identity()
            except Exception as exc:  # a description must not fail
                return f"Aravis camera {self.settings.name} ({exc})"

    def serial_number(self) -> str | None:
        """The serial number the camera reports (GenICam DeviceSerialNumber); None while its
        link is down or where it reports none."""
        link = self._link
        if link is None:
            return None
        with self._io:
            try:
                return link.serial_number()
            except Exception:   # a read that failed: not said
                return None

    def _open(self) -> None:
        link = self._connect(False)
        with self._io:
            self._link = link
        _open_cameras.add(self)

    def _release(self) -> None:
        """Close the current and the failed link (the failed one may sit in GVCP timeouts)."""
        with self._io:
            link, self._link = self._link, None
            failed, self._failed = self._failed, None
        if failed is not None:
            failed.close(lost=True)
        if link is not None:
            link.close()

    def _close(self) -> None:
        _open_cameras.discard(self)
        self._release()

    def _reconnect(self) -> None:
        """Release the links, refresh Aravis's device list and connect (one attempt)."""
        self._release()
        try:
            link = self._connect(True)
        except DeviceError as exc:
            self._down = str(exc).removeprefix(f"{self.url}: ")
            raise
        with self._io:
            self._link = link
        log.info("%s: reconnected", self.url)

    def _use(self, deadline: float, action: Callable[[_Link], T]) -> T:
        """Run ``action`` on the link; a lost link is set aside (released by the next
        ``reconnect()``) and the camera stays down until then."""
        with self._io:
            link = self._link
            if link is None:
                raise ConnectionLostError(f"link down ({self._down})", device=self.url)
            try:
                return action(link)
            except DeviceError as exc:
                if isinstance(exc, ConnectionLostError):
                    self._link, self._failed = None, link
                    self._down = str(exc).removeprefix(f"{self.url}: ")
                raise _released(exc) from None

    def _trigger(self) -> None:
        dropped = self._use(time.monotonic() + self.timeout, _Link.trigger)
        if dropped:
            log.debug("%s: dropped %s at trigger", self.url, counted(dropped, "stale frame"))

    def _grab(self, timeout: float) -> Frame:
        deadline = time.monotonic() + timeout
        got = self._use(deadline, lambda link: link.grab(deadline))
        if isinstance(got, Frame):
            return got
        raise DeviceTimeoutError(no_frame_words(timeout, self.settings.trigger, got),
                                 device=self.url)

    def _set_exposure_us(self, exposure_us: float) -> float:
        applied = self._use(time.monotonic() + self.timeout,
                            lambda link: link.set_exposure(exposure_us))
        self._remember(replace(self.settings, exposure_us=applied))
        return applied

    def _set_gain_db(self, gain_db: float) -> float:
        applied = self._use(time.monotonic() + self.timeout, lambda link: link.set_gain(gain_db))
        self._remember(replace(self.settings, gain_db=applied))
        return applied

    def _remember(self, settings: Settings) -> None:
        """Keep a runtime setting so that a reconnect applies it again."""
        self.settings = settings
        link = self._link
        if link is not None:
            link.settings = settings
