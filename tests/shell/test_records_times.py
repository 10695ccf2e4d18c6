"""The times of one decision in causal order (stationd/shell/records.py, db/ledger.py): a
rundown's ``result_at`` is when the station took its result (the input the core decided on),
and the NOK policy's lock it caused is at that time or after, in the station's database, in
its results feed (what the forwarder sends the line database) and in ``db export``.

Why: an MES integrator's trial read the lock of B11 (``command_at``) 29 ms before the third
NOK that caused it (``result_at``): the core decided the lock at the result's input time, and
the shell stamped the rundown with its own clock as it built the record, after that.

The core and the shell here are the daemon's own (the core driven as the core tests drive
it, its clock a minute behind the wall clock: the station's input time is always before its
storing), the database a real SQLite file; only the order of recorded times is compared."""

from __future__ import annotations

import asyncio
import time
from datetime import datetime
from pathlib import Path
from typing import Any

from drivers.wrench.base import Status, TighteningResult
from stationd.bus import EventBus
from stationd.config import StationConfig
from stationd.shell.effects import Effects
from stationd.shell.records import Records
from stationd.shell.sdnotify import Notifier
from stationd.station.actions import LoadVehicle, NoteLock, Record
from stationd.station.core import StationCore
from stationd.station.events import BoltLocked
from stationd.station.inputs import ResultIn, Started, VehicleLoaded, Written
from stationd.station.policy import NokPolicy, NokRule
from stationd.web.results import LOCKED_STATUS, Results
from tests.db.conftest import BASE, url_of
from tests.station.test_core import BOLTS, PARAMS, Driver, _on, published


def _nok_result(tid: int, pset: int) -> TighteningResult:
    """A NOK as the controller sends it (torque low), its own clock's time."""
    return TighteningResult(False, 20.0, 30.0, Status.LOW, Status.OK, tid, pset, "VIN1",
                            datetime.now(), 23.0, 27.0, 25.0, 10.0, 50.0, 30.0)


class _NoWrench:
    device = None      # acknowledging and the tool's off need no controller here


async def _direct(fn: Any, *args: Any) -> Any:
    return fn(*args)    # the executor's call, in the test's thread


def _station(tmp_path: Path) -> tuple[Driver, Effects, Records]:
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    d = Driver(core=StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(max_nok=3))),
               t=time.time() - 60.0)
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VIN1"))
    none: Any = None
    wrench: Any = _NoWrench()
    call: Any = _direct
    effects = Effects(d.core, records, wrench, none, EventBus(), Notifier({}), call, none)
    return d, effects, records


def _nok(d: Driver, effects: Effects, bolt: int, tid: int) -> list[Any]:
    """``bolt`` run down NOK (tightening ``tid``); the records and locks the core asked for
    carried out by the shell, as the daemon does, the records' answers back to the core."""
    _on(d, bolt)
    d.step(("ack", 0.01, True))
    _on(d, bolt, 1)
    assert d.tool, d.core.reason
    d.t += 0.2
    acts = d.feed(ResultIn(d.t, _nok_result(tid, BOLTS[f"B{bolt}"].pset or 0)))
    for a in acts:
        if isinstance(a, Record | NoteLock):
            back = asyncio.run(effects.do(a))
            if isinstance(back, Written):
                d.feed(back)
    return acts


def _iso(t: str | None) -> datetime:
    assert t is not None
    return datetime.fromisoformat(t)


def test_a_lock_is_never_timestamped_before_the_nok_that_caused_it(tmp_path: Path) -> None:
    d, effects, records = _station(tmp_path)
    _nok(d, effects, 2, 1)
    _nok(d, effects, 2, 2)
    acts = _nok(d, effects, 2, 3)
    assert [(e.bolt, e.count) for e in published(acts, BoltLocked)] == [("B2", 3)]
    repo = records.repo
    assert repo is not None
    # the station's database: each NOK's result_at, then the lock's time
    runs = [r for r in Results(repo).rundowns("VIN1") if r["bolt"] == "B2"]
    assert [(r["tightening_id"], r["status"]) for r in runs] == [(1, "nok"), (2, "nok"),
                                                                  (3, "nok")]
    (lock,) = [c for c in repo.ledger.commands("VIN1") if c.kind == "lock"]
    third = _iso(runs[-1]["result_at"])
    assert third <= lock.at, (
        f"the lock of B2 at {lock.at.isoformat()} is before the NOK that caused it, taken "
        f"at {third.isoformat()}")
    assert all(_iso(r["result_at"]) <= _iso(r["recorded_at"]) for r in runs)   # taken, stored
    # what the forwarder sends the line database: the rundown's result_at and the lock's
    # command time (line_rundowns.result_at, line_commands.command_at)
    feed = repo.ledger.since(0)
    rundowns = [e for e in feed if e["kind"] == "rundown" and e["record"]["bolt"] == "B2"]
    (locked,) = [e for e in feed if e["kind"] == "command" and e["record"]["kind"] == "lock"]
    assert _iso(rundowns[-1]["record"]["result_at"]) <= _iso(locked["record"]["at"]), (
        rundowns[-1]["record"]["result_at"], locked["record"]["at"])
    # ... and stored after it (its feed entry later, in number and in time)
    assert rundowns[-1]["seq"] < locked["seq"]
    assert _iso(rundowns[-1]["at"]) <= _iso(locked["at"])
    # db export: the lock's row after the NOK it comes of, not dated before it
    rows = [r for r in Results(repo).export("VIN1") if r["bolt"] == "B2"]
    assert [(r["status"], r["tightening_id"]) for r in rows] == [
        ("nok", 1), ("nok", 2), ("nok", 3), (LOCKED_STATUS, None)]
    assert _iso(rows[2]["result_at"]) <= _iso(rows[3]["recorded_at"])
    repo.close()


def test_a_record_s_feed_time_is_the_time_it_was_stored(tmp_path: Path) -> None:
    """A rundown's ``recorded_at`` and its feed entry's ``at`` (the line tables' ``at``)
    are one time, taken as it was stored: they read 10-100 ms apart, ``at`` the later."""
    d, effects, records = _station(tmp_path)
    _nok(d, effects, 1, 1)
    repo = records.repo
    assert repo is not None
    (run,) = [e for e in repo.ledger.since(0) if e["kind"] == "rundown"]
    assert _iso(run["at"]) == _iso(run["record"]["recorded_at"]), (
        run["at"], run["record"]["recorded_at"])
    assert _iso(run["record"]["result_at"]) <= _iso(run["at"])
    repo.close()
