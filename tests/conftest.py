"""Shared fixtures: rendered marker views (windows around the marker keep tests fast); the
suite's two speeds (the ``system`` marker, tests/system.py)."""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from collections.abc import Generator

# One BLAS thread per test process, set before NumPy loads OpenBLAS (this is the first
# import of it): the suite runs one xdist worker per core, so each worker's pool of BLAS
# threads only contended for the cores the other worker uses, its threads spinning while
# they waited; tests/vision/test_enhance's matrix products took twice the CPU for it.  The
# subprocesses a test starts inherit it; set OPENBLAS_NUM_THREADS to choose otherwise.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest

from stationd.sim import scenes as sc
from stationd.sim.render import default_camera
from stationd.vision.marker import MarkerSpec
from tests.system import MARK_HINT, Guard, check_lists, is_system

# pytest rewrites each test module's asserts on import and caches the result beside it in
# __pycache__ (ignored by git), unless bytecode is not to be written (PYTHONDONTWRITEBYTECODE
# set in the environment): then every collecting process, each xdist worker, rewrites all of
# them again, about 10 s of CPU each.  The suite writes its cache whatever the environment says.
sys.dont_write_bytecode = False

SPEC = MarkerSpec()
NOISE = {"blur_sigma": 0.8, "noise_sigma": 2.0}
_BACKGROUNDS: list[str] = []   # the folder this process made for the run, removed at its end


GUARD = Guard()


def pytest_configure(config: pytest.Config) -> None:
    """The ``system`` marker's guard (tests/system.py: the suite's two speeds), and one folder
    of rendered simulator backgrounds for the whole run: this process, its
    xdist workers and every daemon, demo and benchmark they start inherit it (the simulated
    cameras then render each 20 MP background once per run, not once per process:
    ``stationd.sim.backgrounds``).  Set ``STATIOND_SIM_BACKGROUNDS=`` (empty) to render every
    one as before.  The simulated cameras run at 10 Hz (``drivers.camera.sim``), unless
    ``STATIOND_SIM_FRAME_RATE`` says otherwise: a station tracking an empty scene at the
    cameras' full 19 Hz kept 1.8 cores busy localizing nothing, and the system tests run two
    daemons side by side on two cores.  Measured over six files of whole-daemon tests
    (``-n 2``): 165 s of user CPU uncapped, 154 s at 19 Hz, 129 s at 10 Hz and at 5 Hz; the
    wall time least at 10 Hz (108 s; 128 s at 5 Hz, where the tests wait for the frames a
    wrench on a bolt needs)."""
    from drivers.camera.sim import RATE_ENV
    from stationd.sim.backgrounds import ENV

    check_lists()
    GUARD.install()
    if os.environ.get(ENV) is None:
        os.environ[ENV] = tempfile.mkdtemp(prefix="stationd-backgrounds-")
        _BACKGROUNDS.append(os.environ[ENV])
    os.environ.setdefault(RATE_ENV, "10")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Each system test marked ``system`` before ``-m`` selects (tests/system.py)."""
    for item in items:
        if is_system(item) and item.get_closest_marker("system") is None:
            item.add_marker(pytest.mark.system)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None
                            ) -> Generator[None, object, object]:
    """The guard knows which test runs, its fixtures' setup and teardown included."""
    GUARD.enter(item)
    try:
        return (yield)
    finally:
        GUARD.leave()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None
                            ) -> Generator[None, object, object]:
    """Teardown stops what was started, also what a system test before started (the
    session's PostgreSQL, stopped after the last test of a worker): nothing to guard."""
    GUARD.leave()
    return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]
                              ) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """A test that started what a system test starts fails also where it caught the guard's
    failure (in a thread, in a broad except)."""
    report = yield
    seen = GUARD.seen.get(item.nodeid)
    if seen and report.passed and report.when in ("setup", "call"):
        report.outcome = "failed"
        report.longrepr = f"{item.nodeid} starts {seen[0]}: it is {MARK_HINT} (tests/system.py)"
    return report


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
