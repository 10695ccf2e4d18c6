"""What the daemon records, over the real protocols: the marker crops kept with a tightening,
a result that arrives after the wrench left its bolt (never the next bolt's), and the bolt
table's order rule.  The harness is tests/shell/daemons.py's: an in-process station on
config/sim (or a copy of it), the lift PLC and the controller on loopback, the cameras
rendered by a World."""

import asyncio
import re
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

import tests.shell.daemons as harness
from db.models import Bolt, TighteningRecord, Vehicle
from db.repository import Repository
from stationd.demo.station import SIM_CONFIG
from stationd.reasons import Why
from stationd.sim.world import wrench_at
from stationd.station.actions import DisableTool
from stationd.station.commands import Issuer, Right, SkipBolt
from stationd.station.events import (
    Because,
    BoltSelected,
    Localized,
    Notice,
    ResultUnattributed,
    State,
    StateReason,
)
from stationd.words import notice_words, reason_words, state_words
from tests.shell.daemons import scenario, until_async, vehicle_bolts

VIN = "FAULTVIN000000001"  # the harness's vehicle
FRAME = (3648, 5472)       # the sim cameras' frame, rows x columns
NO_NOK = {"nok_rate": 0.0}  # every tightening OK: a NOK would change what follows


def _sim_copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, *, records: str = "",
              orders: dict[str, int] | None = None) -> Path:
    """config/sim copied to ``tmp_path``, with a ``records`` section and bolt ``orders``
    added, and the harness pointed at it."""
    src = SIM_CONFIG.parent
    dst = tmp_path / "sim"
    shutil.copytree(src, dst)
    if records:
        with (dst / "station.yaml").open("a") as f:
            f.write(f"records: {records}\n")
    bolts = dst / "bolts.yaml"
    text = bolts.read_text()
    for bolt, order in (orders or {}).items():
        line = f"    - id: {bolt}\n"
        assert text.count(line) == 1
        text = text.replace(line, f"{line}      order: {order}\n")
    bolts.write_text(text)
    monkeypatch.setattr(harness, "SIM_CONFIG", dst / "station.yaml")
    return dst


def _on(st, bolt: str, seed: int):
    """The wrench with its socket on ``bolt``."""
    return wrench_at(np.array(vehicle_bolts(st)[bolt].position), np.random.default_rng(seed),
                     st.cfg.tool.length_mm)


def _tightening(st, bolt: str) -> bool:
    return (st.core.state is State.TIGHTENING and st.core.bolt == bolt
            and st.wrench.controller.tool_enabled)


async def _tighten(st, world, bolt: str, seed: int):
    """Take the wrench to ``bolt``, pull the trigger once the tool is on; the controller's
    tightening, once the daemon acknowledged it (stored)."""
    ctl = st.wrench.controller
    world.set_wrench(_on(st, bolt, seed))
    await until_async(lambda: _tightening(st, bolt), 60)
    shot = ctl.pull_trigger()
    assert shot is not None
    await until_async(lambda: shot.tightening_id in ctl.acked_ids, 30)
    return shot


def _records(url: str) -> list[tuple[str, int | None, list[str], tuple[float, float]]]:
    """(bolt, controller tightening id, images, localized XY) of every record of the
    vehicle, in order."""
    repo = Repository.open(url)
    try:
        with Session(repo.engine) as s:
            rows = s.execute(select(Bolt.code, TighteningRecord.tightening_id,
                                    TighteningRecord.images, TighteningRecord.x_mm,
                                    TighteningRecord.y_mm)
                             .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
                             .join(Vehicle, TighteningRecord.vehicle_id == Vehicle.id)
                             .where(Vehicle.vin == VIN).order_by(TighteningRecord.id)).all()
        return [(code, tid, list(images), (x, y)) for code, tid, images, x, y in rows]
    finally:
        repo.close()


def _sends(st) -> list[str]:
    """The bolts whose parameters were sent (one BoltSelected per send)."""
    return [e.bolt for e in st.bus.of(BoltSelected)]


def _logs(st) -> list[str]:
    """The operator's log lines and every localization's refusal reason."""
    return [notice_words(e) if isinstance(e, Notice) else reason_words(e.reason)
            for e in st.bus.of(Notice, Localized) if getattr(e, "reason", "x") is not None]


