"""A small rendered stereo pair with reference markers and the wrench, for the calibration
check's tests: 1600x1200 cameras (fast to render), registered into a vehicle frame by a rigid
motion that is not the identity (so the frames cannot be confused)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stationd.geometry.camera import Camera, StereoPair
from stationd.geometry.frames import Transform
from stationd.geometry.tool import ToolGeometry
from stationd.localize import PairSetup
from stationd.localize.references import Reference
from stationd.sim.render import MarkerPose, Scene, render
from stationd.sim.scenes import look_at_pair, to_right
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams

CAM = Camera(np.array([[2000.0, 0.0, 799.5], [0.0, 2000.0, 599.5], [0.0, 0.0, 1.0]]),
             np.array([-0.05, 0.08, 1e-4, -1e-4, 0.0]), (1600, 1200))
PAIR = look_at_pair(CAM, np.array([0.0, 0.0, 1000.0]), 300.0)
SPEC = MarkerSpec()
# pair frame -> vehicle frame: turned 25 degrees about z, the cameras 1.3 m under the car
_a = math.radians(25.0)
TV = Transform(np.array([[math.cos(_a), -math.sin(_a), 0.0], [math.sin(_a), math.cos(_a), 0.0],
                         [0.0, 0.0, 1.0]]), np.array([900.0, -750.0, -1300.0]))
#: where the references and the wrench's marker are, in the pair's frame (mm)
R1_PAIR = np.array([-170.0, 110.0, 1000.0])
R2_PAIR = np.array([190.0, 130.0, 1050.0])
WRENCH_PAIR = np.array([60.0, -120.0, 950.0])


def vehicle(p_pair: np.ndarray) -> tuple[float, float, float]:
    v = TV.apply(p_pair)
    return float(v[0]), float(v[1]), float(v[2])


REFS = (Reference("R1", vehicle(R1_PAIR)), Reference("R2", vehicle(R2_PAIR)))


def moved(p_pair: np.ndarray, deg: float, shift_mm: tuple[float, float, float] = (0, 0, 0)
          ) -> np.ndarray:
    """Where a point is in the frame of the pair after the rig turned ``deg`` about its
    vertical (y) axis and shifted: the cameras see it there, the calibration does not know."""
    a = math.radians(deg)
    R = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0],
                  [-math.sin(a), 0.0, math.cos(a)]])
    return np.asarray(R @ p_pair + np.asarray(shift_mm, dtype=np.float64))


@dataclass(frozen=True)
class Frames:
    left: np.ndarray
    right: np.ndarray


def frames(*points: np.ndarray, seed: int = 1, pair: StereoPair = PAIR) -> Frames:
    """Both cameras' images with a marker at each point (pair frame), facing the left
    camera with a small tilt."""
    poses = [MarkerPose.look(p, tilt_deg=8.0, tilt_azimuth_deg=30.0 * k)
             for k, p in enumerate(points)]
    scene = Scene(texture=0.1, blur_sigma=0.8, noise_sigma=2.0)
    left = render(pair.left, Scene(**{**scene.__dict__, "markers": [(p, SPEC) for p in poses]}),
                  seed=seed).image
    right = render(pair.right, Scene(**{**scene.__dict__, "markers": [
        (to_right(pair, p), SPEC) for p in poses]}), seed=seed + 1).image
    return Frames(left, right)


def setup(tool: ToolGeometry | None = None) -> PairSetup:
    return PairSetup(PAIR, TV, VisionParams(), SPEC, tool or ToolGeometry())
