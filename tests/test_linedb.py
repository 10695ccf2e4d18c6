"""The line's results in one place and the bolt tables each station tightened with, read
back from a real PostgreSQL the forwarders wrote (the tests' throw-away server)."""

from __future__ import annotations

import json
import time
from datetime import UTC, datetime

import pytest

from db.repository import Repository
from stationd.boltfile import import_bolts
from stationd.cli import main
from stationd.forward import LineDb
from stationd.linedb import bolt_versions, parameter_rows, results
from tests.db.conftest import BASE, record
from tests.test_line_tables import _forward

VIN = "9SDST0010TL000001"
OTHER = "9SDST0011TL000002"


def _station(tmp_path, name, table_text):
    """A station's own database with its own bolt table (``table_text``)."""
    table = tmp_path / f"{name}.yaml"
    table.write_text(table_text)
    repo = Repository.open(f"sqlite:///{tmp_path / name}.db")
    import_bolts(repo, table)
    return repo, table


def _config(tmp_path, url, sid="ST-A"):
    station = tmp_path / "station.yaml"
    station.write_text(f"database: {{url: 'sqlite:///{tmp_path / 'a.db'}'}}\n"
                       f"line: {{url: '{url}', station_id: {sid}}}\n")
    return str(station)


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_a_vehicles_rundowns_at_every_station_newest_first(tmp_path, pg_url, capsys):
    a, _ = _station(tmp_path, "a", BASE)
    b, _ = _station(tmp_path, "b", BASE)
    for repo in (a, b):
        repo.start_vehicle(VIN, "SEDAN")
    record(a, VIN, "B1", tightening_id=1, torque_nm=50.5, angle_deg=33.0)
    time.sleep(0.01)
    record(b, VIN, "B2", ok=False, tightening_id=1, torque_nm=21.0, angle_deg=12.5)
    time.sleep(0.01)
    record(a, VIN, "B3", tightening_id=2, torque_nm=120.0, angle_deg=40.0)
    a.start_vehicle(OTHER, "SEDAN")
    record(a, OTHER, "B1", tightening_id=3)
    a.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli",
                            kind="skip", vin=VIN, bolt="B2", comment="not a rundown")
    _forward(a, pg_url, "ST-A")
    _forward(b, pg_url, "ST-B")
    engine = LineDb(pg_url)._connect()
    got = results(engine, vin=VIN)
    assert [(r.station_id, r.bolt, r.ok) for r in got] == [
        ("ST-A", "B3", True), ("ST-B", "B2", False), ("ST-A", "B1", True)]
    assert got[1].torque_nm == pytest.approx(21.0) and got[1].angle_deg == pytest.approx(12.5)
    assert {r.model for r in got} == {"SEDAN"} and {r.version for r in got} == {1}
    assert [r.bolt for r in results(engine, vin=VIN, station="ST-B")] == ["B2"]
    assert len(results(engine)) == 4 and len(results(engine, limit=2)) == 2
    engine.dispose()

    config = _config(tmp_path, pg_url)
    code, out, _ = _run(capsys, "line", "results", "--config", config, "--vin", VIN)
    assert code == 0
    lines = out.splitlines()
    assert "3 rundowns of VIN " + VIN + " at 2 stations" in lines[0]
    assert ["ST-A", "ST-B", "ST-A"] == [ln.split()[2] for ln in lines[2:]]
    assert "NOK" in lines[3] and "21.0" in lines[3] and "12.5" in lines[3]
    code, out, _ = _run(capsys, "line", "results", "--config", config, "--vin", VIN,
                        "--station", "ST-B", "--json")
    [row] = [json.loads(ln) for ln in out.splitlines()]
    assert code == 0 and (row["bolt"], row["ok"], row["parameters_version"]) == ("B2", False, 1)
    code, out, _ = _run(capsys, "line", "results", "--config", config, "--vin", "NOSUCHVIN")
    assert code == 1 and "no rundowns of VIN NOSUCHVIN" in out
    # a name in another case finds nothing, and the line says names match exactly
    code, out, _ = _run(capsys, "line", "results", "--config", config, "--station", "st-b")
    assert code == 1 and out.strip() == ("no rundowns of station st-b in the line database "
                                         "(names are matched exactly, case included)")
    code, out, _ = _run(capsys, "line", "bolts", "--config", config, "--bolt", "b2")
    assert code == 1 and out.strip() == ("no bolt parameters of bolt b2 in the line database "
                                         "(names are matched exactly, case included)")
    code, _, err = _run(capsys, "line", "results", "--config", config,
                        "--since", "2026-11-29T13:53", "--until", "2026-11-29T13:00")
    assert code == 2 and err.startswith("stationd: error: --since 2026-11-29T13:53 is after "
                                        "--until 2026-11-29T13:00"), err
    for repo in (a, b):
        repo.close()


