"""Property test of the command line: random argument vectors and random bytes as files, to
every sub-command, in-process through ``stationd.cli.main``.  Whatever comes in: no traceback,
and the exit code is 0, 1 or 2.

Bounded so that it stays fast and harmless: the long jobs (``demo``, ``bench``, ``run``) are
only parsed, never run; devices are only ``sim://`` twins on loopback, a refused loopback port
or URLs that are refused before anything is opened, with waits of at most half a second;
databases are SQLite files in the test's folder; every output path is in the test's folder,
which is also the working directory (so default outputs such as ``hsv.yaml`` land there).
"""

import contextlib
import io
import itertools
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stationd.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
LONG = {"demo", "bench", "run"}
TOKENS = ["-1", "0", "1", "2", "0.2", "nan", "inf", "-inf", "1e309", "", " ", "x", "--json",
          "-", "9x6", "a,b,c,d", "1,2,3,4", "0,0,0,0", "é", "\x7f", "--", "-q"]
BOARDS = ["chessboard:9x6:25", "chessboard:9x6", "charuco:5x5:20:15:DICT_4X4_50",
          "charuco:5x5:20:25:DICT_4X4_50", "charuco:50x50:20:15:DICT_4X4_50", "mono:3x3:1",
          "chessboard:2x2:-1", "chessboard:9x6:nan"]
SAFE_URLS = ["sim://lift", "sim://wrench", "sim://pair9/left", "sim://pair1/middle",
             "modbus-tcp://127.0.0.1:1?unit=1", "openprotocol://127.0.0.1:1", "bogus://x",
             "nourl", "", "sim://", "file:///nonexistent/*.png", "modbus-tcp://[::1"]
