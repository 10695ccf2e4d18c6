"""A stop (a kill, a SIGTERM, a reload) between two fetches of a link cut's catch-up, over a
real SQLite database: the cut's rundown of B1 (a NOK, made during the cut) was fetched and
recorded, the retry made during the same cut not fetched yet.  A re-check with an
independent controller found the new station's catch-up storing the retry as no bolt's,
B1 left ending NOK and its tool on again (tightened twice).  The new station takes over
the watch the stopped catch-up kept: a rundown it fetches made by the time the cut's
rundown was stored holds B1; one made later does not."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from drivers.keeper import FaultKind
from stationd.shell.records import Records
from stationd.station.actions import LoadVehicle, Record, StoreCutUnknown
from stationd.station.core import StationCore
from stationd.station.inputs import (
    CaughtUp,
    DeviceBack,
    DeviceFault,
    ResultIn,
    Started,
    VehicleLoaded,
)
from tests.shell.test_records_copies import PARAMS, _records, _result, _sel


def _stopped_after_the_cut_s_rundown(tmp_path: Path, offline: bool = True) -> Records:
    """B1 enabled; its NOK (7), made during a link cut, fetched and recorded (``offline``);
    then the station stops (its repository closed) and a new one opens the database."""
    first = _records(tmp_path)
    assert isinstance(first.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    b1 = _sel("B1")
    first.note_enable(b1)
    nok = dataclasses.replace(_result(7), ok=False)
    first.write(first.unsaved_result(Record("VIN1", "B1", nok, b1, offline=offline,
                                            t=time.time()), None))
    assert first.repo is not None
    first.repo.close()
    return _records(tmp_path)


def _new_core(records: Records) -> tuple[StationCore, float]:
    """The new station's core, told what the last one owed, the vehicle loaded again and
    the controller back (its catch-up under way).  When the cut's rundown was stored."""
    owed = records.owed(late_result_s=5.0)
    assert owed is not None and owed.cut_rundown is not None
    tid, stored = owed.cut_rundown
    assert tid == 7 and owed.selection.bolt == "B1" and not owed.in_window
    core = StationCore(PARAMS, leave_frames=2)
    core.resume(owed)
    core.feed(Started(time.time()))
    loaded = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(loaded, VehicleLoaded)
    core.feed(loaded)
    core.feed(DeviceBack(time.time(), "wrench", reconnects=0))
    return core, stored


def test_the_retry_the_stopped_catch_up_had_not_fetched_holds_the_cut_s_bolt(
        tmp_path: Path) -> None:
    records = _stopped_after_the_cut_s_rundown(tmp_path)
    core, stored = _new_core(records)
    acts = core.feed(ResultIn(time.time(), _result(8), fetched=True, follows=7,
                              made_at=stored - 1.0))
    acts += core.feed(CaughtUp(time.time(), True, "", 0))
    assert not any(isinstance(a, Record) for a in acts)
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, StoreCutUnknown)] == [("VIN1", "B1")]
    assert "B1" not in core.allowed()
    assert records.repo is not None
    records.repo.close()


def test_the_watch_outlives_the_controller_down_at_the_start(tmp_path: Path) -> None:
    """A reviewer: nothing tested that the watch restored at the start outlives the
    controller's fault before its first catch-up (the controller down as the station
    starts)."""
    records = _stopped_after_the_cut_s_rundown(tmp_path)
    core, stored = _new_core(records)
    core.feed(DeviceFault(time.time(), "wrench", FaultKind.DOWN, "connection refused"))
    core.feed(DeviceBack(time.time(), "wrench", reconnects=1))
    acts = core.feed(ResultIn(time.time(), _result(8), fetched=True, follows=7,
                              made_at=stored - 1.0))
    acts += core.feed(CaughtUp(time.time(), True, "", 1))
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, StoreCutUnknown)] == [("VIN1", "B1")]
    assert records.repo is not None
    records.repo.close()


def test_a_rundown_made_after_the_cut_s_rundown_was_stored_holds_nothing(
        tmp_path: Path) -> None:
    """Made after (the station stopped, the tool went on from the controller's own panel,
    say), or when not known: not known to be that catch-up's (it may have ended long before:
    a reviewer, an old bolt held at every start); nor does a first catch-up that ends
    incomplete hold it; and after the first catch-up, nothing is watched any more."""
    for made, complete in ((+60.0, True), (None, True), (None, False)):
        folder = tmp_path / f"{made}-{complete}"
        folder.mkdir()
        records = _stopped_after_the_cut_s_rundown(folder)
        core, stored = _new_core(records)
        acts = core.feed(ResultIn(time.time(), _result(8), fetched=True, follows=7,
                                  made_at=None if made is None else stored + made))
        acts += core.feed(CaughtUp(time.time(), complete, "" if complete else "refused", 0))
        acts += core.feed(ResultIn(time.time(), _result(9), fetched=True, follows=8,
                                   made_at=stored - 1.0))
        assert not any(isinstance(a, StoreCutUnknown) for a in acts), (made, complete)
        assert "B1" in core.allowed()
        assert records.repo is not None
        records.repo.close()


def test_a_last_rundown_made_with_the_link_up_is_owed_nothing(tmp_path: Path) -> None:
    records = _stopped_after_the_cut_s_rundown(tmp_path, offline=False)
    assert records.owed(late_result_s=5.0) is None
    assert records.repo is not None
    records.repo.close()


def test_a_hold_decided_as_its_vehicle_loads_is_kept_when_the_load_read_first(
        tmp_path: Path) -> None:
    """A reviewer: the restart's catch-up held B1 while VIN1 was loading; the load's read of
    the database came before the hold was stored, and B1 came up open.  The core keeps the
    holds it decided for a vehicle not loaded until the next load, and applies them."""
    records = _stopped_after_the_cut_s_rundown(tmp_path)
    owed = records.owed(late_result_s=5.0)
    assert owed is not None and owed.cut_rundown is not None
    core = StationCore(PARAMS, leave_frames=2)
    core.resume(owed)
    core.feed(Started(time.time()))
    core.feed(DeviceBack(time.time(), "wrench", reconnects=0))
    loaded = records.load_vehicle(LoadVehicle(12, "VIN1"))   # read before the hold is stored
    assert isinstance(loaded, VehicleLoaded) and "B1" not in loaded.held
    acts = core.feed(ResultIn(time.time(), _result(8), fetched=True, follows=7,
                              made_at=owed.cut_rundown[1] - 1.0))
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, StoreCutUnknown)] == [("VIN1", "B1")]
    core.feed(loaded)
    assert "B1" not in core.allowed() and "B1" in core.status().held
    assert records.repo is not None
    records.repo.close()