def test_the_line_database_unreachable_or_empty_is_one_line(tmp_path, pg_url, pg_server,
                                                            capsys):
    code, out, _ = _run(capsys, "line", "results", "--config", _config(tmp_path, pg_url))
    assert code == 1 and "no rundowns in the line database" in out   # nothing forwarded yet
    down = pg_url.replace(f":{pg_server.port}/", ":1/")
    code, out, err = _run(capsys, "line", "results", "--config", _config(tmp_path, down))
    assert code == 3 and "unreachable" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run(capsys, "line", "results", "--config", _config(tmp_path, pg_url),
                        "--limit", "0")
    assert code == 2 and "--limit 0" in err


def test_each_station_keeps_the_bolt_table_it_tightened_with(tmp_path, pg_url, capsys):
    """Two stations with a B2 of their own (another torque window) and a parameter change at
    one: the line keeps every version each station used, keyed by station, so quality tells
    ST-A's B2 from ST-B's; a replay adds nothing."""
    a, table_a = _station(tmp_path, "a", BASE)
    b, _ = _station(tmp_path, "b", BASE.replace("target: 25, min: 23, max: 27",
                                                "target: 28, min: 26, max: 30"))
    for repo in (a, b):
        repo.start_vehicle(VIN, "SEDAN")
        record(repo, VIN, "B2", tightening_id=1)
    table_a.write_text(BASE.replace("target: 25, min: 23, max: 27",
                                    "target: 24, min: 22, max: 26"))
    import_bolts(a, table_a)                      # a change after records: version 2
    record(a, VIN, "B2", tightening_id=2)
    entry = a.ledger.since(0)[-1]
    assert entry["record"]["model"] == "SEDAN"
    assert entry["record"]["parameters"]["version"] == 2
    assert entry["record"]["parameters"]["torque"] == {"target": 24, "min": 22, "max": 26}
    _forward(a, pg_url, "ST-A")
    _forward(b, pg_url, "ST-B")
    a.ledger.set_meta("forwarded_seq", "0")       # a replay after a crash
    _forward(a, pg_url, "ST-A")
    engine = LineDb(pg_url)._connect()
    got = bolt_versions(engine, model="SEDAN", bolt="B2")
    assert [(v.station_id, v.version, v.torque) for v in got] == [
        ("ST-A", 1, (25.0, 23.0, 27.0)), ("ST-A", 2, (24.0, 22.0, 26.0)),
        ("ST-B", 1, (28.0, 26.0, 30.0))]
    assert {v.angle for v in got} == {(30.0, 10.0, 50.0)} and {v.pset for v in got} == {None}
    assert [r.version for r in results(engine, vin=VIN, station="ST-A")] == [2, 1]
    engine.dispose()
    code, out, _ = _run(capsys, "line", "bolts", "--config", _config(tmp_path, pg_url),
                        "--bolt", "B2")
    assert code == 0 and len(out.splitlines()) == 3
    assert "SEDAN B2 at ST-B" in out and "torque 28.0 [26.0, 30.0] Nm" in out
    for repo in (a, b):
        repo.close()


def test_only_rundowns_carrying_their_version_make_parameter_rows():
    """Records forwarded before rundowns carried their version, and other kinds, make none;
    a version is one row however many rundowns carry it."""
    par = {"version": 3, "pset": 7, "torque": {"target": 50, "min": 45, "max": 55},
           "angle": None}
    entries = [{"seq": 1, "kind": "rundown", "record": {"vin": VIN, "bolt": "B1"}},
               {"seq": 2, "kind": "command", "record": {"bolt": "B1"}},
               {"seq": 3, "kind": "rundown", "record": {"model": "M", "bolt": "B1",
                                                        "parameters": par}},
               {"seq": 4, "kind": "rundown", "record": {"model": "M", "bolt": "B1",
                                                        "parameters": par}}]
    [row] = parameter_rows("ST", "db", entries)
    assert (row["version"], row["pset"], row["torque_max"], row["angle_min"],
            row["first_seq"]) == (3, 7, 55, None, 3)


