"""The soak harness: its script, its scorekeeping, and playing a script through hooks."""

import asyncio

import pytest

from stationd.sim.soak import (
    Arrive,
    Depart,
    Outage,
    Reload,
    SoakTally,
    Visit,
    plan_soak,
    run_soak,
)

BOLTS = [f"B{i:02d}" for i in range(1, 31)]


def _tightening_visits(plan):
    return [s for s in plan if isinstance(s, Visit) and not s.leave]


def test_a_plan_has_the_tightenings_asked_over_vehicles_and_is_seeded():
    plan = plan_soak(BOLTS, 500, faults=True, seed=3)
    assert len(_tightening_visits(plan)) == 500 and plan == plan_soak(BOLTS, 500, faults=True,
                                                                     seed=3)
    assert plan != plan_soak(BOLTS, 500, faults=True, seed=4)
    arrivals = [s for s in plan if isinstance(s, Arrive)]
    assert len(arrivals) == sum(isinstance(s, Depart) for s in plan) >= 50
    kinds = {type(s) for s in plan}
    assert {Outage, Reload} <= kinds and any(a.rework for a in arrivals)
    devices = {s.device for s in plan if isinstance(s, Outage)}
    assert devices == {"lift", "wrench", "cameras"}
    assert {s.kind for s in plan if isinstance(s, Reload)} == {"valid", "bad bolt table",
                                                               "lift down"}
    assert any(isinstance(s, Visit) and s.power_cut for s in plan)
    # a rework comes back with a VIN that was closed before it
    for k, a in enumerate(plan):
        if isinstance(a, Arrive) and a.rework:
            assert any(isinstance(b, Arrive) and b.vin == a.vin and not b.rework
                       for b in plan[:k])
    # a vehicle's bolts are distinct (a rework may redo them: that is its point)
    vehicle = []
    for s in plan:
        if isinstance(s, Arrive):
            vehicle = []
        elif isinstance(s, Visit) and not s.leave:
            assert s.bolt not in vehicle
            vehicle.append(s.bolt)


def test_without_faults_no_outage_reload_or_rework():
    plan = plan_soak(BOLTS, 40, seed=1)
    assert not any(isinstance(s, Outage | Reload) or (isinstance(s, Arrive) and s.rework)
                   for s in plan)
    with pytest.raises(ValueError):
        plan_soak([], 5)


class FakeStation:
    """Hooks over an in-memory station that enables the tool for the bolt the wrench is on
    (``wrong``: for the bolt it hovers towards, once), records every result, and cannot
    select while the controller is down."""

    def __init__(self, tally, wrong=False):
        self.tally = tally
        self.wrong = wrong
        self.on = None
        self.enabled = None
        self.down = set()
        self.made = 0
        self.calls = []

    async def arrive(self, vin, model_code):
        self.calls.append(("arrive", vin))

    async def depart(self):
        self.calls.append(("depart",))

    def wrench_to(self, bolt, halfway_to=None):
        if halfway_to is not None and self.wrong:
            self.wrong = False
            self.tally.check_send(halfway_to)  # a station that selects between two bolts
        self.on = None if halfway_to is not None else bolt
        if self.on is None:
            self.enabled = None

    async def wait_enabled(self, bolt, timeout):
        await asyncio.sleep(0)
        if "wrench" in self.down or self.on != bolt:
            self.tally.refused("controller down")
            return False
        self.tally.check_send(bolt)
        self.enabled = bolt
        return True

    async def wait_disabled(self, timeout):
        return self.enabled is None

    def pull_trigger(self):
        if self.enabled is None:
            return False
        self.made += 1
        return True

    async def device_down(self, device):
        self.down.add(device)

    async def device_up(self, device):
        self.down.discard(device)

    async def reload(self, kind):
        self.calls.append(("reload", kind))

    def recorded(self):
        return self.made

    def alive(self):
        return True

    def why_not(self):
        return "controller down" if "wrench" in self.down else "?"


def _play(plan, **kw):
    tally = SoakTally()
    hooks = FakeStation(tally, **kw)
    asyncio.run(run_soak(plan, hooks, tally, hover_s=0, settle_s=0))
    return tally, hooks


