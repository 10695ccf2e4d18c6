"""What the daemon's simulated world says it renders (``stationd/sim/in_daemon.py``): the
pairs whose two cameras are simulated, not every pair of the station file."""

from __future__ import annotations

from dataclasses import replace

from stationd.config import load_station_config
from stationd.demo.station import SIM_CONFIG
from stationd.sim.in_daemon import sim_pairs


def test_a_pair_on_file_cameras_is_not_counted_as_rendered():
    cfg = load_station_config(SIM_CONFIG)
    assert sim_pairs(cfg) == ["pair1", "pair2", "pair3", "pair4"]
    cameras = {**cfg.cameras, "pair1_left": "file:///tmp/frames/left"}
    assert sim_pairs(replace(cfg, cameras=cameras)) == ["pair2", "pair3", "pair4"]
