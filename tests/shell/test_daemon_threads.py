"""The daemon's threads: cameras that take long over their frames (a 20 MP frame, a
simulated world's first renders, a GigE camera in its timeouts) never hold up the lift's
poll: its own thread pool is not theirs."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from drivers.camera.sim import SimCamera
from stationd.demo.station import simulators
from stationd.shell.daemon import Station
from stationd.sim.world import World
from stationd.station.events import State
from stationd.words import state_words
from tests.shell.daemons import scenario, until_async


@pytest.mark.system
def test_a_lift_fault_is_seen_while_every_camera_hangs_in_its_grab(tmp_path, monkeypatch):
    """Every camera of the four pairs hangs in its grab until the test lets them go (more
    grabs than the station's own pool has threads): the PLC's fault bit still takes the
    station out of tracking at its next poll.  (With the cameras on the station's pool, the
    lift's read queued behind their grabs: 6 to 20 s blind after a start in simulation.)"""
    release = threading.Event()
    hanging: list[str] = []
    grab = SimCamera._grab

    def hangs(self: SimCamera, timeout: float) -> Any:
        hanging.append(self.url)
        release.wait(60)
        return grab(self, timeout)

    monkeypatch.setattr(SimCamera, "_grab", hangs)
    seen: list[float] = []

    async def body(st: Station, world: World) -> None:
        try:
            await until_async(lambda: st.core.status().state is State.TRACKING, 30,
                              "tracking")
            await until_async(lambda: len(hanging) >= 4, 30, "the cameras grabbing")
            t0 = time.monotonic()
            simulators(st)[0].set_fault(True)
            await until_async(lambda: st.core.status().state is not State.TRACKING, 20,
                              lambda: f"the fault seen ({st.core.status().state})")
            seen.append(time.monotonic() - t0)
            assert st.core.status().state is State.FAULT
            assert "the lift PLC reports a fault" in state_words(st.core.status().reason)
        finally:
            release.set()

    scenario(tmp_path, body)
    assert seen and seen[0] < 10.0, seen
