"""A bolt held while its loosen pset ran (the loosening's result unreadable), across a restart
(stationd/shell/records.py ``load_vehicle`` and ``record_command``): the vehicle loaded again
brings the hold with what its result came under, so the core still takes the outcome a
supervisor enters for it as a loosening's, and the shell records it as one; the bolt is then
loosened, never done, also in the next load."""

from __future__ import annotations

import time
from pathlib import Path

from db.kinds import LOOSENED, LOOSENING, NOK, HeldUnder
from drivers.wrench.base import UnreadableResult
from stationd.config import StationConfig
from stationd.shell.records import Records
from stationd.station.actions import LoadVehicle, RecordCommand, Selection, StoreUnreadable
from stationd.station.commands import EnterOutcome, Issuer, Right
from stationd.station.core import StationCore
from stationd.station.events import ResultRecorded
from stationd.station.inputs import CommandDone, CommandIn, VehicleLoaded
from stationd.station.policy import NokPolicy, NokRule, Strategy
from tests.db.conftest import BASE, record, url_of
from tests.station.test_core import PARAMS, published

SUPERVISOR = Issuer("sam", frozenset(Right), "cli")


def _loaded(records: Records) -> VehicleLoaded:
    loaded = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(loaded, VehicleLoaded)
    return loaded


def test_a_held_loosening_s_entered_ok_is_a_loosening_after_a_restart(tmp_path: Path) -> None:
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    first = _loaded(records)
    assert records.repo is not None
    record(records.repo, "VIN1", "B1", ok=False, tightening_id=1)
    # the station before the restart: B1's loosen pset 90 enabled, its result unreadable
    sel = Selection("B1", 90, (0.0, 0.0, 0.0), 1.0, 0.5, 1.0, 1.1, None, "VIN1",
                    first.bolts["B1"].parameters_id, loosen=True, operator="olga")
    records.note_enable(sel)
    records.store_unreadable(StoreUnreadable(
        UnreadableResult("0061 garbage", 61, 7, "parameter 01 missing", tightening_id=2,
                         pset=90), "VIN1", "B1", sel))
    again = _loaded(records)                                  # as after a restart
    assert again.held == {"B1": "tightening 2"}
    assert again.held_under == {"B1": HeldUnder(True, 90)}
    assert again.status["B1"] == NOK
    core = StationCore(PARAMS, leave_frames=2, nok=NokPolicy(NokRule(3, Strategy.LOOSEN, 90)))
    core.feed(again)
    assert core.status().held == {"B1"}
    acts = core.feed(CommandIn(time.time(), 1, EnterOutcome(
        "VIN1", "B1", True, 8.0, 400.0, "the controller shows the loosening OK"), SUPERVISOR))
    [rc] = [a for a in acts if isinstance(a, RecordCommand)]
    assert records.record_command(rc, "VIN1") is None
    [rec] = published(core.feed(CommandDone(time.time(), 1)), ResultRecorded)
    assert (rec.kind, rec.pset, rec.ok) == (LOOSENING, 90, True)
    assert "B1" not in core.status().done and not core.status().held
    run = records.repo.ledger.since(0)[-1]["record"]
    assert (run["rundown"], run["status"], run["entered_by"]) == (LOOSENING, "ok", "sam")
    after = _loaded(records)                                  # and after the next restart
    assert after.held == {} and after.status["B1"] == LOOSENED and "B1" not in after.done
    records.repo.close()
