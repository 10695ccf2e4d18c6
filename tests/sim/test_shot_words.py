"""The demo's line for a NOK names every quantity that failed, with the limit it crossed
(issue 30, item 4): it showed the torque alone, so an angle NOK (94 deg > 90) read as a NOK
at a good torque."""

from __future__ import annotations

from drivers.wrench.sim.controller import SimController, SimPset
from stationd.sim.operator import shot_words

PSET = SimPset(25.0, 22.0, 28.0, 30.0, 15.0, 90.0)


def test_a_nok_line_names_each_failed_quantity_and_an_ok_line_both_values() -> None:
    ctl = SimController(psets={1: PSET}, nok_rate=1.0, seed=3)
    seen: dict[tuple[int, int], str] = {}
    for _ in range(200):
        shot = ctl._result(1)         # the controller's tightening, its ground truth
        seen.setdefault((shot.torque_status, shot.angle_status), shot_words(shot))
        words = shot_words(shot)
        assert words.startswith("NOK: ")
        if shot.angle_status == 2:
            assert f"angle {shot.angle_deg:.0f} deg > 90 max" in words
            assert f"(torque {shot.torque_nm:.1f} Nm within limits)" in words
        if shot.angle_status == 0:
            assert f"angle {shot.angle_deg:.0f} deg < 15 min" in words
        if shot.torque_status == 2:
            assert f"torque {shot.torque_nm:.1f} Nm > 28.0 max" in words
            assert f"(angle {shot.angle_deg:.0f} deg within limits)" in words
        if shot.torque_status == 0:
            assert f"torque {shot.torque_nm:.1f} Nm < 22.0 min" in words
    # every side of both quantities came up
    assert {(1, 2), (1, 0), (2, 1), (0, 1)} <= set(seen), seen
    ok = SimController(psets={1: PSET}, nok_rate=0.0, seed=3)._result(1)
    assert shot_words(ok) == f"OK {ok.torque_nm:.1f} Nm, {ok.angle_deg:.0f} deg"


def test_a_result_that_is_no_tightening_says_its_type() -> None:
    """A supervisor's trial of ``run --sim-operator`` with ``result_types=1,3``: the batch
    increment's line read "OK 0.0 Nm, 0 deg", as a bolt tightened at no torque.  A result
    that is no tightening says its type; a tightening's line is as before."""
    ctl = SimController(psets={1: PSET}, nok_rate=0.0, seed=3)
    assert shot_words(ctl._result(1, 3)) == "batch increment (result type 3): no rundown"
    assert shot_words(ctl._result(1, 6)) == "abort job (result type 6): no rundown"
    loose = ctl._result(1, 2)
    assert shot_words(loose) == \
        f"loosening OK {loose.torque_nm:.1f} Nm, {loose.angle_deg:.0f} deg"
    odd = ctl._result(1, 42)
    assert shot_words(odd).startswith("result type 42 (unknown): OK ")
    for code in (1, 7):                 # a tightening, synchronized or not: no type said
        shot = ctl._result(1, code)
        assert shot_words(shot) == f"OK {shot.torque_nm:.1f} Nm, {shot.angle_deg:.0f} deg"


def test_a_bolt_held_for_its_result_is_said_held_not_locked() -> None:
    """A quality trial: the simulated operator's line said "locked, released by the
    supervisor" for a bolt held for an unreadable result, and the records had no lock."""
    from types import SimpleNamespace

    from stationd.sim.operator import stopped_words

    def station(held: dict[str, str], locked: dict[str, int]) -> object:
        now = SimpleNamespace(held=held, locked=locked)
        return SimpleNamespace(core=SimpleNamespace(status=lambda: now))

    assert stopped_words(station({"B06": "tightening 21"}, {}), "B06") == "held"  # type: ignore[arg-type]
    assert stopped_words(station({}, {"B06": 3}), "B06") == "locked"  # type: ignore[arg-type]
