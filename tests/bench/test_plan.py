"""The plan the station benchmarks share: seeded, each bolt once, the wrench's socket on its
bolt within the operator's placement noise."""

from __future__ import annotations

import numpy as np

from stationd.bench.plan import PLACEMENT_SIGMA_MM, wrench_plan
from stationd.boltfile import load_bolts
from stationd.config import load_station_config
from stationd.demo.station import SIM_CONFIG


def test_a_seed_gives_one_plan_of_distinct_bolts_with_the_socket_on_each():
    cfg = load_station_config(SIM_CONFIG)
    assert cfg.bolts_path is not None
    where = {b.bolt_id: np.array(b.position) for b in load_bolts(cfg.bolts_path).models[0].bolts}
    plan = wrench_plan(cfg, 3, 5)
    again = wrench_plan(cfg, 3, 5)
    assert [b for b, _ in plan] == [b for b, _ in again]
    assert all(np.array_equal(p.centre_v, q.centre_v)
               for (_, p), (_, q) in zip(plan, again, strict=True))
    assert len({b for b, _ in plan}) == 5
    assert [b for b, _ in wrench_plan(cfg, 4, 5)] != [b for b, _ in plan]
    for bolt, pose in plan:
        off = pose.socket_v - where[bolt]
        assert off[2] == 0.0 and np.hypot(*off[:2]) < 5 * PLACEMENT_SIGMA_MM
        # the marker sits up the tool from the socket, facing the cameras below
        assert np.isclose(np.linalg.norm(pose.centre_v - pose.socket_v), cfg.tool.length_mm)


def test_more_cycles_than_bolts_plans_every_bolt_once():
    cfg = load_station_config(SIM_CONFIG)
    plan = wrench_plan(cfg, 1, 1000)
    assert cfg.bolts_path is not None
    n = len(load_bolts(cfg.bolts_path).models[0].bolts)
    assert len(plan) == n == len({b for b, _ in plan})