# -- 1. the marker crops kept with a record -------------------------------------------------
@pytest.mark.timeout(240)
@pytest.mark.parametrize("save", [True, False])
def test_a_tightening_keeps_the_marker_crops_when_asked(tmp_path, monkeypatch, save):
    images = tmp_path / "images"
    _sim_copy(tmp_path, monkeypatch,
              records=f"{{images_dir: '{images}', save_images: {str(save).lower()}}}")
    seen = {}

    async def body(st, world):
        assert st.cfg.records.images_dir == images
        assert st.cfg.records.save_images is save
        bolt = next(iter(vehicle_bolts(st)))
        seen.update(bolt=bolt, shot=await _tighten(st, world, bolt, seed=4))

    st = scenario(tmp_path, body, **NO_NOK)
    bolt, tid = seen["bolt"], seen["shot"].tightening_id
    [(rec_bolt, rec_tid, paths, _)] = _records(st.cfg.database_url)
    assert (rec_bolt, rec_tid) == (bolt, tid)
    if not save:
        assert paths == []
        assert not images.exists()  # nothing written, not even the folder
        return
    # one crop per camera of each pair that localized the marker: both sides of a pair
    assert len(paths) >= 2
    assert sorted(paths) == sorted(str(p) for p in (images / VIN).iterdir())
    pairs = set()
    for p in map(Path, paths):
        m = re.fullmatch(rf"{bolt}-{tid}-(pair\d)-(left|right)\.png", p.name)
        assert m, p.name
        pairs.add(m[1])
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        assert img is not None, p
        h, w = img.shape
        assert 20 < h < 600 and 20 < w < 600, (p.name, img.shape)  # a crop, not the frame
        assert h < FRAME[0] and w < FRAME[1]
        # the marker: its white disk in the middle, its black ring around it
        centre = img[h // 2 - 3:h // 2 + 4, w // 2 - 3:w // 2 + 4]
        assert float(centre.mean()) > 170, (p.name, float(centre.mean()))
        assert int(np.percentile(img, 2)) < 60, (p.name, int(np.percentile(img, 2)))
    assert all(any(f"{pair}-{side}.png" in p for p in paths)
               for pair in pairs for side in ("left", "right"))


# -- 2. a result after the wrench left its bolt ---------------------------------------------
def _same_pset_bolts(st) -> tuple[str, str]:
    """Two bolts with the same pset (the pset cannot tell their results apart)."""
    infos = list(vehicle_bolts(st).values())
    a = infos[0]
    b = next(i for i in infos[1:] if i.parameters.pset == a.parameters.pset)
    return a.bolt_id, b.bolt_id


def _pull_as_the_wrench_leaves(st, world, a: str, then=None) -> dict[str, Any]:
    """Arrange for the trigger to be pulled at the moment the station saw the wrench off bolt
    ``a`` (the core turned the tool off) but before its DisableTool reached the controller:
    the tool is still on, so the controller tightens, and its result comes in after the core
    let go of the bolt.  ``then``: where the operator takes the wrench at that same moment."""
    pulled: dict[str, Any] = {}

    def on_action(act):
        if isinstance(act, DisableTool) and act.bolt == a \
                and act.reason == StateReason(Because.NOT_CONFIRMED, bolt=a) \
                and "late" not in pulled:
            assert st.core.state is not State.TIGHTENING
            pulled["late"] = st.wrench.controller.pull_trigger()
            world.set_wrench(then)

    st.on_action = on_action
    return pulled


@pytest.mark.timeout(240)
def test_a_result_after_the_wrench_left_is_its_bolts_never_the_next_ones(tmp_path):
    seen = {}

    async def body(st, world):
        ctl = st.wrench.controller
        a, b = _same_pset_bolts(st)
        pulled = _pull_as_the_wrench_leaves(st, world, a, then=_on(st, b, seed=6))
        world.set_wrench(_on(st, a, seed=5))
        await until_async(lambda: _tightening(st, a), 60)
        world.set_wrench(None)               # the operator moves away, pulling the trigger
        await until_async(lambda: "late" in pulled, 30)
        late = pulled["late"]
        assert late is not None              # the tool was still on: it tightened
        st.on_action = None
        await until_async(lambda: late.tightening_id in ctl.acked_ids, 30)
        assert any(f"result {late.tightening_id} came after the tool went off for {a} "
                   f"(within the late-result window): recorded to {a}" in m for m in _logs(st))
        # meanwhile the wrench is on b: b is selected and tightened with its own result
        await until_async(lambda: _tightening(st, b), 60)
        shot = ctl.pull_trigger()
        assert shot is not None
        await until_async(lambda: shot.tightening_id in ctl.acked_ids, 30)
        seen.update(a=a, b=b, late=late, shot=shot)

    st = scenario(tmp_path, body, **NO_NOK)
    a, b, late, shot = seen["a"], seen["b"], seen["late"], seen["shot"]
    assert late.tightening_id != shot.tightening_id
    assert not list(st.bus.of(ResultUnattributed))
    assert _sends(st) == [a, b]
    records = _records(st.cfg.database_url)
    assert [r[:2] for r in records] == [(a, late.tightening_id), (b, shot.tightening_id)]
    for (bolt, *_, xy) in records:            # each with its own selection's position
        assert np.hypot(*(np.array(xy) - np.array(vehicle_bolts(st)[bolt].position[:2]))) < 2.0
    repo = Repository.open(st.cfg.database_url)
    try:
        rows = {r.bolt_id: r for r in repo.vehicle_report(VIN).bolts}
    finally:
        repo.close()
    assert (rows[a].status, rows[a].tightening_id) == ("ok", late.tightening_id)
    assert (rows[b].status, rows[b].tightening_id) == ("ok", shot.tightening_id)


@pytest.mark.timeout(240)
def test_a_bolt_whose_late_result_was_ok_is_done(tmp_path):
    async def body(st, world):
        ctl = st.wrench.controller
        a = next(iter(vehicle_bolts(st)))
        pulled = _pull_as_the_wrench_leaves(st, world, a)
        world.set_wrench(_on(st, a, seed=5))
        await until_async(lambda: _tightening(st, a), 60)
        world.set_wrench(None)
        await until_async(lambda: "late" in pulled, 30)
        late = pulled["late"]
        assert late is not None and late.ok
        st.on_action = None
        await until_async(lambda: late.tightening_id in ctl.acked_ids, 30)
        repo = Repository.open(st.cfg.database_url)
        try:
            assert {r.bolt_id: r.status for r in repo.vehicle_report(VIN).bolts}[a] == "ok"
        finally:
            repo.close()
        world.set_wrench(_on(st, a, seed=7))  # back on the bolt, already tightened OK
        await until_async(lambda: _sends(st).count(a) > 1
                          or any(f"{a} is already done" in m for m in _logs(st)), 60)
        assert _sends(st) == [a], "parameters sent again for a bolt recorded OK"

    scenario(tmp_path, body, **NO_NOK)


# -- 3. the order rule --------------------------------------------------------------------
@pytest.mark.timeout(240)
def test_an_ordered_bolt_waits_for_the_lower_order(tmp_path, monkeypatch):
    first, second = "B01", "B02"
    _sim_copy(tmp_path, monkeypatch, orders={first: 1, second: 2})
    seen = {}

    async def body(st, world):
        assert (vehicle_bolts(st)[first].order, vehicle_bolts(st)[second].order) == (1, 2)
        world.set_wrench(_on(st, second, seed=8))
        wait = f"{second} must wait: order 2 needs {first} done first"
        # more refusals than the stable frames a selection needs: it is the rule, not time
        await until_async(lambda: sum(wait in m for m in _logs(st))
                          > st.cfg.matching.stable_frames + 1, 60)
        assert _sends(st) == []
        assert st.core.state is State.TRACKING
        shot = await _tighten(st, world, first, seed=9)
        assert _sends(st) == [first]
        world.set_wrench(_on(st, second, seed=10))
        await until_async(lambda: _sends(st) == [first, second], 60)
        await until_async(lambda: _tightening(st, second), 30)
        seen.update(shot=shot)

    st = scenario(tmp_path, body, **NO_NOK)
    assert [r[:2] for r in _records(st.cfg.database_url)] == [
        (first, seen["shot"].tightening_id)]


# -- 4. a database that refuses a result ----------------------------------------------------
@pytest.mark.timeout(240)
def test_a_result_the_database_refuses_is_a_fault_kept_and_stored_when_it_can(tmp_path):
    """A full disk refuses the record of a tightening (injected at the repository: a real
    SQLite reuses its checkpointed WAL, so filling a disk does not fail a write reliably):
    the database is in fault (the station too: the tool off, nothing sent for the next bolt),
    the result is kept and not acknowledged; once the database takes writes again its keeper
    stores it (same tightening id, once), then it is published and acknowledged, and the
    station works on."""
    from db.errors import DbError
    from stationd.station.events import DeviceHealth, ResultRecorded

    full = {"on": False, "refused": 0}
    seen: dict[str, Any] = {}

    def prepare(st):
        repo = st.repo
        real = repo.record_tightening_once     # what the station writes a result through

        def record_tightening_once(*args, **kw):
            if full["on"]:
                full["refused"] += 1
                raise DbError("database write failed: database or disk is full")
            return real(*args, **kw)

        repo.record_tightening_once = record_tightening_once

    async def body(st, world):
        ctl = st.wrench.controller
        bolts = sorted(vehicle_bolts(st))
        first, second = bolts[0], bolts[1]
        seen[first] = (await _tighten(st, world, first, seed=1)).tightening_id  # had room
        world.set_wrench(_on(st, second, 2))
        await until_async(lambda: _tightening(st, second), 60)
        full["on"] = True
        shot = ctl.pull_trigger()
        assert shot is not None
        seen[second] = shot.tightening_id
        await until_async(lambda: "database" in st.core.faults, 30)
        assert st.core.state is State.FAULT
        said = state_words(st.core.reason)
        assert "results not stored" in said and "disk is full" in said
        assert not ctl.tool_enabled
        assert shot.tightening_id not in ctl.acked_ids
        sent = len(_sends(st))
        world.set_wrench(_on(st, bolts[2], 3))               # the next bolt: nothing sent
        await asyncio.sleep(3.0)
        await until_async(lambda: full["refused"] >= 2, 60, "the keeper retried")
        assert len(_sends(st)) == sent and not ctl.tool_enabled
        assert st.core.state is State.FAULT
        full["on"] = False                                   # room again
        await until_async(lambda: shot.tightening_id in ctl.acked_ids, 30)
        await until_async(lambda: "database" not in st.core.faults, 30)
        late = [e for e in st.bus.of(ResultRecorded) if e.tightening_id == shot.tightening_id]
        assert len(late) == 1 and late[0].bolt == second
        health = [(e.ok, e.kind) for e in st.bus.of(DeviceHealth) if e.device == "database"]
        assert health == [(False, "down"), (True, "")], health
        await until_async(lambda: _sends(st)[-1:] == [bolts[2]], 60)   # the station works on

    st = scenario(tmp_path, body, prepare=prepare, **NO_NOK)
    stored = [(bolt, tid) for bolt, tid, _, _ in _records(st.cfg.database_url)]
    assert stored[:2] == list(seen.items())                  # each once, in order
    assert len({tid for _, tid in stored}) == len(stored)


@pytest.mark.timeout(240)
def test_a_database_file_removed_under_the_daemon_is_a_fault_not_acknowledged(tmp_path):
    """Second newcomer trial: ``rm station.db*`` while the daemon ran went unnoticed (its
    open connection wrote into the deleted file), the result was acknowledged and lost, and
    after a restart the bolt was tightened again.  Now the write sees the file gone: a fault
    of the database, the result kept and not acknowledged, nothing more sent."""
    import os

    async def body(st, world):
        ctl = st.wrench.controller
        bolts = sorted(vehicle_bolts(st))
        world.set_wrench(_on(st, bolts[0], 1))
        await until_async(lambda: _tightening(st, bolts[0]), 60)
        for f in tmp_path.glob("s.db*"):
            os.unlink(f)
        shot = ctl.pull_trigger()
        assert shot is not None
        await until_async(lambda: "database" in st.core.faults, 30)
        assert "was removed" in state_words(st.core.reason) and st.core.state is State.FAULT
        await asyncio.sleep(1.0)
        assert shot.tightening_id not in ctl.acked_ids and not ctl.tool_enabled
        sent = len(_sends(st))
        world.set_wrench(_on(st, bolts[1], 2))
        await asyncio.sleep(2.0)
        assert len(_sends(st)) == sent
        # a person's command is refused as not recorded, not "accepted" into the lost file
        vin = st.core.status().vin
        answer = await st.submit(SkipBolt(vin, bolts[2], "no access"),
                                 Issuer("sam", frozenset(Right), "cli"))
        assert not answer.accepted and answer.reason is not None
        assert answer.reason.kind is Why.NOT_RECORDED and "was removed" in str(answer.reason.note)

    scenario(tmp_path, body, **NO_NOK)
