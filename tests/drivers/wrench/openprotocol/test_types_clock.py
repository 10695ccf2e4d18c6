"""Result types, the controller's clock and results made during a link cut, between the
driver and the simulated controller over TCP on 127.0.0.1."""

from __future__ import annotations

import logging
import time
from datetime import datetime

import pytest

from drivers.wrench import open_wrench
from drivers.wrench.base import (
    ResultKind,
    ResultType,
    TighteningResult,
    UnreadableResult,
    result_kind,
)
from drivers.wrench.sim.controller import SimController, SimWrench

from ..conftest import connect, reconnect_within, wait_until

KINDS = {1: ResultKind.TIGHTENING, 2: ResultKind.LOOSENING, 3: ResultKind.EVENT,
         4: ResultKind.EVENT, 5: ResultKind.EVENT, 6: ResultKind.EVENT,
         7: ResultKind.TIGHTENING, 8: ResultKind.EVENT, 9: ResultKind.UNKNOWN}


def ready(w) -> None:
    w.select_pset(1)
    w.enable_tool()


@pytest.mark.parametrize("revision", [3, 7])
def test_every_result_type_arrives_with_its_code(revision, tmp_path):
    with SimController(seed=4, nok_rate=0.0, refused_revisions={60: range(revision + 1, 8)}
                       ) as sim, connect(sim, "tcp", tmp_path) as w:
        assert w.revisions[60] == revision
        ready(w)
        for code in KINDS:
            sim.pull_trigger(code)
        got = [w.wait_result(1.0) for _ in KINDS]
    assert all(isinstance(g, TighteningResult) for g in got)
    results = [g for g in got if isinstance(g, TighteningResult)]
    assert [g.result_type_code for g in results] == list(KINDS)
    assert [g.result_type for g in results] == [*ResultType, None]
    assert [result_kind(g.result_type_code) for g in results] == list(KINDS.values())
    events = [g for g in results if g.result_type_code in (3, 4, 5, 6, 8)]
    assert all(g.torque_nm == 0.0 and g.angle_deg == 0.0 and g.ok for g in events)
    rundowns = [g for g in results if g.result_type_code in (1, 2, 7, 9)]
    assert all(g.torque_nm > 0 for g in rundowns)
    # batch increment then decrement step the counter; ids run on over every type
    by_code = {g.result_type_code: g for g in results}
    assert by_code[3].batch_counter == by_code[2].batch_counter + 1
    assert by_code[4].batch_counter == by_code[3].batch_counter - 1
    assert [g.tightening_id for g in results] == list(range(1, 10))


def test_revision_2_carries_no_type(tmp_path):
    with SimController(seed=4, nok_rate=0.0, refused_revisions={60: range(3, 8)}) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.pull_trigger(3)
        got = w.wait_result(1.0)
    assert isinstance(got, TighteningResult) and got.result_type_code is None


def test_the_controllers_clock_offset(tmp_path, caplog):
    with SimController(seed=4, clock_offset_s=-3600.0) as sim, \
            connect(sim, "tcp", tmp_path) as w:
        offset = w.clock_offset_s
        assert offset is not None and -3602 < offset < -3598
        # an hour off: a warning saying to set it (a technician's trial: an INFO line)
        assert any(r.levelname == "WARNING" and "controller clock -3600 s from the "
                   "station's: set the controller's clock" in r.getMessage()
                   for r in caplog.records), caplog.text
        ready(w)
        t = sim.pull_trigger()
        got = w.wait_result(1.0)
        assert isinstance(got, TighteningResult) and t is not None
        assert got.timestamp == t.timestamp
        # the station's clock at the result, from the controller's
        station = got.timestamp.timestamp() - offset
        assert abs(station - datetime.now().timestamp()) < 3


