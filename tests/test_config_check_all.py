"""``stationd config check`` tells every error of a file (issue 30, item 6): a typo'd key
hid ``max_age_s: 500`` in the same section; the database hint said an SQLite file name is
relative to the current folder, while the station makes it beside its station file; bolt
positions in metres passed without the hint unless every one lay within 10 mm of the origin.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from stationd.boltfile import check_bolts
from stationd.cli import main

SIM = Path(__file__).resolve().parents[1] / "config" / "sim"


@pytest.fixture
def station(tmp_path: Path) -> Path:
    """A copy of config/sim's station (its calibrations and bolt table beside it)."""
    for f in SIM.glob("*.yaml"):
        shutil.copy(f, tmp_path / f.name)
    return tmp_path / "station.yaml"


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def _check(capsys: pytest.CaptureFixture[str], path: Path) -> list[str]:
    assert main(["config", "check", str(path)]) == 2
    captured = capsys.readouterr()
    return (captured.out + captured.err).splitlines()


def test_every_error_of_a_section_each_with_its_line_and_key(station, capsys) -> None:
    _edit(station, "matching: {tolerance_mm: 8.0, margin_mm: 6.0, stable_frames: 3, "
                   "max_age_s: 0.5, leave_frames: 3}",
          "matching:\n  tolerance_mm: 8.0\n  margn_mm: 6.0\n  stable_frames: 3\n"
          "  max_age_s: 500\n  leave_frames: 0.5\n")
    at = {line.split(":")[0].strip(): n
          for n, line in enumerate(station.read_text().splitlines(), 1)}
    lines = [line for line in _check(capsys, station) if "matching." in line]
    assert [line.split(": ")[0:2] for line in lines] == [
        [f"{station}:{at['margn_mm']}", "matching.margn_mm"],
        [f"{station}:{at['max_age_s']}", "matching.max_age_s"],
        [f"{station}:{at['leave_frames']}", "matching.leave_frames"]], lines
    assert "unknown key" in lines[0] and "500 s is not plausible" in lines[1]


def test_a_required_key_with_a_wrong_value_is_told_once(station, capsys) -> None:
    """Read again without it, the section misses a key it requires: that is not a second
    error of the file, and is not told."""
    _edit(station, "tool: {length_mm: 300.0,", "tool: {length_mm: 3000.0,")
    lines = [line for line in _check(capsys, station) if "tool" in line]
    assert len(lines) == 1 and "tool.length_mm: a tool length of 3000 mm" in lines[0], lines


def test_the_database_hint_says_where_the_station_makes_the_file(station, capsys) -> None:
    _edit(station, "database: {url: 'sqlite:///stationd-sim.db'}",
          "database: {url: stationd-sim.db}")
    lines = [line for line in _check(capsys, station) if "database.url" in line]
    assert len(lines) == 1, lines
    assert "write sqlite:///stationd-sim.db for an SQLite file (sqlite:///NAME.db: an SQLite " \
           f"file relative to the station file's folder ({station.parent.resolve()})" in lines[0]
    assert "current folder" not in lines[0]


BOLTS = ("psets:\n  - {id: 1, name: a, torque: {target: 10, min: 9, max: 11},\n"
         "     angle: {target: 30, min: 15, max: 60}}\nmodels:\n  M1:\n    bolts:\n")


@pytest.mark.parametrize("positions", [
    [(12.31, 0.42, -1.25), (12.95, -0.38, -1.25), (14.1, 0.35, -1.2)],   # origin 12 m away
    [(-2.4, 0.8, 0.1), (2.3, -0.75, 0.1), (0.1, 0.9, 0.2)],              # a car, around it
])
def test_bolt_positions_in_metres_wherever_the_origin_is(tmp_path, positions) -> None:
    path = tmp_path / "bolts.yaml"
    path.write_text(BOLTS + "".join(
        f"      - {{id: B0{i}, name: b{i}, position: [{x}, {y}, {z}], pset: 1}}\n"
        for i, (x, y, z) in enumerate(positions, 1)))
    got = check_bolts(path)
    texts = [str(e) for e in got.errors]
    assert len(texts) == 1 and "positions in metres?" in texts[0], texts   # not 3 spacings
    assert texts[0].startswith(f"{path}:7: models.M1.bolts[0].position:")


