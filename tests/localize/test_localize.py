"""The localize component, pure: pairs' views fused into one localization, or the typed reason
why not; its configuration."""

from __future__ import annotations

import numpy as np
import pytest

from stationd.errors import ConfigError
from stationd.geometry.tool import BoltEnd
from stationd.localize import LocalizeConfig, PairView, fuse_views
from stationd.reasons import Reason, Why
from stationd.result import Refusal
from stationd.yamlio import YamlNode


def _end(x: float, tilt: float = 2.0) -> BoltEnd:
    return BoltEnd(np.array([x, 0.0, 0.0]), tilt, np.array([0.0, 0.0, 1.0]))


def test_every_grab_failed_tells_the_core_nothing():
    views = [PairView(Refusal("skew"), 0.0, failed=True), PairView(Refusal("x"), 0.0,
                                                                     failed=True)]
    assert fuse_views(["p1", "p2"], views, LocalizeConfig(), 10.0) is None


def test_pairs_that_agree_are_fused_by_their_expected_error_and_the_oldest_exposure():
    views = [PairView(_end(100.0), 5.0), PairView(_end(101.0, 4.0), 4.9),
             PairView(Refusal("no purple region", side="left"), 4.8)]
    loc = fuse_views(["p1", "p2", "p3"], views, LocalizeConfig(sigma_mm={"p2": 0.5}), 6.0)
    assert loc is not None and loc.point_mm is not None and loc.reason is None
    # weights 1 and 4: 100.8 mm; the exposure of the frames used, not of the refusing pair
    assert loc.point_mm[0] == pytest.approx(100.8) and loc.exposure_t == 4.9
    assert loc.tilt_deg == pytest.approx(3.0)
    even = fuse_views(["p1", "p2"], views[:2], LocalizeConfig(), 6.0)
    assert even is not None and even.point_mm is not None
    assert even.point_mm[0] == pytest.approx(100.5)


def test_pairs_that_disagree_refuse_with_the_spread_and_the_limit():
    views = [PairView(_end(100.0), 5.0), PairView(_end(105.0), 5.0)]
    loc = fuse_views(["p1", "p2"], views, LocalizeConfig(), 6.0)
    assert loc is not None and loc.point_mm is None and loc.reason is not None
    assert loc.reason.kind is Why.PAIRS_DISAGREE and loc.reason.limit == 2.0
    assert loc.reason.distance_mm == pytest.approx(2.5)     # each from the fused point
    wide = fuse_views(["p1", "p2"], views, LocalizeConfig(agreement_mm=5.0), 6.0)
    assert wide is not None and wide.point_mm is not None


def test_without_a_bolt_end_the_reason_is_a_typed_one_or_each_pairs():
    tilted = Refusal("wrench tilted 14.0 deg (> 10 deg)",
                     Reason(Why.TILTED, angle_deg=14.0, limit=10.0))
    views = [PairView(Refusal("no purple region", side="left"), 1.0), PairView(tilted, 2.0)]
    loc = fuse_views(["p1", "p2"], views, LocalizeConfig(), 3.0)
    assert loc is not None and loc.reason == tilted.why and loc.exposure_t == 1.0
    loc = fuse_views(["p1", "p2"], [views[0], PairView(Refusal("ring cut", side="right"), 2.0)],
                     LocalizeConfig(), 3.0)
    assert loc is not None and loc.reason == Reason(
        Why.NOT_LOCALIZED,
        per_pair=(("p1", "left", "no purple region"), ("p2", "right", "ring cut")))


def test_the_section_is_checked_with_its_line():
    cfg = LocalizeConfig.from_node(YamlNode.parse("agreement_mm: 3\nsigma_mm: {pair1: 0.5}\n"))
    assert cfg.agreement_mm == 3.0 and cfg.sigma_mm == {"pair1": 0.5}
    assert LocalizeConfig.from_node(YamlNode.parse("{}")).agreement_mm == 2.0
    for text, message in (("agreement_mm: 0\n", "out of range"),
                          ("sigma_mm: [1, 2]\n", "mapping of pair names"),
                          ("sigma_mm: {pair1: -1}\n", "out of range"),
                          ("weights: {}\n", "unknown key")):
        with pytest.raises(ConfigError, match=message):
            LocalizeConfig.from_node(YamlNode.parse(text, "station.yaml"))
