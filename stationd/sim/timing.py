"""How late the simulated cameras deliver, quiet and under CPU load: a short benchmark.

    python -m stationd.sim.timing --frames 20 --load 2

Grabs stereo pairs of ``config/sim`` (20 MP, the wrench on a bolt) through the real
``StereoGrabber`` and prints, per run, the exposure-to-delivery delay of the frames
(``Frame.arrival - Frame.timestamp``: rendering, here) and the pairs' skew.  The delay is what
a station's ``max_age_s`` must absorb; with the cameras stamping the trigger instant it grows
with the load (frames get older) while the frames stay true to their timestamp.  It also
checks that truth: every pair is grabbed after the wrench moved away, and must still show it.
The first grab of each pose ray-casts its window (about a second per camera on a quiet
2-core machine); the world then composes that pose's frames, so ``--hold`` sets the mix.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from drivers.camera.pair import StereoGrabber
from drivers.devices import Kind, open_device
from stationd.boltfile import load_bolts
from stationd.config import load_station_config
from stationd.sim.load import cpu_load
from stationd.sim.world import World, wrench_at

SIM_CONFIG = Path(__file__).resolve().parents[2] / "config" / "sim" / "station.yaml"


def measure(frames: int, load: int, hold: int = 5, pair: str = "pair1",
            seed: int = 0) -> dict[str, float]:
    """Delay and skew figures (ms) of ``frames`` stereo grabs beside ``load`` busy
    processes, the wrench held on a bolt for ``hold`` grabs (an operator's hand: the first
    grab of a pose ray-casts it, the others compose), and how many pairs did not show the
    wrench they were triggered on."""
    cfg = load_station_config(SIM_CONFIG)
    pc = cfg.pairs[pair]
    if cfg.bolts_path is None or pc.to_vehicle is None or pc.left is None or pc.right is None:
        raise ValueError(f"{SIM_CONFIG}: the simulated station lost its bolts or vehicle frame")
    table = load_bolts(cfg.bolts_path)
    every = [np.array(b.position) for m in table.models for b in m.bolts]
    # the bolts under this pair: the ten nearest its left camera in XY
    centre = pc.to_vehicle.t[:2]
    positions = sorted(every, key=lambda p: float(np.hypot(*(p[:2] - centre))))[:10]
    rng = np.random.default_rng(seed)
    world = World(cfg, seed=seed)
    delays: list[float] = []
    skews: list[float] = []
    untrue = 0
    try:
        left = open_device(Kind.CAMERA, cfg.cameras[pc.left])
        right = open_device(Kind.CAMERA, cfg.cameras[pc.right])
        grabber = StereoGrabber(left, right, 0.005)
        try:
            # backgrounds are rendered once per camera (about 1 s each): not a frame's cost
            world.set_wrench(None)
            grabber.grab(30.0)
            with cpu_load(load):
                bare = (world.background(pair, "left"), world.background(pair, "right"))
                for k in range(frames):
                    if k % hold == 0:
                        pose = wrench_at(positions[int(rng.integers(len(positions)))], rng,
                                         cfg.tool.length_mm)
                    world.set_wrench(pose)
                    left.trigger()
                    right.trigger()
                    world.set_wrench(None)  # the wrench leaves before the frames are made
                    fl, fr = left.grab(30.0), right.grab(30.0)
                    untrue += fl.image is bare[0] or fr.image is bare[1]
                    delays += [fl.delay_s, fr.delay_s]
                    skews.append(abs(fl.timestamp - fr.timestamp))
        finally:
            left.close()
            right.close()
    finally:
        world.close()
    d = np.array(delays) * 1e3
    return {"frames": frames, "load": load, "delay_p50_ms": float(np.percentile(d, 50)),
            "delay_p95_ms": float(np.percentile(d, 95)), "delay_max_ms": float(d.max()),
            "skew_max_ms": float(max(skews) * 1e3), "untrue_pairs": untrue}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m stationd.sim.timing", description=__doc__)
    ap.add_argument("--frames", type=int, default=20, help="stereo pairs per run (1-1000)")
    ap.add_argument("--hold", type=int, default=5, help="grabs per wrench pose (1-100)")
    ap.add_argument("--load", type=int, action="append", default=None,
                    help="busy processes beside the run (repeat for several runs; default 0)")
    args = ap.parse_args(argv)
    if not (1 <= args.frames <= 1000 and 1 <= args.hold <= 100) \
            or any(not 0 <= n <= 64 for n in args.load or []):
        print("--frames is 1-1000, --hold 1-100 and --load 0-64", file=sys.stderr)
        return 2
    t0 = time.monotonic()
    for load in args.load or [0]:
        r = measure(args.frames, load, args.hold)
        print(f"load {r['load']}: {r['frames']} pairs ({args.hold} per pose), "
              f"exposure->delivery p50 {r['delay_p50_ms']:.0f} ms, p95 "
              f"{r['delay_p95_ms']:.0f} ms, max "
              f"{r['delay_max_ms']:.0f} ms; skew max {r['skew_max_ms']:.3f} ms; pairs not "
              f"showing the wrench as of their trigger: {r['untrue_pairs']}", flush=True)
    print(f"({time.monotonic() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