def test_the_clock_measured_again_on_a_live_session(tmp_path, caplog):
    """A connection lasts days and the controller's clock drifts: measured again (MID 0080)
    without a reconnect, the new offset is the one results are placed by, and the journal
    says it moved; a refusal then keeps the last measure; the session goes on."""
    import logging

    with SimController(seed=4, clock_offset_s=0.0) as sim, \
            connect(sim, "tcp", tmp_path) as w, caplog.at_level(logging.INFO):
        ready(w)
        sim.clock_offset_s = 40.0                     # drifted (set forward) meanwhile
        offset = w.check_clock()
        assert offset is not None and 38 < offset < 42
        assert w.clock_offset_s == offset
        assert any("controller clock now +40 s from the station's (+0 s at the last "
                   "measure)" in r.getMessage() for r in caplog.records)
        sim.refuse_mid(80, 99)
        assert w.check_clock() == offset              # refused: the last measure stays
        assert w.status().connected
        sim.pull_trigger()
        got = w.wait_result(1.0)
        assert isinstance(got, TighteningResult)
        station = got.timestamp.timestamp() - offset
        assert abs(station - datetime.now().timestamp()) < 3


def test_a_controller_that_refuses_the_clock_still_starts(sim, tmp_path, caplog):
    sim.refuse_mid(80, 99)
    with connect(sim, "tcp", tmp_path) as w:
        assert w.clock_offset_s is None and w.status().connected
        ready(w)
        # measured again, refused: not said to keep a measure it never had (a trial)
        with caplog.at_level(logging.INFO):
            assert w.check_clock() is None
    said = [r.getMessage() for r in caplog.records if "not measured again" in r.getMessage()]
    assert said and all("still not known" in s and "last measure" not in s for s in said), said


def test_results_made_during_a_link_cut_are_kept_and_fetched(sim, tmp_path):
    """The tool enabled, the link cut, the operator tightens: the controller keeps the
    results (not pushed: nobody is subscribed) and answers MID 0064 for them after the
    reconnect, with its clock again."""
    with connect(sim, "tcp", tmp_path) as w:
        ready(w)
        sim.pull_trigger()
        assert w.wait_result(1.0) is not None
        sim.drop_connections()
        assert wait_until(lambda: not w.status().connected)
        cut = [sim.pull_trigger(), sim.pull_trigger(2)]
        assert all(c is not None for c in cut)
        assert reconnect_within(w)
        assert w.clock_offset_s is not None
        assert w.wait_result(0.2) is None                 # nothing pushed for them
        fetched = [w.fetch_result(c.tightening_id) for c in cut if c is not None]
        newest = w.fetch_result(0)
    assert [f.tightening_id for f in fetched if f is not None] == [2, 3]
    assert all(isinstance(f, TighteningResult) and f.fetched for f in fetched)
    assert [f.result_type_code for f in fetched if isinstance(f, TighteningResult)] == [1, 2]
    assert newest is not None and newest.tightening_id == 3


def test_sim_wrench_takes_the_controllers_behaviour_as_keywords():
    with open_wrench("sim://wrench?nok_rate=0", mislabel=2, clock_offset_s=30.0,
                     timeout=0.5) as w:
        assert isinstance(w, SimWrench)
        offset = w.clock_offset_s
        assert offset is not None and 28 < offset < 32
        w.controller.clock_offset_s = -30.0              # the controller's clock set back
        w.reconnect()
        offset = w.clock_offset_s
        assert offset is not None and -32 < offset < -28
        ready(w)
        w.controller.pull_trigger(3)
        got = w.wait_result(1.0)
    assert isinstance(got, UnreadableResult)   # revision 2 carries no type: held
    assert (got.revision, got.laid_out_as, got.pset) == (7, 2, 1)


def test_a_clock_in_step_is_said_to_agree_at_every_connection(tmp_path, caplog):
    """The controller says whole seconds (its clock cut down): a clock in step measured
    -1..0 s and the journal said "agrees" at one connection and "-1 s" at the next (a line
    engineer's trial)."""
    import logging

    offsets = []
    with SimController(seed=4) as sim, caplog.at_level(logging.INFO):
        for _ in range(4):
            with connect(sim, "tcp", tmp_path) as w:
                assert w.clock_offset_s is not None
                offsets.append(w.clock_offset_s)
            time.sleep(0.3)         # another fraction of a second each time
    said = [r.getMessage() for r in caplog.records if "controller clock" in r.getMessage()]
    assert len(said) == 4
    for offset, words in zip(offsets, said, strict=True):
        if offset > -1.0:           # in step, answered within the second (not under a load
            assert "agrees with the station's" in words, (offset, words)   # that delays it)