def test_a_good_station_passes_and_every_step_is_played():
    plan = [Arrive("V1", 1), Visit("B01"), Visit("B02", hover_with="B03"),
            Visit("B04", leave=True), Outage("wrench", 0.0), Reload("bad bolt table"),
            Visit("B04"), Depart(),
            Arrive("V1", 1, rework=True), Visit("B01"), Depart()]
    tally, hooks = _play(plan)
    s = tally.summary()
    assert tally.passed and s["bolts_tightened"] == 4 and s["results_lost"] == 0
    assert s["wrong_sends"] == 0 and s["exits"] == 0 and s["reworks"] == 1
    assert s["outages"] == {"wrench": 1} and s["reloads"] == {"bad bolt table": 1}
    assert hooks.calls == [("arrive", "V1"), ("reload", "bad bolt table"), ("depart",),
                           ("arrive", "V1"),
                           ("depart",)]


def test_a_power_cut_mid_tightening_needs_a_new_selection_before_the_rundown():
    tally, _ = _play([Arrive("V1", 1), Visit("B01", power_cut=True), Depart()])
    assert tally.passed and tally.tightened == 1
    assert tally.outages == {"controller mid-tightening": 1}


def test_a_send_for_a_bolt_the_wrench_is_not_on_is_counted_wrong():
    tally, _ = _play([Arrive("V1", 1), Visit("B02", hover_with="B03"), Depart()], wrong=True)
    assert not tally.passed and tally.wrong_sends == [
        "parameters for B03 while the wrench is on no bolt"]


def test_lost_results_and_an_exited_station_fail_the_soak():
    tally = SoakTally(results_made=5, results_recorded=4)
    assert tally.results_lost == 1 and not tally.passed

    class Exits(FakeStation):
        def alive(self):
            return False

    t2 = SoakTally()
    asyncio.run(run_soak([Arrive("V1", 1), Visit("B01")], Exits(t2), t2))
    assert t2.exits == 1 and not t2.passed and t2.tightened == 0


def test_sim_devices_drive_the_world_the_plc_and_the_controller():
    """The world's side of the hooks on the real simulated devices: a silent PLC answers no
    Modbus request, a powered-off controller refuses connections."""
    import socket

    import numpy as np

    from drivers.camera import open_camera
    from drivers.errors import DeviceError
    from drivers.lift.sim import SimulatedPlc
    from drivers.wrench.sim.controller import SimController
    from stationd.sim.soak import SimDevices

    from .test_world import LENGTH, _world

    world = _world()
    plc = SimulatedPlc()
    bolts = {"B01": [-120.0, 0.0, 1000.0], "B02": [120.0, 0.0, 1000.0]}
    try:
        with SimController() as ctl:
            port = ctl.listen_tcp()
            dev = SimDevices(world, plc, ctl, bolts, LENGTH, seed=2)
            asyncio.run(dev.arrive("SOAK0000000000001", 7))
            state = plc.state()
            assert state.at_working_height and (state.model_code, state.vin) == (
                7, "SOAK0000000000001")
            dev.wrench_to("B01")
            assert np.hypot(*(world.pose.socket_v - bolts["B01"])[:2]) < 2.0
            first = world.pose
            dev.wrench_to("B01")
            assert world.pose is first   # one pose per place: rendered once, ahead
            dev.wrench_to("B01", halfway_to="B02")
            assert np.allclose(world.pose.socket_v, [0.0, 0.0, 1000.0])
            dev.wrench_to(None)
            assert world.pose is None and not dev.pull_trigger()  # no tool enabled
            asyncio.run(dev.device_down("wrench"))
            with pytest.raises(OSError), socket.create_connection(("127.0.0.1", port), 1):
                pass
            asyncio.run(dev.device_up("wrench"))
            socket.create_connection(("127.0.0.1", port), 1).close()
            asyncio.run(dev.device_down("cameras"))      # the only pair, "w": unplugged
            cam = open_camera("sim://w/left")
            with pytest.raises(DeviceError):
                cam.grab(0.5)
            asyncio.run(dev.device_up("cameras"))
            assert cam.grab(0.5).image.shape[:2] == (240, 320)
            cam.close()
            asyncio.run(dev.device_down("lift"))
            assert plc._silent
            asyncio.run(dev.device_up("lift"))
            asyncio.run(dev.depart())
            assert not plc.state().at_working_height
    finally:
        plc.close()
        world.close()
