"""The result published for the screens (:mod:`stationd.station.results`): the windows it was
judged against, as the controller sent them, or, for a result fetched late (MID 0065 carries
none), its bolt's tightening window from the records."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from db.bolts import Parameters, Window
from db.kinds import LOOSENING
from drivers.wrench.base import Status, TighteningResult
from stationd.station.actions import Record
from stationd.station.events import ResultRecorded
from stationd.station.inputs import LoadedBolt, ResultIn, ResultsSkipped, Written
from tests.station.test_core import Driver, _ready, published
from tests.station.test_result_types import _enabled

M10 = Parameters(1, Window(50.0, 45.0, 55.0), Window(30.0, 15.0, 60.0))
BOLTS = {"B1": LoadedBolt((0.0, 0.0, 0.0), 1, parameters=M10),
         "B2": LoadedBolt((60.0, 0.0, 0.0), 2), "B3": LoadedBolt((0.0, 60.0, 5.0), 1)}


def _result(tid: int, limits: bool) -> TighteningResult:
    """A NOK of pset 1, 44.6 Nm (low), with the controller's windows or none (fetched)."""
    lim = (45.0, 55.0, 50.0, 15.0, 60.0) if limits else (0.0, 0.0, 0.0, 0.0, 0.0)
    return TighteningResult(False, 44.6, 34.0, Status.LOW, Status.OK, tid, 1, "",
                            datetime(2026, 12, 1, 8, 0, 0), *lim, 30.0)


def _published(d: Driver, r: TighteningResult, **how: Any) -> ResultRecorded:
    acts = d.feed(ResultIn(d.t, r, **how))
    [rec] = [a for a in acts if isinstance(a, Record)]
    [said] = published(d.feed(Written(d.t, rec)), ResultRecorded)
    assert isinstance(said, ResultRecorded)
    return said


def _ready_b1() -> Driver:
    d = _ready()
    d.bolts = BOLTS
    d.step(("lift", 0.1, False, False, "VIN1"))
    d.step(("lift", 0.1, True, True, "VIN2"))
    assert d.core.vin == "VIN2"
    return d


def test_a_pushed_result_carries_the_controller_s_windows():
    d = _ready_b1()
    _enabled(d, 1)
    said = _published(d, _result(41, limits=True))
    assert (said.torque_min, said.torque_max, said.angle_min, said.angle_max) == \
        (45.0, 55.0, 15.0, 60.0)


def test_a_result_fetched_late_has_its_bolt_s_window_not_zero_to_zero():
    """A new user's trial: the screen said a fetched NOK of 44.6 Nm "torque high, angle high"
    against 0.0-0.0, where it was low against 45-55 and its angle within 15-60."""
    d = _ready_b1()
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 3.0
    d.feed(ResultsSkipped(d.t, 42))   # 42 pushed skipped 41: fetched first
    said = _published(d, _result(41, limits=False), fetched=True, follows=40,
                      made_at=enabled_at + 2.0, live=True, before=42)
    assert said.bolt == "B1" and said.kind != LOOSENING
    assert (said.torque_min, said.torque_max, said.angle_min, said.angle_max) == \
        (45.0, 55.0, 15.0, 60.0)


def test_a_fetched_result_of_a_bolt_without_known_parameters_has_no_window():
    """B3 has no parameters in hand: no window is made up (none known, not 0 to 0)."""
    d = _ready_b1()
    _enabled(d, 3)
    enabled_at = d.t
    d.t += 3.0
    d.feed(ResultsSkipped(d.t, 42))   # 42 pushed skipped 41: fetched first
    said = _published(d, _result(41, limits=False), fetched=True, follows=40,
                      made_at=enabled_at + 2.0, live=True, before=42)
    assert said.bolt == "B3"
    assert (said.torque_min, said.torque_max, said.angle_min, said.angle_max) == \
        (None, None, None, None)
