"""An outcome a supervisor entered for a held bolt, in the database: the command and its
rundown written together, the rundown marked entered (who, why, the unreadable result it
resolves) in the feed and the exports, the hold over for a restart, and a NOK entered counted
in the bolt's NOK row like a measured one."""

from __future__ import annotations

import csv
import io
import math
from datetime import UTC, datetime, timedelta

import pytest

from db.entered import record_entered
from db.errors import DataError
from db.ledger import COMMAND, RUNDOWN
from stationd.web.results import Results, rundowns_csv
from tests.db.conftest import record
from tests.db.test_controller_records import _unreadable


def _enter(repo, ok: bool = True, bolt: str = "B1", **kw):
    args = {"torque_nm": 49.6, "angle_deg": 31.0, "at": datetime.now(UTC) + timedelta(
        seconds=1), "user": "sam", "source": "cli", "comment": "read on the controller", **kw}
    return record_entered(repo, vin="VIN1", bolt=bolt, ok=ok, **args)


def test_an_entered_ok_is_a_rundown_marked_entered_that_ends_the_hold(sedan):
    repo = sedan
    sel = {"point_mm": [1.0, 2.0, 3.0], "tilt_deg": 2.5, "distance_mm": 0.7,
           "exposure_t": 1.0, "decided_t": 1.1, "loosen": False, "operator": "olga"}
    version = repo.bolts_for_model("SEDAN")[0].parameters_id
    repo.note_enable("VIN1", "B1", 1, version, sel, datetime.now(UTC))
    uid = _unreadable(repo, 12, "B1")
    assert repo.held_bolts("VIN1") == {"B1": "tightening 12"}
    rid = _enter(repo)
    assert repo.held_bolts("VIN1") == {}                 # a restart holds it no more
    [cmd_entry, run_entry] = repo.ledger.since(1)        # after the unreadable's entry
    assert cmd_entry["kind"] == COMMAND and run_entry["kind"] == RUNDOWN
    assert (cmd_entry["record"]["kind"], cmd_entry["record"]["bolt"],
            cmd_entry["record"]["user"]) == ("enter-outcome", "B1", "sam")
    run = run_entry["record"]
    assert run["id"] == rid and run["status"] == "ok" and run["rundown"] == "tightening"
    assert (run["torque_nm"], run["angle_deg"], run["tightening_id"]) == (49.6, 31.0, 12)
    assert (run["entered_by"], run["entered_comment"], run["unreadable_id"]) == (
        "sam", "read on the controller", uid)
    # the enable its unreadable result answered: where the wrench was, who held it
    assert run["position_mm"] == [1.0, 2.0, 3.0] and run["operator"] == "olga"
    assert repo.vehicle_report("VIN1").bolts[0].status == "ok"
    # the export says it was entered, and by whom
    rows = list(csv.DictReader(io.StringIO(rundowns_csv(Results(repo).export("VIN1")))))
    [b1] = [r for r in rows if r["bolt"] == "B1" and r["status"] == "ok"]
    assert (b1["entered_by"], b1["comment"]) == ("sam", "read on the controller")
    [vehicle_b1] = [b for b in Results(repo).vehicle("VIN1")["bolts"] if b["bolt"] == "B1"]
    assert vehicle_b1["rundowns"][0]["entered_by"] == "sam"


def test_a_measured_rundown_says_it_is_not_entered(sedan):
    record(sedan, "VIN1", "B2", tightening_id=3)
    [entry] = sedan.ledger.since(0)
    assert entry["record"]["entered_by"] is None and entry["record"]["unreadable_id"] is None


def test_an_entered_nok_counts_in_the_nok_row(sedan):
    repo = sedan
    record(repo, "VIN1", "B1", ok=False, tightening_id=1)
    _unreadable(repo, 2, "B1")
    _enter(repo, ok=False, torque_nm=56.1)
    assert repo.nok_streaks("VIN1") == {"B1": 2}
    assert repo.held_bolts("VIN1") == {}


def test_an_entered_outcome_without_a_stored_unreadable_result_still_records(sedan):
    _enter(sedan, bolt="B2")
    [_, run] = sedan.ledger.since(0)
    assert run["record"]["unreadable_id"] is None and run["record"]["tightening_id"] is None
    assert run["record"]["position_mm"] == [0.0, 0.0, 0.0]


def test_an_entered_outcome_needs_finite_values_and_an_open_vehicle(sedan):
    with pytest.raises(DataError):
        _enter(sedan, torque_nm=math.nan)
    sedan.close_vehicle("VIN1")
    with pytest.raises(DataError, match="closed"):
        _enter(sedan)
    assert sedan.ledger.commands("VIN1") == []     # nothing written, not even the command


def test_opc_ua_says_an_entered_result_was_entered_and_by_whom():
    from stationd.opcua.results import message

    rec = {"vin": "VIN1", "bolt": "B1", "rundown": "tightening", "status": "ok"}
    assert message(rec) == "VIN1 B1: tightening OK"
    assert message({**rec, "entered_by": "sam"}) == \
        "VIN1 B1: tightening OK (entered by sam, not measured)"
