import numpy as np

from stationd.reasons import Skip, SkipKind, Wait, WaitKind
from stationd.station.matching import BoltMatcher, BoltRule, MatchParams, check_spacing
from stationd.words import reason_words, wait_words

BOLTS = {"B1": np.array([0.0, 0.0, 0.0]), "B2": np.array([40.0, 0.0, 10.0]),
         "B3": np.array([40.0, 12.0, 0.0])}


def _why(match) -> str:
    """A refusal in the words the operator reads."""
    return reason_words(match.reason) if match.reason is not None else ""


def _m(**kw):
    return BoltMatcher(BOLTS, MatchParams(**kw))


def test_taken_only_after_stable_frames():
    m = _m(stable_frames=3)
    got = [m.update(np.array([1.0, -1.0, 300.0])) for _ in range(3)]
    assert [g.bolt for g in got] == [None, None, "B1"]
    assert "hold the wrench still on it (1 of 3" in _why(got[0])


def test_refusal_breaks_the_streak():
    m = _m(stable_frames=2)
    assert m.update(np.array([0.5, 0, 0])).bolt is None
    m.refuse("left: marker not found")
    assert m.update(np.array([0.5, 0, 0])).bolt is None  # streak restarted
    assert m.update(np.array([0.5, 0, 0])).bolt == "B1"


def test_switching_bolts_restarts_the_streak():
    m = _m(stable_frames=2, margin_mm=1.0)
    m.update(np.array([0.0, 0, 0]))
    assert m.update(np.array([40.0, -3, 0])).bolt is None  # B2 now: streak 1
    assert m.update(np.array([40.0, -3, 0])).bolt == "B2"


def test_out_of_tolerance_ambiguous_stale_done():
    m = _m(stable_frames=1, tolerance_mm=8.0, margin_mm=6.0)
    assert "no bolt within" in _why(m.update(np.array([20.0, 0, 0])))
    r = m.update(np.array([40.0, 6.0, 0]))  # between B2 and B3
    assert r.bolt is None and "ambiguous" in _why(r)
    assert "too old" in _why(m.update(np.array([0.0, 0, 0]), age_s=2.0))
    assert m.update(np.array([0.0, 0, 0])).bolt == "B1"
    m.mark_done("B1")
    r = m.update(np.array([0.0, 0, 0]))
    assert r.bolt is None and "already done" in _why(r)
    assert _m(stable_frames=1, allow_retighten=True).update(np.array([0.0, 0, 0])).bolt == "B1"


def test_never_the_wrong_bolt_under_noise():
    """Random wrench positions around random bolts: whatever is taken is the true bolt."""
    rng = np.random.default_rng(0)
    m = _m(stable_frames=1)
    for _ in range(2000):
        true = rng.choice(list(BOLTS))
        p = BOLTS[true] + np.append(rng.normal(0, 2.0, 2), 0.0)
        got = m.update(p)
        if got.bolt is not None:
            assert got.bolt == true
        m.reset()


def test_spacing_check():
    assert check_spacing(BOLTS, 8.0) == ["B2 and B3 are 12.0 mm apart in X-Y (< 16 = 2 x 8)"]


def test_spacing_rule_is_the_matchers_metric():
    """Bolts one above the other (30 mm in Z, 0 in plan): the matcher cannot tell them apart,
    and the shared rule refuses them; bolts far apart in plan but level pass both."""
    stacked = {"LOW": np.array([0.0, 0.0, 0.0]), "HIGH": np.array([0.0, 0.0, 30.0])}
    assert check_spacing(stacked, 8.0) == ["LOW and HIGH are 0.0 mm apart in X-Y (< 16 = 2 x 8)"]
    m = BoltMatcher(stacked, MatchParams(stable_frames=1))
    assert "ambiguous" in (_why(m.update(np.array([0.0, 0.0, 15.0]))) or "")
    apart = {"A": np.array([0.0, 0.0, 0.0]), "B": np.array([16.0, 0.0, 0.0])}
    assert check_spacing(apart, 8.0) == []
    assert BoltMatcher(apart, MatchParams(stable_frames=1)).update(np.zeros(3)).bolt == "A"


