"""The station file's devices: its cameras and stereo pairs, the lift and the controller.

Why apart from the station's assembly (:mod:`stationd.config`): these sections name devices
by URL and files beside the station file (calibrations, vehicle registrations), and check
them against each other (a pair's two cameras of its own, one device for the lift and one
for the controller, a simulated camera showing its own pair).  What a device can do is its
driver's to say (``drivers.devices``, ``drivers.wrench.takes_register_map``), never read
from its URL's scheme here.

A URL is checked (form, scheme, options; no device is opened) when ``check`` is given: by
``stationd config check`` and for a station the daemon runs (see :func:`device_url`).
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.devices import Kind, world_view
from drivers.devices import check_url as check_device_url
from drivers.errors import UrlError
from drivers.lift.base import RegisterMap
from drivers.wrench import takes_register_map
from drivers.wrench.modbus_map import WrenchRegisterMap
from stationd.configread import (
    SectionReader,
    existing_file,
    named_items,
    present,
    relative_path,
)
from stationd.devicekey import device_key
from stationd.devicemaps import lift_map, wrench_map
from stationd.filekind import expect
from stationd.geometry.camera import StereoPair
from stationd.geometry.frames import REGISTRATION_KEYS, Transform
from stationd.yamlio import YamlNode

BASELINE_MM = (20.0, 2000.0)    # plausible stereo baselines, millimetres
METRES_LIKE_MM = 10.0           # a pair-to-vehicle translation shorter than this is in metres
#: plausible limits of a pair's exposure skew, ms: under 0.1 it is seconds written as ms (or 0,
#: which no two exposures meet); at 100 ms a wrench moved by hand has moved centimetres
MAX_SKEW_MS = (0.1, 100.0)
PAIR_KEYS = ("calibration", "to_vehicle", "left", "right", "max_skew_ms")


@dataclass(frozen=True)
class WrenchConfig:
    """The tightening controller: its URL, and for a register-driven one (``modbus-tcp://``,
    ``modbus-rtu://``: its driver says, ``drivers.wrench.takes_register_map``) its register
    map (``drivers/wrench/modbus_map.py``; None: defaults)."""

    url: str = "sim://wrench"
    registers: WrenchRegisterMap | None = None

    @classmethod
    def from_node(cls, node: YamlNode, *, check_url: bool = False) -> WrenchConfig:
        """``check_url``: check the URL's form and scheme now (see :func:`device_url`)."""
        m = node.mapping(("url", "registers", "poll_ms"))
        url = device_url(m["url"], "wrench", check=check_url) if "url" in m else cls.url
        regs = wrench_map(m["registers"]) if "registers" in m else None
        if regs is not None and not takes_register_map(url):
            raise m["registers"].error(f"a register map is for a Modbus controller, not "
                                       f"{url}")
        return cls(url, regs)

    def open_options(self) -> dict[str, Any]:
        """Keywords for ``open_wrench``: the register map when one is configured."""
        return {} if self.registers is None else {"register_map": self.registers}


@dataclass(frozen=True)
class LiftConfig:
    """The lift PLC: its URL and register map (``drivers.lift.RegisterMap``)."""

    url: str = "sim://lift"
    registers: RegisterMap = field(default_factory=RegisterMap)
    poll_ms: float = 100.0  # a PLC serves an HMI and a line controller too: read this often

    @classmethod
    def from_node(cls, node: YamlNode, *, check_url: bool = False) -> LiftConfig:
        """``check_url``: check the URL's form and scheme now (see :func:`device_url`)."""
        m = node.mapping(("url", "registers", "poll_ms"))
        url = device_url(m["url"], "lift", check=check_url) if "url" in m else cls.url
        regs = lift_map(m["registers"]) if "registers" in m else RegisterMap()
        poll = m["poll_ms"].number(lo=10.0, hi=5000.0) if "poll_ms" in m else cls.poll_ms
        return cls(url=url, registers=regs, poll_ms=poll)


@dataclass(frozen=True, eq=False)
class PairConfig:
    """One stereo pair: its cameras, calibration and, once registered, its map to the vehicle
    frame.  ``left``/``right`` name entries of ``cameras`` (None: not wired to devices yet).

    ``to_vehicle_path`` is where ``stationd calibrate vehicle`` writes the transform (a file of
    its own, so the hand-written station config is never rewritten); ``to_vehicle`` is None
    until that file exists.
    """

    name: str
    calibration_path: Path
    calibration: StereoPair
    to_vehicle_path: Path
    to_vehicle: Transform | None
    left: str | None = None
    right: str | None = None
    max_skew_s: float = 0.005


def device_url(node: YamlNode, kind: str, *, check: bool = False, sources: bool = False
               ) -> str:
    """A device URL of ``kind`` (camera, lift, wrench).

    With ``check``, the device is built, not opened: its form and scheme are checked against
    the driver's registry, its options with their ranges (a camera's by its backend, which
    parses its URL before loading any SDK; the lift's and the controller's likewise), so a
    URL that can never work is a configuration error, not a station in fault for good.
    ``stationd config check`` and the daemon's loader (``station=True``: the first start and
    every reload) check; other readers of a station file (tools, benchmarks) do not need to.
    ``sources`` (the checker only): what a device reads must exist now (a camera replay's
    files); the daemon starts in fault on it instead, retried as a device that is down.
    """
    url = node.text()
    if check:
        try:
            check_device_url(Kind(kind), url, sources=sources)
        except UrlError as exc:   # the line shows the URL: the message need not repeat it
            text = str(exc)
            if exc.device and text.startswith(f"{exc.device}: "):
                text = text[len(exc.device) + 2:]
            raise node.error(text) from None
    return url


def _max_skew_ms(node: YamlNode) -> float:
    """A pair's exposure skew limit, in milliseconds: below :data:`MAX_SKEW_MS` it is seconds
    (0.005 for 5 ms) or 0 (no two exposures are ever that close: the pair never localizes);
    above, the wrench moves more than a bolt's tolerance between its two images."""
    skew = node.number()
    if not MAX_SKEW_MS[0] <= skew <= MAX_SKEW_MS[1]:
        hint = f"; in seconds? write {skew * 1e3:g} for {skew * 1e3:g} ms" \
            if 0 < skew < MAX_SKEW_MS[0] <= skew * 1e3 else \
            "; 0 accepts no pair of frames: the pair would never localize" if skew == 0 else ""
        raise node.error(f"{skew:g} ms is not plausible: the two exposures of a pair may be "
                         f"{MAX_SKEW_MS[0]:g}-{MAX_SKEW_MS[1]:g} ms apart (milliseconds, 5 by "
                         f"default{hint})")
    return skew


def _camera_url(node: YamlNode, *, check: bool, sources: bool = False) -> str:
    return device_url(node.mapping(("url",), required=("url",))["url"], "camera", check=check,
                      sources=sources)


def one_device_each(lift_url: str, wrench_url: str, wrench: YamlNode) -> None:
    """The lift and the controller must be two devices (keys of ``stationd.devicekey``: two
    URLs that reach one endpoint are one device, as for the device locks).  One Modbus
    endpoint and unit as both would take the controller's registers for the lift's, and the
    lift's for a bolt's parameters; one serial line opened twice garbles both."""
    key = device_key(lift_url, Kind.LIFT)
    if key is None or key != device_key(wrench_url, Kind.WRENCH):
        return
    where = wrench.mapping(("url", "registers", "poll_ms"))["url"]
    if key.startswith("serial "):
        raise where.error(f"the same serial line as lift.url ({key.removeprefix('serial ')}): "
                          "the lift and the controller would each open it and garble each "
                          "other's frames (give the controller its own port)")
    raise where.error(f"the same device as lift.url ({key}): the lift PLC and the tightening "
                      "controller are two devices (give the controller its own address, "
                      "port or unit)")


def _camera_ref(node: YamlNode, cameras: Collection[str] | None) -> str:
    """A camera name of a pair; ``cameras`` None: the section is unreadable, not checked."""
    cam = node.text()
    if cameras is not None and cam not in cameras:
        raise node.error(f"no camera {cam!r} under cameras "
                         f"(cameras: {', '.join(cameras) or 'none'})")
    return cam


def _load_transform(path: Path) -> Transform:
    """A pair -> vehicle transform; a translation that looks like metres is refused (the pairs
    are a metre or more from the vehicle origin: |t| < 10 can only be metres for millimetres)."""
    node = YamlNode.load(path)
    expect(node, "registration", REGISTRATION_KEYS)
    tf = Transform.from_node(node)
    norm = float(np.linalg.norm(tf.t))
    if norm < METRES_LIKE_MM:
        raise node.error(f"translation t {[round(float(v), 4) for v in tf.t]} (|t| = "
                         f"{norm:.3g}) looks like metres: the vehicle frame is in millimetres")
    return tf


def _baseline(calibration: StereoPair, node: YamlNode) -> StereoPair:
    """A pair whose baseline is not 20-2000 mm has a calibration in other units (metres); one
    whose right camera is to the left of its left one was calibrated from swapped images."""
    b = float(np.linalg.norm(calibration.T))
    if not BASELINE_MM[0] <= b <= BASELINE_MM[1]:
        raise node.error(f"stereo baseline {b:.4g} mm is not plausible "
                         f"({BASELINE_MM[0]:g}-{BASELINE_MM[1]:g} mm): T must be in millimetres")
    swapped = calibration.swapped()
    if swapped is not None:
        raise node.error(f"{swapped} (calibrate the pair again with --left and --right the "
                         "other way round)")
    return calibration



@dataclass
class DeviceSections:
    """The cameras and pairs of one station file, read through ``reader``: when it
    collects, each camera and pair on its own, so independent mistakes are all told.

    ``base``: the folder relative paths are read from, ``note`` what a missing one's message
    adds (``configread.link_note``); ``check``: URLs are checked (``sources``: what a camera
    reads must exist now, the checker only); ``unregistered``: a pair whose vehicle
    registration is not read (``calibrate vehicle`` writing it anew: a broken one must not
    stop it).
    """

    reader: SectionReader
    base: Path
    check: bool
    sources: bool = False
    note: str = ""
    unregistered: str | None = None
    #: name -> (URL, its node) of each camera read, for the pairs' checks
    camera_urls: dict[str, tuple[str, YamlNode]] = field(default_factory=dict)

    def cameras(self, node: YamlNode) -> tuple[dict[str, str], list[str] | None]:
        """Name -> URL, and every name defined, a camera with errors included (a pair naming
        it is not also told it is undefined); None when the section itself is unreadable."""
        items = self.reader.guard(None, named_items, node)
        if items is None:
            return {}, None
        urls: dict[str, str] = {}
        device: dict[str, str] = {}   # the URL without its options -> the camera naming it
        for name, item in items:
            url = self.reader.guard(None, _camera_url, item, check=self.check,
                                    sources=self.sources)
            if url is None:
                continue
            same = device.setdefault(url.split("?", 1)[0], name)
            if same != name:   # one camera as two: a pair would triangulate one image twice
                self.reader.refuse(item.error(
                    f"the same camera as {same!r} ({url.split('?', 1)[0]}): every camera "
                    "is one device"))
                continue
            urls[name] = url
            self.camera_urls[name] = (url, item.mapping(("url",))["url"])
        return urls, [name for name, _ in items]

    def pairs(self, node: YamlNode, cameras: Collection[str] | None) -> dict[str, PairConfig]:
        """Name -> pair, the pairs that read; ``cameras``: the names :meth:`cameras` gave
        (None: that section is unreadable, the pairs' cameras are not checked)."""
        out: dict[str, PairConfig] = {}
        used: dict[str, str] = {}   # camera -> "the left camera of pair P"
        for name, item in self.reader.guard([], named_items, node):
            pair = self.reader.guard(None, self._pair, name, item, cameras)
            if pair is None:
                continue
            taken = False
            for side, cam in (("left", pair.left), ("right", pair.right)):
                if cam is None:
                    continue
                if cam in used:   # both images of a pair, or two pairs, from one camera
                    self.reader.refuse(item.mapping(PAIR_KEYS)[side].error(
                        f"camera {cam!r} is already {used[cam]}: a pair needs two cameras "
                        "of its own (one image triangulated with itself gives a confident, "
                        "wrong point)"))
                    taken = True
                used.setdefault(cam, f"the {side} camera of pair {name!r}")
            if not taken:
                out[name] = pair
                if self.check:
                    self._sim_cameras(pair, node)
        return out

    def _sim_cameras(self, pair: PairConfig, pairs: YamlNode) -> None:
        """A simulated camera shows the view of the pair it names, which the simulated world
        renders for each pair of this file through its calibration: ``sim://PAIR/SIDE`` must
        be the pair and side it serves (another pair's view, or a pair the world does not
        have, leaves the pair in fault for good)."""
        names = list(pairs.mapping(tuple(str(k) for k in pairs.value()))) \
            if isinstance(pairs.value(), dict) else []
        for side, cam in (("left", pair.left), ("right", pair.right)):
            if cam is None or cam not in self.camera_urls:
                continue
            url, url_node = self.camera_urls[cam]
            view = world_view(url)   # the URL was checked with the camera
            if view is None or view == (pair.name, side):
                continue
            sim_pair, sim_side = view
            what = f"the simulated world's {sim_side} view of pair {sim_pair!r}" \
                if sim_pair in names else \
                f"pair {sim_pair!r}, which the simulated world does not have (it renders " \
                f"this file's pairs: {', '.join(names)})"
            self.reader.refuse(url_node.error(
                f"camera {cam!r} is the {side} camera of pair {pair.name!r} but shows "
                f"{what}: write sim://{pair.name}/{side}"))

    def _pair(self, name: str, node: YamlNode, cameras: Collection[str] | None,
              ) -> PairConfig | None:
        """One pair; None when collecting and any part of it has errors (all reported)."""
        m = node.mapping(PAIR_KEYS, required=("calibration",))
        errors_before = len(self.reader.errors)
        sides = {side: self.reader.guard(None, _camera_ref, m[side], cameras) if side in m else None
                 for side in ("left", "right")}
        skew_ms = self.reader.guard(None, _max_skew_ms, m["max_skew_ms"]) \
            if "max_skew_ms" in m else 5.0
        cal_path = self.reader.guard(None, existing_file, m["calibration"], self.base,
                                     "calibration file", self.note)
        tv_path = self.reader.guard(None, relative_path, m["to_vehicle"], self.base) \
            if "to_vehicle" in m \
            else self.base / f"{name}.vehicle.yaml"
        tv = None
        if tv_path is not None:
            there = self.reader.guard(None, present, m.get("to_vehicle", node), tv_path,
                                      "vehicle registration file")
            if there is None:
                tv_path = None   # cannot be looked at: told
            elif there and name != self.unregistered:
                tv = self.reader.guard(None, _load_transform, tv_path)
        calibration = self.reader.guard(None, StereoPair.load, cal_path) \
            if cal_path is not None else None
        if calibration is not None:
            calibration = self.reader.guard(None, _baseline, calibration, m["calibration"])
        if len(self.reader.errors) > errors_before or skew_ms is None or cal_path is None \
                or calibration is None or tv_path is None:
            return None
        if tv is None:  # a pair with errors is told those, not this
            self.reader.warnings.append(m.get("to_vehicle", node).error(
                f"{tv_path} does not exist: the pair is not registered into the vehicle "
                f"frame yet (stationd calibrate vehicle writes it){self.note}"))
        return PairConfig(name, cal_path, calibration, tv_path, tv, sides["left"],
                          sides["right"], skew_ms / 1e3)
