"""The calibration check on rendered frames: references measured where they should be, a moved
pair found with the right reference and figure, and the wrench never taken for a reference (nor
a reference for the wrench, also once the pair has moved)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from stationd.geometry.tool import BoltEnd, ToolGeometry
from stationd.localize import localize_pair, with_references
from stationd.localize.check import RefWhy, Verdict, check_pair
from stationd.reasons import Why
from stationd.result import Refusal
from tests.localize.refscene import (
    PAIR,
    R1_PAIR,
    R2_PAIR,
    REFS,
    TV,
    WRENCH_PAIR,
    Frames,
    frames,
    moved,
    setup,
)

TOL, SEARCH = 2.0, 75.0
# the wrench's marker faces the left camera, tilted in the vehicle frame: allowed here
TOOL = ToolGeometry(max_tilt_deg=60.0)


@pytest.fixture(scope="module")
def in_place() -> Frames:
    return frames(R1_PAIR, R2_PAIR, WRENCH_PAIR)


@pytest.fixture(scope="module")
def nudged() -> Frames:
    """The rig turned 0.3 degrees: R2 (farther off the axis) moves most, about 5 mm."""
    return frames(moved(R1_PAIR, 0.3), moved(R2_PAIR, 0.3), seed=3)


@pytest.fixture(scope="module")
def knocked() -> Frames:
    """The rig turned 4 degrees, no wrench in view: the references leave their excluded image
    regions (70 mm and more away)."""
    return frames(moved(R1_PAIR, 4.0), moved(R2_PAIR, 4.0), seed=5)


def _check(f: Frames, refs=REFS, **kw) -> object:
    return check_pair("pair2", PAIR, TV, f.left, f.right, refs, tolerance_mm=TOL,
                      search_mm=SEARCH, **kw)


def test_references_in_place_are_measured_to_a_fraction_of_the_tolerance(in_place):
    c = _check(in_place)
    assert c.verdict is Verdict.OK and c.pair == "pair2"
    assert {m.name for m in c.measures} == {"R1", "R2"}
    for m, ref in zip(c.measures, REFS, strict=True):
        assert m.offset_mm is not None and m.offset_mm < 0.2
        assert np.allclose(m.measured_mm, ref.position_mm, atol=0.2)   # the vehicle frame
    assert c.offset_mm == max(m.offset_mm for m in c.measures)


def test_a_moved_pair_is_moved_with_its_worst_reference_and_the_figure(nudged):
    c = _check(nudged)
    assert c.verdict is Verdict.MOVED and c.reference == "R2"
    truth = float(np.linalg.norm(TV.apply(moved(R2_PAIR, 0.3)) - TV.apply(R2_PAIR)))
    assert c.offset_mm == pytest.approx(truth, abs=0.3) and c.offset_mm > TOL


def test_a_knocked_pair_still_finds_its_references_in_the_search_window(knocked):
    c = _check(knocked)
    assert c.verdict is Verdict.MOVED and c.offset_mm is not None and c.offset_mm > 50.0


def test_the_wrench_beside_a_reference_makes_it_ambiguous_not_measured(in_place):
    near = frames(R1_PAIR, R2_PAIR, R2_PAIR + np.array([55.0, 0.0, 0.0]), seed=7)
    c = _check(near)
    by = {m.name: m for m in c.measures}
    assert by["R2"].why is RefWhy.AMBIGUOUS and by["R1"].offset_mm is not None
    assert by["R2"].note == ("2 markers around it: the wrench beside it? measured again once "
                             "it is moved away")
    assert c.verdict is Verdict.OK and c.reference == "R1"


def test_nothing_measured_is_not_checked_with_why(in_place):
    lifted = tuple(replace(r, on_lift=True) for r in REFS)
    c = _check(in_place, lifted, lift_at_height=False)
    assert c.verdict is Verdict.NOT_CHECKED and c.why is RefWhy.LIFT_AWAY
    blank = frames(seed=9)
    c = _check(blank)
    assert c.verdict is Verdict.NOT_CHECKED and c.why is RefWhy.NOT_FOUND
    c = check_pair("pair2", PAIR, TV, in_place.left[:, :800], in_place.right, REFS,
                   tolerance_mm=TOL, search_mm=SEARCH)
    assert c.verdict is Verdict.NOT_CHECKED and c.why is RefWhy.NO_FRAMES


def test_today_two_markers_in_view_refuse_the_wrench_as_ambiguous(in_place):
    """What the pipeline did before the references: three markers, none taken."""
    view, _ = localize_pair("pair2", setup(tool=TOOL), in_place.left, in_place.right, 1.0)
    assert isinstance(view.end, Refusal) and "ambiguous" in view.end.reason


def test_with_references_excluded_the_wrench_is_localized_beside_them(in_place):
    s = with_references(setup(tool=TOOL), REFS, SEARCH)
    view, _ = localize_pair("pair2", s, in_place.left, in_place.right, 1.0)
    assert isinstance(view.end, BoltEnd)
    centre = view.end.point_mm - TOOL.length_mm * view.end.axis
    assert np.linalg.norm(centre - TV.apply(WRENCH_PAIR)) < 0.5


def test_a_moved_pair_never_gives_a_bolt_end_at_a_reference(nudged, knocked):
    s = with_references(setup(tool=TOOL), REFS, SEARCH)
    view, _ = localize_pair("pair2", s, nudged.left, nudged.right, 1.0)
    # moved a little: still inside the excluded image regions
    assert isinstance(view.end, Refusal) and "reference marker's place" in view.end.reason
    # moved far: both seen outside them: two markers, none taken
    view, _ = localize_pair("pair2", s, knocked.left, knocked.right, 1.0)
    assert isinstance(view.end, Refusal) and "ambiguous" in view.end.reason
    # one of them alone (the other covered): refused by its place in the vehicle frame
    one = frames(moved(R1_PAIR, 3.5), seed=11)
    view, _ = localize_pair("pair2", s, one.left, one.right, 1.0)
    assert isinstance(view.end, Refusal) and view.end.why is not None, view.end
    assert view.end.why.kind is Why.REFERENCE_SEEN and view.end.why.reference == "R1"
    assert 50.0 < (view.end.why.distance_mm or 0.0) < SEARCH
