"""Where the selections' crops are written: inside the images folder whatever the VIN (it
comes from the PLC) and the bolt's code say; and never onto a full disk: below
``records.images_keep_free_mb`` free they are not saved, said once, and saved again once there
is room (an IT administrator's trial: ~400 KB a tightening filled the disk, the database went
into fault and the tool off)."""

from __future__ import annotations

import logging
import shutil
from collections import namedtuple
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from stationd.config import RecordsConfig, StationConfig
from stationd.errors import StationError
from stationd.localize import Localization
from stationd.shell.records import Records


def test_a_vin_or_a_bolt_code_never_takes_the_images_out_of_their_folder(tmp_path: Path):
    """A security review: a VIN ``../../../tmp/zz`` from the PLC made the crops go outside
    the images folder, an absolute one (``/run/lock/x``) anywhere the daemon may write."""
    images = tmp_path / "images"
    cfg = replace(StationConfig(), records=RecordsConfig(images, True, 0))   # any disk
    records = Records(cfg)
    loc = Localization(np.zeros(3), crops={"pair1/left": np.full((8, 8, 3), 200, np.uint8)})
    for vin, bolt in (("../../../zz", "B1"), ("/run/lock/x", "B2"), ("VIN1", "../B3"),
                      ("..", "."), ("WVW ZZZ\n1", "B/4")):
        written = [Path(p) for p in records.save_images(vin, bolt, 7, loc)]
        assert len(written) == 1, (vin, bolt)
        assert written[0].resolve().is_relative_to(images.resolve()), written
        assert written[0].parent.parent == images and written[0].is_file()
    assert {p.name for p in images.iterdir()} == {"_._.._.._zz", "_run_lock_x", "VIN1", "_.",
                                                  "WVW_ZZZ_1"}
    assert not (tmp_path / "zz").exists() and not Path("/run/lock/x").exists()
    # an ordinary VIN and bolt keep their names
    plain = records.save_images("WVWZZZ1JZXW000001", "B07", 12, loc)
    assert plain == [str(images / "WVWZZZ1JZXW000001" / "B07-12-pair1-left.png")]


Usage = namedtuple("Usage", "total used free")


def test_images_wait_for_room_and_the_records_go_on(tmp_path: Path, monkeypatch, caplog):
    images = tmp_path / "images"
    records = Records(StationConfig(records=RecordsConfig(images, True, 1024)))
    loc = SimpleNamespace(crops={"p1/left": np.zeros((8, 8), np.uint8),
                                 "p1/right": np.zeros((8, 8), np.uint8)})
    free = {"mb": 500.0}
    monkeypatch.setattr(shutil, "disk_usage",
                        lambda path: Usage(10**12, 0, int(free["mb"] * 1e6)))
    with caplog.at_level(logging.INFO):
        assert records.save_images("VIN1", "B1", 1, loc) == []     # type: ignore[arg-type]
        assert records.save_images("VIN1", "B2", 2, loc) == []     # type: ignore[arg-type]
        free["mb"] = 5000.0
        saved = records.save_images("VIN1", "B3", 3, loc)          # type: ignore[arg-type]
    assert len(saved) == 2 and all(Path(p).is_file() for p in saved)
    assert not list(images.glob("*/B1-*")) and not list(images.glob("*/B2-*"))
    said = [(r.levelno, r.getMessage()) for r in caplog.records if "images" in r.getMessage()]
    assert [level for level, _ in said] == [logging.WARNING, logging.INFO], said
    assert "500 MB free" in said[0][1] and "records.images_keep_free_mb" in said[0][1]


def test_the_reserve_is_read_from_the_station_file(tmp_path: Path):
    from stationd.config import load_station_config as load_config

    station = tmp_path / "station.yaml"
    station.write_text(f"records: {{images_dir: {tmp_path}, save_images: true, "
                       "images_keep_free_mb: 200}\n")
    assert load_config(station).records.images_keep_free_mb == 200
    assert RecordsConfig().images_keep_free_mb == 1024
    station.write_text("records: {images_keep_free_mb: -5}\n")
    with pytest.raises(StationError, match="images_keep_free_mb"):
        load_config(station)
