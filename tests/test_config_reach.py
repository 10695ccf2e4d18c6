"""A path the station file names that the station's user cannot reach: one line naming the
path and why, exit 2, and ``config check`` lists it with file, line and key.

A new user's trial: as user ``nobody``, a database, bolt table or calibration under
``/root`` gave a traceback ending in ``PermissionError: [Errno 13]`` and exit 1 (systemd
restarts that forever).  Root reaches every folder, so the permission case runs the commands
as another user; the other errors of the system's (a file where a folder was meant, a name
too long) are the same for root and are checked in this process.
"""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from stationd.config import load_station_config
from stationd.errors import ConfigError
from stationd.stationcheck import check_station, validate_station

ROOT = Path(__file__).resolve().parents[1]
SIM = ROOT / "config" / "sim"
#: the user a permission test runs its commands as, when the tests run as root
NOBODY = 65534
#: the places of the three paths in config/sim/station.yaml, as the checker names them
DATABASE = ("database: {url: 'sqlite:///stationd-sim.db'}", "database.url")
BOLTS = ("bolts: bolts.yaml", "bolts")
CALIBRATION = ("calibration: pair1.yaml", "pairs.pair1.calibration")


def _station(folder: Path, *, database: str | None = None, bolts: str | None = None,
             calibration: str | None = None) -> Path:
    """A copy of config/sim in ``folder`` with the three paths replaced where given."""
    for f in SIM.iterdir():
        if f.is_file() and not f.name.startswith("stationd-sim.db"):
            shutil.copy(f, folder)
    station = folder / "station.yaml"
    text = station.read_text().replace("http: {listen: '127.0.0.1:8080'}", "")
    for (old, _), new in ((DATABASE, database and f"database: {{url: 'sqlite:///{database}'}}"),
                          (BOLTS, bolts and f"bolts: {bolts}"),
                          (CALIBRATION, calibration and f"calibration: {calibration}")):
        if new is not None:
            assert old in text
            text = text.replace(old, new)
    station.write_text(text)
    return station


def _errors_by_key(station: Path) -> dict[str, str]:
    checked = check_station(station)
    assert checked.config is None
    return {e.key or "": str(e) for e in checked.errors}


def test_a_file_where_a_folder_is_meant_is_named_for_each_path(tmp_path):
    """``/x/afile/stationd.db`` with ``afile`` a file: the database's was "folder does not
    exist: create it" (it is there), the bolt table's and calibration's "does not exist"."""
    afile = tmp_path / "afile"
    afile.write_text("a file, not a folder\n")
    station = _station(tmp_path, database=f"{afile}/stationd.db", bolts=f"{afile}/bolts.yaml",
                       calibration=f"{afile}/pair1.yaml")
    errors = _errors_by_key(station)
    assert set(errors) == {DATABASE[1], BOLTS[1], CALIBRATION[1]}, errors
    said = f"{afile} is a file, not a folder"
    assert errors[DATABASE[1]].endswith(f"database {afile}/stationd.db: {said}")
    assert errors[BOLTS[1]].endswith(f"bolt file {afile}/bolts.yaml: {said}")
    assert errors[CALIBRATION[1]].endswith(f"calibration file {afile}/pair1.yaml: {said}")
    with pytest.raises(ConfigError, match=said):
        validate_station(station)   # the daemon's start and reload


@pytest.mark.parametrize("which", ["database", "bolts", "calibration"])
def test_any_error_of_the_systems_on_a_path_is_one_line_not_a_traceback(tmp_path, which):
    """A name longer than the file system takes (ENAMETOOLONG) was an OSError out of
    ``Path.exists``: a traceback from ``config check``, ``stationd run`` and a reload."""
    long = tmp_path / ("a" * 300)
    station = _station(tmp_path, **{which: f"{long}/{which}.yaml"})
    key = {"database": DATABASE, "bolts": BOLTS, "calibration": CALIBRATION}[which][1]
    errors = _errors_by_key(station)
    assert list(errors) == [key], errors
    assert errors[key].endswith("cannot be reached (file name too long)")
    assert "station.yaml:" in errors[key] and "\n" not in errors[key]
    with pytest.raises(ConfigError, match=r"cannot be reached \(file name too long\)"):
        load_station_config(station, station=True)


