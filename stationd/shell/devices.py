"""The station's devices, opened from its configuration: what each keeper opens, reconnects
and closes.

Every device comes from :func:`drivers.devices.open_device` (one way for every kind) and is
typed by its kind (:class:`Lift`, :class:`Wrench`, a :class:`Pair` of cameras), so the
daemon's joins are checked.  What "up" means is decided here: a PLC is up when it answers a
read (a peer answering garbage was "back" every few seconds), a pair when it delivers frames
its calibration describes.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from db.cameras import Replaced
from db.errors import DbError
from drivers.camera import CameraDevice
from drivers.camera.pair import StereoGrabber
from drivers.devices import Kind, open_device
from drivers.errors import DeviceError, ProtocolError
from drivers.keeper import one_line
from drivers.lift import Lift
from drivers.wrench import Wrench
from stationd.config import StationConfig
from stationd.localize import size_problem

log = logging.getLogger("stationd")

#: how long the read that proves a (re)connected PLC answers may take, s
LIFT_CHECK_S = 1.0


class Pair:
    """A stereo pair as the station keeps it: its two cameras and their grabber."""

    def __init__(self, cams: list[CameraDevice], grabber: StereoGrabber) -> None:
        self.cams = cams
        self.grabber = grabber

    def close(self) -> None:
        for cam in self.cams:
            quiet(cam.close)


#: ``pins(pair, calibration digest, {side: serial number})``: the sides whose camera is not
#: the one the calibration was first used with (``Records.pin_cameras``)
Pins = Callable[[str, str, Mapping[str, str | None]], list[Replaced]]


class Devices:
    """Opens the station's devices from ``cfg``; ``options`` per kind go to the backends
    (tests and the demo: a simulated controller's psets, a timeout).  With ``pins``, a pair
    is up only with the cameras its calibration was first used with."""

    def __init__(self, cfg: StationConfig,
                 options: dict[str, dict[str, Any]] | None = None,
                 pins: Pins | None = None) -> None:
        self.cfg = cfg
        self.options = options or {}
        self.pins = pins

    def pair_names(self) -> list[str]:
        """The pairs wired to two cameras."""
        return [n for n, pc in self.cfg.pairs.items() if pc.left and pc.right]

    def open_lift(self) -> Lift:
        """The PLC, opened and read once: up when it answers, not when its port accepts."""
        lift = open_device(Kind.LIFT, self.cfg.lift.url, register_map=self.cfg.lift.registers,
                           **self.options.get("lift", {}))
        try:
            lift.read_state(LIFT_CHECK_S)
        except BaseException:
            quiet(lift.close)
            raise
        return lift

    def open_wrench(self) -> Wrench:
        return open_device(Kind.WRENCH, self.cfg.wrench.url, **self.cfg.wrench.open_options(),
                           **self.options.get("wrench", {}))

    def open_pair(self, name: str) -> Pair:
        """Both cameras of ``name``, opened once each; the one opened is closed again if the
        other fails."""
        pc = self.cfg.pairs[name]
        if pc.left is None or pc.right is None:
            raise ValueError(f"pair {name} is not wired to two cameras")
        cams: list[CameraDevice] = []
        failed: list[tuple[str, Exception]] = []
        try:
            for side in (pc.left, pc.right):
                try:
                    cams.append(open_device(Kind.CAMERA, self.cfg.cameras[side]))
                except DeviceError as exc:   # the other one tried too: both said at once
                    failed.append((side, exc))
        except BaseException:
            for cam in cams:
                quiet(cam.close)
            raise
        if failed:
            for cam in cams:
                quiet(cam.close)
            raise _both(failed)
        journal_cameras(name, pc.left, pc.right, cams)
        try:
            self._check_pins(name, cams)
        except BaseException:
            for cam in cams:
                quiet(cam.close)
            raise
        # unnamed: the station says the pair's name before its reason
        return Pair(cams, StereoGrabber(cams[0], cams[1], pc.max_skew_s, name=""))

    def reconnect_pair(self, name: str, pair: Pair) -> None:
        """Both cameras back and one grab: back only with frames its calibration describes
        (a DeviceError or ProtocolError otherwise)."""
        pc = self.cfg.pairs[name]
        for cam in pair.cams:
            cam.reconnect()
        left, right = pair.grabber.grab(1.0)
        problem = size_problem(pc.calibration, left.image, right.image)
        if problem is not None:
            raise ProtocolError(problem)
        journal_cameras(name, pc.left or "left", pc.right or "right", pair.cams)
        self._check_pins(name, pair.cams)

    def _check_pins(self, name: str, cams: list[CameraDevice]) -> None:
        """The pair's cameras are the ones its calibration was first used with (pinned now
        if it never was): a ProtocolError naming the replaced camera otherwise, or when they
        cannot be checked (the database down: the pair waits for it, never trusted blind)."""
        if self.pins is None:
            return
        pc = self.cfg.pairs[name]
        serials = {"left": serial_of(cams[0]), "right": serial_of(cams[1])}
        try:
            replaced = self.pins(name, pc.calibration.digest(), serials)
        except DbError as exc:
            raise ProtocolError(f"its cameras not checked against its calibration "
                                f"({one_line(exc)}); retried") from None
        if replaced:
            names = {"left": pc.left or "left", "right": pc.right or "right"}
            raise ProtocolError("; ".join(replaced_words(names[r.side], r, pc.calibration_path)
                                          for r in replaced))


def serial_of(cam: CameraDevice) -> str | None:
    """The camera's serial number; None where it says none or the read fails."""
    try:
        return cam.serial_number()
    except Exception:   # a camera that cannot say is a camera not pinned, never a crash
        return None


