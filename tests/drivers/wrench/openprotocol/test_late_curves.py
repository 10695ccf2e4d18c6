"""The curves of an earlier tightening, asked for after the fact (``fetch_curve``: MID 0008
for MID 0900 with send alternative 3, R2.8.0 table 158), between the driver and the
simulated controller over TCP on 127.0.0.1."""

from __future__ import annotations

import pytest

from drivers.wrench.openprotocol.curve import replay_data, subscribe_data
from drivers.wrench.sim.controller import SimController

from ..conftest import connect, reconnect_within, wait_until


def ready(w) -> None:
    w.select_pset(1)
    w.enable_tool()


def subscriptions(sim: SimController) -> list[tuple[int, bytes]]:
    return [(r.mid, r.data) for r in sim.received() if r.mid in (8, 9)]


def test_the_data_asked_for_is_laid_out_as_the_specification_says():
    # 0900, revision 001, extra data length, then: alternative 3, first and last index,
    # 2 trace types, angle and torque
    assert replay_data(70061, 70061) == b"090000129" + b"3" + b"0000070061" * 2 + b"02001002"
    # alternative 0 (new data): the time stamp and index identifiers unused
    assert subscribe_data() == b"090000138" + b"0" + b"0" * 29 + b"02001002"


def test_curves_of_an_earlier_tightening_without_a_live_subscription(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        assert not w.curves_on
        ready(w)
        made = [sim.pull_trigger() for _ in range(3)]
        assert all(w.wait_result(1.0) is not None for _ in made)
        got = w.fetch_curve(2)
        assert [(c.tightening_id, c.name) for c in got] == [(2, "angle"), (2, "torque")]
        assert w.wait_curve(0.0) is None                 # handed back, not queued
        assert wait_until(lambda: sim.curve_acks == 2)   # each acknowledged (MID 0005)
        assert subscriptions(sim) == [(8, replay_data(2, 2)), (9, b"090000100")]
        assert w.status().connected and not w.curves_on
    assert sim.errors == []


def test_a_live_subscription_is_stopped_for_it_and_made_again(tmp_path):
    with SimController(seed=5, nok_rate=0.0) as sim, \
            connect(sim, "tcp", tmp_path, curves=True) as w:
        assert w.curves_on
        ready(w)
        sim.pull_trigger()
        assert w.wait_result(1.0) is not None
        live = [w.wait_curve(1.0), w.wait_curve(1.0)]
        late = w.fetch_curve(1)
        # the same tightening's traces, as the controller sent them live
        assert [(c.tightening_id, c.trace_type, c.values) for c in late] == [
            (c.tightening_id, c.trace_type, c.values) for c in live if c is not None]
        assert subscriptions(sim)[1:] == [(9, b"090000100"), (8, replay_data(1, 1)),
                                         (9, b"090000100"), (8, subscribe_data())]
        assert w.curves_on
        sim.pull_trigger()                                # live curves go on
        assert w.wait_result(1.0) is not None
        after = [w.wait_curve(1.0), w.wait_curve(1.0)]
        assert [c.tightening_id for c in after if c is not None] == [2, 2]
    assert sim.errors == []


@pytest.mark.parametrize("curves", [True, False])
def test_a_tightening_the_controller_no_longer_has_gives_none(curves, tmp_path):
    with SimController(seed=5, nok_rate=0.0, curves=curves) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.pull_trigger()
        assert w.wait_result(1.0) is not None
        sim.forget_results(1)
        assert w.fetch_curve(1) == []                     # refused: MID 0004 01 (or 78)
        assert w.status().connected
        assert w.fetch_curve(5) == []


def test_the_curves_of_a_tightening_made_during_a_link_cut(sim, tmp_path):
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected)
        made = sim.pull_trigger()
        assert made is not None and reconnect_within(w)
        result = w.fetch_result(made.tightening_id)
        curves = w.fetch_curve(made.tightening_id)
    assert result is not None and result.tightening_id == made.tightening_id
    assert [(c.tightening_id, c.name) for c in curves] == [
        (made.tightening_id, "angle"), (made.tightening_id, "torque")]
    assert max(curves[1].values) == pytest.approx(made.torque_nm, abs=0.5)


def test_over_rs232_none_are_asked(sim, tmp_path):
    with connect(sim, "serial", tmp_path) as w:
        ready(w)
        sim.pull_trigger()
        assert w.wait_result(1.0) is not None
        assert w.fetch_curve(1) == []
    assert subscriptions(sim) == []
