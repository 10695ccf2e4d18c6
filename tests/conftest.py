"""Shared fixtures: rendered marker views (windows around the marker keep tests fast)."""

from __future__ import annotations

import os
import shutil
import tempfile

import numpy as np
import pytest

from stationd.sim import scenes as sc
from stationd.sim.render import default_camera
from stationd.vision.marker import MarkerSpec

SPEC = MarkerSpec()
NOISE = {"blur_sigma": 0.8, "noise_sigma": 2.0}
_BACKGROUNDS: list[str] = []   # the folder this process made for the run, removed at its end


def pytest_configure(config: pytest.Config) -> None:
    """One folder of rendered simulator backgrounds for the whole run: this process, its
    xdist workers and every daemon, demo and benchmark they start inherit it (the simulated
    cameras then render each 20 MP background once per run, not once per process:
    ``stationd.sim.backgrounds``).  Set ``STATIOND_SIM_BACKGROUNDS=`` (empty) to render every
    one as before."""
    from stationd.sim.backgrounds import ENV

    if os.environ.get(ENV) is None:
        os.environ[ENV] = tempfile.mkdtemp(prefix="stationd-backgrounds-")
        _BACKGROUNDS.append(os.environ[ENV])


def pytest_unconfigure(config: pytest.Config) -> None:
    for folder in _BACKGROUNDS:
        shutil.rmtree(folder, ignore_errors=True)


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
