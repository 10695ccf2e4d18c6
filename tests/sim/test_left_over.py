"""What the simulated operator's round finds left open by the round before it (a restart's
new plan is drawn anew): :func:`stationd.sim.operator.left_over`, of a real core's status."""

from __future__ import annotations

from stationd.sim.operator import left_over
from stationd.station.inputs import ResultIn
from tests.station.test_core import _on
from tests.station.test_loosen import _driver, res


def test_a_round_after_a_restart_finds_the_bolts_left_open_again():
    """What the simulated operator's round finds left by the round before a restart
    (:func:`stationd.sim.operator.left_over`): a bolt loosened after its NOKs (to be
    tightened again) and a locked one, whatever its new plan names (a quality trial: B02,
    released and loosened before a restart, was never tightened again)."""
    d = _driver()
    _on(d, 1, 2)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    d.feed(ResultIn(d.t, res(1, 1, False, 1)))           # B1 NOK: to be loosened
    assert left_over(d.core.status(), ["B1", "B2", "B3"]) == ["B1"]
    assert left_over(d.core.status(), ["B2", "B3"]) == []
