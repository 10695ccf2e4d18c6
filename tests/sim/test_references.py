"""The simulated world shows the reference markers to every camera that sees them, and a pair
knocked out of place between two vehicles: the calibration check finds it moved, with the
right pair and about the right figure, while the other pair stays in place."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from drivers.camera import open_camera
from stationd.geometry.frames import Transform
from stationd.localize.check import Verdict, check_pair
from stationd.localize.references import References
from stationd.sim.render import Scene
from stationd.sim.world import World
from stationd.vision.marker import MarkerSpec
from stationd.yamlio import YamlNode
from tests.localize.refscene import PAIR, TV

# two pairs side by side, 250 mm apart along the vehicle's x
TV2 = Transform(TV.A, TV.t + np.array([250.0, 0.0, 0.0]))
PAIRS = {"pair1": (PAIR, TV), "pair2": (PAIR, TV2)}
# two references both pairs see, on the vehicle frame's plane z = -300 (1 m above the cameras)
POSITIONS = {"R1": (1000.0, -720.0, -300.0), "R2": (1180.0, -640.0, -300.0)}


def _refs() -> References:
    text = "markers:\n" + "".join(f"  {k}: [{x}, {y}, {z}]\n" for k, (x, y, z) in POSITIONS.items())
    return References.from_node(YamlNode.parse(text, "station.yaml"), pairs=PAIRS,
                                marker=MarkerSpec(), matching_tolerance_mm=8.0)


def _grab(pair: str) -> tuple[np.ndarray, np.ndarray]:
    out = []
    for side in ("left", "right"):
        with open_camera(f"sim://{pair}/{side}") as cam:
            out.append(cam.grab().image)
    return out[0], out[1]


def _check(refs: References, pair: str):
    cal, tv = PAIRS[pair]
    left, right = _grab(pair)
    return check_pair(pair, cal, tv, left, right, refs.of(pair), tolerance_mm=refs.tolerance_mm,
                      search_mm=refs.exclusion_mm)


def test_a_pair_moved_between_vehicles_is_found_moved_and_only_it():
    refs = _refs()
    assert refs.sees == {"pair1": ("R1", "R2"), "pair2": ("R1", "R2")}
    cfg = SimpleNamespace(
        pairs={n: SimpleNamespace(calibration=cal, to_vehicle=tv) for n, (cal, tv) in
               PAIRS.items()}, marker=MarkerSpec(), references=refs)
    world = World(cfg, seed=3, scene=Scene(texture=0.1, blur_sigma=0.8, noise_sigma=2.0))
    try:
        first = {p: _check(refs, p) for p in PAIRS}
        assert all(c.verdict is Verdict.OK for c in first.values()), first
        assert max(c.offset_mm for c in first.values()) < 0.3
        # between two vehicles pair2 is bumped: turned 0.25 degrees about its vertical axis
        world.move_pair("pair2", rotation_deg=(0.0, 0.25, 0.0))
        second = {p: _check(refs, p) for p in PAIRS}
    finally:
        world.close()
    assert second["pair1"].verdict is Verdict.OK
    moved = second["pair2"]
    assert moved.verdict is Verdict.MOVED and moved.reference in POSITIONS
    # 0.25 degrees at about a metre: a few millimetres, beyond the 2 mm tolerance
    assert moved.offset_mm == pytest.approx(np.radians(0.25) * 1000.0, rel=0.5)
    assert moved.offset_mm > refs.tolerance_mm


def test_a_pair_put_back_shows_its_own_frames_again_at_once():
    """(0, 0, 0) puts a knocked pair back: its cameras' sources as they were, the rendered
    background the very same (nothing rendered again), the other pair untouched."""
    refs = _refs()
    cfg = SimpleNamespace(
        pairs={n: SimpleNamespace(calibration=cal, to_vehicle=tv) for n, (cal, tv) in
               PAIRS.items()}, marker=MarkerSpec(), references=refs)
    world = World(cfg, seed=3, scene=Scene(noise_sigma=2.0))
    try:
        home = world.background("pair2", "left")
        other = world.background("pair1", "left")
        world.move_pair("pair2", rotation_deg=(0.0, 0.25, 0.0))
        knocked = world.background("pair2", "left")
        assert knocked is not home and not np.array_equal(knocked, home)
        world.move_pair("pair2")
        assert world.background("pair2", "left") is home
        assert world.background("pair1", "left") is other
    finally:
        world.close()