def replaced_words(camera: str, r: Replaced, calibration: Path) -> str:
    """Why a pair is refused: which camera, its serial against the calibration's."""
    return (f"camera {camera} is S/N {r.seen}, but the pair's calibration ({calibration.name}) "
            f"was made with S/N {r.pinned} (first used {r.pinned_at:%Y-%m-%d %H:%M} UTC): a "
            f"camera replaced or swapped needs the pair calibrated again (stationd calibrate "
            f"stereo, then its new calibration file and a reload); nothing is localized in "
            f"this pair until then")


def journal_cameras(pair: str, left: str, right: str, cams: list[CameraDevice]) -> None:
    """Each camera of ``pair`` as it says it is (model, serial number, interface, pixel
    format and size), journaled as it opens or comes back: a technician's trial found the
    controller's serial in the journal and no camera's, so a camera replaced (or plugged
    back into another port) left no trace of which unit took the pictures."""
    for name, cam in zip((left, right), cams, strict=True):
        try:
            words = cam.identity()
        except Exception as exc:   # a description never fails an open
            words = f"not said ({one_line(exc)})"
        log.info("%s: camera %s: %s", pair, name, words)


def reconnect_lift(lift: Lift) -> None:
    """The PLC's link back, and one read answered: back only on a valid reply."""
    lift.reconnect()
    lift.read_state(LIFT_CHECK_S)


def close(device: Lift | Wrench | Pair) -> None:
    device.close()


def quiet(fn: Callable[[], None]) -> None:
    """Run a closing step; a failure is logged and the shutdown goes on."""
    try:
        fn()
    except Exception as exc:
        log.warning("closing: %s", one_line(exc))


def _both(failed: list[tuple[str, Exception]]) -> Exception:
    """The error of a pair whose cameras did not open: the one camera's, or, both failing,
    one of the first's kind saying both (a technician's trial: the second camera's fault was
    said only once the first came back)."""
    if len(failed) == 1:
        return failed[0][1]
    first = failed[0][1]
    words = "; ".join(f"camera {side}: {exc}" for side, exc in failed)
    try:
        return type(first)(words)
    except TypeError:   # a kind with other arguments: the first as it is
        return first