def test_bolts_in_millimetres_are_not_taken_for_metres(tmp_path) -> None:
    """Two bolts of a bracket 20 mm apart (the least the spacing rule lets through spreads
    over 16 mm), and the simulated car's 50 bolts."""
    path = tmp_path / "bolts.yaml"
    path.write_text(BOLTS + "      - {id: B01, name: a, position: [1200, 300, 5], pset: 1}\n"
                            "      - {id: B02, name: b, position: [1220, 300, 5], pset: 1}\n")
    assert check_bolts(path).ok
    assert check_bolts(SIM / "bolts.yaml").ok


def test_every_error_of_the_references(station, capsys) -> None:
    """The calibration check's section too (read after the pairs, with their calibrations)."""
    station.write_text(station.read_text() + "references:\n  markers:\n"
                       "    R1: [680.0, -480.0]\n    R2: {position: [900.0, -300.0, -300.0], "
                       "mount: crane}\n  period_min: 0\n")
    lines = [line for line in _check(capsys, station) if "references." in line]
    assert [line.split(": ")[1] for line in lines] == [
        "references.markers.R1", "references.markers.R2.mount", "references.period_min"], lines


def test_an_unknown_key_in_the_nok_section_hides_no_other_error(station, capsys) -> None:
    """The NOK policy's overrides are checked against the bolt table after the sections: a
    section that did not read (an unknown key) stopped the whole check there, with none of
    the other sections' errors (found by a new user)."""
    _edit(station, "matching: {tolerance_mm: 8.0, margin_mm: 6.0, stable_frames: 3, "
                   "max_age_s: 0.5, leave_frames: 3}",
          "matching: {tolerance_mm: 8.0, margin_mm: 6.0, stable_frames: 0, "
          "max_age_s: 0.5, leave_frames: 3}\nnok: {max_nok: 3, colour: red}")
    lines = _check(capsys, station)
    assert any("nok.colour" in line and "unknown key" in line for line in lines), lines
    assert any("matching.stable_frames" in line for line in lines), lines


def test_a_section_written_twice_hides_no_other_error(station, capsys) -> None:
    """A second ``matching:`` appended (a new user's edit) was the only error told: a typo
    elsewhere in the file was not.  The duplicate is told, the first one read on."""
    _edit(station, "matching: {tolerance_mm: 8.0, margin_mm: 6.0, stable_frames: 3, "
                   "max_age_s: 0.5, leave_frames: 3}",
          "matching: {tolerance_mm: 8.0, margin_mm: 6.0, stable_frames: 0, "
          "max_age_s: 0.5, leave_frames: 3}")
    station.write_text(station.read_text() + "matching: {tolerance_mm: 9.0}\n")
    lines = _check(capsys, station)
    assert any("matching" in line and "duplicate key" in line for line in lines), lines
    assert any("matching.stable_frames" in line for line in lines), lines


HASH = "scrypt$16384$8$1$MDEyMzQ1Njc4OWFiY2RlZg==$" + "A" * 43 + "="


def test_every_error_of_the_access_section(station, capsys) -> None:
    """Five bad users and an idle time out of range were told one a run (a user left out
    after its wrong role was told missed the role, and the check stopped there)."""
    station.write_text(station.read_text() + (
        "access:\n  users:\n"
        f"    sam: {{role: supervisr, password: '{HASH}'}}\n"
        "    ann: {role: operator, password: hunter22}\n"
        "    bob: {role: operator}\n"
        "    cid: {role: engineer, password: 'scrypt$16384$8$1$abc$def'}\n"
        "    dan: operator\n"
        f"    eve: {{role: supervisor, password: '{HASH}'}}\n"
        "  operator_idle_s: 1\n"))
    lines = [line for line in _check(capsys, station) if "access." in line]
    assert [line.split(": ")[1] for line in lines] == [
        "access.users.sam.role", "access.users.ann.password", "access.users.bob",
        "access.users.cid.password", "access.users.dan", "access.operator_idle_s"], lines
    assert "'supervisr' is not one of: operator, supervisor, engineer" in lines[0]
    assert "missing key: password" in lines[2]


def test_every_error_of_one_user_at_once(station, capsys) -> None:
    """A new user's trial: ``{role: boss, password: "hunter22"}`` was told its role only, the
    plain-text password once the role was fixed; a user without a password the same."""
    station.write_text(station.read_text() + (
        "access:\n  users:\n"
        '    bob: {role: boss, password: "hunter22"}\n'
        "    cid: {role: boss}\n"))
    lines = [line for line in _check(capsys, station) if "access." in line]
    assert [line.split(": ", 2)[1:] for line in lines] == [
        ["access.users.bob.role", "'boss' is not one of: operator, supervisor, engineer"],
        ["access.users.bob.password", "not a scrypt hash: the file keeps only the hash of a "
                                      "password (`stationd user hash` prints it), never the "
                                      "password"],
        ["access.users.cid.role", "'boss' is not one of: operator, supervisor, engineer"],
        ["access.users.cid", "missing key: password"]], lines