def test_a_registration_and_an_images_folder_that_cannot_be_reached_are_errors(tmp_path):
    """The pair's vehicle registration and the records' images folder are looked at too."""
    long = tmp_path / ("b" * 300)
    station = _station(tmp_path)
    text = station.read_text().replace("to_vehicle: pair1.vehicle.yaml",
                                       f"to_vehicle: {long}/pair1.vehicle.yaml")
    station.write_text(text + f"records: {{images_dir: {long}/images}}\n")
    errors = _errors_by_key(station)
    assert errors["pairs.pair1.to_vehicle"].endswith(
        f"vehicle registration file {long}/pair1.vehicle.yaml: cannot be reached (file name "
        "too long)")
    assert errors["records.images_dir"].endswith(
        f"folder {long}/images: cannot be reached (file name too long)")


# -- a folder closed to the service's user: the commands run as another user --------------------
@pytest.fixture
def open_folder() -> Iterator[Path]:
    """A folder every user may enter (pytest's tmp_path is its owner's only), removed at the
    end."""
    folder = Path(tempfile.mkdtemp(prefix="stationd-reach-"))
    try:
        folder.chmod(0o755)
        yield folder
    finally:
        for closed in folder.rglob("*"):   # a folder closed for the test: opened to remove
            if closed.is_dir():
                closed.chmod(0o755)
        shutil.rmtree(folder)