# -- sequence: order and batch -------------------------------------------------------------
# Bolts 40 mm apart on a line: never ambiguous, so only the sequence decides.
LINE = {b: np.array([40.0 * k, 0.0, 0.0])
        for k, b in enumerate(["A1", "A2", "A3", "B1", "U1", "U2", "U3", "F"])}
RULES = {"A1": BoltRule(1, "subframe"), "A2": BoltRule(1, "subframe"),
         "A3": BoltRule(2, "subframe"), "B1": BoltRule(None, "shield"),
         "U1": BoltRule(1), "U2": BoltRule(1), "U3": BoltRule(2)}  # F: no rule at all


def _seq(done=(), **kw):
    return BoltMatcher(LINE, MatchParams(**{"stable_frames": 1, **kw}), set(done), rules=RULES)


def _at(bolt):
    return LINE[bolt] + np.array([0.7, -0.4, 250.0])


def test_order_blocks_then_allows_once_done():
    m = _seq()
    r = m.update(_at("U3"))
    assert r.bolt is None and _why(r) == "U3 must wait: order 2 needs U1, U2 done first"
    assert r.candidate == "U3" and r.distance_mm is not None  # leave detection still sees it
    m.mark_done("U1")
    assert _why(m.update(_at("U3"))) == "U3 must wait: order 2 needs U2 done first"
    assert m.update(_at("U2")).bolt == "U2"  # same order as U1: no constraint between them
    m.mark_done("U2")
    assert m.update(_at("U3")).bolt == "U3"


def test_unordered_bolts_are_unconstrained_and_orders_stay_in_their_batch():
    m = _seq()
    assert m.update(_at("F")).bolt == "F"  # no rule at all
    assert m.update(_at("B1")).bolt == "B1"  # a batch, no order
    assert m.why_blocked("U1") is None and m.why_blocked("A1") is None
    # subframe's order 2 waits for subframe's order 1 only, not for the unbatched U1, U2
    wait = m.why_blocked("A3")
    assert wait == Wait(WaitKind.ORDER, order=2, batch="subframe", bolts=("A1", "A2"))
    assert wait_words(wait) == "order 2 in batch subframe needs A1, A2 done first"
    m.mark_done("A1")
    m.mark_done("A2")
    assert m.update(_at("A3")).bolt == "A3"


def test_batch_lock_in():
    m = _seq()
    m.mark_done("A1")  # subframe is open: nothing else until it is finished
    for other in ("U1", "B1", "F"):
        r = m.update(_at(other))
        assert r.bolt is None and r.candidate == other
        assert _why(r) == f"{other} must wait: finish batch subframe first: A2, A3 remaining"
    assert m.update(_at("A2")).bolt == "A2"
    m.mark_done("A2")
    assert _why(m.update(_at("U1"))).endswith("finish batch subframe first: A3 remaining")
    assert m.update(_at("A3")).bolt == "A3"
    m.mark_done("A3")  # closed: the rest of the world again
    assert m.update(_at("U1")).bolt == "U1"
    m.mark_done("B1")  # a batch of one opens and closes at once
    assert m.update(_at("F")).bolt == "F"


def test_a_skipped_bolt_blocks_and_says_so():
    m = _seq()
    m.skipped["A1"] = Skip(SkipKind.REFUSED, reason="pset 2 unknown")
    assert _why(m.update(_at("A1"))).startswith("A1 skipped:")  # skipped comes first
    r = m.update(_at("A3"))
    assert r.bolt is None and _why(r) == (
        "A3 must wait: order 2 in batch subframe needs A1, A2 done first; "
        "A1 was skipped: controller refused its parameters (pset 2 unknown)")
    m.mark_done("A2")  # subframe open, A1 will never be done: the rest waits, and says why
    assert _why(m.update(_at("U1"))) == (
        "U1 must wait: finish batch subframe first: A1, A3 remaining; "
        "A1 was skipped: controller refused its parameters (pset 2 unknown)")


