"""The plan a station benchmark runs: which bolts of the simulated vehicle, in which order, and
where the operator holds the wrench on each.  One function, so that the benchmarks that
compare with each other (``bench station``, ``bench linkcut``) place the wrench alike for a
seed."""

from __future__ import annotations

import numpy as np

from stationd.boltfile import load_bolts
from stationd.config import StationConfig
from stationd.sim.world import WrenchPose, wrench_at

#: the operator's placement noise on a bolt, mm (XY, one sigma): the demo's operator's
PLACEMENT_SIGMA_MM = 0.3


def wrench_plan(cfg: StationConfig, seed: int, cycles: int) -> list[tuple[str, WrenchPose]]:
    """``cycles`` bolts of the station's first vehicle model in a seeded random order (all of
    them when it has fewer), each with the wrench's pose on it."""
    assert cfg.bolts_path is not None  # noqa: S101 - the simulated station names its bolts
    rng = np.random.default_rng(seed)
    bolts = load_bolts(cfg.bolts_path).models[0].bolts
    plan = []
    for k in rng.permutation(len(bolts))[:cycles]:
        b = bolts[int(k)]
        target = np.array(b.position) + np.append(rng.normal(0, PLACEMENT_SIGMA_MM, 2), 0.0)
        plan.append((b.bolt_id, wrench_at(target, rng, cfg.tool.length_mm)))
    return plan
