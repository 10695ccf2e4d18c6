import numpy as np
import pytest

from stationd.config import load_station_config
from stationd.errors import ConfigError
from tests.conftest import SPEC

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def test_example_station_config_loads():
    cfg = load_station_config(ROOT / "config" / "station.example.yaml")
    assert cfg.marker == SPEC
    assert cfg.vision.centre_method == "paper" and cfg.vision.gates.max_rms_px == 0.35


def test_sim_station_files_are_the_generators_output():
    from stationd.sim.station_files import files

    for name, text in files().items():
        assert (ROOT / "config" / "sim" / name).read_text() == text, name


def test_sim_station_config_loads_with_its_four_pairs():
    cfg = load_station_config(ROOT / "config" / "sim" / "station.yaml")
    assert sorted(cfg.pairs) == ["pair1", "pair2", "pair3", "pair4"]
    for name, p in cfg.pairs.items():
        assert p.left == f"{name}_left" and cfg.cameras[p.left] == f"sim://{name}/left"
        assert p.to_vehicle is not None and abs(np.linalg.det(p.to_vehicle.A) - 1) < 1e-9
        assert p.calibration.left.size == (5472, 3648)
    assert cfg.lift.url == "sim://lift" and cfg.wrench.url == "sim://wrench"
    assert cfg.matching.stable_frames == 3 and cfg.bolts_path.name == "bolts.yaml"


@pytest.mark.parametrize("text,needle", [
    ("vision:\n  centre_methd: paper\n", "cfg.yaml:2: vision.centre_methd: unknown key"),
    ("marker:\n  inner_mm: 20\n", "marker: marker radii must satisfy"),
    ("vision:\n  hsv:\n    h: [118]\n    s: [50, 255]\n    v: [45, 255]\n", "vision.hsv.h"),
    ("vision:\n  hsv: missing.yaml\n", "does not exist"),
    ("vision:\n  gates:\n    min_points: 2\n", "out of range"),
    ("lifts: {}\n", "unknown key"),
    ("cameras:\n  c1: {url: 'sim://p/left'}\npairs:\n  p:\n    calibration: cfg.yaml\n"
     "    left: c9\n", "no camera 'c9'"),
    ("matching:\n  stable_frames: 0\n", "matching.stable_frames: 0 is out of range"),
    ("bolts: nowhere.yaml\n", "bolt file"),
    ("lift: modbus://x\n", "lift: expected a mapping"),
])
def test_config_errors_name_file_line_and_key(tmp_path, text, needle):
    p = tmp_path / "cfg.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as ei:
        load_station_config(p)
    assert needle in str(ei.value)
