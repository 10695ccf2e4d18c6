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
