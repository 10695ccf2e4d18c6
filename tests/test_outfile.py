"""The one rule for every output file (stationd.outfile): never through or over a link,
never over a file of another kind, whole or not at all, with the umask's mode."""

import os
import shutil
import stat
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from stationd.errors import InputError
from stationd.outfile import (
    DRAWING_STAMP,
    forget_written,
    kind_of,
    refuse_to_replace,
    stamp_png,
    write_all,
    write_atomic,
    written,
)

SIM = Path(__file__).resolve().parents[1] / "config" / "sim"


def _chunks(png: bytes) -> list[tuple[bytes, bytes]]:
    """Every chunk of a PNG, each CRC checked."""
    out, i = [], 8
    while i < len(png):
        (n,) = struct.unpack(">I", png[i:i + 4])
        kind, data = png[i + 4:i + 8], png[i + 8:i + 8 + n]
        assert struct.unpack(">I", png[i + 8 + n:i + 12 + n])[0] == zlib.crc32(kind + data)
        out.append((kind, data))
        i += 12 + n
    return out


def test_a_stamped_png_is_a_valid_png_known_as_the_drawing(tmp_path):
    img = np.random.default_rng(0).integers(0, 255, (40, 60, 3), dtype=np.uint8)
    png = cv2.imencode(".png", img)[1].tobytes()
    stamped = stamp_png(png, DRAWING_STAMP)
    chunks = _chunks(stamped)
    assert [k for k, _ in chunks][:2] == [b"IHDR", b"tEXt"] and chunks[-1][0] == b"IEND"
    assert chunks[1][1] == b"Software\0stationd detect --draw"
    assert np.array_equal(cv2.imdecode(np.frombuffer(stamped, np.uint8), cv2.IMREAD_COLOR),
                          img)
    (tmp_path / "d.png").write_bytes(stamped)
    (tmp_path / "p.png").write_bytes(png)
    (tmp_path / "j.jpg").write_bytes(cv2.imencode(".jpg", img)[1].tobytes())
    assert [kind_of(tmp_path / n) for n in ("d.png", "p.png", "j.jpg")] == [
        "drawing", "png", "image"]
    with pytest.raises(ValueError, match="not a PNG"):
        stamp_png(b"GIF89a", DRAWING_STAMP)


def test_calibrations_are_told_apart_by_kind(tmp_path):
    """``calibrate camera --out pair.yaml`` replaced a pair calibration: each calibration is
    a kind of its own, as a station file and a bolt table are."""
    from stationd.geometry.camera import StereoPair

    pair = StereoPair.load(SIM / "pair1.yaml")
    (tmp_path / "cam.yaml").write_text(
        "# a camera\n" + "\n".join(f"{k}: {v}" for k, v in pair.left.to_dict().items()))
    assert kind_of(SIM / "pair1.yaml") == "pair"
    assert kind_of(tmp_path / "cam.yaml") == "camera"
    assert kind_of(SIM / "pair1.vehicle.yaml") == "registration"
    assert kind_of(SIM / "station.yaml") == "station"
    assert kind_of(SIM / "bolts.yaml") == "bolts"
    (tmp_path / "other.yaml").write_text("K: 1\nnotes: x\n")   # K alone: not a camera's
    assert kind_of(tmp_path / "other.yaml") == "yaml"


def test_a_link_is_refused_whatever_it_points_at(tmp_path):
    """An output is never written through a link (it would replace the target) nor over
    one: a link to a file of the very kind, to nothing, or to a folder, all refused."""
    shutil.copy(SIM / "pair1.yaml", tmp_path / "pair1.yaml")
    for name, target, what in (("same.yaml", "pair1.yaml", "a stereo pair calibration"),
                               ("dangling.yaml", "gone.yaml", "which does not exist"),
                               ("dir.yaml", ".", "a folder")):
        (tmp_path / name).symlink_to(tmp_path / target)
        with pytest.raises(InputError, match=f"is a symbolic link to .*, {what}.*; an output "
                           "is never written through or over a link: give --out"):
            refuse_to_replace(tmp_path / name, "a stereo pair calibration", ("pair",))
    refuse_to_replace(tmp_path / "pair1.yaml", "a stereo pair calibration", ("pair",))
    refuse_to_replace(tmp_path / "new.yaml", "a stereo pair calibration", ("pair",))


def test_written_files_take_the_umask_mode_or_keep_the_replaced_ones(tmp_path):
    old = os.umask(0o027)
    try:
        write_atomic(tmp_path / "a.png", b"\x89PNG bytes")
        write_all([(tmp_path / "b.yaml", "b: 1\n"), (tmp_path / "c.yaml", "c: 1\n")])
    finally:
        os.umask(old)
    for name in ("a.png", "b.yaml", "c.yaml"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o640, name
    assert (tmp_path / "a.png").read_bytes() == b"\x89PNG bytes"
    (tmp_path / "b.yaml").chmod(0o604)
    write_atomic(tmp_path / "b.yaml", "b: 2\n")
    assert stat.S_IMODE((tmp_path / "b.yaml").stat().st_mode) == 0o604
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.yaml", "c.yaml"]


def test_a_signal_between_two_renames_comes_after_the_last(tmp_path, monkeypatch):
    """``calibrate stereo`` writes the pair and a camera together, all or none; a Ctrl-C
    that landed between the two renames left one new and one old, and one just after a
    rename a file in place that the stop line never named.  The signal waits until every
    file is in place, and each is remembered as written; with the command line's own
    handler, and threads beside the main one (the kernel may give the signal to any)."""
    import signal
    import threading

    from stationd.cli import _signals

    pair, cam = tmp_path / "pair.yaml", tmp_path / "cam.yaml"
    pair.write_text("old\n")
    cam.write_text("old\n")
    real = os.replace
    sent: list[str] = []

    def replace_then_interrupted(src: str, dst: os.PathLike[str]) -> None:
        real(src, dst)
        if not sent:
            sent.append(str(dst))
            os.kill(os.getpid(), signal.SIGINT)   # the Ctrl-C, between the two renames

    forget_written()
    before = signal.signal(signal.SIGINT, signal.default_int_handler)   # not ignored
    monkeypatch.setattr("stationd.outfile.os.replace", replace_then_interrupted)
    idle = threading.Event()
    beside = threading.Thread(target=idle.wait, daemon=True)
    beside.start()
    try:
        with _signals(restore=True) as stopped, pytest.raises(KeyboardInterrupt):
            write_all([(pair, "new pair\n"), (cam, "new cam\n")])
    finally:
        idle.set()
        signal.signal(signal.SIGINT, before)
    assert stopped.signal == signal.SIGINT
    assert sent == [str(pair)]
    assert (pair.read_text(), cam.read_text()) == ("new pair\n", "new cam\n")
    assert written() == (pair, cam)
    assert [f.name for f in tmp_path.iterdir() if f.name.startswith(".")] == []
