"""The ``references:`` section: read with its defaults, refused with its file and line when a
reference cannot be checked or a value is implausible; the exclusions it gives the wrench's
search."""

from __future__ import annotations

import numpy as np
import pytest

from stationd.errors import ConfigError
from stationd.localize.references import References, exclusions, project
from stationd.vision.marker import MarkerSpec
from stationd.yamlio import YamlNode
from tests.localize.refscene import PAIR, R1_PAIR, REFS, TV, vehicle

PAIRS = {"pair1": (PAIR, TV)}
R1 = vehicle(R1_PAIR)


def _read(text: str, pairs=PAIRS) -> References:
    return References.from_node(YamlNode.parse(text, "station.yaml"), pairs=pairs,
                                marker=MarkerSpec(), matching_tolerance_mm=8.0)


def _yaml(pos) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in pos) + "]"


def test_a_section_with_its_defaults_and_what_each_pair_sees():
    refs = _read(f"markers:\n  R1: {_yaml(R1)}\n  R2: {{position: {_yaml(REFS[1].position_mm)},"
                 " mount: lift}\n")
    assert [r.name for r in refs.markers] == ["R1", "R2"]
    assert not refs.markers[0].on_lift and refs.markers[1].on_lift
    assert refs.tolerance_mm == pytest.approx(2.0)          # a quarter of the matching one
    assert refs.period_s == pytest.approx(30 * 60.0)
    assert refs.exclusion_mm == pytest.approx(75.0)
    assert refs.sees == {"pair1": ("R1", "R2")} and refs.pairs == ("pair1",)
    assert [r.name for r in refs.of("pair1")] == ["R1", "R2"]
    refs = _read(f"markers: {{R1: {_yaml(R1)}}}\ntolerance_mm: 1.0\nperiod_min: 5\n")
    assert refs.tolerance_mm == 1.0 and refs.period_s == 300.0


@pytest.mark.parametrize(("text", "message", "line"), [
    ("markers: {{R1: [0, 0, -5000]}}\n", "seen by no pair", 1),
    ("markers:\n  R1: {r1}\n  R1: {r1}\n", "duplicate", 3),
    ("markers:\n  R1: {r1}\n  R2: {near}\n", "fields would overlap", 3),
    ("markers:\n  R1: [0, 0, 1e6]\n", "not plausible", 2),
    ("markers:\n  R1: [0, 0]\n", "3", 2),
    ("markers: {{R1: {r1}}}\ntolerance_mm: 0.01\n", "not plausible", 2),
    ("markers: {{R1: {r1}}}\ntolerance_mm: 5\n", "half the matching tolerance", 2),
    ("markers: {{R1: {r1}}}\nperiod_min: 0\n", "out of range", 2),
    ("markers: {{R1: {{position: {r1}, mount: roof}}}}\n", "lift", 1),
    ("markers: {{}}\n", "at least one", 1),
    ("tolerance_mm: 1\n", "markers", 1),
])
def test_refused_with_file_and_line(text, message, line):
    near = np.asarray(R1) + np.array([30.0, 0.0, 0.0])
    with pytest.raises(ConfigError, match=message) as err:
        _read(text.format(r1=_yaml(R1), near=_yaml(near)))
    assert err.value.path == "station.yaml" and err.value.line == line


def test_a_registered_pair_that_sees_no_reference_is_refused():
    blind = {"pair1": (PAIR, TV), "pair2": (PAIR, type(TV)(TV.A, TV.t + 5000.0))}
    with pytest.raises(ConfigError, match="pair pair2 sees no reference marker"):
        _read(f"markers: {{R1: {_yaml(R1)}}}\n", blind)
    # a pair not registered yet sees nothing and is not checked (it localizes nothing)
    refs = _read(f"markers: {{R1: {_yaml(R1)}}}\n", {"pair1": (PAIR, TV), "pair3": (PAIR, None)})
    assert refs.pairs == ("pair1",)


def test_a_reference_only_a_pair_not_registered_yet_sees_is_not_refused():
    """``calibrate vehicle --pair front`` reads the station with front unregistered: its
    reference R1, seen by no other pair, was refused as seen by no pair, and the command
    with it (a line engineer re-registering a pair the check found moved had to delete the
    references first).  While a pair is not registered, it may be the one that sees it."""
    far = "markers: {R1: [0, 0, -5000]}\n"
    refs = References.from_node(YamlNode.parse(far, "station.yaml"),
                                pairs={"pair1": (PAIR, None)}, marker=MarkerSpec(),
                                matching_tolerance_mm=8.0, registering="pair1")
    assert refs.sees == {"pair1": ()}
    with pytest.raises(ConfigError, match="seen by no pair"):
        _read(far, {"pair1": (PAIR, TV)})      # every pair registered: a wrong position
    # a pair merely not registered in the file does not excuse a reference nobody sees (a
    # mistyped one would go unmeasured, silently: a reviewer's point)
    with pytest.raises(ConfigError, match="seen by no pair"):
        _read(f"markers:\n  R1: {_yaml(R1)}\n  R2: [0, 0, -5000]\n",
              {"pair1": (PAIR, TV), "pair3": (PAIR, None)})


def test_exclusions_cover_each_reference_image_in_both_cameras():
    seen = project(PAIR, TV, R1, MarkerSpec())
    assert seen is not None
    left, right = exclusions(PAIR, TV, REFS, MarkerSpec())
    assert len(left) == len(right) == 2
    (u, v, r), _ = seen
    assert left[0][:2] == pytest.approx((u, v)) and left[0][2] == pytest.approx(1.5 * r)
    assert exclusions(PAIR, None, REFS, MarkerSpec()) == ((), ())
