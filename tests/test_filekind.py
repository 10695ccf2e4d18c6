"""Each kind of the station's files given to each reader the commands use: its own kind is
read, any other is refused in one line naming what the file is and what was expected (a
station file given as a pair calibration said ``cameras: unknown key``, issue 19)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from stationd.boltfile import TOP_KEYS, load_bolts
from stationd.config import STATION_KEYS, load_station_config
from stationd.errors import ConfigError
from stationd.filekind import KINDS, described, expect, kind_of_keys
from stationd.geometry.camera import PAIR_KEYS, Camera, StereoPair
from stationd.geometry.frames import REGISTRATION_KEYS
from stationd.outfile import kind_of
from stationd.stationcheck import check_station
from stationd.yamlio import YamlNode

ROOT = Path(__file__).resolve().parents[1]
SIM = ROOT / "config" / "sim"
EXPECTED = {"camera": "a camera calibration", "pair": "a stereo pair calibration",
            "registration": "a vehicle registration", "station": "a station file",
            "bolts": "a bolt table"}


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One file of each kind (the simulated station's), beside the files they name."""
    d = tmp_path_factory.mktemp("kinds")
    for f in SIM.iterdir():
        shutil.copy(f, d)
    pair = yaml.safe_load((SIM / "pair1.yaml").read_text())
    (d / "camera.yaml").write_text(yaml.safe_dump(pair["left"]))
    return {"camera": d / "camera.yaml", "pair": d / "pair1.yaml",
            "registration": d / "pair1.vehicle.yaml", "station": d / "station.yaml",
            "bolts": d / "bolts.yaml"}


def _registration(path: Path) -> Any:
    """A registration as the commands read it: named by a pair of the station file."""
    station = path.parent / f"station-with-{path.stem}.yaml"
    station.write_text((path.parent / "station.yaml").read_text().replace(
        "to_vehicle: pair1.vehicle.yaml", f"to_vehicle: {path.name}", 1))
    return load_station_config(station)


READERS: dict[str, Callable[[Path], Any]] = {
    "camera": Camera.load,             # detect --camera
    "pair": StereoPair.load,           # localize --pair, a pair's calibration: in a station
    "registration": _registration,     # a pair's to_vehicle: in a station file
    "station": load_station_config,    # every --config
    "bolts": load_bolts,               # db import, the station's bolts:
}


@pytest.mark.parametrize("given", list(EXPECTED))
@pytest.mark.parametrize("reader", list(READERS))
def test_each_kind_of_file_given_to_each_reader(files, reader, given):
    if reader == given:
        READERS[reader](files[given])              # its own kind: read
        return
    with pytest.raises(ConfigError) as caught:
        READERS[reader](files[given])
    message = str(caught.value)
    assert f"{files[given]}:" in message                            # the file given, a line
    assert f"this is {described(given)}, not {EXPECTED[reader]} (" in message, message
    assert "unknown key" not in message


def test_a_station_file_given_as_a_pair_calibration_in_the_command_and_the_check(
        files, tmp_path, capsys):
    """The case of the issue, as a commissioning engineer meets it: ``localize --pair`` and a
    station file whose pair names a station file as its calibration (``config check``)."""
    from stationd.cli import main

    station = files["station"]
    code = main(["localize", str(files["pair"]), str(files["pair"]), "--pair", str(station)])
    err = capsys.readouterr().err
    assert code == 2 and err.splitlines() == [
        f"stationd: error: {station}:2: this is a station file, not a stereo pair calibration "
        "(a pair calibration has left:, right:, R: and T:, from stationd calibrate stereo)"]
    wrong = tmp_path / "station.yaml"
    for f in files["station"].parent.iterdir():
        shutil.copy(f, tmp_path)
    wrong.write_text(wrong.read_text().replace("calibration: pair2.yaml",
                                               "calibration: station.yaml", 1))
    errors = [str(e) for e in check_station(wrong).errors]
    assert any("pair2" not in e and "this is a station file, not a stereo pair calibration "
               "(a pair calibration has left:, right:, R: and T:" in e for e in errors), errors


def test_a_file_of_mixed_keys_is_read_with_its_unknown_keys_at_their_lines():
    """One of the reader's own keys: it is read, the stray key told where it is."""
    root = YamlNode.parse("K: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nsize: [4, 4]\ncameras: {}\n",
                          "cam.yaml")
    expect(root, "camera", ("K", "dist", "size"))     # not refused as a station file
    with pytest.raises(ConfigError, match=r"cam.yaml:3: cameras: unknown key"):
        Camera.from_node(root)
    assert kind_of_keys({"hsv"}) == "hsv" and kind_of_keys({"x"}) is None
    assert kind_of_keys({"K", "notes"}) is None            # K alone is no camera calibration


def test_the_kinds_keys_are_the_readers_own(files):
    """The keys that tell a kind are keys its reader accepts; ``outfile`` names them alike."""
    assert KINDS["station"].keys <= set(STATION_KEYS)
    assert KINDS["bolts"].keys == set(TOP_KEYS)
    assert KINDS["pair"].keys == set(PAIR_KEYS)
    assert KINDS["registration"].keys <= set(REGISTRATION_KEYS)
    assert {k: kind_of(p) for k, p in files.items()} == {k: k for k in files}
