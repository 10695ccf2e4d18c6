import numpy as np

from stationd.station.matching import BoltMatcher, MatchParams, check_spacing

BOLTS = {"B1": np.array([0.0, 0.0, 0.0]), "B2": np.array([40.0, 0.0, 10.0]),
         "B3": np.array([40.0, 12.0, 0.0])}


def _m(**kw):
    return BoltMatcher(BOLTS, MatchParams(**kw))


def test_taken_only_after_stable_frames():
    m = _m(stable_frames=3)
    got = [m.update(np.array([1.0, -1.0, 300.0])) for _ in range(3)]
    assert [g.bolt for g in got] == [None, None, "B1"]
    assert "stable for 1 of 3" in got[0].reason


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
    assert "no bolt within" in m.update(np.array([20.0, 0, 0])).reason
    r = m.update(np.array([40.0, 6.0, 0]))  # between B2 and B3
    assert r.bolt is None and "ambiguous" in r.reason
    assert "stale" in m.update(np.array([0.0, 0, 0]), age_s=2.0).reason
    assert m.update(np.array([0.0, 0, 0])).bolt == "B1"
    m.mark_done("B1")
    r = m.update(np.array([0.0, 0, 0]))
    assert r.bolt is None and "already done" in r.reason
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
    assert check_spacing(BOLTS, 8.0) == ["B2 and B3 are 12.0 mm apart (< 2 x 8)"]
