"""Review finding: a person's loosen command now discards ``_nok_last``; a NOK whose push
was lost, fetched while the pushed result after it is awaited (its NOK policy owed until
that one is judged: :meth:`LostRules._push_judged`), loses its policy -- its lock at
``max_nok`` -- when a loosen command lands in between."""

from __future__ import annotations

from stationd.station.commands import LoosenBolt
from stationd.station.inputs import ResultIn, ResultsSkipped
from stationd.station.policy import NokPolicy, NokRule
from tests.station.test_commands import SUPERVISOR
from tests.station.test_core import _ready
from tests.station.test_result_types import _enabled, res


def test_a_loosen_command_between_a_lost_nok_and_its_pushed_result_keeps_the_lock_due():
    d = _ready(nok=NokPolicy(NokRule(max_nok=1, strategy="repeat", loosen_pset=90)))
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 5.0
    d.feed(ResultsSkipped(d.t, 42))
    # B1's NOK 41, its push lost, fetched: max_nok (1) reached, its lock due once 42 is judged
    d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                    made_at=enabled_at + 3.0, live=True, before=42))
    assert d.core._lock_due == {"B1": 1} and "B1" not in d.core.matcher.locked
    # meanwhile a supervisor orders B1 loosened (its last rundown a NOK: accepted)
    acts = d.command(1, LoosenBolt("VIN1", "B1", "rework"), SUPERVISOR)
    assert "B1" in d.core._loosen, acts
    # 42 pushed (a batch increment, no rundown): the NOK policy owed applies now
    d.feed(ResultIn(d.t, res(42, 1, True, 3)))
    # 1 NOK in a row with max_nok 1: locked, as without the command, and as the records say
    # at a reload (db nok_streaks: a loosen command does not end the row; VehicleLoaded
    # locks a bolt whose streak reaches max_nok)
    assert d.core.matcher.locked.get("B1") == 1, d.core.matcher.locked
