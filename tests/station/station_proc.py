"""A station process for the restart tests: ``stationd run`` with the simulated world inside.

The test process serves the lift (Modbus TCP) and the controller (Open Protocol TCP), as a
plant's PLC and controller would be separate machines; the ``sim://`` cameras need their world
in this process, so it lives here and puts the wrench where the file POSE says (a bolt id, or
nothing: out of view).  The daemon itself is the real one: ``stationd.serve.serve``,
with its signal handling, so SIGTERM and SIGKILL hit exactly what systemd would.

    python tests/station/station_proc.py STATION.yaml POSE
"""

from __future__ import annotations

import asyncio
import logging
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from stationd.boltfile import load_bolts  # noqa: E402
from stationd.config import load_station_config  # noqa: E402
from stationd.serve import serve  # noqa: E402
from stationd.sim.world import World, wrench_at  # noqa: E402
from stationd.station.sdnotify import Notifier  # noqa: E402


def main(cfg_path: str, pose_path: str) -> None:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(levelname)s %(message)s")
    cfg = load_station_config(cfg_path)
    assert cfg.bolts_path is not None
    world = World(cfg, seed=5)
    bolts = {b.bolt_id: np.array(b.position) for m in load_bolts(cfg.bolts_path).models
             for b in m.bolts}
    rng = np.random.default_rng(0)
    pose = Path(pose_path)

    def follow() -> None:
        last = None
        while True:
            text = pose.read_text().strip() if pose.exists() else ""
            if text != last:
                last = text
                world.set_wrench(wrench_at(bolts[text], rng, cfg.tool.length_mm, 3.0)
                                 if text else None)
            time.sleep(0.02)

    threading.Thread(target=follow, daemon=True).start()
    asyncio.run(serve(cfg_path, cfg, Notifier()))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
