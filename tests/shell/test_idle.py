"""Idle, the daemon leaves its devices alone: with the lift up but not at working height it
reads the PLC once per ``lift.poll_ms`` (a real PLC serves an HMI and a line controller too)
and does not spin a core.  Counted at the simulated PLC's Modbus server."""

from __future__ import annotations

import asyncio
import time

import pytest

from stationd.station.events import State
from stationd.words import state_words
from tests.shell.daemons import run_station, station, until_async


@pytest.mark.timeout(120)
def test_idle_station_reads_the_plc_at_most_20_times_a_second(tmp_path):
    st, world = station(tmp_path)
    plc = st.lift.plc
    figures = {}

    async def idle(st, world):
        plc.set_height(400.0)              # up, not at working height
        await until_async(lambda: st.core.state is State.WAITING_VEHICLE, 60,
                          lambda: f"waiting for a vehicle: {state_words(st.core.reason)}")
        n0, c0, t0 = plc.requests, time.process_time(), time.monotonic()
        await asyncio.sleep(3.0)
        dt = time.monotonic() - t0
        figures.update(rate=(plc.requests - n0) / dt, cpu=(time.process_time() - c0) / dt)

    run_station(st, world, idle)
    print(f"idle: {figures['rate']:.1f} PLC requests/s, {100 * figures['cpu']:.1f} % of a core "
          "(daemon and simulated PLC together)")
    assert 0 < figures["rate"] <= 20
    assert figures["cpu"] < 0.5     # a spinning loop took 94 %; the figure is printed above
