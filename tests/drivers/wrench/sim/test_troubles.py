"""A troubled simulated controller from its URL (``sim://wrench?result_types=...&
garble_every=N&lose_push_every=N``), read by the real Open Protocol client: the trigger's
results are those types in turn, every Nth body does not read and every Nth push is lost
(kept for MID 0064).  Why: a quality engineer ran the whole station only on a well-behaved
controller; these are what the station's result rules are for."""

from __future__ import annotations

import pytest

from drivers.errors import UrlError
from drivers.wrench import open_wrench
from drivers.wrench.base import TighteningResult, UnreadableResult
from drivers.wrench.sim.controller import SimWrench

from ..conftest import FAST, WAIT_S


def test_the_trigger_makes_the_types_in_turn_spoils_and_loses_as_asked():
    w = open_wrench("sim://wrench?result_types=1,2&garble_every=3&lose_push_every=4&"
                    "nok_rate=0", **FAST)
    assert isinstance(w, SimWrench)
    try:
        w.send_vin("WVWZZZ1JZXW000001")
        w.select_pset(1)
        w.enable_tool()
        made = [w.controller.pull_trigger() for _ in range(5)]
        assert all(m is not None for m in made)
        got = []
        while len(got) < 4:     # the 4th push lost: 1, 2, 3 and 5 come
            r = w.wait_result(WAIT_S)
            assert r is not None
            got.append(r)
        first, second, third, fifth = got
        assert isinstance(first, TighteningResult) and first.result_type_code == 1
        assert isinstance(second, TighteningResult) and second.result_type_code == 2
        assert isinstance(third, UnreadableResult)       # its torque spoiled
        assert isinstance(fifth, TighteningResult) and fifth.result_type_code == 1
        ids = [m.tightening_id for m in made if m is not None]
        assert fifth.tightening_id == ids[4]
        kept = w.fetch_result(ids[3])                    # never pushed, kept: fetched
        assert isinstance(kept, TighteningResult) and kept.result_type_code == 2
        # an explicit type is the caller's, outside the schedule
        assert w.controller.pull_trigger(3) is not None
    finally:
        w.close()


@pytest.mark.parametrize("query, said", [
    # (the words of `stationd sim controller --result-types`)
    ("result_types=1,x", "result_types: expected codes like 1,3,2, not '1,x'"),
    ("result_types=100", "result_types: expected codes 0-99 like 1,3,2, not '100'"),
    ("garble_every=-1", "must be >= 0"),
])
def test_bad_trouble_options_are_one_readable_error(query, said):
    with pytest.raises(UrlError) as e:          # one line, naming the URL
        open_wrench(f"sim://wrench?{query}", connect=False)
    assert said in str(e.value) and str(e.value).startswith("sim://wrench?")


def test_the_standalone_simulator_takes_the_troubles_as_options():
    """``stationd sim controller`` and ``python -m drivers.wrench.sim``: the troubles of the
    URL as options (a new user's trial found them only in the URL), read into the same
    SimController keywords; a negative count is refused in words."""
    import argparse

    from drivers.wrench.sim import cli as sim_cli
    from drivers.wrench.sim.controller import UNKNOWN_MID, SimController

    args = sim_cli.parser().parse_args(["--lose-push-every", "3", "--garble-every", "5",
                                        "--no-old-results"])
    kw = sim_cli.behaviour(args)
    assert (kw["lose_push_every"], kw["garble_every"], kw["refused_mids"]) == \
        (3, 5, {64: UNKNOWN_MID})
    sim = SimController(**kw)
    assert (sim.lose_push_every, sim.garble_every) == (3, 5)
    assert sim_cli.troubles_words(args) == ("; 1 push in 3 lost, 1 result in 5 unreadable, "
                                            "no old results (MID 0064 refused)")
    plain = sim_cli.parser().parse_args([])
    assert sim_cli.behaviour(plain)["refused_mids"] is None
    assert sim_cli.troubles_words(plain) == ""
    with pytest.raises(argparse.ArgumentTypeError, match="expected a whole number >= 0"):
        sim_cli._count("-2")
