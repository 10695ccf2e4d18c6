"""The view model says one thing everywhere (issue 19 item 7): one bolt pointed out "next"
when the rules allow many, the wrench panel from the same localization as the map and the
headline, and a station starting up says so rather than "stale"."""

from __future__ import annotations

from stationd.reasons import Reason, Wait, WaitKind, Why
from stationd.station.events import (
    Because,
    BoltSelected,
    Localized,
    Refused,
    StateChanged,
    StateReason,
)
from stationd.web.view import STARTUP_GRACE_S, View, fold
from tests.web.scenario import opened

#: the stale-frames refusal as the operator reads it
STALE_7524 = ("camera frames too old (7524 ms): the cameras or the station's computer fall "
              "behind")

EVERY = ("B1", "B2", "B3", "B4")     # no order: every open bolt is allowed
NOT_SEEN = Reason(Why.NOT_LOCALIZED, note="no purple region in view")


def at(x: float, y: float, allowed: tuple[str, ...] = EVERY, t: float = 10.0,
       reason: Reason | None = None) -> Localized:
    return Localized(point_mm=(x, y, 0.0), tilt_deg=1.5, reason=reason, candidate=None,
                     distance_mm=None, age_ms=30.0, allowed=allowed, t=t)


def lost(reason: Reason = NOT_SEEN, allowed: tuple[str, ...] = EVERY, t: float = 10.0
         ) -> Localized:
    return Localized(point_mm=None, tilt_deg=None, reason=reason, candidate=None,
                     distance_mm=None, age_ms=30.0, allowed=allowed, t=t)


def nexts(v: View) -> list[str]:
    return [b.bolt for b in v.bolts.values() if b.state == "next"]


def test_one_open_bolt_is_next_the_nearest_to_the_wrench():
    v = fold([*opened(), at(390.0, 290.0)])          # by B4 (400, 300)
    assert nexts(v) == ["B4"]
    assert {b.state for b in v.bolts.values()} == {"next", "pending"}
    assert {b["label"] for b in v.to_json()["bolts"]} == {"next", "to do"}
    v.apply(at(10.0, 280.0))                          # by B3
    assert nexts(v) == ["B3"]


def test_out_of_view_the_pointer_stays_else_the_tables_first():
    v = fold([*opened(), at(390.0, 10.0), lost()])
    assert nexts(v) == ["B2"]                        # pointed out last, still open
    assert nexts(fold([*opened(), lost()])) == ["B1"]    # never seen: the table's first
    # only an allowed bolt is pointed out (an order: B3 and B4 wait)
    assert nexts(fold([*opened(), at(390.0, 290.0, allowed=("B1", "B2"))])) == ["B2"]


def test_the_bolt_pointed_out_selected_points_out_another():
    v = fold([*opened(), at(2.0, 1.0)])
    assert nexts(v) == ["B1"]
    v.apply(BoltSelected(bolt="B1", pset=1, point_mm=(2.0, 1.0, 0.0), distance_mm=2.2,
                         tilt_deg=1.0))
    assert v.bolts["B1"].state == "selected" and nexts(v) == ["B3"]   # then the nearest


def test_a_blocked_bolt_stays_blocked_until_allowed_and_is_never_next_before():
    wait = Reason(Why.MUST_WAIT, bolt="B4", wait=Wait(WaitKind.ORDER, order=2, bolts=("B3",)))
    v = fold([*opened(), at(399.0, 299.0, allowed=("B1", "B2", "B3")),
              Refused(reason=wait, bolt="B4")])
    assert v.bolts["B4"].state == "blocked"
    v.apply(at(399.0, 299.0, allowed=("B1", "B2", "B3")))
    assert v.bolts["B4"].state == "blocked" and nexts(v) == ["B2"]
    v.apply(at(399.0, 299.0))                         # the rule allows it now
    assert nexts(v) == ["B4"]


