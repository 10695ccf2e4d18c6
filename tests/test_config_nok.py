"""The station file's NOK policy against the bolt tables the station loads: `config check`
lists each override no table has with its line, a start or a reload refuses it (the running
station kept), the tables of the database are used when the file names no bolt table."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from db.repository import Repository
from stationd.boltfile import load_bolts
from stationd.config import load_station_config
from stationd.errors import ConfigError
from stationd.stationcheck import check_station, validate_station
from tests.test_config import SIM, _line

NOK = ("nok:\n  strategy: loosen\n  loosen_pset: 90\n  psets:\n    7: {max_nok: 1}\n"
       "  bolts:\n    B01: {max_nok: 2}\n    B99: {strategy: skip}\n")


@pytest.fixture
def station(tmp_path: Path) -> Path:
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    path = tmp_path / "station.yaml"
    path.write_text(path.read_text() + NOK)
    return path


def test_config_check_names_each_override_no_table_has_with_its_line(station):
    result = check_station(station)
    assert not result.ok
    found = [(e.line, str(e)) for e in result.errors]
    assert [line for line, _ in found] == [_line(station, "7: {max_nok"),
                                           _line(station, "B99:")]
    assert "pset 7: no bolt of" in found[0][1] and "bolt B99: no model of" in found[1][1]


def test_a_start_or_reload_refuses_it_and_a_policy_the_table_has_loads(station):
    """The daemon's start and every reload validate the station (``validate_station``);
    the reader reads the file and opens no bolt table."""
    with pytest.raises(ConfigError, match="pset 7: no bolt") as err:
        validate_station(station)
    assert (err.value.path, err.value.line) == (str(station), _line(station, "7: {max_nok"))
    load_station_config(station)           # a tool reading its vision only: not checked
    load_station_config(station, station=True)    # the file alone: read, not against tables
    station.write_text(station.read_text().replace("    7: {max_nok: 1}", "    3: {max_nok: 1}")
                       .replace("    B99: {strategy: skip}\n", ""))
    cfg = validate_station(station)
    assert cfg.nok.rule("B01", 1).max_nok == 2 and cfg.nok.rule("B03", 3).max_nok == 1
    assert cfg.nok.default.loosen_pset == 90


def test_stationd_run_refuses_it_before_a_world_or_a_daemon_starts(station, capsys):
    """``stationd run`` validates the station first (the start's ``validate_station``), so a
    simulated station with an override no table has builds no world and opens no database."""
    from stationd.cli import main

    code = main(["run", "--config", str(station), "--sim-operator"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert f"{station}:{_line(station, '7: {max_nok')}: nok.psets.7: pset 7: no bolt" in err
    assert not (station.parent / "stationd-sim.db").exists()


def test_a_loosen_pset_a_bolt_is_tightened_with_is_refused(station):
    station.write_text(station.read_text().replace("loosen_pset: 90", "loosen_pset: 2"))
    result = check_station(station)
    assert any("loosen_pset 2 tightens B02" in str(e) and e.line == _line(
        station, "loosen_pset: 2") for e in result.errors), result.errors


def test_without_a_bolt_file_the_database_tables_are_checked(station):
    text = station.read_text()
    table = load_bolts(station.parent / "bolts.yaml")
    db = station.parent / "tables.db"
    with Repository.open(f"sqlite:///{db}") as repo:
        repo.import_bolts(table)
    station.write_text(text.replace("bolts: bolts.yaml\n", "").replace(
        "sqlite:///stationd-sim.db", f"sqlite:///{db}"))
    result = check_station(station)
    assert [str(e).split(": ", 1)[1] for e in result.errors] == [
        f"nok.psets.7: pset 7: no bolt of the database {db} is tightened with it and no table "
        "there defines it", f"nok.bolts.B99: bolt B99: no model of the database {db} has it"]


def test_without_a_bolt_file_a_database_without_models_is_warned_of(tmp_path):
    """A station without ``bolts:`` whose database knows no vehicle model refuses every
    vehicle ("unknown vehicle model code"): ``config check`` says so before it runs (a new
    user found it said "ok"), and says nothing once the database has the tables."""
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    db = tmp_path / "tables.db"
    station.write_text(station.read_text().replace("bolts: bolts.yaml\n", "").replace(
        "sqlite:///stationd-sim.db", f"sqlite:///{db}"))

    def warned() -> list[str]:
        result = check_station(station)
        assert result.ok, result.errors
        return [str(w) for w in result.warnings if "no bolt table" in str(w)]

    [missing] = warned()
    assert f"the database {db} does not exist yet" in missing
    assert f"stationd db import BOLTS.yaml --config {station}" in missing
    Repository.open(f"sqlite:///{db}").close()          # made, empty
    [empty] = warned()
    assert f"the database {db} has no vehicle model" in empty
    with Repository.open(f"sqlite:///{db}") as repo:
        repo.import_bolts(load_bolts(tmp_path / "bolts.yaml"))
    assert warned() == []


def test_a_loosen_pset_no_rule_uses_is_warned_of_with_its_line(tmp_path):
    """``loosen_pset`` under the default ``repeat``: the station tightens a NOK bolt again
    without loosening it, whatever the engineer meant by it (a new user's trial).  Warned of
    (the file stays valid); where an override below takes it with ``loosen``, it is used."""
    for f in SIM.iterdir():
        shutil.copy(f, tmp_path)
    path = tmp_path / "station.yaml"
    base = path.read_text()
    path.write_text(base + "nok:\n  max_nok: 3\n  loosen_pset: 90\n")
    result = check_station(path)
    assert result.ok
    [w] = [w for w in result.warnings if "loosen_pset" in str(w)]
    assert w.line == _line(path, "loosen_pset: 90")
    assert "loosen_pset 90 is not used: strategy repeat tightens the bolt again after a NOK " \
           "without loosening it (strategy: loosen loosens it first)" in str(w)
    path.write_text(base + "nok:\n  loosen_pset: 90\n  bolts:\n    B01: {strategy: loosen}\n"
                    "    B02: {strategy: skip, loosen_pset: 91}\n")
    result = check_station(path)
    assert result.ok
    assert [str(w).split(": ", 2)[-1] for w in result.warnings if "loosen_pset" in str(w)] \
        == ["loosen_pset 91 is not used: strategy skip skips the bolt after a NOK (strategy: "
            "loosen loosens it first)"]
