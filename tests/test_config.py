import re
import shutil

import numpy as np
import pytest

from stationd.config import check_station, load_station_config
from stationd.errors import ConfigError
from tests.conftest import SPEC

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
SIM = ROOT / "config" / "sim"


def test_example_station_config_loads():
    cfg = load_station_config(ROOT / "config" / "station.example.yaml")
    assert cfg.marker == SPEC
    assert cfg.vision.centre_method == "paper" and cfg.vision.gates.max_rms_px == 0.35
    assert list(cfg.pairs) == ["front"] and cfg.pairs["front"].left == "front_left"
    assert cfg.lift.url.startswith("modbus-tcp://") and cfg.lift.registers.vin is not None
    assert cfg.wrench.url.startswith("openprotocol://") and cfg.wrench.registers is None
    assert cfg.matching.max_age_s == 0.5 and cfg.records.save_images


def test_a_register_driven_wrench_takes_its_register_map(tmp_path):
    (tmp_path / "s.yaml").write_text(
        "wrench:\n  url: modbus-tcp://10.0.0.9:502?unit=2\n  registers:\n"
        "    tool_enable: {address: 205, bit: 15}\n    vin: null\n")
    w = load_station_config(tmp_path / "s.yaml").wrench
    assert w.registers is not None and w.registers.vin is None
    assert w.registers.tool_enable.address == 205
    assert w.open_options() == {"register_map": w.registers}
    (tmp_path / "s.yaml").write_text(
        "wrench:\n  url: openprotocol://10.0.0.9\n  registers:\n    vin: null\n")
    with pytest.raises(ConfigError, match=r"s.yaml:\d+: wrench.registers: a register map is "
                                          r"for a Modbus controller"):
        load_station_config(tmp_path / "s.yaml")