COUNTER = itertools.count()


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """The folder every example works in, with a few valid inputs beside the random ones."""
    d = tmp_path_factory.mktemp("fuzz")
    rng = np.random.default_rng(3)
    cv2.imwrite(str(d / "small.png"), rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    cam = {"K": [[80.0, 0, 32.0], [0, 80.0, 24.0], [0, 0, 1]], "dist": [0, 0, 0, 0, 0],
           "size": [64, 48]}
    (d / "cam.yaml").write_text(yaml.safe_dump(cam))
    (d / "pair.yaml").write_text(yaml.safe_dump({
        "left": cam, "right": cam, "R": np.eye(3).tolist(), "T": [-100.0, 0, 0]}))
    (d / "bolts.yaml").write_bytes((ROOT / "config" / "bolts.example.yaml").read_bytes())
    return d


def _file(work: Path, data: bytes, suffix: str) -> str:
    path = work / f"r{next(COUNTER)}{suffix}"
    path.write_bytes(data)
    return str(path)


@st.composite
def _argv(draw, work: Path):
    """One command line: a sub-command's template filled with random values and files."""
    def blob(suffix: str = ".yaml") -> str:
        kind = draw(st.sampled_from(["bytes", "yaml", "valid", "valid", "valid", "missing",
                                     "folder"]))
        if kind == "bytes":
            return _file(work, draw(st.binary(max_size=200)), suffix)
        if kind == "yaml":
            text = yaml.safe_dump(draw(st.dictionaries(
                st.sampled_from(["K", "size", "dist", "R", "T", "left", "right", "vision",
                                 "marker", "hsv", "pairs", "psets", "models", "cameras"]),
                st.one_of(st.integers(-3, 3), st.floats(allow_nan=True),
                          st.lists(st.integers(-2, 2), max_size=4), st.text(max_size=5)),
                max_size=4)))
            return _file(work, text.encode(), suffix)
        if kind == "valid":
            return str(work / ("small.png" if suffix == ".png" else draw(
                st.sampled_from(["cam.yaml", "pair.yaml", "bolts.yaml"]))))
        if kind == "folder":
            return str(work)
        return str(work / "no" / "such.file")

    def image() -> str:
        return blob(".png")

    def out(suffix: str) -> str:
        return str(draw(st.sampled_from([str(work / f"o{next(COUNTER)}{suffix}"),
                                         str(work / "no" / f"o{suffix}"), str(work),
                                         str(work / "small.png")])))

    def tok() -> str:
        return str(draw(st.one_of(st.sampled_from(TOKENS), st.text(max_size=8))))

    def opt(name: str, value: str) -> list[str]:
        return [name, value] if draw(st.booleans()) else []

    db = draw(st.sampled_from([f"sqlite:///{work}/fz.db", f"sqlite:///{work}/no/x.db",
                               "sqlite://", "nonsense", "sqlite:///" + str(work)]))
    wait = draw(st.sampled_from(["-5", "0", "nan", "inf", "0.1", "0.2", "x"]))
    cmd = draw(st.sampled_from([
        "detect", "localize", "marker", "tune-color", "calibrate stereo", "calibrate camera",
        "calibrate vehicle", "probe lift", "probe wrench", "probe camera", "db import",
        "db export", "db report", "config check", "demo", "bench vision", "bench chain",
        "bench station", "run"]))
    argv = cmd.split()
    if cmd == "detect":
        which = draw(st.sampled_from(["--camera", "--pair", "both"]))
        argv += [image(), *(["--camera", blob()] if which != "--pair" else []),
                 *(["--pair", blob()] if which != "--camera" else []),
                 *opt("--side", draw(st.sampled_from(["left", "right", "up"]))),
                 *opt("--config", blob()), *opt("--json", "--json")]
    elif cmd == "localize":
        argv += [image(), image(), "--pair", blob(), *opt("--config", blob()),
                 *opt("--repeat", draw(st.sampled_from(["-1", "0", "2", "x"])))]
    elif cmd == "marker":
        argv += [*opt("--out", out(".svg")), *opt("--config", blob())]
    elif cmd == "tune-color":
        argv += [image(), *opt("--roi", tok()), *opt("--out", out(".yaml"))]
    elif cmd == "calibrate stereo":
        argv += ["--left", image(), "--right", image(), "--board",
                 draw(st.sampled_from(BOARDS)), *opt("--out", out(".yaml")),
                 *opt("--out-left", out(".yaml")), *opt("--json", "--json")]
    elif cmd == "calibrate camera":
        argv += [image(), image(), "--board", draw(st.sampled_from(BOARDS)),
                 *opt("--out", out(".yaml"))]
    elif cmd == "calibrate vehicle":
        argv += ["--pair", tok(), "--points", blob(), *opt("--config", blob()),
                 *opt("--kind", tok())]
    elif cmd.startswith("probe"):
        argv += [draw(st.sampled_from(SAFE_URLS)), *opt("--timeout", wait),
                 *opt("--json", "--json")]
        if cmd == "probe wrench":
            argv += [*opt("--pset", tok()), *opt("--wait-result", wait)]
        if cmd == "probe lift":
            argv += opt("--config", blob())
        if cmd == "probe camera":
            argv += opt("--save", out(".png"))
    elif cmd == "db import":
        argv += [blob(), "--db", db, *opt("--tolerance", tok()), *opt("--json", "--json")]
    elif cmd == "db export":
        argv += ["--db", db, *opt("--out", out(".yaml"))]
    elif cmd == "db report":
        argv += [tok(), "--db", db, *opt("--json", "--json")]
    elif cmd == "config check":
        argv += [blob() for _ in range(draw(st.integers(0, 2)))]
    else:  # the long jobs: parsed only (see _runnable)
        argv += [*opt("--seed", tok()), *opt("--out", out(".json")), *opt("--cycles", tok())]
    # now and then a token out of place, an option twice or one cut off
    mutation = draw(st.sampled_from(["none"] * 5 + ["insert", "drop", "duplicate"]))
    if mutation == "insert":
        argv.insert(draw(st.integers(0, len(argv))), tok())
    elif mutation == "drop" and argv:
        del argv[draw(st.integers(0, len(argv) - 1))]
    elif mutation == "duplicate" and argv:
        argv.append(argv[draw(st.integers(0, len(argv) - 1))])
    return argv


def _runnable(argv: list[str], work: Path) -> bool:
    """Whether running ``argv`` is bounded and harmless (else it is only parsed)."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            args = build_parser().parse_args(argv)
        except SystemExit:
            return True  # a usage error: main answers it without running anything
    if args.command in LONG:
        return False
    if any(a.startswith(("/", "~", "..")) and not Path(a).resolve().is_relative_to(work)
           for a in argv):
        return False  # a path outside the test's folder (a device node, a system file)
    for key in ("out", "out_left", "out_right", "save", "points"):
        value = getattr(args, key, None)
        if value is not None and not Path(value).resolve().is_relative_to(work):
            return False
    db = getattr(args, "db", None)
    if db is not None and "://" in db and db != "sqlite://" \
            and not db.startswith(f"sqlite:///{work}"):
        return False
    if args.command == "probe":
        waits = [getattr(args, k, None) for k in ("timeout", "wait_result")]
        return args.url in SAFE_URLS and all(w is None or w <= 0.5 for w in waits)
    if args.command == "localize":
        return bool(args.repeat <= 3)
    if args.command == "calibrate" and args.calibrate == "vehicle":
        return args.config is None or Path(args.config).resolve().is_relative_to(work)
    return True


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse: usage errors (2), --help and --version (0)
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


FUZZ = settings(max_examples=120, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


def _check(argv: list[str], work: Path) -> None:
    if not _runnable(argv, work):
        return
    code, out, err = _run(argv)
    assert code in (0, 1, 2), (argv, code, err)
    assert "Traceback" not in err and "Traceback" not in out, (argv, err)
    if code == 2:
        assert err.strip(), (argv, "exit 2 without a word")


@FUZZ
@given(data=st.data())
def test_every_command_answers_random_input_without_a_traceback(work, monkeypatch, data):
    monkeypatch.chdir(work)
    before = set(os.listdir(ROOT))
    _check(data.draw(_argv(work)), work)
    assert set(os.listdir(ROOT)) == before  # nothing written beside the sources


@settings(max_examples=60, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(argv=st.lists(st.one_of(
    st.sampled_from(["detect", "localize", "marker", "tune-color", "calibrate", "stereo",
                     "camera", "vehicle", "probe", "lift", "wrench", "db", "import", "export",
                     "report", "config", "check", "demo", "bench", "run", "--json", "--out",
                     "--config", "--seed", "--help", "--version", "-q", "--board", "--pair"]),
    st.sampled_from(TOKENS), st.text(max_size=6)), max_size=6))
def test_random_argument_vectors_are_answered_in_one_line(work, monkeypatch, argv):
    monkeypatch.chdir(work)
    _check(argv, work)
