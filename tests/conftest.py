"""Shared fixtures: rendered marker views (windows around the marker keep tests fast)."""

from __future__ import annotations

import numpy as np
import pytest

from stationd.sim import scenes as sc
from stationd.sim.render import default_camera
from stationd.vision.marker import MarkerSpec

SPEC = MarkerSpec()
NOISE = {"blur_sigma": 0.8, "noise_sigma": 2.0}


@pytest.fixture(scope="session")
def camera():
    return default_camera()


@pytest.fixture(scope="session")
def station_pair():
    return sc.station_pair()


def view(camera, distance, tilt, seed=0, **kw):
    """A rendered window around a marker at ``distance`` mm and ``tilt`` deg."""
    rng = np.random.default_rng(seed)
    pose = sc.random_pose(rng, camera, distance, tilt, spread=0.4)
    v = sc.render_view(camera, pose, SPEC, seed, **{**NOISE, **kw})
    assert v is not None
    return v, pose


def pose_in_pair(pair, seed=0, tilt=(5.0, 35.0)):
    return sc.pose_in_pair(np.random.default_rng(seed), pair, tilt=tilt)


@pytest.fixture(scope="session")
def pg_server():
    """A real PostgreSQL server for this test process (skipped, with the reason, where none
    can be started); each test makes its own database with ``pg_server.create(name)``."""
    from tests.pgserver import PgServer

    server = PgServer()
    if server.missing:
        pytest.skip(server.missing)
    server.start()
    yield server
    server.stop()


@pytest.fixture
def pg_url(pg_server, request):
    """A fresh, empty database on the test server."""
    import re

    name = re.sub(r"\W", "_", request.node.name.lower())[:40] + f"_{id(request) % 100000}"
    return pg_server.create(name)