def test_resumed_vehicle_counts_what_was_done_before():
    m = BoltMatcher(LINE, MatchParams(stable_frames=1), {"A1", "A2", "U1"}, rules=RULES)
    assert "already done" in _why(m.update(_at("A1")))
    assert _why(m.update(_at("U2"))) == "U2 must wait: finish batch subframe first: A3 remaining"
    assert m.update(_at("A3")).bolt == "A3"
    m.mark_done("A3")
    assert _why(m.update(_at("U3"))) == "U3 must wait: order 2 needs U2 done first"
    # two batches left open (resumed like that): either may be finished, else neither could
    two = BoltMatcher(LINE, MatchParams(stable_frames=1), {"A1", "B1"}, rules={
        **RULES, "B1": BoltRule(None, "x"), "F": BoltRule(None, "x")})
    assert two.update(_at("F")).bolt == "F" and two.update(_at("A2")).bolt == "A2"
    wait = two.why_blocked("U1")
    assert wait == Wait(WaitKind.BATCH, batches=(("subframe", ("A2", "A3")), ("x", ("F",))))
    assert wait is not None and wait_words(wait) == (
        "finish batch subframe first: A2, A3 remaining; finish batch x first: F remaining")


def test_a_blocked_frame_breaks_the_streak():
    m = _seq(stable_frames=2, done={"A1"})
    assert m.update(_at("A2")).streak == 1
    assert "must wait" in _why(m.update(_at("U1")))
    assert m.update(_at("A2")).bolt is None  # streak restarted
    assert m.update(_at("A2")).bolt == "A2"


def test_without_rules_nothing_is_ordered():
    m = BoltMatcher(LINE, MatchParams(stable_frames=1), {"A1"})
    assert all(m.why_blocked(b) is None for b in LINE)
    assert m.update(_at("U3")).bolt == "U3"


def _allowed(bolt, rules, done):
    """The rule, written out independently: what may be taken next."""
    order, batch = rules.get(bolt, (None, None))
    batches = {bt for _, bt in rules.values() if bt is not None}
    members = {bt: [b for b, (_, x) in rules.items() if x == bt] for bt in batches}
    opened = {bt for bt, ms in members.items()
              if any(b in done for b in ms) and not all(b in done for b in ms)}
    if opened and batch not in opened:
        return False
    return order is None or all(b in done for b, (o, bt) in rules.items()
                                if bt == batch and o is not None and o < order)


def test_the_sequence_holds_under_jitter():
    """Random tables, a wrench dwelling on random bolts with placement noise, some bolts
    skipped, some vehicles resumed: nothing out of sequence is ever taken, a bolt the rule
    forbids is refused with its reason, and without skips there is always a next bolt."""
    rng = np.random.default_rng(7)
    ids = list(LINE)
    for _ in range(40):
        rules = {b: (rng.choice([None, 1, 2, 3]), rng.choice([None, "a", "b"]))
                 for b in ids if rng.random() < 0.9}
        done = {b for b in ids if rng.random() < 0.15}
        m = BoltMatcher(LINE, MatchParams(stable_frames=int(rng.integers(1, 4))), set(done),
                        rules={b: BoltRule(o, bt) for b, (o, bt) in rules.items()})
        for _ in range(60):
            true = str(rng.choice(ids))
            for _ in range(int(rng.integers(1, 6))):  # dwell on it for a few frames
                p = LINE[true] + np.append(rng.normal(0, 2.5, 2), rng.normal(250, 30))
                before = set(m.done)
                got = m.update(p)
                if got.bolt is not None:
                    assert got.bolt == true and got.bolt not in before
                    assert _allowed(got.bolt, rules, before), (got.bolt, rules, before)
                    if rng.random() < 0.1:
                        m.skipped[got.bolt] = Skip(SkipKind.REFUSED, reason="pset 2 unknown")
                    else:
                        m.mark_done(got.bolt)
                    break
                if (got.candidate == true and true not in m.done and true not in m.skipped
                        and not _allowed(true, rules, m.done)):
                    assert "must wait" in _why(got)
            left = [b for b in ids if b not in m.done]
            if left and not m.skipped:
                assert any(m.why_blocked(b) is None for b in left), (rules, m.done)