def _close(a, b, path="") -> None:
    """Equal structures, numbers within 1e-9 (relative or absolute): another CPU's last bit
    (-1.7e-18 for 0.0) is the same file."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), path
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float | int) and not isinstance(a, bool):
        assert isinstance(b, float | int) and not isinstance(b, bool), path
        assert b == pytest.approx(a, rel=1e-9, abs=1e-9), path
    else:
        assert a == b, path


def test_sim_station_files_are_the_generators_output():
    import yaml

    from stationd.sim.station_files import files

    for name, text in files().items():
        committed = (ROOT / "config" / "sim" / name).read_text()
        _close(yaml.safe_load(text), yaml.safe_load(committed), name)


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


# -- check_station: every error of a station file ------------------------------------------------
@pytest.fixture
def sim_copy(tmp_path):
    """A copy of config/sim (station, calibrations, to_vehicle files, bolts) to break."""
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    return tmp_path


def _edit(path, old, new):
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))
    return path


def _sub(path, pattern, new):
    """``_edit`` with a regular expression (values the generator may change)."""
    import re

    text = path.read_text()
    assert re.search(pattern, text), pattern
    path.write_text(re.sub(pattern, new, text, count=1))
    return path


def _line(path, needle, nth=0):
    """1-based line of the nth line of the file containing ``needle``."""
    return [i + 1 for i, line in enumerate(path.read_text().splitlines()) if needle in line][nth]


def test_shipped_station_files_check_clean():
    sim = check_station(SIM / "station.yaml")
    assert sim.ok and sim.errors == [] and sim.warnings == []
    assert sim.config is not None and len(sim.config.pairs) == 4 and len(sim.config.cameras) == 8
    assert sim.bolts is not None and sim.bolts.table is not None
    assert sim.bolts.table.summary() == "1 model(s), 50 bolt(s), 3 pset(s)"
    # the example names the simulated pair's files and the example bolt table
    example = check_station(ROOT / "config" / "station.example.yaml")
    assert example.ok and example.warnings == [] and example.bolts is not None


def test_independent_errors_are_all_reported_and_load_raises_one_of_them(sim_copy):
    station = _edit(sim_copy / "station.yaml", "left: pair3_left", "left: pair9_left")
    station.write_text(station.read_text() + "vision:\n  centre_methd: paper\n")
    result = check_station(station)
    assert not result.ok and result.config is None
    assert [str(e) for e in result.errors] == [
        f"{station}:{_line(station, 'pair9_left')}: pairs.pair3.left: no camera 'pair9_left' "
        "under cameras (cameras: pair1_left, pair1_right, pair2_left, pair2_right, pair3_left, "
        "pair3_right, pair4_left, pair4_right)",
        f"{station}:{_line(station, 'centre_methd')}: vision.centre_methd: unknown key "
        "(accepted: centre_method, enhance, enhancement, gates, hsv, leitz, max_candidates, "
        "residual, search_scale)",
    ]
    # the daemon's loader reads the same sections with the same code and stops at the first
    with pytest.raises(ConfigError) as ei:
        load_station_config(station)
    assert str(ei.value) == str(result.errors[1])  # vision is read before the pairs


def test_unknown_top_level_keys_are_each_reported_and_the_rest_still_checked(sim_copy):
    station = _edit(sim_copy / "station.yaml", "lift: {url: 'sim://lift'}",
                    "lifts: {url: 'sim://lift'}\ntool_: 1")
    _edit(station, "stable_frames: 3", "stable_frames: 0")
    errors = check_station(station).errors
    assert "missing section 'lift'" in str(errors[0]) and errors[0].key is None
    keys = [(e.line, e.key) for e in errors[1:]]
    assert keys == [(_line(station, "lifts:"), "lifts"), (_line(station, "tool_:"), "tool_"),
                    (_line(station, "matching:"), "matching.stable_frames")]


def test_a_station_file_names_its_devices(sim_copy):
    """Without lift: or wrench: a station would run simulated devices unnoticed."""
    station = _edit(sim_copy / "station.yaml", "lift: {url: 'sim://lift'}", "")
    _edit(station, "wrench: {url: 'sim://wrench'}", "")
    messages = [str(e) for e in check_station(station).errors]
    assert len(messages) == 2, messages
    assert "missing section 'lift'" in messages[0] and "missing section 'wrench'" in messages[1]
    with pytest.raises(ConfigError, match="missing section 'lift'"):
        load_station_config(station, station=True)
    assert load_station_config(station).pairs  # detect/localize read vision and pairs only


@pytest.mark.parametrize(("old", "new", "key", "message"), [
    (r"max_age_s: [0-9.]+", "max_age_s: 500", "matching.max_age_s", "500 s is not plausible"),
    (r"max_age_s: [0-9.]+", "max_age_s: 0.001", "matching.max_age_s",
     "0.001 s is not plausible"),
    (r"length_mm: 300\.0", "length_mm: 0.3", "tool.length_mm",
     "a tool length of 0.3 mm is not plausible (marker to socket tip: 50-1000 mm)"),
])
def test_implausible_values_are_refused_with_their_units(sim_copy, old, new, key, message):
    station = _sub(sim_copy / "station.yaml", old, new)
    [error] = check_station(station).errors
    assert error.key == key and message in str(error), str(error)
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_station_config(station)


def test_calibrations_in_metres_are_refused(sim_copy):
    """A pair calibration whose T is in metres (baseline 0.4) and a vehicle transform whose t
    is in metres: each refused, naming the unit, in its own file."""
    text = (sim_copy / "pair1.yaml").read_text()
    _edit(sim_copy / "pair1.yaml", "T: [-384.8296876873498, 0.0, 109.11512944801376]",
          "T: [-0.3848296876873498, 0.0, 0.10911512944801376]")
    assert text != (sim_copy / "pair1.yaml").read_text()
    _sub(sim_copy / "pair2.vehicle.yaml", r"(?m)^t: .*$", "t: [0.9, 0.75, -1.3]")
    errors = check_station(sim_copy / "station.yaml").errors
    texts = [str(e) for e in errors]
    assert any("stereo baseline 0.4 mm is not plausible (20-2000 mm)" in t for t in texts), texts
    assert any("pair2.vehicle.yaml" in t and "looks like metres" in t for t in texts), texts
    assert len(texts) == 2, texts


def test_a_relative_sqlite_path_is_relative_to_the_station_file(sim_copy, tmp_path,
                                                                 monkeypatch):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    cfg = load_station_config(sim_copy / "station.yaml")
    assert cfg.database_url == f"sqlite:///{sim_copy.resolve() / 'stationd-sim.db'}"
    _edit(sim_copy / "station.yaml", "sqlite:///stationd-sim.db", "sqlite:////var/lib/s.db")
    assert load_station_config(sim_copy / "station.yaml").database_url == \
        "sqlite:////var/lib/s.db"


def test_files_the_station_names_are_checked(sim_copy):
    station = sim_copy / "station.yaml"
    _edit(station, "pair1: {calibration: pair1.yaml", "pair1: {calibration: nope.yaml")
    _edit(station, "bolts: bolts.yaml", "bolts: gone.yaml")
    (sim_copy / "pair2.vehicle.yaml").write_text("A: [[1, 0, 0]]\nt: [0, 0, 0]\n")
    _edit(sim_copy / "pair3.yaml", "R:", "Rot:")
    result = check_station(station)
    assert [(e.path, e.key) for e in result.errors] == [
        (str(station), "pairs.pair1.calibration"),
        (str(station), "bolts"),
        (str(sim_copy / "pair2.vehicle.yaml"), "A"),
        (str(sim_copy / "pair3.yaml"), "Rot"),
    ]
    assert "calibration file" in str(result.errors[0]) and "does not exist" in \
        str(result.errors[0])
    assert f"bolt file {sim_copy / 'gone.yaml'} does not exist" in str(result.errors[1])
    assert result.bolts is None


def test_a_missing_to_vehicle_file_is_a_warning_not_an_error(sim_copy):
    """The daemon runs without it (the pair is not registered yet) and ``stationd calibrate
    vehicle`` writes it: not an error, but a person setting the station up should know."""
    (sim_copy / "pair4.vehicle.yaml").unlink()
    station = _edit(sim_copy / "station.yaml", "to_vehicle: pair2.vehicle.yaml",
                    "to_vehicle: pair2.vehicel.yaml")  # a typo: the loader takes it silently
    _edit(station, "to_vehicle: pair4.vehicle.yaml, ", "")  # the default, <pair>.vehicle.yaml
    result = check_station(station)
    assert result.ok and result.config is not None
    assert result.config.pairs["pair2"].to_vehicle is None
    assert [(e.line, e.key) for e in result.warnings] == [
        (_line(station, "pair2.vehicel"), "pairs.pair2.to_vehicle"),
        (_line(station, "pair4: {"), "pairs.pair4")]
    assert "pair4.vehicle.yaml does not exist: the pair is not registered into the vehicle " \
           "frame yet" in str(result.warnings[1])


@pytest.mark.parametrize(("old", "new", "key", "message"), [
    ("url: 'sim://pair2/right'", "url: 'gige://pair2/right'", "cameras.pair2_right.url",
     "unknown camera scheme 'gige'; accepted: aravis://"),
    ("lift: {url: 'sim://lift'}", "lift: {url: 'modbus-udp://10.0.0.1'}", "lift.url",
     "unknown lift scheme 'modbus-udp'; accepted: modbus-tcp://"),
    ("wrench: {url: 'sim://wrench'}", "wrench: {url: 'openprotocol://h:99999'}", "wrench.url",
     "openprotocol://h:99999: the port is not a number in 0-65535; accepted: openprotocol://"),
    ("wrench: {url: 'sim://wrench'}", "wrench: {url: 'wrench.local'}", "wrench.url",
     "'wrench.local' is not a device URL (scheme://...)"),
    ("lift: {url: 'sim://lift'}", "lift: {url: 'modbus-tcp://10.0.0.1?unit=300'}", "lift.url",
     "option unit='300' is not valid: a Modbus unit id is 0-247"),
    ("database: {url: 'sqlite:///stationd-sim.db'}", "database: {url: 'bogus://x'}",
     "database.url", "database URL 'bogus://x'"),
    # a third newcomer trial: Open Protocol's options passed the check, the controller then
    # stayed down ("unknown option(s) foo"), and a reload onto the file was accepted
    ("wrench: {url: 'sim://wrench'}", "wrench: {url: 'openprotocol://10.0.0.9?foo=1'}",
     "wrench.url",
     "unknown option(s) foo (accepted: connect_timeout, keepalive, link_ack, timeout"),
    ("wrench: {url: 'sim://wrench'}", "wrench: {url: 'openprotocol://10.0.0.9?timeout=-5'}",
     "wrench.url", "timeout must be > 0"),
    ("wrench: {url: 'sim://wrench'}",
     "wrench: {url: 'openprotocol+serial:///dev/ttyUSB9?baud=abc'}", "wrench.url",
     "option baud='abc' is not valid"),
])
def test_device_urls_are_checked_without_opening_a_device(sim_copy, old, new, key, message):
    station = _edit(sim_copy / "station.yaml", old, new)
    [error] = check_station(station).errors
    assert (error.line, error.key) == (_line(station, new.split("'")[1]), key)
    assert message in str(error)
    # the daemon's loader (first start and every reload) refuses the same, with the same words
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_station_config(station, station=True)
    load_station_config(station)  # other readers of a station file need not open its devices


def test_the_bolt_table_is_checked_with_the_stations_tolerance(sim_copy):
    bolts = sim_copy / "bolts.yaml"
    text = bolts.read_text()
    _edit(bolts, "- id: B02", "- id: B01")
    station = sim_copy / "station.yaml"
    [error] = check_station(station).errors
    assert (error.path, error.line, error.key) == (str(bolts), _line(bolts, "id: B01", 1),
                                                   "models.SIM-1.bolts[1].id")
    assert "duplicate bolt id 'B01'" in str(error)
    # two bolts 20 mm apart: fine at the 8 mm tolerance, too close at the station's 12 mm
    bolts.write_text(text.replace("position: [984.0, 358.7, -21.5]",
                                  "position: [1509.8, -529.3, -44.3]"))
    assert check_station(station).ok
    _edit(station, "tolerance_mm: 8.0", "tolerance_mm: 12.0")
    [error] = check_station(station).errors
    assert error.path == str(bolts) and "twice the matching tolerance of 12 mm" in str(error)
    _edit(station, "tolerance_mm: 12.0", "tolerance_mm: 0")  # the loader takes 0
    [error] = check_station(station).errors
    assert error.key == "matching" and "the bolt table cannot be checked" in str(error)


@pytest.mark.parametrize(("text", "message"), [
    ("cameras: [\n", "cfg.yaml:2: malformed YAML"),
    ("# nothing\n", "cfg.yaml: the file is empty"),
    ("- marker\n", "cfg.yaml:1: expected a mapping"),
])
def test_an_unreadable_station_file_is_one_error(tmp_path, text, message):
    p = tmp_path / "cfg.yaml"
    p.write_text(text)
    [error] = check_station(p).errors
    assert str(error).startswith(str(tmp_path / message))


def test_a_bolt_without_pset_on_a_psets_only_controller_is_a_warning(sim_copy):
    bolts = sim_copy / "bolts.yaml"
    text = bolts.read_text()
    head, tail = text.split("- id: B01", 1)
    bolts.write_text(head + "- id: B01" + tail.replace(
        "pset: 1", "torque: {target: 9.0, min: 8.0, max: 10.0}", 1))
    result = check_station(sim_copy / "station.yaml")
    assert result.ok
    [warning] = result.warnings
    assert warning.key == "wrench" and "B01 (SIM-1): no pset" in str(warning)
    assert "selects psets only" in str(warning)


@pytest.mark.parametrize(("old", "new", "key", "message"), [
    # a pair whose right image is its left camera's (one image triangulated with itself)
    ("right: pair1_right", "right: pair1_left", "pairs.pair1.right",
     "camera 'pair1_left' is already the left camera of pair 'pair1'"),
    # two pairs sharing a camera
    ("left: pair2_left", "left: pair1_right", "pairs.pair2.left",
     "camera 'pair1_right' is already the right camera of pair 'pair1'"),
    # two camera names for one device (its options aside)
    ("pair2_left: {url: 'sim://pair2/left'}", "pair2_left: {url: 'sim://pair1/left?x=1'}",
     "cameras.pair2_left", "the same camera as 'pair1_left' (sim://pair1/left)"),
])
def test_a_camera_serves_one_side_of_one_pair(sim_copy, old, new, key, message):
    station = _edit(sim_copy / "station.yaml", old, new)
    errors = check_station(station).errors
    assert [(e.key, e.line) for e in errors][:1] == [(key, _line(station, new))]
    assert message in str(errors[0])
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_station_config(station, station=True)


def test_a_duplicate_top_level_key_is_the_one_error_not_missing_sections(sim_copy):
    """Every section of a file whose top level has a duplicate key went unread, and was then
    also reported missing (four made-up errors before the real one)."""
    station = sim_copy / "station.yaml"
    station.write_text(station.read_text() + "bolts: bolts.yaml\n")
    errors = check_station(station).errors
    assert len(errors) == 1 and "bolts: duplicate key" in str(errors[0]), errors
