"""``stationd probe camera``: exit codes 0 / 1 / 2 through the real CLI, on file://, sim://
and Aravis's fake GigE camera."""

import argparse
import json

import cv2
import numpy as np
import pytest

from drivers.camera import sim
from stationd import probe
from stationd.cli import main
from stationd.probe_camera import add_camera_probe


@pytest.fixture(autouse=True)
def camera_probe_wired(monkeypatch):
    """Until stationd/probe.py calls add_camera_probe itself, add it the same way."""
    original = probe.add_probe_parser

    def add_probe_parser(sub):
        original(sub)
        actions = sub.choices["probe"]._actions
        psub = next(a for a in actions if isinstance(a, argparse._SubParsersAction))
        if "camera" not in psub.choices:
            add_camera_probe(psub)

    monkeypatch.setattr(probe, "add_probe_parser", add_probe_parser)


@pytest.fixture
def frames(tmp_path):
    for i in (1, 2):
        assert cv2.imwrite(str(tmp_path / f"left_{i}.png"), np.full((30, 40, 3), 50 * i,
                                                                      np.uint8))
    return tmp_path


def test_file_replay_frame_saved_exit_0(frames, tmp_path, capsys):
    out = tmp_path / "frame.png"
    code = main(["probe", "camera", f"file://{frames}/left_*.png", "--json", "--save",
                 str(out)])
    obj = json.loads(capsys.readouterr().out)
    assert code == 0 and obj["ok"] is True and obj["identity"].startswith("file replay")
    assert (obj["width"], obj["height"], obj["pixel_format"]) == (40, 30, "BGR8")
    assert obj["saved"] == str(out) and cv2.imread(str(out))[0, 0].tolist() == [50, 50, 50]


def test_text_output(frames, capsys):
    assert main(["probe", "camera", f"file://{frames}/left_1.png"]) == 0
    text = capsys.readouterr().out
    assert "frame 0: 40x30 BGR from BGR8, timestamp 20" in text


def test_unreadable_frame_exit_1(frames, capsys):
    (frames / "left_1.png").write_bytes(b"garbage")
    code = main(["probe", "camera", f"file://{frames}/left_*.png"])
    err = capsys.readouterr().err
    assert code == 1 and "left_1.png: not a readable image" in err and err.count("\n") == 1


def test_sim_without_then_with_a_world(capsys):
    # without a world the probe starts the simulated station's (tests/test_probe.py renders
    # one); a pair that station does not have is bad input
    code = main(["probe", "camera", "sim://pair9/left", "--json"])
    captured = capsys.readouterr()
    assert code == 2 and captured.out == ""
    assert "no pair 'pair9' in the simulated station" in captured.err
    assert captured.err.count("\n") == 1
    # a world already registered (a running demo) is used, not replaced
    sim.register_world("pair1", lambda side, seed, at: np.zeros((5, 6, 3), np.uint8))
    try:
        assert main(["probe", "camera", "sim://pair1/right", "--json"]) == 0
    finally:
        sim.unregister_world("pair1")
    assert json.loads(capsys.readouterr().out)["width"] == 6


@pytest.mark.parametrize("argv,needle", [
    (["gige://cam1"], "unknown camera scheme 'gige'"),
    (["sim://pair1/left?sede=3"], "unknown option sede"),
    (["file:///x/*.png", "--timeout", "0"], "--timeout 0: must be > 0"),
    (["sim://pair1/left", "--save", "frame.xyz"], "no image writer for .xyz"),
    (["sim://pair1/left", "--save", "/no/such/dir/f.png"], "no such directory /no/such/dir"),
])
def test_bad_url_or_option_exit_2(argv, needle, capsys):
    code = main(["probe", "camera", *argv])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and err.count("\n") == 1


def test_aravis_fake_camera(fake, capsys):
    code = main(["probe", "camera", fake.url("region=0,0,64,48&pixel_format=BayerGR8"),
                 "--json"])
    obj = json.loads(capsys.readouterr().out)
    assert code == 0 and obj["identity"].startswith("Aravis Fake S/N STATIOND1")
    assert (obj["width"], obj["height"], obj["pixel_format"]) == (64, 48, "BayerGR8")


def test_aravis_camera_that_never_sends_exit_1(fake, capsys):
    code = main(["probe", "camera", fake.url("region=0,0,64,48&trigger=line0"),
                 "--timeout", "0.3"])
    err = capsys.readouterr().err
    assert code == 1 and "no frame within 0.3 s" in err and err.count("\n") == 1
