"""Review findings: the screen's bolts against a real core (issue 31)."""

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
