"""The station's device opener (``stationd.shell.devices``): a pair's two cameras."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.engine import write_session
from db.models import CameraPin
from drivers.camera.sim import register_world, unregister_world
from drivers.errors import DeviceError, ProtocolError
from stationd.config import load_station_config
from stationd.shell.devices import Devices
from stationd.shell.records import Records

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


def _pinned(tmp_path: Path, left: str = "sim://pair1/left", *, opened: bool = True
            ) -> tuple[Devices, Records]:
    """Pair 1's devices with the station's records on a real SQLite database: a pair is up
    only with the cameras its calibration was first used with."""
    cfg = load_station_config(SIM)
    cfg = replace(cfg, database_url=f"sqlite:///{tmp_path}/s.db",
                  cameras={**cfg.cameras, "pair1_left": left})
    records = Records(cfg)
    if opened:
        records.open()
    return Devices(cfg, pins=records.pin_cameras), records


def test_a_camera_replaced_under_the_same_calibration_is_refused(tmp_path: Path) -> None:
    """A camera replaced by another unit (its serial number), the pair not calibrated again:
    its frames are the right size, and the old unit's calibration would have localized the
    wrench where it is not.  Refused, naming the camera, both serials and the calibration."""
    devices, _ = _pinned(tmp_path)
    devices.open_pair("pair1").close()                   # first opened: pinned
    devices, _ = _pinned(tmp_path, "sim://pair1/left?serial=SIM-SPARE-7")
    with pytest.raises(ProtocolError) as err:
        devices.open_pair("pair1")
    said = str(err.value)
    assert said.startswith("camera pair1_left is S/N SIM-SPARE-7, but the pair's calibration "
                           "(pair1.yaml) was made with S/N SIM-pair1-left"), said
    assert "calibrated again" in said and "pair1_right" not in said
    # the same unit back: up again
    devices, _ = _pinned(tmp_path)
    devices.open_pair("pair1").close()


def test_a_pair_coming_back_with_another_camera_is_not_back(tmp_path: Path) -> None:
    """The camera swapped while the station ran (unplugged, another unit plugged in): the
    reconnect's grab fits the calibration's size, and the pair is still not back."""
    devices, records = _pinned(tmp_path)
    pair = devices.open_pair("pair1")
    pc = devices.cfg.pairs["pair1"]
    assert records.repo is not None
    with write_session(records.repo.engine) as s:    # pinned to another unit meanwhile
        pin = s.get(CameraPin, ("pair1", "right", pc.calibration.digest()))
        assert pin is not None
        pin.serial = "HIK-00DA1234"
    w, h = pc.calibration.right.size
    register_world("pair1", lambda side, seed, at: np.zeros((h, w, 3), np.uint8))
    try:
        with pytest.raises(ProtocolError, match=r"camera pair1_right is S/N SIM-pair1-right, "
                                                r"but .* made with S/N HIK-00DA1234"):
            devices.reconnect_pair("pair1", pair)
    finally:
        unregister_world("pair1")
        pair.close()


def test_cameras_that_cannot_be_checked_are_not_trusted(tmp_path: Path) -> None:
    """The database not open (yet): the pair waits for it, it is never taken unchecked."""
    devices, _ = _pinned(tmp_path, opened=False)
    with pytest.raises(ProtocolError, match="not checked against its calibration "
                                            r"\(the database is not open\); retried"):
        devices.open_pair("pair1")


def test_a_camera_without_a_serial_number_opens_unpinned(tmp_path: Path) -> None:
    """A backend that cannot tell one unit from another (image files) is not pinned."""
    import cv2

    (tmp_path / "l").mkdir()
    cv2.imwrite(str(tmp_path / "l" / "0.png"), np.zeros((6, 8, 3), np.uint8))
    devices, records = _pinned(tmp_path, f"file://{tmp_path}/l/*.png")
    devices.open_pair("pair1").close()
    devices.open_pair("pair1").close()
    assert records.repo is not None
    with Session(records.repo.engine) as s:
        assert {p.side for p in s.scalars(select(CameraPin))} == {"right"}
