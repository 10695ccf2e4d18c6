"""Each pair's cameras pinned to the calibration they were first used with (``db.cameras``),
on a real SQLite database."""

from __future__ import annotations

from pathlib import Path

import pytest

from db.cameras import pin_cameras
from db.errors import DatabaseError
from db.repository import Repository


@pytest.fixture
def repo(tmp_path: Path) -> Repository:
    return Repository.open(f"sqlite:///{tmp_path}/s.db")


def test_the_first_cameras_are_pinned_and_then_taken(repo: Repository) -> None:
    assert pin_cameras(repo, "pair1", "cal-a", {"left": "L1", "right": "R1"}) == []
    assert pin_cameras(repo, "pair1", "cal-a", {"left": "L1", "right": "R1"}) == []


def test_another_unit_under_the_same_calibration_is_named_with_its_pin(repo: Repository) -> None:
    pin_cameras(repo, "pair1", "cal-a", {"left": "L1", "right": "R1"})
    [r] = pin_cameras(repo, "pair1", "cal-a", {"left": "L2", "right": "R1"})
    assert (r.side, r.pinned, r.seen) == ("left", "L1", "L2")
    assert r.pinned_at.tzinfo is not None
    # swapped left and right: both sides refused
    swapped = pin_cameras(repo, "pair1", "cal-a", {"left": "R1", "right": "L1"})
    assert {(r.side, r.pinned, r.seen) for r in swapped} == {("left", "L1", "R1"),
                                                            ("right", "R1", "L1")}
    # still refused: a refusal pins nothing new
    assert len(pin_cameras(repo, "pair1", "cal-a", {"left": "L2", "right": "R1"})) == 1


def test_a_new_calibration_pins_anew_and_pairs_are_apart(repo: Repository) -> None:
    pin_cameras(repo, "pair1", "cal-a", {"left": "L1", "right": "R1"})
    assert pin_cameras(repo, "pair1", "cal-b", {"left": "L2", "right": "R1"}) == []
    assert pin_cameras(repo, "pair2", "cal-a", {"left": "L9", "right": "R9"}) == []
    # the old calibration back (a file restored from a backup): its own cameras again
    assert [r.seen for r in pin_cameras(repo, "pair1", "cal-a",
                                        {"left": "L2", "right": "R1"})] == ["L2"]


def test_a_camera_without_a_serial_number_is_not_pinned(repo: Repository) -> None:
    assert pin_cameras(repo, "pair1", "cal-a", {"left": None, "right": ""}) == []
    assert pin_cameras(repo, "pair1", "cal-a", {"left": "L1", "right": "R1"}) == []
    assert len(pin_cameras(repo, "pair1", "cal-a", {"left": "L1", "right": "R2"})) == 1


def test_pins_survive_a_reopen(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path}/s.db"
    pin_cameras(Repository.open(url), "pair1", "cal-a", {"left": "L1", "right": "R1"})
    [r] = pin_cameras(Repository.open(url), "pair1", "cal-a", {"left": "L1", "right": "R3"})
    assert r.pinned == "R1"


def test_a_database_that_refuses_writes_is_a_database_error(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path}/s.db"
    Repository.open(url)
    ro = Repository.open(url, read_only=True)
    with pytest.raises(DatabaseError, match="cameras of pair1 not checked"):
        pin_cameras(ro, "pair1", "cal-a", {"left": "L1", "right": "R1"})
