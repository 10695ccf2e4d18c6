"""Where the selections' crops are written: inside the images folder whatever the VIN (it
comes from the PLC) and the bolt's code say."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from stationd.config import RecordsConfig, StationConfig
from stationd.localize import Localization
from stationd.shell.records import Records


def test_a_vin_or_a_bolt_code_never_takes_the_images_out_of_their_folder(tmp_path: Path):
    """A security review: a VIN ``../../../tmp/zz`` from the PLC made the crops go outside
    the images folder, an absolute one (``/run/lock/x``) anywhere the daemon may write."""
    images = tmp_path / "images"
    cfg = replace(StationConfig(), records=RecordsConfig(images, True))
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