def test_every_error_of_the_tool_section(station, capsys) -> None:
    """Its required length, wrong, hid the tilt and the rule after it."""
    _edit(station, "tool: {length_mm: 300.0, max_tilt_deg: 10.0, rule: axis}",
          "tool: {length_mm: 0.3, max_tilt_deg: 0.17, rule: axes}")
    lines = [line for line in _check(capsys, station) if "tool." in line]
    assert sorted(line.split(": ")[1] for line in lines) == [
        "tool.length_mm", "tool.max_tilt_deg", "tool.rule"], lines


def test_a_wrong_right_of_a_role_hides_neither_the_others_nor_the_roles(station,
                                                                      capsys) -> None:
    """``roles: {operator: [skip, fly]}`` left the operator role out of the roles, and a
    user's wrong role was told "'boss' is not one of: " with nothing after it."""
    station.write_text(station.read_text() + (
        "access:\n  roles: {operator: [skip, fly, flew], lead: [release]}\n  users:\n"
        f"    sam: {{role: boss, password: '{HASH}'}}\n"
        f"    olga: {{role: operator, password: '{HASH}'}}\n"))
    lines = [line for line in _check(capsys, station) if "access." in line]
    assert [line.split(": ")[1] for line in lines] == [
        "access.roles.operator[1]", "access.roles.operator[2]", "access.users.sam.role"], lines
    assert "'flew' is not one of" in lines[1]
    assert lines[2].endswith("'boss' is not one of: operator, supervisor, engineer, lead")


def test_the_station_file_is_taken_with_config_as_the_other_commands_take_it(station,
                                                                              capsys) -> None:
    """Issue 30: ``config check --config STATION.yaml`` (as ``run``, ``status``, ``db
    report`` take it) was "unrecognized arguments: --config"; none at all says what to give;
    the help no longer says "the first error of each section"."""
    from stationd.cli import build_parser

    assert main(["config", "check", "--config", str(station)]) == 0
    assert capsys.readouterr().out.startswith(f"{station}: ok, station: 4 pairs")
    _edit(station, "max_age_s: 0.5", "max_age_s: 500")
    assert main(["config", "check", str(station.parent / "bolts.yaml"),
                 "--config", str(station)]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith(f"{station.parent / 'bolts.yaml'}: ok, ")
    assert captured.err.endswith("stationd: error: 1 error in 1 of 2 files\n")
    # a bolt table given as the station file is refused, as run --config refuses it (it
    # was 'ok': a line engineer's trial)
    assert main(["config", "check", "--config", str(station.parent / "bolts.yaml")]) == 2
    said = capsys.readouterr().err
    assert said.startswith(f"{station.parent / 'bolts.yaml'}: this is a bolt table, not a "
                           "station file: check it without --config"), said
    # the same path given as a FILE too: checked as what it is there
    bolts = str(station.parent / "bolts.yaml")
    assert main(["config", "check", bolts, "--config", bolts]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith(f"{bolts}: ok, ") and "this is a bolt table" in captured.err
    assert main(["config", "check"]) == 2
    assert capsys.readouterr().err == ("stationd: error: config check: no file to check: "
                                       "stationd config check FILE ... (station files, bolt "
                                       "tables) or --config STATION.yaml\n")
    commands = next(a for a in build_parser()._actions if a.dest == "command")
    assert isinstance(commands.choices, dict)
    config = commands.choices["config"]
    assert "every error of each file" in " ".join(config.format_help().split())


def test_the_summary_names_the_bolt_table_the_station_file_names_where_its_errors_are(
        station: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A technician's trial: an error in the bolt table a station file names was summed up
    as "1 error in 1 of 1 file", the file given, not the one with the error."""
    _edit(station.parent / "bolts.yaml", "target: 25.0", "target: 250.0")
    assert main(["config", "check", "--config", str(station)]) == 2
    err = capsys.readouterr().err
    assert err.endswith(f"stationd: error: 1 error in 1 of 1 file (those of "
                        f"{station.parent / 'bolts.yaml'} counted with the station file "
                        "naming it)\n"), err
