"""The demo's verdict and its station files, without running the simulated vehicle (that is
test_station_sim's): the summary from typed events, one readable line for a station the demo
cannot simulate, any station file's geometry on simulated devices."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from stationd.cli import main
from stationd.config import load_station_config
from stationd.demo.station import SIM_CONFIG, _summary, simulated
from stationd.station.events import EventBus, ParamsSent, ResultRecorded

EXAMPLE = Path(__file__).resolve().parents[2] / "config" / "station.example.yaml"


def _station(latencies=(100.0, 200.0), records=2):
    bus = EventBus()
    for ms in latencies:
        bus.publish(ParamsSent("B01", 1, {"total": ms}))
    for k in range(records):
        bus.publish(ResultRecorded("V", "B01", True, 20.0, 30.0, k))
    return SimpleNamespace(bus=bus)


REPORT = [{"bolt": "B01", "result": "OK 20.0 Nm", "ok": True},
          {"bolt": "B02", "result": "OK 20.1 Nm", "ok": True}]


def test_the_summary_ends_with_pass_only_when_every_bolt_was_handled_and_none_wrong():
    s = _summary(_station(), REPORT, 2, 0)
    assert s["verdict"].startswith("PASS: 2/2 bolts handled")
    assert s["latency_ms"]["p50"] == 150.0
    wrong = _summary(_station(), REPORT, 2, 1)
    assert wrong["verdict"].startswith("FAIL: 1 parameter send(s) for a wrong bolt")
    missed = _summary(_station(records=1), [*REPORT[:1], {"bolt": "B02",
                                                          "result": "not selected (stale)"}], 2, 0)
    assert missed["verdict"].startswith("FAIL") and "1 of 2 bolts not handled" in \
        missed["verdict"]
    lost = _summary(_station(records=1), REPORT, 2, 0)
    assert "1 result(s) not recorded" in lost["verdict"]


def test_an_empty_run_has_null_figures_not_nan():
    s = _summary(_station((), 0), [], 1, 0)
    assert s["latency_ms"]["p95"] is None and s["xy_error_mm"]["max"] is None


def test_any_station_files_geometry_runs_on_simulated_devices(tmp_path):
    cfg = simulated(load_station_config(EXAMPLE), tmp_path)
    assert cfg.lift.url == "sim://lift" and cfg.wrench.url == "sim://wrench"
    assert cfg.wrench.registers is None
    assert cfg.cameras == {"front_left": "sim://front/left", "front_right": "sim://front/right"}
    assert str(tmp_path) in cfg.database_url


def test_an_affine_vehicle_transform_is_one_readable_line_and_exit_2(tmp_path, capsys):
    shutil.copytree(SIM_CONFIG.parent, tmp_path / "sim")
    path = tmp_path / "sim" / "pair1.vehicle.yaml"
    text = path.read_text().replace("kind: rigid", "kind: affine")
    cfg = load_station_config(SIM_CONFIG)
    a = cfg.pairs["pair1"].to_vehicle.A * 1.02                  # a 2 % scale: affine
    rows = "\n".join(f"- [{', '.join(repr(float(v)) for v in r)}]" for r in a)
    head, _, rest = text.partition("A:\n")
    path.write_text(head + "A:\n" + rows + "\n" + rest[rest.index("t:"):])
    assert not np.allclose(load_station_config(tmp_path / "sim" / "station.yaml")
                           .pairs["pair1"].to_vehicle.A, cfg.pairs["pair1"].to_vehicle.A)
    code = main(["demo", "--config", str(tmp_path / "sim" / "station.yaml"), "--cycles", "1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "pair1: to_vehicle is affine" in err
