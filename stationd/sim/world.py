"""The simulated world around a station: a vehicle on the lift, an operator with the wrench.

It drives the daemon's own simulated twins (the PLC behind ``sim://lift``, the controller
behind ``sim://wrench``) and renders what each ``sim://PAIR/SIDE`` camera sees through the
pair's true geometry (the simulated station's calibration is exact).  The operator takes the
wrench to bolts, sometimes hovers between two or leaves before tightening, and pulls the
trigger once the controller has the tool enabled.

Time: the world keeps the history of the wrench's poses (when each was set, host
``time.time()``), and a camera triggered at ``t`` is rendered with the pose of ``t``, however
late it is grabbed and however long the render takes.  A slow machine therefore delivers the
same frames later (older, so the station may refuse them as stale), never frames that mix a
past timestamp with a present wrench: the fault that let a loaded demo send parameters for a
bolt the wrench had left.

A pose is ray-cast once per camera, the first time a frame needs it, and composed into later
frames (as :meth:`World.prerender` does ahead of time): the window's noise is then the same
in every frame of one pose, which the detector cannot tell from fresh noise.
"""

from __future__ import annotations

import bisect
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from drivers.camera.sim import register_world, unregister_world
from stationd.config import StationConfig
from stationd.sim.frames import FrameSource, Patch
from stationd.sim.render import MarkerPose, Scene
from stationd.vision.marker import MarkerSpec


@dataclass(frozen=True)
class WrenchPose:
    """Where the wrench is: the marker's centre and rotation in the vehicle frame."""

    centre_v: np.ndarray
    rotation_v: np.ndarray
    socket_v: np.ndarray  # the socket tip: the truth the localization is compared with


def wrench_at(point_v: np.ndarray, rng: np.random.Generator, length_mm: float,
              max_tilt_deg: float = 5.0) -> WrenchPose:
    """The wrench with its socket at ``point_v``, tilted up to ``max_tilt_deg``."""
    tilt = math.radians(rng.uniform(0, max_tilt_deg))
    az = rng.uniform(0, 2 * math.pi)
    axis = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az),
                     math.cos(tilt)])
    n = -axis  # the marker faces down, at the cameras
    a = rng.normal(size=3)
    x = a - (a @ n) * n
    x /= np.linalg.norm(x)
    rot = np.column_stack([x, np.cross(n, x), n])
    return WrenchPose(point_v - length_mm * axis, rot, np.asarray(point_v, dtype=np.float64))


def reference_pose(position_mm: tuple[float, float, float]) -> WrenchPose:
    """A reference marker fixed at ``position_mm`` (vehicle frame), facing down at the
    cameras (as the wrench's marker does)."""
    n = np.array([0.0, 0.0, -1.0])
    x = np.array([1.0, 0.0, 0.0])
    c = np.asarray(position_mm, dtype=np.float64)
    return WrenchPose(c, np.column_stack([x, np.cross(n, x), n]), c)


HISTORY_S = 30.0  # how far back poses are kept; an older trigger is stale for any station
LIVE_PATCHES = 64  # live-rendered (pose, camera) patches kept: 8 cameras x 8 recent poses