def _as_user(argv: list[str], cwd: Path) -> tuple[subprocess.CompletedProcess[str], str]:
    """``python -m stationd argv`` as the user the test checks for (``nobody`` when the tests
    run as root: root enters every folder; else the tests' own user), and that user's name.
    Skipped, saying why, when that user cannot run this checkout's Python here."""
    as_root = os.geteuid() == 0
    who: dict[str, Any] = {"user": NOBODY, "group": NOBODY, "extra_groups": []} if as_root else {}
    name = pwd.getpwuid(NOBODY if as_root else os.geteuid()).pw_name
    env = {**os.environ, "HOME": str(cwd),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    try:
        probe = subprocess.run([sys.executable, "-c", "import stationd.cli"], cwd=cwd,
                               env=env, capture_output=True, text=True, timeout=60, **who)
    except OSError as exc:   # the switch of user, or the exec, itself refused
        pytest.skip(f"cannot run a process as uid {NOBODY}: {exc}")
    if probe.returncode != 0:
        pytest.skip(f"user {name} cannot run {sys.executable} on {ROOT} here "
                    f"({probe.stderr.strip().splitlines()[-1:]})")
    r = subprocess.run([sys.executable, "-m", "stationd", *argv], cwd=cwd, env=env,
                       capture_output=True, text=True, timeout=120, **who)
    return r, name


@pytest.mark.system
def test_paths_the_user_cannot_reach_are_one_line_each_and_exit_2(open_folder):
    closed = open_folder / "closed"
    (closed / "x").mkdir(parents=True)
    closed.chmod(0o000)   # (root's; for the tests' own user, closed to it too)
    station = _station(open_folder, database=f"{closed}/x/stationd.db",
                       bolts=f"{closed}/x/bolts.yaml", calibration=f"{closed}/x/pair1.yaml")
    check, user = _as_user(["config", "check", "--config", str(station)], open_folder)
    assert check.returncode == 2, check.stderr
    said = (f"folder {closed}/x cannot be reached by user {user} (permission denied: {closed} "
            "is closed to that user)")
    lines = (check.stdout + check.stderr).splitlines()
    assert "Traceback" not in check.stderr
    for what, (_, key) in (("database", DATABASE), ("bolt file", BOLTS),
                           ("calibration file", CALIBRATION)):
        name = {"database": "stationd.db", "bolt file": "bolts.yaml",
                "calibration file": "pair1.yaml"}[what]
        assert any(line.startswith(f"{station}:") and f": {key}: {what} {closed}/x/{name}: "
                   f"{said}" in line for line in lines), (what, lines)
    run, _ = _as_user(["run", "--config", str(station)], open_folder)
    assert run.returncode == 2, run.stderr
    assert run.stderr.count("\n") == 1 and run.stderr.startswith("stationd: error: "), \
        run.stderr
    assert said in run.stderr


@pytest.mark.parametrize("which", ["bolts", "calibration"])
def test_a_nul_character_in_a_path_is_one_line_not_a_traceback(tmp_path, which):
    """A path written with a NUL (``"\\0"`` in YAML) was a ValueError out of ``Path.stat``: a
    traceback from ``config check``."""
    station = _station(tmp_path, **{which: f'"{tmp_path}/a\\0b.yaml"'})
    key = {"bolts": BOLTS, "calibration": CALIBRATION}[which][1]
    errors = _errors_by_key(station)
    assert list(errors) == [key], errors
    assert "NUL" in errors[key] and "\n" not in errors[key]
    with pytest.raises(ConfigError, match="NUL"):
        load_station_config(station, station=True)


# -- the selections' images folder the daemon cannot write ------------------------------------
def _read_only_images(tmp_path: Path, *, save: bool) -> tuple[Path, Path]:
    """A station file (and its images folder, read-only to everyone) whose records go to
    that folder, ``save_images`` as ``save``."""
    images = tmp_path / "images"
    images.mkdir()
    images.chmod(0o555)
    station = _station(tmp_path)
    station.write_text(station.read_text() + f"records: {{images_dir: {images}, "
                                              f"save_images: {str(save).lower()}}}\n")
    return station, images


def test_an_images_folder_nobody_may_write_is_an_error_at_start_and_in_the_check(tmp_path):
    """A commissioning trial: ``records.images_dir`` that the daemon cannot write was taken at
    the start, and every bolt selected then wrote two warnings to the journal ("image ... not
    saved: [Errno 13] Permission denied"), for ever, while a database folder it cannot write
    is one line at the start, exit 2.  The images folder is checked as the database's is: a
    folder nobody may write (or on a read-only file system) by ``config check`` and the
    daemon, one this user may not write by the daemon."""
    station, images = _read_only_images(tmp_path, save=True)
    said = f"folder {images} cannot be written by anyone"
    errors = _errors_by_key(station)
    assert list(errors) == ["records.images_dir"], errors
    assert said in errors["records.images_dir"]
    with pytest.raises(ConfigError, match=said):
        validate_station(station)   # the daemon's start and reload
    # a folder still to be made: its nearest folder that is there must take it
    station.write_text(station.read_text().replace(f"images_dir: {images},",
                                                   f"images_dir: {images}/new/crops,"))
    with pytest.raises(ConfigError, match=said):
        validate_station(station)


def test_an_images_folder_the_daemon_never_writes_is_not_checked(tmp_path):
    """``save_images`` off with an SQLite database (its lock beside it): the daemon writes
    nothing in ``records.images_dir`` (the screens only read the images saved earlier, a
    read-only archive of them too), so its being read-only refuses nothing: the check
    refused the start with exit 2, which the unit does not restart (a station that ran
    before the upgrade stayed down)."""
    station, _ = _read_only_images(tmp_path, save=False)
    assert "records.images_dir" not in _errors_by_key_or_none(station)
    validate_station(station)   # the daemon's start and reload: taken


def _errors_by_key_or_none(station: Path) -> dict[str, str]:
    checked = check_station(station)
    return {e.key or "": str(e) for e in checked.errors}

@pytest.mark.system
def test_an_images_folder_the_daemons_user_cannot_write_is_one_line_and_exit_2(open_folder):
    images = open_folder / "images"     # root's (or the tests' user's), 0755
    images.mkdir()
    images.chmod(0o755)
    data = open_folder / "data"         # the database's: any user's
    data.mkdir()
    data.chmod(0o777)
    station = _station(open_folder, database=f"{data}/stationd.db")
    station.write_text(station.read_text() + f"records: {{images_dir: {images}, "
                                              "save_images: true}\n")
    as_root = os.geteuid() == 0
    if not as_root:
        pytest.skip("needs another user than the folder's owner: run as root")
    run, user = _as_user(["run", "--config", str(station)], open_folder)
    assert run.returncode == 2, run.stderr
    assert run.stderr.count("\n") == 1 and "records.images_dir" in run.stderr, run.stderr
    assert f"folder {images} cannot be written by user {user}" in run.stderr, run.stderr
