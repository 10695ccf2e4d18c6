"""The scripted operator's pure parts: its plan on a vehicle from what the station says
(done, skipped, locked), so a round on a vehicle that stays across a reload goes on where the
last one was; and whom it signs in as (a user of the station file's operator role)."""

from __future__ import annotations

from pathlib import Path

import yaml

from stationd.config import load_station_config
from stationd.sim.in_daemon import SIM_OPERATOR, sim_operator
from stationd.sim.operator import Plan, plan_of
from stationd.station.commands import Right
from tests.shell.test_commands_daemon import HASH

ROOT = Path(__file__).resolve().parents[2]


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


def _cfg(tmp: Path, access: dict[str, object] | None):
    for f in (ROOT / "config" / "sim").glob("*.yaml"):
        (tmp / f.name).write_text(f.read_text())
    doc = yaml.safe_load((tmp / "station.yaml").read_text())
    doc.pop("access", None)
    if access is not None:
        doc["access"] = access
    (tmp / "station.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_station_config(tmp / "station.yaml")


def test_the_operator_signs_in_as_a_user_of_the_operator_role(tmp_path):
    users = {"sam": {"role": "supervisor", "password": HASH},
             "zoe": {"role": "operator", "password": HASH},
             "olga": {"role": "operator", "password": HASH}}
    who, said = sim_operator(_cfg(tmp_path, {"users": users, "operator_required": True}))
    assert said is None and who is not None
    assert who.user == "olga" and who.rights == frozenset({Right.SKIP})     # first by name


def test_without_an_operator_user_its_own_name_unless_sign_in_is_required(tmp_path):
    who, said = sim_operator(_cfg(tmp_path, None))              # config/sim: no access
    assert who == SIM_OPERATOR and said is not None
    assert "has the operator role: the operator signs in as 'operator'" in said
    supervisor = {"users": {"sam": {"role": "supervisor", "password": HASH}}}
    assert sim_operator(_cfg(tmp_path, supervisor))[0] == SIM_OPERATOR
    who, said = sim_operator(_cfg(tmp_path, {**supervisor, "operator_required": True}))
    assert who is None and said is not None        # not the supervisor's name on rundowns
    assert "requires a signed-in operator" in said and "for a person to sign in" in said


def test_the_simulated_supervisor_releases_as_a_releaser_of_the_file(tmp_path):
    """Releases were recorded by 'supervisor', no user of a file that names its supervisors
    (a new user's trial), while the operator signed in as the file's own."""
    from stationd.sim.operator import SUPERVISOR, supervisor_of

    users = {"zed": {"role": "supervisor", "password": HASH},
             "sam": {"role": "supervisor", "password": HASH},
             "olga": {"role": "operator", "password": HASH}}
    who = supervisor_of(_cfg(tmp_path, {"users": users}), "demo")
    assert (who.user, who.source) == ("sam", "demo") and Right.RELEASE in who.rights
    alone = supervisor_of(_cfg(tmp_path, None), "sim operator")   # config/sim: no access
    assert (alone.user, alone.rights, alone.source) == (SUPERVISOR.user, SUPERVISOR.rights,
                                                        "sim operator")


def test_a_bolt_not_selected_without_a_refusal_says_how_many_frames_came():
    """"not selected (tracking the wrench)" on a loaded machine said nothing of why: the
    localizations of the operator's wait are counted (a line engineer's trial)."""
    from types import SimpleNamespace

    from stationd.bus import EventBus
    from stationd.reasons import Reason, Why
    from stationd.sim.operator import _why_not
    from stationd.station.core import StationCore
    from stationd.station.events import Localized

    def seen(t: float, reason: Reason | None = None) -> Localized:
        return Localized(point_mm=(0.0, 0.0, 0.0), tilt_deg=1.0, reason=reason,
                         candidate=None, distance_mm=None, age_ms=30.0, allowed=(), t=t)

    bus = EventBus()
    for t in (10.0, 50.0, 70.0, 75.0):
        bus.publish(seen(t))
    st = SimpleNamespace(bus=bus, core=StationCore())
    said = _why_not(st)
    assert said.endswith("; 3 localizations in the last 30 s, the last without a refusal: a "
                         "machine too busy for the frames a selection needs?"), said
    bus.publish(seen(76.0, Reason(Why.NOT_LOCALIZED, note="marker not found")))
    assert "localizations in the last" not in _why_not(st)