class World:
    """Renders the cameras and holds the wrench poses the operator sets, with their times."""

    def __init__(self, cfg: StationConfig, *, seed: int = 0, spec: MarkerSpec | None = None,
                 scene: Scene | None = None) -> None:
        self.cfg = cfg
        self.spec = spec or cfg.marker
        self.pose: WrenchPose | None = None
        self._lock = threading.Lock()
        # when each pose was set (ascending) and the pose: before the first, no wrench
        self._times: list[float] = [-math.inf]
        self._poses: list[WrenchPose | None] = [None]
        base = scene or Scene(texture=0.15, vignetting=0.3, blur_sigma=0.8, noise_sigma=2.0)
        self._base, self._seed = base, seed
        # the reference markers fixed in the cell (the station file's ``references:``), and
        # each pair's true pose against its calibration (:meth:`move_pair`): pair frame as
        # calibrated -> where the cameras really are, x_true = R x + t
        refs = getattr(cfg, "references", None)
        self.references: list[WrenchPose] = [reference_pose(r.position_mm)
                                             for r in (refs.markers if refs else ())]
        self._moved: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._sources: dict[tuple[str, str], FrameSource] = {}
        # each camera's source as the pair stands in place: a pair put back gets its frames
        # (its rendered background) again at once
        self._home: dict[tuple[str, str], FrameSource] = {}
        # (id(pose), pair, side) -> (pose, patches rendered ahead)
        self._ahead: dict[tuple[int, str, str], tuple[WrenchPose, list[Patch]]] = {}
        # the same for poses rendered live, oldest first (a wrench held still is rendered
        # once per camera, then composed: ray-casting a 20 MP window costs about a second)
        self._live: dict[tuple[int, str, str], tuple[WrenchPose | None, Patch]] = {}
        for name in cfg.pairs:
            self._make_sources(name)
            register_world(name, self._source_for(name), replace=True)

    def _make_sources(self, name: str) -> None:
        """The pair's two cameras, their backgrounds showing the references where the pair
        (as it really stands) sees them."""
        k = list(self.cfg.pairs).index(name)
        cal = self.cfg.pairs[name].calibration
        home = name not in self._moved
        for j, side in enumerate(("left", "right")):
            if home and (name, side) in self._home:
                self._sources[(name, side)] = self._home[(name, side)]
                continue
            fixed = [(mp, self.spec) for mp in (self._camera_pose(name, side, r)
                                                for r in self.references) if mp is not None]
            src = FrameSource(getattr(cal, side), self._base, self._seed + 2 * k + j, fixed)
            self._sources[(name, side)] = src
            if home:
                self._home[(name, side)] = src

    def move_pair(self, name: str, rotation_deg: tuple[float, float, float] = (0, 0, 0),
                  shift_mm: tuple[float, float, float] = (0, 0, 0)) -> None:
        """Knock pair ``name`` out of place: its cameras turn by ``rotation_deg`` (about the
        calibrated left camera's x, y, z axes, in that order) and shift by ``shift_mm``, its
        calibration and registration unchanged (a test's camera bumped between vehicles).
        Its frames from now on show the world from there; (0, 0, 0) puts it back."""
        R = np.eye(3)
        for axis, deg in enumerate(rotation_deg):
            a = math.radians(deg)
            c, s_ = math.cos(a), math.sin(a)
            i, j = [(1, 2), (2, 0), (0, 1)][axis]
            m = np.eye(3)
            m[i, i], m[i, j], m[j, i], m[j, j] = c, -s_, s_, c
            R = m @ R
        shift = np.asarray(shift_mm, dtype=np.float64)
        with self._lock:
            if np.allclose(R, np.eye(3), rtol=0.0, atol=1e-15) and not shift.any():
                self._moved.pop(name, None)   # back in place: its own frames again
            else:
                self._moved[name] = (R, shift)
            for key in [k for k in self._ahead if k[1] == name]:
                del self._ahead[key]
            for key in [k for k in self._live if k[1] == name]:
                del self._live[key]
        self._make_sources(name)

    def close(self) -> None:
        for name in self.cfg.pairs:
            unregister_world(name)

    def prerender(self, poses: Sequence[WrenchPose], variants: int = 2) -> None:
        """Render ahead what every camera sees of each pose (``variants`` noise draws each,
        taken in turn): a benchmark then composes frames at frame rate instead of ray-casting
        on the cores whose latency it measures.  Other poses are still rendered live."""
        for src in self._sources.values():
            _ = src.background
        for pose in poses:
            for (pair, side), src in self._sources.items():
                mp = self._camera_pose(pair, side, pose)
                self._ahead[(id(pose), pair, side)] = (pose, [
                    src.patch(mp, self.spec, seed=src.seed + 7919 * (v + 1))
                    for v in range(variants)])

    def buffer_bytes(self) -> int:
        """The world's own image memory (backgrounds, frames rendered ahead): a benchmark
        subtracts it from the process's to tell the daemon's share."""
        seen: dict[int, int] = {}
        for src in self._sources.values():   # its background and its frames' buffers
            seen[id(src)] = src.resident_bytes()
        live = [[patch] for _, patch in self._live.values()]
        for patches in [p for _, p in self._ahead.values()] + live:
            for pt in patches:
                arr = pt if isinstance(pt, np.ndarray) else pt[1] if pt is not None else None
                if arr is not None:
                    seen[id(arr)] = arr.nbytes
        return sum(seen.values())

    def background(self, pair: str, side: str) -> np.ndarray:
        """What the camera shows with no wrench in view (the very array its frames are then)."""
        return self._sources[(pair, side)].background

    def cut_cameras(self, pair: str) -> None:
        """The pair's cameras stop delivering (a cable pulled): every grab fails."""
        unregister_world(pair)

    def restore_cameras(self, pair: str) -> None:
        """The pair's cameras deliver again."""
        register_world(pair, self._source_for(pair), replace=True)

    def set_wrench(self, pose: WrenchPose | None, at: float | None = None) -> None:
        """The wrench is at ``pose`` (None: on no bolt, out of view) from host time ``at``
        (default now) on.  An explicit time before the last one set is refused (ValueError):
        the past that cameras may still be rendering does not change.  ``now`` is never
        refused: a host clock stepped back counts as the last time set."""
        with self._lock:
            t = max(time.time(), self._times[-1]) if at is None else float(at)
            if not t >= self._times[-1]:
                raise ValueError(f"the wrench's poses are set in time order: {t} is before "
                                 f"{self._times[-1]}")
            self.pose = pose
            self._times.append(t)
            self._poses.append(pose)
            # forget poses older than HISTORY_S, keeping the one in force at the horizon
            keep = bisect.bisect_right(self._times, t - HISTORY_S) - 1
            if keep > 0:
                del self._times[:keep], self._poses[:keep]

    def pose_at(self, t: float) -> WrenchPose | None:
        """The wrench's pose at host time ``t``: the last one set at or before ``t`` (the
        oldest kept for a ``t`` older than the history)."""
        with self._lock:
            i = bisect.bisect_right(self._times, t) - 1
            return self._poses[max(i, 0)]

    def seen_by(self, pose: WrenchPose, margin_px: float = 100.0) -> list[str]:
        """The pairs whose two cameras both see the marker's centre at ``pose``, at least
        ``margin_px`` inside their frames: where the station could localize it."""
        pairs = []
        for name, pc in self.cfg.pairs.items():
            ok = True
            for side in ("left", "right"):
                mp = self._camera_pose(name, side, pose)
                cam = getattr(pc.calibration, side)
                if mp is None or not bool(cam.contains(cam.project(mp.centre_mm[None, :]),
                                                       margin_px)[0]):
                    ok = False
                    break
            if ok:
                pairs.append(name)
        return pairs

    def _camera_pose(self, pair: str, side: str, pose: WrenchPose) -> MarkerPose | None:
        pc = self.cfg.pairs[pair]
        tv = pc.to_vehicle
        if tv is None:
            return None
        # the inverse of x_v = A x_p + t, for an affine A too (A.T inverts only a rotation);
        # the marker's axes are then made orthonormal again (the nearest rotation)
        c = np.linalg.solve(tv.A, pose.centre_v - tv.t)
        u, _, vt = np.linalg.svd(np.linalg.solve(tv.A, pose.rotation_v))
        rot = u @ vt
        if pair in self._moved:   # the pair is not where its calibration says: the truth
            Rm, tm = self._moved[pair]
            c, rot = Rm @ c + tm, Rm @ rot
        if side == "right":
            c, rot = pc.calibration.R @ c + pc.calibration.T, pc.calibration.R @ rot
        if c[2] <= 0 or float(rot[:, 2] @ c) >= 0:
            return None  # behind the camera or seen from the back
        return MarkerPose(c, rot)

    def _source_for(self, pair: str) -> Callable[[str, int, float], np.ndarray]:
        def source(side: str, seed: int, at: float) -> np.ndarray:
            pose = self.pose_at(at)
            src = self._sources[(pair, side)]
            ahead = self._ahead.get((id(pose), pair, side))
            if ahead is not None and ahead[0] is pose:
                return src.compose(ahead[1][seed % len(ahead[1])])
            key = (id(pose), pair, side)
            with self._lock:
                live = self._live.get(key)
            if live is not None and live[0] is pose:
                return src.compose(live[1])
            mp = None if pose is None else self._camera_pose(pair, side, pose)
            # rendered once per pose and camera (then composed): its noise seeded by the
            # camera, not by the frame that first saw the pose, so the same placement is the
            # same window in every process (read back from the shared render folder)
            patch = src.patch(mp, self.spec, seed=src.seed + 1000)
            with self._lock:
                self._live[key] = (pose, patch)
                while len(self._live) > LIVE_PATCHES:
                    del self._live[next(iter(self._live))]
            return src.compose(patch)
        return source
