"""The station's device opener (``stationd.shell.devices``): a pair's two cameras."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from stationd.config import load_station_config
from stationd.shell.devices import Devices

SIM = Path(__file__).resolve().parents[2] / "config" / "sim" / "station.yaml"


def _pair_of(tmp_path: Path, left: str, right: str) -> Devices:
    cfg = load_station_config(SIM)
    pc = cfg.pairs["pair1"]
    cameras = {**cfg.cameras, str(pc.left): left, str(pc.right): right}
    return Devices(replace(cfg, cameras=cameras))


def test_a_pair_whose_two_cameras_do_not_open_says_both(tmp_path: Path) -> None:
    """A maintenance technician's trial: both cameras of a pair down at the start, the first
    one's fault alone was said; the second one's only once the first came back."""
    devices = _pair_of(tmp_path, f"file://{tmp_path}/l/*.png", f"file://{tmp_path}/r/*.png")
    with pytest.raises(DeviceError) as err:
        devices.open_pair("pair1")
    said = str(err.value)
    assert said.startswith("camera pair1_left: ") and "; camera pair1_right: " in said, said
    assert f"{tmp_path}/l" in said and f"{tmp_path}/r" in said


def test_a_pair_with_one_camera_down_says_that_one_as_before(tmp_path: Path) -> None:
    devices = _pair_of(tmp_path, "sim://pair1/left", f"file://{tmp_path}/r/*.png")
    with pytest.raises(DeviceError) as err:
        devices.open_pair("pair1")
    assert "camera pair1_" not in str(err.value) and f"{tmp_path}/r" in str(err.value)


def test_each_camera_of_a_pair_is_journaled_as_it_says_it_is(tmp_path: Path, caplog) -> None:
    """A maintenance technician's trial: the controller's serial number was in the journal,
    no camera's, so a replaced camera left no trace of which unit took the pictures.  Each
    camera says what it is as its pair opens, under the pair's and the camera's names."""
    import logging

    import cv2
    import numpy as np

    for side in ("l", "r"):
        (tmp_path / side).mkdir()
        cv2.imwrite(str(tmp_path / side / "0.png"), np.zeros((6, 8, 3), np.uint8))
    devices = _pair_of(tmp_path, f"file://{tmp_path}/l/*.png", f"file://{tmp_path}/r/*.png")
    with caplog.at_level(logging.INFO, logger="stationd"):
        pair = devices.open_pair("pair1")
    try:
        lines = [r.getMessage() for r in caplog.records if r.name == "stationd"]
        for side, folder in (("left", "l"), ("right", "r")):
            [line] = [m for m in lines if m.startswith(f"pair1: camera pair1_{side}: ")]
            assert f"{tmp_path}/{folder}" in line, line
    finally:
        pair.close()
