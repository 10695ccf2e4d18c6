"""The screens' bolts against a real core, case by case (an independent review of the core's
writing every bolt's state, issue 31): attention that ends in the core's status, a slow
database's late record, the controller's refusal of a skipped bolt, a closed vehicle's late
loosening, a done bolt a gap holds."""

from __future__ import annotations

from db.kinds import LOOSENED, NOK
from stationd.station.core import StationCore
from stationd.station.inputs import Started
from stationd.station.policy import NokPolicy, NokRule
from tests.station.test_core import PARAMS, _on
from tests.web.test_view_core import Screened, _rundown, _screened


def _selected_then_left(d: Screened, bolt: int) -> None:
    """The wrench on ``bolt``: selected, the tool on; taken away before any rundown."""
    _on(d, bolt, 2)
    d.step(("ack", 0.01, True))
    _on(d, bolt, 1)
    assert d.tool
    d.step(("loc", 0.1, 0, 0.05, 0.0))   # out of view: the tool goes off, no result
    assert not d.tool


def test_a_loosened_bolt_left_before_its_rundown_is_still_drawn_loosened():
    d = _screened()
    _rundown(d, 1, 1, ok=False)    # a NOK under the loosen strategy
    _rundown(d, 1, 2, ok=True)     # its loosening OK: loosened last
    assert d.view.bolts["B1"].state == LOOSENED
    # the core holds B1 loosened (its tightening pset next); the screen falls to "to do"
    # (_tool_off's _set(PENDING)): Screened's check fails, the status is not the core's
    _selected_then_left(d, 1)
    assert d.view.bolts["B1"].state == LOOSENED, d.view.bolts["B1"]


def test_a_nok_bolt_open_again_left_before_its_rundown_is_still_drawn_nok():
    d = Screened(core=StationCore(PARAMS, leave_frames=2,
                                  nok=NokPolicy(NokRule(3, "repeat", None))))
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VIN1"))
    _rundown(d, 1, 1, ok=False)    # NOK, open again (repeat): its last rundown a NOK
    assert d.view.bolts["B1"].state == NOK
    # selected again, left: drawn "to do" where the core (and the report) says NOK
    _selected_then_left(d, 1)
    assert d.view.bolts["B1"].state == NOK, d.view.bolts["B1"]


def _closed_loosening_due(d: Screened) -> int:
    """B1 tightened OK, a person's loosen command on it, the tool on for its loosen pset; the
    lift goes down before its result: the vehicle closes with B1's result due."""
    from stationd.station.actions import CloseVehicle
    from stationd.station.commands import LoosenBolt
    from stationd.station.inputs import VehicleEnded
    from tests.station.test_commands import SUPERVISOR
    _rundown(d, 1, 1, ok=True)
    d.command(1, LoosenBolt("VIN1", "B1", "washer missing"), SUPERVISOR)
    _on(d, 1, 2)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    assert d.tool and d.core.selection is not None and d.core.selection.loosen
    pset = d.core.selection.pset
    assert pset is not None
    for _ in range(4):
        d.step(("lift", 0.05, False, False, None))
    close = [a for _, acts in d.log for a in acts if isinstance(a, CloseVehicle)]
    assert d.core.vin is None and close and close[0].due == ("B1",), close
    # the database closes it: B2, B3 missing, B1's result due
    d.feed(VehicleEnded(d.t, "VIN1", missing=("B2", "B3"), due=("B1",)))
    assert d.view.closed is not None and d.view.closed["due"] == ["B1"]
    return pset


def test_a_late_loosening_nok_of_a_closed_vehicle_counts_it_ending_nok():
    from db.kinds import LOOSENING
    from stationd.station.events import ResultRecorded
    from stationd.station.inputs import ResultIn
    from tests.station.test_loosen import res
    d = _screened()
    pset = _closed_loosening_due(d)
    assert not d.view.loaded and d.view.counters()["nok"] == 0
    # its loosening, in its window: a NOK (the joint did not come loose); stored late, as
    # the records say it the bolt ends NOK (db.report._status: a loosening NOK is NOK)
    d.feed(ResultIn(d.t, res(2, pset, False)))
    d.view.apply(ResultRecorded("VIN1", "B1", False, 60.0, 2.0, 2, pset=pset, late=True,
                                kind=LOOSENING))
    assert d.view.counters()["nok"] == 1, d.view.bolts["B1"]