def test_line_init_makes_the_tables_once_and_a_forwarder_uses_them(tmp_path, pg_url, capsys):
    """A line engineer prepares the line database before any station forwards: ``line init``
    makes the tables; again, it changes nothing; a station then forwards into them."""
    code, out, err = _run(capsys, "line", "init", pg_url)
    assert code == 0 and err == ""
    assert "made line_calibration_checks, line_commands, line_controller_events, line_feed, " \
           "line_gaps, line_parameters, line_rundowns, line_unattributed, " \
           "line_unreadable_results" in out and "PASSWORD" not in out
    assert "filled" not in out                            # nothing to type yet
    engine = LineDb(pg_url)._connect()
    from sqlalchemy import inspect
    assert {"line_feed", "line_parameters"} <= set(inspect(engine).get_table_names())
    assert "ix_line_feed_vin" in {i["name"] for i in inspect(engine).get_indexes("line_feed")}
    engine.dispose()
    code, out, _ = _run(capsys, "line", "init", pg_url)
    assert code == 0 and "every table there already" in out
    a, _ = _station(tmp_path, "a", BASE)
    a.start_vehicle(VIN, "SEDAN")
    record(a, VIN, "B1", tightening_id=1)
    _forward(a, pg_url, "ST-A")
    code, out, _ = _run(capsys, "line", "init", pg_url)   # after forwarding: nothing lost
    assert code == 0
    engine = LineDb(pg_url)._connect()
    assert [r.bolt for r in results(engine)] == ["B1"]
    engine.dispose()
    a.close()


def test_line_init_with_a_bad_url_or_the_server_down_is_one_line(pg_url, pg_server, capsys):
    down = pg_url.replace(f":{pg_server.port}/", ":1/")
    # a URL that cannot be one: 2 (bad input); the server down: 3, as line status says it
    for url, needle, exit_code in (
            ("not a url", "not a database URL", 2),
            ("sqlite:///line.db", "the line database is PostgreSQL", 2),
            (down, f"line database {down} unreachable: ", 3),
            # a sweep: psycopg took port 0 as its default and named 5432
            ("postgresql+psycopg://u@127.0.0.1:0/line", "port 0 is not 1-65535", 2)):
        code, out, err = _run(capsys, "line", "init", url)
        assert code == exit_code and out == "", url
        assert needle in err and len(err.strip().splitlines()) == 1, err
        assert "Traceback" not in err


@pytest.mark.parametrize("scheme", ["postgres", "psql"])
def test_line_init_with_postgresql_under_another_scheme_says_what_to_write(capsys, scheme):
    """``postgres://`` (Heroku's) was answered "the line database is PostgreSQL, not
    postgres": what to write, as ``--db`` and ``database: url`` say it."""
    code, out, err = _run(capsys, "line", "init", f"{scheme}://stationd@line-db/line")
    assert code == 2 and out == ""
    assert err == (f"stationd: error: line init: write postgresql+psycopg://stationd@line-db/"
                   f"line ({scheme}:// is not a driver SQLAlchemy has here)\n")


def test_a_rundowns_operator_reaches_the_line_also_in_a_table_made_before_it(tmp_path, pg_url,
                                                                             capsys):
    """The line keeps each rundown's operator (the user signed in at the station) in the
    record and as a column; a line database made before that column gets it added."""
    from sqlalchemy import inspect, text

    engine = LineDb(pg_url)._connect()
    with engine.begin() as conn:   # a line database made by the version before
        conn.execute(text("ALTER TABLE line_feed DROP COLUMN operator"))
    assert "operator" not in {c["name"] for c in inspect(engine).get_columns("line_feed")}
    engine.dispose()
    a, _ = _station(tmp_path, "a", BASE)
    a.start_vehicle(VIN, "SEDAN")
    record(a, VIN, "B1", tightening_id=1, operator="olga")
    time.sleep(0.01)
    record(a, VIN, "B2", tightening_id=2)                     # nobody signed in
    _forward(a, pg_url, "ST-OP")
    _forward(a, pg_url, "ST-OP")                              # a second start: unchanged
    engine = LineDb(pg_url)._connect()
    got = results(engine, vin=VIN, station="ST-OP")
    assert [(r.bolt, r.operator) for r in got] == [("B2", None), ("B1", "olga")]
    engine.dispose()
    code, out, _ = _run(capsys, "line", "results", "--config",
                        _config(tmp_path, pg_url, "ST-OP"), "--vin", VIN, "--station",
                        "ST-OP", "--json")
    assert code == 0 and [json.loads(ln)["operator"] for ln in out.splitlines()] == [
        None, "olga"]
    a.close()
