"""The screens draw a bolt's state as the core holds it (issue 31: one writer of the
station's state).  A real core (the pure core's tests' driver) runs a vehicle through its
NOK policy, its locks and holds and the people's commands; every event it publishes is
folded into the screens' view model, and after every input the view's bolts say what the
core's snapshot says: locked, held, to be loosened (with its loosen pset), checked first,
what the report counts (ending NOK, run down), and a status the screen draws."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from db.kinds import LOOSENED, NOK, OK, PENDING, SKIPPED, TO_LOOSEN
from stationd.station.actions import Publish
from stationd.station.commands import EnterOutcome, LoosenBolt, ReleaseBolt, SkipBolt
from stationd.station.core import StationCore
from stationd.station.inputs import ResultIn, Started, UnreadableIn
from stationd.web.view import Shown, View
from tests.station.test_commands import SUPERVISOR
from tests.station.test_core import PARAMS, Driver, _on
from tests.station.test_loosen import POLICY, res
from tests.station.test_result_types import unreadable

#: what the screen draws for each status the core holds, where no lock and no attention
#: (next, selected, the tool on) is drawn over it
DRAWN = {PENDING: (PENDING, Shown.NEXT, Shown.BLOCKED), OK: (OK,), NOK: (NOK,),
         SKIPPED: (SKIPPED,), TO_LOOSEN: (TO_LOOSEN,), LOOSENED: (LOOSENED,)}


@dataclass
class Screened(Driver):
    """The driver, with a screen folding every event the core publishes."""

    view: View = field(default_factory=View)
    compared: int = 0

    def follow(self, acts: list[Any]) -> None:
        super().follow(acts)
        for a in acts:
            if isinstance(a, Publish):
                self.view.apply(a.event)
        if self.core.vin is None or not self.view.loaded:
            return
        for v in self.core.bolt_views():
            b = self.view.bolts[v.bolt]
            assert (b.locked, b.held) == (v.locked is not None or v.held is not None,
                                          v.held is not None), (v, b)
            assert (b.check_first, b.ends_nok, b.ran) == (v.check_first, v.last_nok, v.ran), \
                (v, b)
            assert b.loosen == (v.status == TO_LOOSEN), (v, b)
            if v.loosen_pset is not None:
                assert b.loosen_pset == v.loosen_pset, (v, b)
            if b.locked:
                assert b.state == Shown.LOCKED, (v, b)
            elif b.state not in (Shown.SELECTED, Shown.TIGHTENING):
                assert b.state in DRAWN[v.status], (v, b)
            self.compared += 1


def _screened() -> Screened:
    d = Screened(core=StationCore(PARAMS, leave_frames=2, nok=POLICY))
    d.feed(Started(d.t))
    d.step(("lift", 0.1, True, True, "VIN1"))
    return d


def _rundown(d: Screened, bolt: int, tid: int, ok: bool) -> None:
    """The wrench on ``bolt`` until the tool is on, then a result of the pset sent."""
    _on(d, bolt, 2)
    d.step(("ack", 0.01, True))
    _on(d, bolt, 1)
    assert d.tool, d.core.reason
    pset = d.core.selection.pset if d.core.selection is not None else None
    d.feed(ResultIn(d.t, res(tid, pset or 0, ok)))


def test_the_screen_draws_every_bolt_as_the_core_holds_it():
    d = _screened()
    request = iter(range(1, 100))
    # B1: NOK under loosen, its loosening NOK twice more: locked; released, loosened, OK
    _rundown(d, 1, 1, ok=False)
    assert d.view.bolts["B1"].state == TO_LOOSEN
    _rundown(d, 1, 2, ok=False)
    _rundown(d, 1, 3, ok=False)
    assert d.view.bolts["B1"].state == Shown.LOCKED and "B1" in d.core.matcher.locked
    d.command(next(request), ReleaseBolt("VIN1", "B1", "checked"), SUPERVISOR)
    assert d.view.bolts["B1"].state == TO_LOOSEN
    _rundown(d, 1, 4, ok=True)
    assert d.view.bolts["B1"].state == LOOSENED
    _rundown(d, 1, 5, ok=True)
    assert d.view.bolts["B1"].state == OK
    # a person's loosen command on it: to be loosened, no longer done
    d.command(next(request), LoosenBolt("VIN1", "B1", "washer missing"), SUPERVISOR)
    assert d.view.bolts["B1"].state == TO_LOOSEN
    # B2: its result not read: held; released (checked first), then its own result
    _on(d, 2, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    d.feed(UnreadableIn(d.t, unreadable(6, d.core.selection.pset if d.core.selection
                                         else 0)))
    assert d.view.bolts["B2"].held and d.view.bolts["B2"].state == Shown.LOCKED
    d.command(next(request), ReleaseBolt("VIN1", "B2", "checked"), SUPERVISOR)
    assert d.view.bolts["B2"].check_first and not d.view.bolts["B2"].held
    # B3: held, its outcome entered as a NOK: open to be loosened (its NOK rule)
    _on(d, 3, 2)
    d.step(("ack", 0.01, True))
    _on(d, 3, 1)
    d.feed(UnreadableIn(d.t, unreadable(7, d.core.selection.pset if d.core.selection
                                         else 0)))
    d.command(next(request), EnterOutcome("VIN1", "B3", False, 30.0, 10.0, "read on it"),
              SUPERVISOR)
    assert d.view.bolts["B3"].ends_nok and not d.view.bolts["B3"].held
    # B2 skipped: its check first ends
    d.command(next(request), SkipBolt("VIN1", "B2", "no access"), SUPERVISOR)
    assert d.view.bolts["B2"].state == SKIPPED and not d.view.bolts["B2"].check_first
    assert d.compared > 100
