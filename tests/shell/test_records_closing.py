"""A vehicle that leaves while its last bolt's result is still due from the controller
(the core, :mod:`stationd.station.lift`, and the records, :mod:`stationd.shell.records`,
over a real SQLite database).  A supervisor's trial: the tool ran on B1 (its NOK before, a
retry) and the lift went down before the result's push arrived; the close said B1 "ending
NOK", the journal and the screens with it, and the OK recorded a moment later changed
nothing of that verdict.  Now the close says B1's result due (neither NOK nor missing), and
once it is recorded to that vehicle (or can no longer come) the verdict is said again from
the records: an event on the bus and a journal line."""

from __future__ import annotations

import logging
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest

from drivers.wrench.base import Status, TighteningResult
from stationd.config import StationConfig
from stationd.shell.records import Records
from stationd.station.actions import CloseVehicle, LoadVehicle, Publish, Record, SettleClosing
from stationd.station.events import ClosingSettled, VehicleClosed
from stationd.station.inputs import (
    LiftRead,
    NewestChecked,
    ResultIn,
    Tick,
    VehicleLoaded,
    Written,
)
from tests.db.conftest import url_of
from tests.station.test_core import _ready
from tests.station.test_result_types import _enabled

BOLTS = """\
psets:
  - id: 1
    torque: {target: 50, min: 45, max: 55}
  - id: 2
    torque: {target: 50, min: 45, max: 55}
models:
  M:
    code: 7
    bolts:
      - {id: B1, name: one, position: [0, 0, 0], pset: 1}
      - {id: B2, name: two, position: [60, 0, 0], pset: 2}
      - {id: B3, name: three, position: [0, 60, 5], pset: 1}
"""
AT = datetime(2026, 12, 1, 8, 0, 0)


def _result(tid: int, ok: bool, pset: int = 1) -> TighteningResult:
    st = Status.OK if ok else Status.LOW
    return TighteningResult(ok, 50.0 if ok else 20.0, 30.0, st, Status.OK, tid, pset, "", AT,
                            45.0, 55.0, 50.0, 15.0, 60.0, 30.0)


class Station:
    """The core played by the test driver, its records on disk: the Records, Closes and
    Settles carried out as the shell does, each outcome fed back; what was published."""

    def __init__(self, tmp_path: Path) -> None:
        bolts = tmp_path / "bolts.yaml"
        bolts.write_text(BOLTS)
        self.records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"),
                                             bolts_path=bolts))
        self.records.open()
        self.published: list[Any] = []
        self.d = _ready()
        loaded = self.records.load_vehicle(LoadVehicle(7, "VIN1"))
        assert isinstance(loaded, VehicleLoaded)

    def feed(self, ev: Any) -> list[Any]:
        acts = self.d.feed(ev)
        self.carry(acts)
        return acts

    def carry(self, acts: list[Any]) -> None:
        for a in acts:
            if isinstance(a, Publish):
                self.published.append(a.event)
            elif isinstance(a, Record):
                u = self.records.unsaved_result(a, None)
                self.records.write(u)
                self.feed(Written(self.d.t, a))
            elif isinstance(a, CloseVehicle):
                self.feed(self.records.close_vehicle(a.vin, a.after_lift_outage, a.due))
            elif isinstance(a, SettleClosing):
                self.feed(self.records.settle_closing(a))

    def of(self, kind: type) -> list[Any]:
        return [e for e in self.published if isinstance(e, kind)]


def _retry_as_the_lift_goes_down(st: Station) -> None:
    """B2 tightened OK; B1 NOK, then B1's tool on again and the lift going down as the
    operator pulls (the result's push not in yet)."""
    d = st.d
    _enabled(d, 2)
    st.feed(ResultIn(d.t, _result(40, True, pset=2)))
    _enabled(d, 1)
    st.feed(ResultIn(d.t, _result(41, False)))
    _enabled(d, 1)
    d.t += 0.3
    d.ready = d.at_height = False
    st.feed(LiftRead(d.t, False, False, 7, "VIN1"))


def test_a_result_due_as_the_vehicle_leaves_is_said_due_then_the_verdict_follows_it(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    st = Station(tmp_path)
    caplog.set_level(logging.INFO, logger="stationd")
    _retry_as_the_lift_goes_down(st)
    [closed] = st.of(VehicleClosed)
    assert (closed.vin, closed.missing, closed.nok, closed.due) == ("VIN1", ("B3",), (),
                                                                    ("B1",))
    [line] = [r.getMessage() for r in caplog.records if "closed:" in r.getMessage()]
    assert "0 ending NOK" in line and "1 result due (B1)" in line, line
    assert "1 missing (B3)" in line, line
    assert not st.of(ClosingSettled)
    # B1's OK comes (its late-result window): recorded to B1 of VIN1, the verdict said again
    st.d.t += 0.5
    st.feed(ResultIn(st.d.t, _result(42, True)))
    [settled] = st.of(ClosingSettled)
    assert (settled.vin, settled.missing, settled.nok, settled.due, settled.settled) == \
        ("VIN1", ("B3",), (), (), ("B1",))
    assert st.records.repo is not None
    report = st.records.repo.vehicle_report("VIN1")
    assert report.ok == ["B1", "B2"] and report.nok == []
    [again] = [r.getMessage() for r in caplog.records if "closing verdict" in r.getMessage()]
    assert "settled (B1 OK)" in again and "2 OK, 0 ending NOK" in again, again
    assert "result due (" not in again, again            # none due any more


def test_a_result_due_that_never_comes_settles_as_missing_once_the_check_found_nothing(
        tmp_path: Path) -> None:
    """B1's result never comes: its window ends, the controller's newest checked finds
    nothing made: the verdict follows, B1 ending NOK (its last rundown, as recorded)."""
    st = Station(tmp_path)
    st.d.answer_checks = False
    _retry_as_the_lift_goes_down(st)
    st.d.t += st.d.core.late_result_s + 1.0
    st.feed(Tick(st.d.t))
    assert not st.of(ClosingSettled), "the check still runs: B1's result may come"
    st.feed(NewestChecked(st.d.t, nothing_made=True, serial=st.d.core.status().checking))
    [settled] = st.of(ClosingSettled)
    assert (settled.missing, settled.nok, settled.due, settled.settled) == \
        (("B3",), ("B1",), (), ("B1",))


def test_a_vehicle_closing_with_nothing_due_is_said_once_as_before(tmp_path: Path) -> None:
    st = Station(tmp_path)
    d = st.d
    _enabled(d, 1)
    st.feed(ResultIn(d.t, _result(41, False)))
    d.t += d.core.late_result_s + 1.0
    st.feed(Tick(d.t))
    d.ready = d.at_height = False
    d.step(("lift", 0.2, False, False, "VIN1"))
    st.carry([a for _, acts in d.log[-1:] for a in acts])
    [closed] = st.of(VehicleClosed)
    assert (closed.missing, closed.nok, closed.due) == (("B2", "B3"), ("B1",), ())
    d.t += 30.0
    st.feed(Tick(d.t))
    assert not st.of(ClosingSettled)
