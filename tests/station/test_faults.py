"""Faults during a vehicle, over the real protocols: the daemon goes to fault with the reason,
sends nothing wrong, and resumes when the device is back."""

import asyncio
import time
from dataclasses import replace

import numpy as np
import pytest

from db.repository import Repository
from stationd.config import load_station_config
from stationd.sim.world import World, wrench_at
from stationd.station.cycle import EnableTool, SendParams, State
from stationd.station.daemon import Station
from stationd.station.demo import SIM_CONFIG, _sim_psets


async def _until(pred, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        await asyncio.sleep(0.05)
    raise AssertionError("condition not reached in time")


def _station(tmp_path, **wrench_kw):
    cfg = load_station_config(SIM_CONFIG)
    cfg = replace(cfg, database_url=f"sqlite:///{tmp_path}/s.db")
    st = Station(cfg, device_kw={"wrench": {"psets": _sim_psets(cfg.bolts_path), **wrench_kw}})
    st.open()
    return st, World(cfg, seed=1)


def _scenario(tmp_path, body, **wrench_kw):
    st, world = _station(tmp_path, **wrench_kw)

    async def main():
        stop = asyncio.Event()
        task = asyncio.create_task(st.run(stop))
        try:
            st.lift.plc.set_vehicle(1, "FAULTVIN000000001")
            st.lift.plc.raise_lift()
            await _until(lambda: st.vin is not None, 30)
            await body(st, world)
        finally:
            stop.set()
            await task

    try:
        asyncio.run(main())
    finally:
        world.close()
        st.close()
    return st


@pytest.mark.timeout(240)
def test_refused_parameters_fault_then_the_bolt_is_skipped(tmp_path):
    cfg = load_station_config(SIM_CONFIG)
    from stationd.boltfile import load_bolts
    bolt = load_bolts(cfg.bolts_path).models[0].bolts[0]

    async def body(st, world):
        rng = np.random.default_rng(0)
        world.set_wrench(wrench_at(np.array(bolt.position), rng, st.cfg.tool.length_mm))
        await _until(lambda: any(e[0] == "recovered" for e in st.events), 60)
        assert any(e[0] == "Log" and "controller refused the parameters for "
                   f"{bolt.bolt_id}" in e[1].message for e in st.events)
        n_sent = sum(1 for e in st.events if e[0] == "SendParams")
        await asyncio.sleep(3.0)  # still on the bolt: nothing is sent again
        assert sum(1 for e in st.events if e[0] == "SendParams") == n_sent
        assert st.cycle.state is State.TRACKING
        assert f"{bolt.bolt_id} skipped" in " ".join(e[1].message for e in st.events
                                                if e[0] == "Log")
        world.set_wrench(None)
        st.lift.plc.lower_lift()
        await _until(lambda: st.vin is None, 30)

    st = _scenario(tmp_path, body, refusals={bolt.parameters.pset: 2})
    assert not any(isinstance(e[1], EnableTool) for e in st.events)
    closed = [e[1] for e in st.events if e[0] == "vehicle closed"]
    assert closed and bolt.bolt_id in closed[0][1]  # reported missing


@pytest.mark.timeout(240)
def test_lift_plc_vanishing_is_a_fault_until_it_returns(tmp_path):
    async def body(st, world):
        plc = st.lift.plc
        port = plc.tcp_port
        plc.stop_tcp()
        await _until(lambda: st.cycle.state is State.FAULT, 30)
        assert st.cycle.reason.startswith("lift:")
        world.set_wrench(wrench_at(np.array(next(iter(st.bolts.values())).position),
                                   np.random.default_rng(1), st.cfg.tool.length_mm))
        await asyncio.sleep(1.0)
        assert not any(isinstance(e[1], SendParams) for e in st.events)  # nothing in fault
        plc.start_tcp(port)
        await _until(lambda: st.cycle.state is not State.FAULT, 60)
        await _until(lambda: any(isinstance(e[1], SendParams) for e in st.events), 60)

    _scenario(tmp_path, body)


def _first_bolt(st):
    return next(iter(st.bolts.values()))


@pytest.mark.timeout(240)
def test_a_camera_that_stops_delivering_is_a_fault_until_it_returns(tmp_path):
    async def body(st, world):
        world.cut_cameras("pair2")
        await _until(lambda: st.cycle.state is State.FAULT, 30)
        assert st.cycle.reason.startswith("cameras: pair2:")
        b = _first_bolt(st)
        world.set_wrench(wrench_at(np.array(b.position), np.random.default_rng(2),
                                   st.cfg.tool.length_mm))
        await asyncio.sleep(1.5)
        assert st.cycle.state is State.FAULT            # still blind: nothing sent
        assert not any(isinstance(e[1], SendParams) for e in st.events)
        world.restore_cameras("pair2")
        await _until(lambda: any(isinstance(e[1], SendParams) for e in st.events), 60)
        assert [e[1].bolt for e in st.events if isinstance(e[1], SendParams)] == [b.bolt_id]
        assert any(e[0] == "recovered" and e[1].startswith("cameras:") for e in st.events)

    _scenario(tmp_path, body)


@pytest.mark.timeout(240)
def test_the_controller_dropping_mid_tightening_is_a_fault_then_the_bolt_is_done(tmp_path):
    vin = "FAULTVIN000000001"
    seen = {}

    async def body(st, world):
        ctl = st.wrench.controller
        await _until(lambda: ctl.vin == vin, 30)          # the VIN went to the controller
        b = _first_bolt(st)
        world.set_wrench(wrench_at(np.array(b.position), np.random.default_rng(3),
                                   st.cfg.tool.length_mm))
        await _until(lambda: st.cycle.state is State.TIGHTENING and ctl.tool_enabled, 60)
        ctl.power_off()                                    # gone mid-tightening
        await _until(lambda: st.cycle.state is State.FAULT, 30)
        assert st.cycle.reason.startswith("wrench:")
        sends = sum(isinstance(e[1], SendParams) for e in st.events)
        await asyncio.sleep(1.0)
        assert sum(isinstance(e[1], SendParams) for e in st.events) == sends
        ctl.power_on()                                     # back, with its RAM lost
        await _until(lambda: st.cycle.state is State.TIGHTENING and ctl.tool_enabled, 60)
        assert ctl.vin == vin                              # sent again after the reconnect
        shot = ctl.pull_trigger()
        assert shot is not None
        await _until(lambda: shot.tightening_id in ctl.acked_ids, 30)  # stored, acknowledged
        sent = [e[1].bolt for e in st.events if isinstance(e[1], SendParams)]
        assert set(sent) == {b.bolt_id}                   # never another bolt's parameters
        seen.update(bolt=b.bolt_id, shot=shot)

    st = _scenario(tmp_path, body)
    repo = Repository.open(st.cfg.database_url)
    try:
        rows = {r.bolt_id: r for r in repo.vehicle_report(vin).bolts}
    finally:
        repo.close()
    assert rows[seen["bolt"]].status == ("ok" if seen["shot"].ok else "nok")
