import numpy as np

from stationd.station.cycle import (
    Cycle,
    DisableTool,
    EnableTool,
    Record,
    SendParams,
    State,
)
from stationd.station.matching import BoltMatcher, MatchParams

BOLTS = {"B1": np.array([0.0, 0.0, 0.0]), "B2": np.array([60.0, 0.0, 0.0])}
AT = {k: v + np.array([0.5, -0.5, 0.0]) for k, v in BOLTS.items()}


def _cycle(**kw):
    c = Cycle(BoltMatcher(BOLTS, MatchParams(stable_frames=3)), **kw)
    c.started()
    return c


def _kinds(actions):
    return [type(a).__name__ for a in actions]


def test_happy_path_one_bolt():
    c = _cycle()
    assert c.lift(True) == [] and c.state is State.TRACKING
    assert all(not isinstance(a, SendParams) for a in c.localized(AT["B1"]))
    c.localized(AT["B1"])
    assert c.localized(AT["B1"]) == [SendParams("B1")] and c.state is State.BOLT_SELECTED
    assert c.params_acknowledged("B1") == [EnableTool("B1")] and c.state is State.TIGHTENING
    acts = c.result("B1", {"torque": 25.0}, ok=True)
    assert _kinds(acts) == ["DisableTool", "Record"] and c.state is State.TRACKING
    # B1 is done: staying on it sends nothing
    assert not any(isinstance(a, SendParams) for _ in range(5) for a in c.localized(AT["B1"]))


def test_nothing_is_sent_while_the_lift_is_not_ready():
    c = _cycle()
    for _ in range(10):
        assert c.localized(AT["B1"]) == []
    assert c.state is State.WAITING_VEHICLE


def test_wrench_leaving_before_tightening_disables_the_tool():
    c = _cycle(leave_frames=2)
    c.lift(True)
    for _ in range(3):
        c.localized(AT["B1"])
    c.params_acknowledged("B1")
    assert c.localized(None, "left: marker not found") == []
    acts = c.localized(AT["B2"])
    assert _kinds(acts) == ["DisableTool"] and c.state is State.TRACKING


def test_lift_lowering_mid_tightening_disables_the_tool():
    c = _cycle()
    c.lift(True)
    for _ in range(3):
        c.localized(AT["B2"])
    c.params_acknowledged("B2")
    acts = c.lift(False)
    assert acts == [DisableTool("lift not at working height")]
    assert c.state is State.WAITING_VEHICLE


def test_refusal_is_a_fault_until_recovered():
    c = _cycle()
    c.lift(True)
    for _ in range(3):
        c.localized(AT["B1"])
    acts = c.params_refused("B1", "pset 3 not defined (code 02)")
    assert isinstance(acts[0], DisableTool) and c.state is State.FAULT
    assert "refused" in c.reason
    for _ in range(5):
        assert c.localized(AT["B1"]) == [] and c.lift(True) == []
    c.recovered()
    assert c.state is State.WAITING_VEHICLE


def test_late_acknowledgement_keeps_the_tool_off():
    c = _cycle(leave_frames=1)
    c.lift(True)
    for _ in range(3):
        c.localized(AT["B1"])
    c.localized(AT["B2"])  # left B1
    acts = c.params_acknowledged("B1")
    assert isinstance(acts[0], DisableTool) and not any(isinstance(a, EnableTool) for a in acts)


def test_random_event_sequences_never_break_the_rules():
    """Invariants over random event streams: parameters are sent only in TRACKING with the lift
    ready, for a bolt where the wrench really is; the tool is enabled only after an ack of
    the bolt whose parameters were just sent."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        c = _cycle(leave_frames=2)
        lift_ready, sent, where = False, None, None
        for _ in range(300):
            ev = rng.integers(6)
            if ev == 0:
                lift_ready = bool(rng.random() < 0.8)
                acts = c.lift(lift_ready)
            elif ev in (1, 2):
                where = str(rng.choice(["B1", "B2", "none"]))
                p = None if where == "none" else AT[where] + np.append(rng.normal(0, 1, 2), 0)
                before = c.state
                acts = c.localized(p, "refused" if p is None else None)
                for a in acts:
                    if isinstance(a, SendParams):
                        assert before is State.TRACKING and lift_ready and a.bolt == where
                        sent = a.bolt
            elif ev == 3 and sent is not None:
                acts = c.params_acknowledged(sent)
                for a in acts:
                    if isinstance(a, EnableTool):
                        assert a.bolt == sent and c.bolt == sent
            elif ev == 4 and c.bolt is not None:
                acts = c.result(c.bolt, None, ok=bool(rng.random() < 0.9))
                assert any(isinstance(a, Record) for a in acts)
            elif ev == 5 and rng.random() < 0.1:
                acts = c.fault("controller vanished") if rng.random() < 0.5 else c.recovered()
            if c.state is State.FAULT:
                assert c.bolt is None
