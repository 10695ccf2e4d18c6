"""The scripted operator's pure parts: its plan on a vehicle from what the station says
(done, skipped, locked), so a round on a vehicle that stays across a reload goes on where the
last one was."""

from __future__ import annotations

from stationd.sim.operator import Plan, plan_of


def test_a_fresh_vehicle_is_visited_in_the_plans_order():
    assert plan_of(["B07", "B02", "B11"], set(), set()) == Plan(("B07", "B02", "B11"), (), ())


def test_bolts_done_or_skipped_are_left_out_and_a_lock_waits_for_a_release():
    """After a reload the new round read the plan anew: it hovered on each bolt done ("already
    done") and went past the lock it waited on."""
    plan = plan_of(["B46", "B11", "B02", "B30", "B07"], finished={"B11", "B30", "B99"},
                   stopped_now={"B46", "B50"})
    assert plan.visit == ("B02", "B07")
    assert plan.waiting == ("B46",)             # not gone past: a person's release first
    assert plan.finished == ("B11", "B30")
