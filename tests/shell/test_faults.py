"""Faults during a vehicle, over the real protocols: the daemon goes to fault with the reason,
sends nothing wrong, and resumes when the device is back."""

import asyncio
import json
import time

import numpy as np
import pytest

from db.repository import Repository
from stationd.config import load_station_config
from stationd.demo.station import SIM_CONFIG
from stationd.sim.world import wrench_at
from stationd.station.events import (
    BoltSelected,
    BoltSkipped,
    DeviceHealth,
    PairFrames,
    ParamsRefusedEvent,
    State,
    ToolEnabled,
    VehicleClosed,
)
from stationd.words import state_words
from tests.shell.daemons import scenario, until_async, vehicle_bolts


def _of(st, *kinds):
    return list(st.bus.of(*kinds))


def _sends(st):
    """The bolts whose parameters were sent (one BoltSelected per send), in order."""
    return [e.bolt for e in _of(st, BoltSelected)]


def _back(st, device):
    return any(e.device == device and e.ok for e in _of(st, DeviceHealth))


@pytest.mark.timeout(240)
def test_refused_parameters_fault_then_the_bolt_is_skipped(tmp_path):
    cfg = load_station_config(SIM_CONFIG)
    from stationd.boltfile import load_bolts
    bolt = load_bolts(cfg.bolts_path).models[0].bolts[0]

    async def body(st, world):
        rng = np.random.default_rng(0)
        world.set_wrench(wrench_at(np.array(bolt.position), rng, st.cfg.tool.length_mm))
        await until_async(lambda: _back(st, "wrench"), 60)
        assert [e.bolt for e in _of(st, ParamsRefusedEvent)] == [bolt.bolt_id]
        n_sent = len(_sends(st))
        await asyncio.sleep(3.0)  # still on the bolt: nothing is sent again
        assert len(_sends(st)) == n_sent
        assert st.core.state is State.TRACKING
        assert [e.bolt for e in _of(st, BoltSkipped)] == [bolt.bolt_id]
        world.set_wrench(None)
        st.lift.plc.lower_lift()
        await until_async(lambda: _of(st, VehicleClosed), 30)

    st = scenario(tmp_path, body, refusals={bolt.parameters.pset: 2})
    assert not _of(st, ToolEnabled)
    closed = _of(st, VehicleClosed)
    assert closed and bolt.bolt_id in closed[0].missing  # reported missing


@pytest.mark.timeout(240)
def test_lift_plc_vanishing_is_a_fault_until_it_returns(tmp_path):
    async def body(st, world):
        plc = st.lift.plc
        port = plc.tcp_port
        plc.stop_tcp()
        await until_async(lambda: st.core.state is State.FAULT, 30)
        assert state_words(st.core.reason).startswith("lift:")
        world.set_wrench(wrench_at(np.array(next(iter(vehicle_bolts(st).values())).position),
                                   np.random.default_rng(1), st.cfg.tool.length_mm))
        await asyncio.sleep(1.0)
        assert not _sends(st)  # nothing in fault
        plc.start_tcp(port)
        await until_async(lambda: st.core.state is not State.FAULT, 60)
        await until_async(lambda: _sends(st), 60)
        # the commissioning screen's pair summaries (published at their own, throttled rate:
        # a selection can now come before the next one), JSON as they are (no NaN)
        await until_async(lambda: any(e.sides["left"]["found"] for e in _of(st, PairFrames)), 10)
        frames = [e for e in _of(st, PairFrames) if e.sides["left"]["found"]]
        assert frames and {e.pair for e in frames} <= set(st.cfg.pairs)
        json.dumps(frames[-1].to_json(), allow_nan=False)

    scenario(tmp_path, body)


def _first_bolt(st):
    return next(iter(vehicle_bolts(st).values()))


@pytest.mark.timeout(240)
def test_a_camera_that_stops_delivering_is_a_fault_until_it_returns(tmp_path):
    async def body(st, world):
        world.cut_cameras("pair2")
        await until_async(lambda: st.core.state is State.FAULT, 30)
        assert state_words(st.core.reason).startswith("pair2:")
        b = _first_bolt(st)
        world.set_wrench(wrench_at(np.array(b.position), np.random.default_rng(2),
                                   st.cfg.tool.length_mm))
        await asyncio.sleep(1.5)
        assert st.core.state is State.FAULT            # still blind: nothing sent
        assert not _sends(st)
        world.restore_cameras("pair2")
        await until_async(lambda: _sends(st), 60)
        assert _sends(st) == [b.bolt_id]
        assert _back(st, "pair2")

    scenario(tmp_path, body)


@pytest.mark.timeout(240)
def test_the_controller_dropping_mid_tightening_is_a_fault_then_the_bolt_is_done(tmp_path):
    vin = "FAULTVIN000000001"
    seen = {}

    async def body(st, world):
        ctl = st.wrench.controller
        await until_async(lambda: ctl.vin == vin, 30)          # the VIN went to the controller
        b = _first_bolt(st)
        world.set_wrench(wrench_at(np.array(b.position), np.random.default_rng(3),
                                   st.cfg.tool.length_mm))
        await until_async(lambda: st.core.state is State.TIGHTENING and ctl.tool_enabled, 60)
        ctl.power_off()                                    # gone mid-tightening
        await until_async(lambda: st.core.state is State.FAULT, 30)
        assert state_words(st.core.reason).startswith("wrench:")
        sends = len(_sends(st))
        await asyncio.sleep(1.0)
        assert len(_sends(st)) == sends
        ctl.power_on()                                     # back, with its RAM lost
        await until_async(lambda: st.core.state is State.TIGHTENING and ctl.tool_enabled, 60)
        assert ctl.vin == vin                              # sent again after the reconnect
        shot = ctl.pull_trigger()
        assert shot is not None
        await until_async(lambda: shot.tightening_id in ctl.acked_ids, 30)  # stored, acknowledged
        assert set(_sends(st)) == {b.bolt_id}                   # never another bolt's parameters
        seen.update(bolt=b.bolt_id, shot=shot)

    st = scenario(tmp_path, body)
    repo = Repository.open(st.cfg.database_url)
    try:
        rows = {r.bolt_id: r for r in repo.vehicle_report(vin).bolts}
    finally:
        repo.close()
    assert rows[seen["bolt"]].status == ("ok" if seen["shot"].ok else "nok")


