"""A station process for the restart tests: ``stationd run`` with the simulated world inside.

The test process serves the lift (Modbus TCP) and the controller (Open Protocol TCP), as a
plant's PLC and controller would be separate machines; the ``sim://`` cameras need their world
in this process, so it lives here and puts the wrench where the file POSE says (a bolt id, or
nothing: out of view).  The daemon itself is the real one: ``stationd.shell.serve.serve``,
with its signal handling, so SIGTERM and SIGKILL hit exactly what systemd would.  A file
``knock`` beside POSE knocks pairs out of place (a line ``PAIR DEGREES`` each: turned about
their vertical axis; a pair no longer named is put back).  Each change is acknowledged once
the world has it: ``POSE.taken`` and ``knock.taken`` then hold the text taken (a test waits
for them, never for a time: ``tests.shell.daemons.taken``); ``plain`` renders a plain
background (no texture, no vignetting: the 20 MP backgrounds render faster); ``lock`` holds
the station's lock as ``stationd run`` does (one daemon per database: what ``stationd
calibrate check`` asks to know that a daemon runs).

    python tests/shell/station_proc.py STATION.yaml POSE [plain] [lock]
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
from stationd.lock import StationLocks  # noqa: E402
from stationd.shell.sdnotify import Notifier  # noqa: E402
from stationd.shell.serve import hold_locks, serve  # noqa: E402
from stationd.sim.render import Scene  # noqa: E402
from stationd.sim.world import World, WrenchPose, wrench_at  # noqa: E402


def main(cfg_path: str, pose_path: str, plain: bool = False, lock: bool = False) -> None:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(levelname)s %(message)s")
    cfg = load_station_config(cfg_path)
    assert cfg.bolts_path is not None
    world = World(cfg, seed=5, scene=Scene(blur_sigma=0.8, noise_sigma=2.0) if plain else None)
    bolts = {b.bolt_id: np.array(b.position) for m in load_bolts(cfg.bolts_path).models
             for b in m.bolts}
    rng = np.random.default_rng(0)
    pose = Path(pose_path)
    knock = pose.with_name("knock")

    # a bolt's placement is drawn once (seeded) and kept: the wrench back on a bolt is where it
    # was, and the world composes the windows it rendered then instead of ray-casting them
    # again (each costs a core for about a second: these tests are not about the vision)
    placed: dict[str, WrenchPose] = {}

    def on(bolt: str) -> WrenchPose:
        if bolt not in placed:
            placed[bolt] = wrench_at(bolts[bolt], rng, cfg.tool.length_mm, 3.0)
        return placed[bolt]

    def follow() -> None:
        last, knocked = None, ""
        while True:
            text = pose.read_text().strip() if pose.exists() else ""
            if text != last:
                last = text
                world.set_wrench(on(text) if text else None)
                _acknowledge(pose, text)
            moved = knock.read_text().strip() if knock.exists() else ""
            if moved != knocked:
                turns = dict(line.split() for line in moved.splitlines())
                for name in cfg.pairs:
                    world.move_pair(name, rotation_deg=(0.0, float(turns.get(name, 0.0)), 0.0))
                knocked = moved
                _acknowledge(knock, moved)
            time.sleep(0.02)

    threading.Thread(target=follow, daemon=True).start()
    locks = StationLocks() if lock else None
    if locks is not None:     # as ``stationd run``: one daemon per database and device
        hold_locks(locks, cfg)
    try:
        asyncio.run(serve(cfg_path, cfg, Notifier(), locks))
    finally:
        if locks is not None:
            locks.release()


def _acknowledge(path: Path, text: str) -> None:
    """``PATH.taken`` holds ``text``: the world has it (written whole: a reader never sees
    half of it)."""
    part = path.with_name(path.name + ".taken.part")
    part.write_text(text)
    part.replace(path.with_name(path.name + ".taken"))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], plain="plain" in sys.argv[3:], lock="lock" in sys.argv[3:])
