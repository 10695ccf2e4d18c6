"""Pieces of ``bench chain`` that run fast: the station layout and vehicle registration."""

from dataclasses import replace

import numpy as np

from stationd.bench import chain
from stationd.sim import scenes as sc


def test_station_pairs_look_at_the_chassis():
    station = sc.build_station(np.random.default_rng(0), 4)
    assert len(station) == 4
    for sp in station:
        up = sp.R_vc[:, 2]  # the left camera's optical axis, in the vehicle frame
        assert up[2] > 0.8  # looking up at the chassis
        R = sp.R_vc
        assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) > 0


def test_registration_from_rendered_reference_points_recovers_the_pair_pose():
    rng = np.random.default_rng(1)
    sp = sc.build_station(rng, 1)[0]
    sp = replace(sp, calibrated=sp.true_pair)  # exact calibration: the fit alone is tested
    fit, rep = chain.register_pair(rng, sp, 4)
    assert rep["rms_mm"] < 0.05
    assert np.allclose(fit.A, sp.R_vc, atol=1e-4)
    assert np.linalg.norm(fit.t - sp.c_v) < 0.2