@pytest.mark.timeout(240)
def test_frames_of_the_wrong_size_are_a_fault_not_an_exit(tmp_path, monkeypatch):
    """A pair whose cameras deliver frames its calibration does not describe (here 64x48
    image files): retried, then a fault naming the sizes; the station stays up, sends
    nothing."""
    import shutil

    import cv2

    import tests.shell.daemons as harness

    dst = tmp_path / "sim"
    shutil.copytree(SIM_CONFIG.parent, dst)
    frames = tmp_path / "frames"
    frames.mkdir()
    for side in ("left", "right"):
        cv2.imwrite(str(frames / f"{side}_0.png"), np.full((48, 64, 3), 90, np.uint8))
    text = (dst / "station.yaml").read_text()
    for side in ("left", "right"):
        text = text.replace(f"'sim://pair1/{side}'", f"'file://{frames}/{side}_*.png?loop=1'")
    (dst / "station.yaml").write_text(text)
    monkeypatch.setattr(harness, "SIM_CONFIG", dst / "station.yaml")

    async def body(st, world):
        await until_async(lambda: st.core.state is State.FAULT, 60)
        assert state_words(st.core.reason).startswith(
            "pair1: left frames are 64x48, the calibration is for 5472x3648")
        await asyncio.sleep(1.0)
        assert st.core.state is State.FAULT and not _sends(st)

    scenario(tmp_path, body)


@pytest.mark.timeout(240)
def test_a_database_failing_at_a_vehicle_is_a_fault_its_keeper_probes_back(tmp_path):
    """The database fails as a vehicle arrives (a disk error, injected into the repository:
    as root a real SQLite file cannot be made unreadable): a fault naming the database, no
    vehicle, nothing sent; its keeper probes it with backoff (not at every tick) and once it
    answers the vehicle is loaded."""
    from db.errors import DbError

    probes: list[float] = []
    down = {"on": True}

    def prepare(st):
        repo = st.repo
        real_model, real_models = repo.model_for_code, repo.models

        def model_for_code(code):
            if down["on"]:
                raise DbError("disk I/O error")
            return real_model(code)

        def models():
            probes.append(time.monotonic())
            if down["on"]:
                raise DbError("disk I/O error")
            return real_models()

        repo.model_for_code, repo.models = model_for_code, models

    async def body(st, world):
        await until_async(lambda: "database" in st.core.faults, 30)
        assert st.core.state is State.FAULT
        assert "database: disk I/O error" in state_words(st.core.reason)
        assert st.vin is None and not _sends(st)
        await asyncio.sleep(4.0)
        # backoff 0.5 s doubling to 5 s: a handful of probes, not one per tick
        assert 2 <= len(probes) <= 5, probes
        down["on"] = False
        await until_async(lambda: st.vin == "DBFAULTVIN0000001", 30)
        assert "database" not in st.core.faults and _back(st, "database")
        # one fault and one return, the same kind throughout
        health = [(e.ok, e.kind) for e in _of(st, DeviceHealth) if e.device == "database"]
        assert health == [(False, "down"), (True, "")], health

    scenario(tmp_path, body, vin="DBFAULTVIN0000001", prepare=prepare, loaded=False)


@pytest.mark.timeout(240)
def test_a_camera_not_the_one_its_calibration_was_made_with_is_a_fault(tmp_path):
    """The pair's calibration was first used with another unit of pair1's left camera (its
    serial number pinned in the database): the pair is refused, the station in fault naming
    both serials, nothing sent; the right unit back (its pin matching again: here rewritten,
    as a camera cannot be swapped under a test), the pair comes back by its keeper's retry."""
    from db.engine import write_session
    from db.models import CameraPin

    digest = load_station_config(SIM_CONFIG).pairs["pair1"].calibration.digest()

    def pin(st, serial):
        with write_session(st.repo.engine) as s:
            s.get(CameraPin, ("pair1", "left", digest)).serial = serial

    from db.cameras import pin_cameras

    # pinned before the station opens its cameras (the database of an earlier start)
    repo = Repository.open(f"sqlite:///{tmp_path}/s.db")
    assert pin_cameras(repo, "pair1", digest, {"left": "HIK-DA0001"}) == []
    repo.engine.dispose()

    async def body(st, world):
        await until_async(lambda: st.core.state is State.FAULT, 60)
        assert state_words(st.core.reason).startswith(
            "pair1: camera pair1_left is S/N SIM-pair1-left, but the pair's calibration "
            "(pair1.yaml) was made with S/N HIK-DA0001"), state_words(st.core.reason)
        await asyncio.sleep(1.0)
        assert st.core.state is State.FAULT and not _sends(st) and st.vin is None
        pin(st, "SIM-pair1-left")
        await until_async(lambda: _back(st, "pair1"), 90, "pair1 back")
        await until_async(lambda: st.vin is not None, 30, "the vehicle loaded")
        world.set_wrench(wrench_at(np.array(vehicle_bolts(st)["B01"].position),
                                   np.random.default_rng(3), st.cfg.tool.length_mm))
        await until_async(lambda: _sends(st) == ["B01"], 60, "B01 sent once pair1 is back")

    scenario(tmp_path, body, loaded=False)
