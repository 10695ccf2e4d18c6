"""The benchmark command runs and its figures are sane (a smoke run, not a timing test)."""

import argparse
import json

import numpy as np
import pytest

from stationd.bench.vision import run_vision_bench
from stationd.errors import InputError


def test_rod_section_quick(tmp_path, capsys):
    out = tmp_path / "b.json"
    args = argparse.Namespace(only="rod", quick=True, out=str(out), seed=3)
    assert run_vision_bench(args) == 0
    res = json.loads(out.read_text())
    rod = res["rod"]
    assert rod["refused"] == 0 and rod["corrected"]["n"] == 16
    assert rod["corrected"]["mean"] < 0.05
    assert rod["corrected"]["mean"] < rod["ellipse"]["mean"]  # the correction helps
    assert "Reference rod" in capsys.readouterr().out


def test_unknown_section_is_an_input_error(tmp_path):
    args = argparse.Namespace(only="rod,warp", quick=True, out=str(tmp_path / "b.json"), seed=1)
    with pytest.raises(InputError, match="unknown section"):
        run_vision_bench(args)


def test_robustness_section_counts_found_wrong_and_phantoms(capsys):
    from stationd.bench.robustness import bench_robustness, print_table

    res = bench_robustness(np.random.default_rng(2), True,
                           only=("clean", "occluded 20-40 %", "phantom: washer"), n=2)
    assert res["clean"]["found"] == 2 and res["clean"]["wrong"] == 0
    assert res["clean"]["median"] < 0.05
    assert res["phantom: washer"]["phantom"] == 0
    assert "apriltag" in res["occluded 20-40 %"]
    print_table(res)
    out = capsys.readouterr().out
    assert "condition" in out and "AprilTag 3" in out and "phantom: washer" in out


def test_speed_section_breaks_the_time_down_by_stage(capsys):
    """On a 5 MP pair (the 20 MP camera at half resolution, to keep the test fast): every
    stage is reported, the parts never exceed their whole, the frame without a marker is
    refused for want of purple, and the table names the target."""
    from stationd.bench.report import print_report
    from stationd.bench.vision import STAGES, bench_speed
    from stationd.geometry.camera import Camera
    from stationd.sim.render import default_camera

    cam = default_camera()
    K = cam.K.copy()
    K[:2, :2] *= 0.5
    K[:2, 2] = (K[:2, 2] + 0.5) * 0.5 - 0.5  # pixel centres stay on the same rays
    small = Camera(K=K, dist=cam.dist, size=(cam.size[0] // 2, cam.size[1] // 2))
    res = bench_speed(np.random.default_rng(1), True, camera=small, apriltag=False)
    assert res["found"] and res["frame"] == [2736, 1824] and res["runs"] == 5
    stages = res["stage_ms_median"]
    assert set(STAGES) <= set(stages) and "total" in stages
    assert all(v >= 0.0 for v in stages.values())
    assert stages["retinex"] <= stages["segment"]  # a part of the search
    assert res["stages_within_total"] is True    # in every run (medians need not add up)
    assert res["pair_cpu_ms_median"] > 0.0 and res["stereo_ms_median"] > 0.0
    assert res["target_pair_ms"] == 30.0
    empty = res["no_marker"]
    assert not empty["found"] and "no purple region" in empty["reason"]
    # the reduced search ran and nothing after it did
    assert {"reduce", "segment"} <= set(empty["stage_ms"])
    assert not {"rays", "edges", "fit"} & set(empty["stage_ms"])
    print_report({"speed": res})
    out = capsys.readouterr().out
    assert "of which Retinex" in out and "frame without a marker" in out
    assert "<= 30 ms per stereo pair" in out