def test_a_result_stored_late_leaves_the_bolt_the_tool_is_on_again_drawn_so():
    from stationd.station.events import ResultRecorded
    from stationd.station.inputs import ResultIn
    from stationd.web.view import Shown
    from tests.station.test_loosen import res
    d = _screened()
    _on(d, 1, 2)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    pset = d.core.selection.pset
    d.feed(ResultIn(d.t, res(1, pset, False)))   # a NOK: its loosen pset next
    # its record slow (the database busy, or down and back): meanwhile the wrench stays on
    # B1, selected again for its loosen pset, the tool on
    _on(d, 1, 2)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    assert d.tool and d.core.selection.loosen
    assert d.view.selected == "B1" and d.view.bolts["B1"].state == Shown.SELECTED
    # the NOK's record done: the screen's news of it
    d.view.apply(ResultRecorded("VIN1", "B1", False, 41.0, 31.0, 1, pset=pset))
    assert d.view.selected == "B1", "the selection of the bolt the tool is on was dropped"
    assert d.view.bolts["B1"].state == Shown.SELECTED, d.view.bolts["B1"]


def test_a_bolt_skipped_by_the_controller_s_refusal_is_drawn_and_counted_skipped():
    from db.kinds import SKIPPED
    d = _screened()
    _on(d, 2, 2)
    d.step(("ack", 0.01, False))    # the controller refuses B2's parameters: B2 skipped
    assert "B2" in d.core.matcher.skipped
    # BoltsChanged (SKIPPED) comes first, then ParamsRefusedEvent draws it "blocked" over
    # it, and BoltSkipped's words find it not drawn skipped: blocked for good (a status the
    # core never holds), not counted skipped, and said missing when the vehicle leaves
    assert d.view.bolts["B2"].state == SKIPPED, d.view.bolts["B2"]
    assert d.view.counters()["skipped"] == 1


def _done_and_held_by_a_gap() -> Screened:
    """B1 run down (41, its push lost), its window's check finding nothing; run down again,
    OK (42), whose push reveals 41 as a gap that may be its first rundown: done and held."""
    from stationd.station.inputs import NewestChecked
    from tests.station.test_gap_again import _again_and_revealed
    from tests.station.test_lost import _window_ends
    d = Screened(core=StationCore(PARAMS, leave_frames=2))
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VIN1"))
    check = _window_ends(d, 1, 3.0)
    d.feed(NewestChecked(d.t, serial=check.serial))
    _again_and_revealed(d)
    m = d.core.matcher
    assert m is not None and "B1" in m.done and "B1" in m.held
    return d


def test_a_done_bolt_held_by_a_gap_is_not_drawn_nok_when_the_vehicle_leaves():
    from stationd.station.inputs import VehicleEnded
    d = _done_and_held_by_a_gap()
    for _ in range(4):
        d.step(("lift", 0.05, False, False, None))
    # the records: B1's last rundown OK (neither missing nor NOK), B2 and B3 missing
    d.feed(VehicleEnded(d.t, "VIN1", missing=("B2", "B3")))
    # View._close: a bolt drawn LOCKED not missing is drawn NOK, "locked when the vehicle
    # left" -- a held bolt whose last rundown is an OK
    assert d.view.bolts["B1"].state != NOK, d.view.bolts["B1"]


def test_a_done_bolt_released_from_a_gap_s_hold_is_not_said_to_be_checked_before_tightening():
    from db.kinds import OK
    from stationd.station.commands import ReleaseBolt
    from stationd.web.view import CHECK_FIRST_WORDS
    from tests.station.test_commands import SUPERVISOR
    d = _done_and_held_by_a_gap()
    d.command(1, ReleaseBolt("VIN1", "B1", "checked on the controller"), SUPERVISOR)
    b = d.view.bolts["B1"]
    assert b.state == OK and "B1" in d.core.matcher.done
    # the core marks it check-first (orders.py adds every released hold's bolt, done or
    # not), and the screen's release words say it may be tightened already: check the
    # controller before tightening -- a bolt drawn OK, never to be tightened again
    assert CHECK_FIRST_WORDS not in b.reason and not b.check_first, b
