import numpy as np
import pytest

from stationd.bench.scenes import station_pair
from stationd.config import load_station_config
from stationd.errors import ConfigError
from stationd.geometry.camera import StereoPair
from tests.conftest import SPEC

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def test_example_station_config_loads():
    cfg = load_station_config(ROOT / "config" / "station.example.yaml")
    assert cfg.marker == SPEC
    assert cfg.vision.centre_method == "paper" and cfg.vision.gates.max_rms_px == 0.35


def test_sim_pair_file_is_the_demo_pair():
    pair = StereoPair.load(ROOT / "config" / "sim" / "pair1.yaml")
    ref = station_pair()
    assert np.allclose(pair.R, ref.R) and np.allclose(pair.T, ref.T)
    assert np.allclose(pair.left.K, ref.left.K) and pair.left.size == (5472, 3648)


@pytest.mark.parametrize("text,needle", [
    ("vision:\n  centre_methd: paper\n", "cfg.yaml:2: vision.centre_methd: unknown key"),
    ("marker:\n  inner_mm: 20\n", "marker: marker radii must satisfy"),
    ("vision:\n  hsv:\n    h: [118]\n    s: [50, 255]\n    v: [45, 255]\n", "vision.hsv.h"),
    ("vision:\n  hsv: missing.yaml\n", "does not exist"),
    ("vision:\n  gates:\n    min_points: 2\n", "out of range"),
    ("lifts: {}\n", "unknown key"),
    ("lift: modbus://x\n", "lift: expected a mapping"),
])
def test_config_errors_name_file_line_and_key(tmp_path, text, needle):
    p = tmp_path / "cfg.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as ei:
        load_station_config(p)
    assert needle in str(ei.value)