def test_the_wrench_panel_says_what_the_map_and_the_headline_say():
    v = fold(opened())
    assert v.wrench_line() == "not localized"
    v.apply(Localized(point_mm=(401.0, 299.0, 2.0), tilt_deg=1.5, reason=None, candidate="B4",
                      distance_mm=1.4, age_ms=30.0, allowed=EVERY))
    assert v.wrench_line() == "X 401  Y 299  Z 2 mm, tilt 1.5\u00b0, near B4 (1.4 mm)"
    v.apply(lost())
    v.apply(Refused(reason=NOT_SEEN))
    assert v.wrench is not None and "x" not in v.wrench       # no crosshair drawn
    assert v.wrench_line() == "not in view (details: Cameras)"
    assert v.headline() == "Bring the wrench to a bolt"
    tilted = Reason(Why.TILTED, angle_deg=41.4, limit=10.0)
    v.apply(lost(tilted))
    v.apply(Refused(reason=tilted))
    assert v.headline() == "wrench tilted 41.4 deg (> 10 deg)"
    assert v.wrench_line() == f"seen, not used: {v.headline()}"   # not "not in view"
    assert v.to_json()["wrench_line"] == v.wrench_line()


STALE = Reason(Why.STALE, age_ms=7524.0, limit=500.0)


def test_stale_frames_before_any_fresh_one_say_the_station_is_starting():
    start = [StateChanged(state="starting", reason=StateReason(Because.OPENING)), *opened()]
    assert fold(start).headline() == "Starting: waiting for the cameras' first frames"
    v = fold([*start, at(0.0, 0.0, reason=STALE, t=100.0), Refused(reason=STALE, t=100.0)])
    assert v.headline() == "Starting: the cameras' first frames are late (7524 ms old)"
    assert v.tone() == "idle"
    # fresh frames came: stale after them is the stale alarm (amber)
    v.apply(at(200.0, 150.0, t=101.0))
    v.apply(at(0.0, 0.0, reason=STALE, t=102.0))
    v.apply(Refused(reason=STALE, t=102.0))
    assert (v.headline(), v.tone()) == (STALE_7524, "act")
    # a station that never gets a fresh frame says stale after the grace
    v = fold([*start, at(0.0, 0.0, reason=STALE, t=100.0), Refused(reason=STALE, t=100.0),
              at(0.0, 0.0, reason=STALE, t=101.0 + STARTUP_GRACE_S)])
    assert (v.headline(), v.tone()) == (STALE_7524, "act")
    # a reload starts again: the first frames may be late again
    v.apply(StateChanged(state="starting", reason=StateReason(Because.OPENING)))
    v.apply(StateChanged(state="tracking", reason=StateReason(Because.TRACKING)))
    v.apply(at(0.0, 0.0, reason=STALE, t=500.0))
    v.apply(Refused(reason=STALE, t=500.0))
    assert v.headline().startswith("Starting: ")


def test_a_bolt_the_wrench_settles_on_is_not_drawn_blocked():
    """"B21: hold the wrench still on it (1 of 3 frames)" in the headline while B21 was drawn
    "blocked": the bolt the wrench settles on stays the one pointed out; only the sequence
    blocks a bolt."""
    settling = Reason(Why.NOT_STABLE, bolt="B4", count=1, needed=3)
    v = fold([*opened(), at(399.0, 299.0), Refused(reason=settling, bolt="B4")])
    assert v.bolts["B4"].state == "next"
    assert v.headline() == "B4: hold the wrench still on it (1 of 3 frames)"
    assert v.tone() == "idle"


def test_a_wrench_midway_between_two_bolts_does_not_flip_the_pointer():
    v = fold([*opened(), at(190.0, 0.0)])             # B1 at 0, B2 at 400: B1 nearer
    assert nexts(v) == ["B1"]
    for x in (205.0, 195.0, 208.0, 200.0):              # hovering midway
        v.apply(at(x, 0.0))
        assert nexts(v) == ["B1"]
    v.apply(at(230.0, 0.0))                             # clearly nearer B2 now
    assert nexts(v) == ["B2"]
