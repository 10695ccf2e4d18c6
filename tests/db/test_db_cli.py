"""``stationd db import|export|report`` and ``stationd config check``: output and exit codes."""

from __future__ import annotations

import json
import re
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from stationd import cli
from stationd.db_cli import (
    add_config_parser,
    add_db_parser,
    cmd_config_check,
    cmd_db_report,
)
from tests.db.conftest import BASE, EXAMPLE, ROOT, record, url_of


def _wired(argv, func) -> bool:
    """Whether stationd's own parser already has the command (cli.py wires them)."""
    try:
        args = cli.build_parser().parse_args(argv)
    except SystemExit:
        return False
    return getattr(args, "func", None) is func


@pytest.fixture
def run(monkeypatch, capsys):
    """Run ``stationd ARGS`` through cli.main (its error handling included); until cli.py
    wires the commands, a parser with just these commands stands in for build_parser."""
    if not (_wired(["config", "check", "f.yaml"], cmd_config_check)
            and _wired(["db", "report", "V"], cmd_db_report)):
        def build():
            p = cli._Parser(prog="stationd")
            sub = p.add_subparsers(dest="command", required=True, parser_class=cli._Parser)
            add_db_parser(sub)
            add_config_parser(sub)
            return p
        monkeypatch.setattr(cli, "build_parser", build)
    capsys.readouterr()  # the probe's usage error

    def _run(*argv):
        try:
            code = cli.main([str(a) for a in argv])
        except SystemExit as exc:  # argparse usage errors
            code = exc.code
        out, err = capsys.readouterr()
        return code, out, err
    return _run


@pytest.fixture
def db(tmp_path):
    return url_of(tmp_path / "station.db")


def _one_line(err: str) -> str:
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_import_prints_changes_then_no_changes(run, db):
    code, out, err = run("db", "import", EXAMPLE, "--db", db)
    assert code == 0 and err == ""
    assert "models added: SEDAN-A, WAGON-B" in out and "bolts added: SEDAN-A/SF-FL" in out
    code, out, err = run("db", "import", EXAMPLE, "--db", db)
    assert (code, out, err) == (0, "no changes (9 bolts unchanged)\n", "")
    code, out, _ = run("db", "import", EXAMPLE, "--db", db, "--json")
    obj = json.loads(out)
    assert code == 0 and obj["changes"] is False and len(obj["unchanged"]) == 9


def test_an_import_without_config_or_db_says_which_database_it_went_into(run, tmp_path,
                                                                         monkeypatch):
    """A day-one trial: ``stationd db import bolts.yaml`` without ``--config`` imported into a
    new ``stationd.db`` in the current folder (root's home) and said only what it added, as
    if the station had the table; its daemon's database never saw it.  Without either option
    the database is named, new or not, with the option that names the station's."""
    monkeypatch.chdir(tmp_path)
    code, out, err = run("db", "import", EXAMPLE)
    assert code == 0 and "models added: SEDAN-A" in out
    assert err == (f"note: imported into {tmp_path / 'stationd.db'}, a new database (the "
                   "default without --config or --db: the current folder's stationd.db); "
                   "a station's is --config STATION.yaml\n"), err
    code, out, err = run("db", "import", EXAMPLE)
    assert code == 0 and out == "no changes (9 bolts unchanged)\n"
    assert err.startswith(f"note: imported into {tmp_path / 'stationd.db'} (the default"), err


def test_import_of_an_invalid_file_lists_every_error_and_changes_nothing(run, db, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BASE.replace("target: 25, min: 23", 'target: "25 Nm", min: 23')
                   .replace("id: B2", "id: B1"))
    code, out, err = run("db", "import", bad, "--db", db)
    lines = err.splitlines()
    assert code == 2 and out == ""
    assert lines[0].startswith(f"{bad}:17: models.SEDAN.bolts[1].id: duplicate bolt id")
    assert lines[1].startswith(f"{bad}:20: models.SEDAN.bolts[1].torque.target: expected a "
                               "number in N m, got the string '25 Nm'")
    assert lines[2] == f"stationd: error: {bad}: 2 errors, nothing imported"
    assert not (tmp_path / "station.db").exists()
    code, _, err = run("db", "import", tmp_path / "missing.yaml", "--db", db)
    assert code == 2 and "missing.yaml: file not found" in err


def test_export_round_trip_through_the_commands(run, db, tmp_path):
    run("db", "import", EXAMPLE, "--db", db)
    out_file = tmp_path / "out.yaml"
    code, out, err = run("db", "export", "--db", db, "--out", out_file)
    assert code == 0 and err == "" and out.startswith(f"wrote {out_file}: 2 models, 9 bolts")
    code, out, _ = run("db", "import", out_file, "--db", db)
    assert code == 0 and out.startswith("no changes")
    code, out, _ = run("db", "export", "--db", db)
    assert code == 0 and out == out_file.read_text()


def test_report_exit_codes(run, db):
    from db.repository import Repository

    run("db", "import", EXAMPLE, "--db", db)
    with Repository.open(db) as repo:
        repo.start_vehicle("VIN1", "WAGON-B")
        record(repo, "VIN1", "SF-FL")
        record(repo, "VIN1", "SF-FR", ok=False)
    code, out, err = run("db", "report", "VIN1", "--db", db)
    assert code == 1 and err == ""
    assert out.splitlines()[0] == ("VIN1 (WAGON-B, open): bolts: 1 OK, 1 ending NOK (SF-FR), "
                                   "0 skipped, 1 missing (TB-C); rundowns: 2 tightenings, "
                                   "1 NOK result")
    assert "TB-C" in out.splitlines()[3] and "MISSING" in out.splitlines()[3]
    code, out, _ = run("db", "report", "VIN1", "--db", db, "--json")
    obj = json.loads(out)
    assert code == 1 and obj["missing"] == ["TB-C"] and obj["nok"] == ["SF-FR"]
    assert obj["unattributed"] == []
    with Repository.open(db) as repo:
        # taken by the station a minute before it was stored (the database was down)
        record(repo, "VIN1", "SF-FR", result_at=datetime.now(UTC) - timedelta(minutes=1))
        record(repo, "VIN1", "TB-C")
        repo.others.record_unattributed(vin="VIN1", controller_vin=None, tightening_id=77, pset=4,
                                        ok=False, torque_nm=9.5, angle_deg=12.0, result_at=None,
                                        reason="result 77 (pset 4) outside any tightening",
                                        result_type=1)
        # a loosening no bolt owns is said as one (it read "tightening ... OK": an MES
        # integrator's trial), and one without a type as a result
        for tid, code in ((78, 2), (79, None)):
            repo.others.record_unattributed(vin="VIN1", controller_vin=None, tightening_id=tid,
                                            pset=4, ok=True, torque_nm=9.5, angle_deg=12.0,
                                            result_at=None, reason="fetched", result_type=code)
        # fetched with VIN1 at height, made on another vehicle (the controller says which):
        # said, or it reads as VIN1's (a technician's trial, after a restore)
        repo.others.record_unattributed(
            vin="VIN1", controller_vin="VIN0", tightening_id=80, pset=4, ok=True,
            torque_nm=9.5, angle_deg=12.0, result_at=datetime(2026, 12, 1, 6, 30, tzinfo=UTC),
            reason="fetched", result_type=1)
        repo.others.record_unattributed(
            vin="VIN1", controller_vin="VIN1", tightening_id=81, pset=4, ok=True,
            torque_nm=9.5, angle_deg=12.0, result_at=None, reason="fetched", result_type=1)
        repo.close_vehicle("VIN1")
    code, out, _ = run("db", "report", "VIN1", "--db", db)
    # SF-FR tightened again to OK: no bolt ends NOK, its NOK result is still said
    assert code == 0 and out.splitlines()[0].endswith(
        ": bolts: 3 OK, 0 ending NOK, 0 skipped, 0 missing; rundowns: 4 tightenings, "
        "1 NOK result"), out
    # torque in the unit the journal, the demo and probe print (it said "N m" alone)
    assert "unattributed: tightening 77 pset 4 NOK 9.5 Nm" in out
    assert "unattributed: loosening 78 pset 4 OK" in out
    assert "unattributed: result 79 pset 4 OK" in out
    assert ("unattributed: tightening 80 pset 4 OK 9.5 Nm, 12.0 deg, made on VIN0 at "
            "2026-12-01 06:30:00 UTC (fetched)") in out
    assert "unattributed: tightening 81 pset 4 OK 9.5 Nm, 12.0 deg (fetched)" in out
    assert "made on" not in out.replace("made on VIN0", "")
    assert "OK       50.0 Nm, 35.0 deg, v1, 2 attempts" in out and " N m" not in out
    assert "2. tightening OK pset 2, 50.0 Nm, 35.0 deg, at " in out
    # dated when the station took it, and when it was stored (an operator trial: a rundown
    # stored late read as tightened after its vehicle had left)
    [late] = [line for line in out.splitlines() if "2. tightening OK pset 2" in line]
    assert re.search(r"at \d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC \(stored \d\d:\d\d:\d\d\), by",
                     late), late
    code, out, _ = run("db", "report", "VIN1", "--db", db, "--json")
    assert [(u["tightening_id"], u["result_type"]) for u in json.loads(out)[
        "unattributed"]] == [(77, 1), (78, 2), (79, None), (80, 1), (81, 1)]
    code, out, err = run("db", "report", "NOPE", "--db", db)
    assert code == 2 and out == ""
    assert _one_line(err) == "stationd: error: vehicle 'NOPE' is not in the database"


def test_read_commands_do_not_create_a_database(run, tmp_path):
    missing = tmp_path / "none.db"
    for argv in (("db", "report", "V"), ("db", "export")):
        code, _, err = run(*argv, "--db", url_of(missing))
        assert code == 2 and _one_line(err).startswith(f"stationd: error: no database at "
                                                       f"{missing}")
    assert not missing.exists()


def test_database_errors_are_one_line(run, tmp_path):
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not a database" * 200)
    code, _, err = run("db", "report", "V", "--db", url_of(junk))
    assert code == 2 and f"not an SQLite database: {junk} is another kind of file" \
        in _one_line(err)
    code, _, err = run("db", "import", EXAMPLE, "--db", "nosuchdriver://x")
    assert code == 2 and _one_line(err).startswith("stationd: error: database URL")
    code, _, err = run("db", "import", EXAMPLE, "--db", url_of(tmp_path / "a" / "b.db"))
    assert code == 2 and f"folder {tmp_path / 'a'} does not exist" in _one_line(err)


@pytest.mark.parametrize(("command", "url", "said"), [
    # issue 19: "imported" into memory and kept nothing; a folder; a missing folder
    ("import", "sqlite:///:memory:", "sqlite:///:memory: is a database in memory: it starts "
                                     "empty and is gone when the command ends"),
    ("export", "sqlite:///:memory:", "is a database in memory"),
    ("import", "sqlite:///{tmp}", "{tmp} is a folder, not a database file (name a file in "
                                  "it, e.g. sqlite:///{tmp}/stationd.db)"),
    ("report", "sqlite:///{tmp}", "{tmp} is a folder, not a database file"),
    ("import", "sqlite:///{tmp}/newdir/x.db", "folder {tmp}/newdir does not exist: create "
                                              "it"),
    # made a file named "imp.db?mode=ro" (the options as part of its name); /proc
    ("import", "sqlite:///{tmp}/imp.db?mode=ro&uri=true",
     "an SQLite file's URL takes no options after '?' (mode, uri): write "
     "sqlite:///{tmp}/imp.db"),
    ("import", "sqlite:////proc/x.db", "folder /proc cannot be written by anyone"),
    # what a URL looks like, instead of SQLAlchemy's words
    ("import", "t1.db", "database URL 't1.db': not a URL: write sqlite:///t1.db for an SQLite "
                        "file"),
    ("export", "{tmp}/t1.db", "not a URL: write sqlite:///{tmp}/t1.db"),
    ("import", "postgres://x/y", "database URL 'postgres://x/y': write "
                                 "postgresql+psycopg://x/y"),
    ("report", "mongodb://x/y", "no database kind 'mongodb' (sqlite:///NAME.db: an SQLite "
                                "file relative to the current folder"),
])
def test_every_db_url_mistake_is_told_in_the_users_words(run, tmp_path, command, url, said):
    """``--db`` of every ``db`` command goes through one check, the one ``config check``
    makes of a station's database (``db.location``); nothing is created."""
    before = sorted(tmp_path.iterdir())
    args = {"import": (EXAMPLE,), "export": (), "report": ("V",)}[command]
    code, out, err = run("db", command, *args, "--db", url.format(tmp=tmp_path))
    assert code == 2 and out == "", out
    assert said.format(tmp=tmp_path) in _one_line(err)
    assert sorted(tmp_path.iterdir()) == before


def test_export_into_a_missing_folder_says_so_before_reading(run, db, tmp_path):
    assert run("db", "import", EXAMPLE, "--db", db)[0] == 0
    for extra in ((), ("--results",)):
        out = tmp_path / "nodir" / "x.yaml"
        code, _, err = run("db", "export", *extra, "--db", db, "--out", out)
        assert code == 2 and _one_line(err) == (f"stationd: error: {out}: folder {out.parent} "
                                                "does not exist (create it first, or give "
                                                "another --out)")
    assert not (tmp_path / "nodir").exists()


def test_default_database_is_stationd_db_in_the_current_directory(run, tmp_path,
                                                                   monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, _ = run("db", "import", EXAMPLE)
    assert code == 0 and (tmp_path / "stationd.db").exists()


def test_config_check(run, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BASE.replace("order: 2", "order: zero").replace("    code: 12\n",
                                                                    "    code: 12\n    x: 1\n"))
    also_bad = tmp_path / "also.yaml"
    also_bad.write_text("models: [\n")
    code, out, err = run("config", "check", EXAMPLE)
    assert (code, err) == (0, "")
    assert out == f"{EXAMPLE}: ok, 2 models, 9 bolts, 4 psets\n"
    code, out, err = run("config", "check", EXAMPLE, bad, also_bad)
    lines = err.splitlines()
    assert code == 2 and out.startswith(f"{EXAMPLE}: ok")
    assert lines[0].startswith(f"{bad}:9: models.SEDAN.x: unknown key")
    assert lines[1].startswith(f"{bad}:27: models.SEDAN.bolts[2].order: expected an integer")
    assert lines[2].startswith(f"{also_bad}:2: malformed YAML")
    assert lines[3] == "stationd: error: 3 errors in 2 of 3 files"
    code, _, err = run("config", "check", bad, "--tolerance", "-1")
    assert code == 2 and _one_line(err).startswith(
        "stationd config check: error: argument --tolerance: -1 mm")


def _first_line(path: Path, start: str) -> int:
    return next(n for n, line in enumerate(path.read_text().splitlines(), 1)
                if line.startswith(start))


def test_config_check_tells_station_files_from_bolt_tables(run, tmp_path):
    sim = ROOT / "config" / "sim"
    example = ROOT / "config" / "station.example.yaml"
    code, out, err = run("config", "check", sim / "station.yaml", example, EXAMPLE)
    # the example's database folder is the service's, made by systemd: said while missing;
    # and its bolt table is another vehicle than the simulated pair it names looks at
    url_line = _first_line(example, "  url: 'sqlite")
    bolt_line = _first_line(EXAMPLE, "      - id: SF-FL")   # the first bolt no pair sees
    assert code == 0
    assert err.splitlines() == [
        f"warning: {EXAMPLE}:{bolt_line}: models.SEDAN-A.bolts[0]: SF-FL (SEDAN-A) at "
        "[-350.0, 420.0, 0.0]; SF-FR (SEDAN-A) at [-350.0, -420.0, 0.0]; SF-RL (SEDAN-A) at "
        "[250.0, 400.0, 5.0] and 4 more: seen by no registered pair (the wrench's marker, 300 "
        "mm below the bolt with the wrench upright, is not in front of both cameras and inside "
        "both images): check the positions (vehicle frame, mm)",
        *([] if Path("/var/lib/stationd").exists() else [
            f"warning: {example}:{url_line}: database.url: folder /var/lib/stationd does not "
            "exist yet: systemd makes it when the service starts (StateDirectory=stationd); "
            "create it, owned by the user the station runs as, to run the daemon by hand "
            "(stationd run)"])]
    assert out.splitlines() == [
        f"{sim / 'station.yaml'}: ok, station: 4 pairs, 8 cameras; "
        f"bolts {sim / 'bolts.yaml'}: 1 model, 50 bolts, 3 psets",
        f"{example}: ok, station: 1 pair, 2 cameras; "
        f"bolts {EXAMPLE}: 2 models, 9 bolts, 4 psets",
        f"{EXAMPLE}: ok, 2 models, 9 bolts, 4 psets",
    ]


def test_config_check_of_a_broken_station_lists_every_error(run, tmp_path):
    station = tmp_path / "station.yaml"
    station.write_text("cameras:\n  c1: {url: 'sim://p/left'}\n"
                       "pairs:\n  p: {calibration: p.yaml, left: c1, right: c2}\n"
                       "wrench: {url: 'torque://w'}\n"
                       "bolts: bolts.yaml\n"
                       "lift: {url: 'sim://lift'}\n")
    (tmp_path / "bolts.yaml").write_text(BASE.replace("id: B2", "id: B1"))
    both = tmp_path / "both.yaml"
    both.write_text("cameras: {}\nmodels: {}\n")
    neither = tmp_path / "neither.yaml"
    neither.write_text("{}\n")
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    code, out, err = run("config", "check", station, both, neither, empty)
    lines = err.splitlines()
    assert code == 2 and out == ""
    assert lines[0] == (f"{station}:4: pairs.p.right: no camera 'c2' under cameras "
                        "(cameras: c1)")
    assert lines[1] == (f"{station}:4: pairs.p.calibration: calibration file "
                        f"{tmp_path / 'p.yaml'} does not exist")
    assert lines[2].startswith(f"{station}:5: wrench.url: unknown wrench scheme 'torque'")
    assert lines[3].startswith(f"{tmp_path / 'bolts.yaml'}:17: models.SEDAN.bolts[1].id: "
                               "duplicate bolt id 'B1'")
    assert lines[4] == (f"{both}:1: cannot tell a station file (it has cameras) from a bolt "
                        "table (it has models): a file is one or the other")
    assert lines[5].startswith(f"{neither}:1: neither a station file nor a bolt table (it has "
                               "no keys; a station file has marker, vision, cameras")
    assert lines[6] == f"{empty}: the file is empty"
    assert lines[7:] == [f"stationd: error: 7 errors in 4 of 4 files (those of "
                         f"{tmp_path / 'bolts.yaml'} counted with the station file naming it)"]


def test_config_check_warns_of_an_unregistered_pair_but_passes(run, tmp_path):
    import shutil

    for f in (ROOT / "config" / "sim").iterdir():
        shutil.copy(f, tmp_path)
    (tmp_path / "pair3.vehicle.yaml").unlink()
    code, out, err = run("config", "check", tmp_path / "station.yaml")
    assert code == 0 and out.startswith(f"{tmp_path / 'station.yaml'}: ok, station: 4 pairs")
    assert _one_line(err) == (
        f"warning: {tmp_path / 'station.yaml'}:16: pairs.pair3.to_vehicle: "
        f"{tmp_path / 'pair3.vehicle.yaml'} does not exist: the pair is not registered into "
        "the vehicle frame yet (stationd calibrate vehicle writes it)")


def test_export_results_every_rundown_as_csv_or_json(run, db, tmp_path):
    """Quality's export: every rundown (a NOK then its rework), per VIN or all, since a date;
    bad choices in one line."""
    import csv
    import io
    from datetime import UTC, datetime

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")
        record(repo, "VIN1", "SF-FL", ok=False, tightening_id=1)
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=2)
        repo.start_vehicle("VIN2", "WAGON-B")
        record(repo, "VIN2", "SF-FL", ok=True, tightening_id=3)
        others = sorted(set(repo.vehicle_report("VIN1").missing))
        repo.close_vehicle("VIN1")          # VIN1 left the station; VIN2 is still on the lift
    code, out, err = run("db", "export", "--results", "--db", db)
    rows = list(csv.DictReader(io.StringIO(out)))
    assert code == 0 and err == ""
    # each vehicle's rundowns, then its bolts without any (an export of rundowns alone read
    # as a complete vehicle: newcomer trial): missing on the vehicle that left, pending on
    # the one still on the lift (its bolts are to do, not forgotten)
    assert [(r["vin"], r["bolt"], r["attempt"], r["status"]) for r in rows] == [
        ("VIN1", "SF-FL", "1", "nok"), ("VIN1", "SF-FL", "2", "ok"),
        *(("VIN1", b, "0", "missing") for b in others),
        ("VIN2", "SF-FL", "1", "ok"), *(("VIN2", b, "0", "pending") for b in others)]
    assert others and "SF-FL" not in others
    first = rows[0]   # the limits the rundown was judged against, beside its values
    assert float(first["torque_min_nm"]) <= float(first["torque_max_nm"])
    assert all(rows[i]["torque_nm"] == "" for i in range(len(rows))
               if rows[i]["status"] in ("missing", "pending"))
    code, out, _ = run("db", "export", "--results", "--vin", "VIN2", "--format", "json",
                       "--db", db)
    assert code == 0 and [r["tightening_id"] for r in json.loads(out)] == \
        [3] + [None] * len(others)
    tomorrow = datetime.now(UTC).date().isoformat() + "T23:59:59"
    code, out, _ = run("db", "export", "--results", "--since", tomorrow, "--db", db)
    assert code == 0 and out.count("\n") == 1          # the header, no rundown
    target = tmp_path / "results.csv"
    code, out, _ = run("db", "export", "--results", "--out", str(target), "--db", db)
    assert code == 0 and target.read_text().count("\n") == 1 + 3 + 2 * len(others)
    # the open vehicle's bolts are not run down yet, not missing (a trial read the vehicle
    # on the lift as its bolts forgotten)
    assert len(others) == 2 and "3 rundowns and 2 missing bolts (and 2 not run down yet on 1 " \
        "open vehicle) of 2 vehicles" in out
    for args, message in ((["--vin", "NOPE"], "NOPE"), (["--since", "yesterday"], "ISO date"),
                          (["--format", "csv"], "go with --results"),
                          (["--results", "--format", "yaml"], "csv (the default) or json")):
        extra = ["--results"] if args[0] not in ("--format", "--results") else []
        code, out, err = run("db", "export", *extra, *args, "--db", db)
        assert code == 2 and out == "" and message in _one_line(err), err


def test_db_commands_take_the_database_of_a_station_file(run, tmp_path):
    """``--config STATION.yaml``: the database the daemon of that station writes (a relative
    SQLite path is the station file's folder's), and its matching tolerance for an import."""
    import shutil

    for f in (ROOT / "config" / "sim").iterdir():
        if f.is_file() and not f.name.startswith("stationd-sim.db"):
            shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    code, out, err = run("db", "import", tmp_path / "bolts.yaml", "--config", station)
    assert code == 0 and (tmp_path / "stationd-sim.db").exists() and err == ""
    code, out, _ = run("db", "export", "--config", station)
    assert code == 0 and "B01" in out
    # another table than the one the station file names: imported, and said not to last
    # (its daemon imports its own at each start and reload: a line engineer's trial)
    other = tmp_path / "other.yaml"
    other.write_text(out)
    code, _, err = run("db", "import", other, "--config", station)
    assert code == 0 and _one_line(err) == (
        f"warning: {station} names its bolt table ({tmp_path / 'bolts.yaml'}): its daemon "
        f"imports that file at each start and reload, replacing this import; to keep "
        f"{other}'s tables, copy it there or name it in bolts:")
    code, out, err = run("db", "export", "--config", station, "--db", "sqlite:///x.db")
    assert code == 2 and "not allowed with argument" in err
    # the station's tolerance: 30 mm makes the simulated vehicle's close bolts too close
    station.write_text(station.read_text().replace("tolerance_mm: 8.0", "tolerance_mm: 30.0"))
    code, out, err = run("db", "import", tmp_path / "bolts.yaml", "--config", station)
    assert code == 2 and "twice the matching tolerance of 30 mm" in err


def test_reports_and_exports_open_the_database_read_only(tmp_path):
    """A read command neither migrates nor writes: it works on a database its user may not
    write (checked below as uid 65534 when the tests run as root), leaves the file as it was,
    and refuses a database not at this release's schema instead of migrating it."""
    import hashlib
    import os
    import shutil
    import sqlite3
    import subprocess
    import sys
    import tempfile

    from db.errors import DatabaseError
    from db.repository import Repository

    # a folder uid 65534 can reach (pytest's own are root's only)
    folder = Path(tempfile.mkdtemp(prefix="stationd-ro-", dir="/tmp"))
    db = folder / "s.db"
    (tmp_path / "bolts.yaml").write_text(BASE)
    writer = Repository.open(url_of(db))          # the daemon: its -wal and -shm exist
    try:
        from stationd.boltfile import import_bolts
        import_bolts(writer, tmp_path / "bolts.yaml")
        writer.start_vehicle("VINRO", "SEDAN")
        record(writer, "VINRO", "B1")
        before = hashlib.sha256(db.read_bytes()).hexdigest()
        reader = Repository.open(url_of(db), read_only=True)
        try:
            assert [b.status for b in reader.vehicle_report("VINRO").bolts][:1] == ["ok"]
            with pytest.raises(DatabaseError):
                reader.start_vehicle("VINRO2", "SEDAN")          # mode=ro: no write
        finally:
            reader.close()
        assert hashlib.sha256(db.read_bytes()).hexdigest() == before
        # the clone's interpreter and code as uid 65534 sees them (a clone in a private
        # folder, mode 700, is out of its reach: then this part is skipped, saying so; an
        # interpreter it cannot even start is a PermissionError of the exec, not an exit code)
        why = _unreachable_as_nobody() if os.geteuid() == 0 else None
        if why is not None:
            pytest.skip(f"uid 65534 cannot run this clone's interpreter (a private folder?): "
                        f"{why}")
        if os.geteuid() == 0:
            # as a user who may read but not write the folder (the service user's database)
            os.chmod(folder, 0o755)  # noqa: S103 - readable by the other user, on purpose
            for f in folder.iterdir():
                os.chmod(f, 0o644)
            r = subprocess.run(
                [sys.executable, "-m", "stationd", "db", "report", "VINRO", "--db",
                 url_of(db)], capture_output=True, text=True, timeout=60,
                user=65534, group=65534, cwd="/", env={**os.environ, "HOME": "/"})
            # exit 1: the report's verdict (B2, B3 missing), not an error
            assert r.returncode == 1 and r.stderr == "", r.stderr
            assert "VINRO" in r.stdout and "MISSING" in r.stdout
    finally:
        writer.close()
        shutil.rmtree(folder, ignore_errors=True)
    # a database of another schema (here: none) is refused, not migrated
    old = tmp_path / "old.db"
    sqlite3.connect(old).close()
    with pytest.raises(DatabaseError, match="schema none"):
        Repository.open(url_of(old), read_only=True)
    assert old.stat().st_size == 0


def _unreachable_as_nobody() -> str | None:
    """Why uid 65534 cannot import stationd with this clone's interpreter (None: it can)."""
    import os
    import subprocess
    import sys

    try:
        reach = subprocess.run([sys.executable, "-c", "import stationd"], capture_output=True,
                               user=65534, group=65534, cwd="/", timeout=60,
                               env={**os.environ, "HOME": "/"})
    except OSError as exc:        # the interpreter itself is out of reach: exec refused
        return f"{sys.executable}: {exc.strerror or exc}"
    if reach.returncode != 0:
        return reach.stderr.decode(errors="replace").strip()[-200:]
    return None


def test_a_bolt_skipped_after_its_noks_is_reported_and_exported_skipped_with_who(run, db):
    """A bolt locked after its NOKs, then skipped by a supervisor: the report and the
    exports named no one (the decision only in the command list).  It still ends NOK (the
    joint is NOK, not untouched), said skipped by whom and why, its rundowns kept; a rundown
    after the skip counts as before."""
    import csv
    import io
    import time
    from datetime import UTC, datetime

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")
        for tid in (1, 2, 3):
            record(repo, "VIN1", "SF-FL", ok=False, tightening_id=tid)
        record(repo, "VIN1", "SF-FR", ok=False, tightening_id=4)
        time.sleep(0.01)
        for bolt in ("SF-FL", "SF-FR"):
            repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli",
                                       kind="skip", vin="VIN1", bolt=bolt,
                                       comment="thread damaged")
        time.sleep(0.01)
        record(repo, "VIN1", "SF-FR", ok=True, tightening_id=5)   # tightened after all
    code, out, _ = run("db", "report", "VIN1", "--db", db)
    lines = out.splitlines()
    assert code == 1 and "1 ending NOK (SF-FL skipped by sam), 0 skipped" in lines[0], \
        lines[0]
    fl = next(x for x in lines if x.strip().startswith("SF-FL"))
    assert fl.split()[1] == "NOK"                   # its status: its last rundown's
    assert "; then skipped by sam: thread damaged" in fl, fl
    assert any(x.strip().startswith("1. tightening NOK") for x in lines)   # its rundowns kept
    fr = next(x for x in lines if x.strip().startswith("SF-FR"))
    assert fr.split()[1] == "OK" and "skipped" not in fr
    code, out, _ = run("db", "export", "--results", "--vin", "VIN1", "--db", db)
    rows = [r for r in csv.DictReader(io.StringIO(out)) if r["bolt"] == "SF-FL"]
    assert [(r["status"], r["skipped_by"], r["comment"]) for r in rows] == [
        ("nok", "", ""), ("nok", "", ""), ("nok", "", ""),
        ("skipped", "sam", "thread damaged")]


def test_a_release_of_a_locked_bolt_is_a_row_of_the_results_export(run, db):
    """Three NOKs, a supervisor's release, an OK: the export read as a bolt that took four
    tries (a new user's trial found the release only in the screen's command list)."""
    import csv
    import io
    import json
    import time
    from datetime import UTC, datetime

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")
        for tid in (1, 2, 3):
            record(repo, "VIN1", "SF-FL", ok=False, tightening_id=tid)
        time.sleep(0.01)
        repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli",
                                   kind="release", vin="VIN1", bolt="SF-FL",
                                   comment="joint cleaned")
        time.sleep(0.01)
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=4)
    code, out, _ = run("db", "export", "--results", "--vin", "VIN1", "--db", db)
    rows = sorted((r for r in csv.DictReader(io.StringIO(out)) if r["bolt"] == "SF-FL"),
                  key=lambda r: r["recorded_at"])
    assert [(r["status"], r["released_by"], r["comment"]) for r in rows] == [
        ("nok", "", ""), ("nok", "", ""), ("nok", "", ""),
        ("released", "sam", "joint cleaned"), ("ok", "", "")]
    code, out, _ = run("db", "export", "--results", "--vin", "VIN1", "--format", "json",
                       "--db", db)
    every = json.loads(out)
    [rel] = [r for r in every if r["status"] == "released"]
    assert (rel["bolt"], rel["released_by"]) == ("SF-FL", "sam")
    # one set of keys for every row (a release's row had keys the others had not)
    assert len({tuple(sorted(r)) for r in every}) == 1
    out_file = db.removeprefix("sqlite:///") + ".csv"
    code, out, _ = run("db", "export", "--results", "--vin", "VIN1", "--out", out_file,
                       "--db", db)
    assert code == 0 and "4 rundowns" in out and "1 release" in out, out


def test_a_persons_loosen_command_is_a_row_of_the_results_export(run, db):
    """A supervisor's loosen command on a bolt tightened OK (an auditor's suspicion): the
    export read OK, a loosening, OK, with no word of who opened the OK bolt again or why;
    the shift's hand-over and db report name it (a quality auditor's trial)."""
    import csv
    import io
    import time

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=1)
        time.sleep(0.01)
        repo.ledger.record_command(at=datetime.now(UTC), user="sue",
                                   source="cli 127.0.0.1", kind="loosen", vin="VIN1",
                                   bolt="SF-FL", comment="suspected cross-thread")
        time.sleep(0.01)
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=2, kind="loosening")
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=3)
    for fmt in ("csv", "json"):
        code, out, _ = run("db", "export", "--results", "--vin", "VIN1", "--format", fmt,
                           "--db", db)
        assert code == 0
        rows = list(csv.DictReader(io.StringIO(out))) if fmt == "csv" else json.loads(out)
        mine = [r for r in rows if r["bolt"] == "SF-FL"]
        assert [r["rundown"] or "" for r in mine] == [
            "tightening", "", "loosening", "tightening"], (fmt, mine)
        order = mine[1]
        assert order["ordered_by"] == "sue" and order["comment"] == "suspected cross-thread"
        assert order["result_id"], "the command's record outside the station"


def test_a_nok_tightened_after_a_release_is_exported_after_the_lock_and_release(run, db):
    """A lock after 3 NOKs, released at once, then a 4th NOK within 2 s of the lock (its
    tool enabled after the release): the export put the lock and the release after that 4th
    NOK, as if 4 NOKs in a row came before the lock (an auditor's trial: the demo's own
    line said "NOK; NOK; NOK; locked, released by the supervisor; NOK")."""
    import csv
    import io

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    t0 = datetime(2026, 12, 1, 22, 50, 34, tzinfo=UTC)
    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")
        for tid, sent, taken in ((1, 0.0, 0.15), (2, 0.8, 0.95), (3, 1.5, 1.6)):
            record(repo, "VIN1", "SF-FL", ok=False, tightening_id=tid,
                   sent_at=t0 + timedelta(seconds=sent),
                   result_at=t0 + timedelta(seconds=taken))
        lock_at = t0 + timedelta(seconds=1.6)     # the third NOK's result_at
        repo.ledger.record_command(at=lock_at, user="station", source="NOK policy",
                                   kind="lock", vin="VIN1", bolt="SF-FL",
                                   comment="3 NOK in a row")
        repo.ledger.record_command(at=lock_at + timedelta(seconds=0.05), user="sam",
                                   source="screen", kind="release", vin="VIN1",
                                   bolt="SF-FL", comment="joint checked")
        record(repo, "VIN1", "SF-FL", ok=False, tightening_id=4,
               sent_at=t0 + timedelta(seconds=2.1), result_at=t0 + timedelta(seconds=2.2))
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=5,
               sent_at=t0 + timedelta(seconds=2.8), result_at=t0 + timedelta(seconds=2.9))
    for fmt in ("csv", "json"):
        code, out, _ = run("db", "export", "--results", "--vin", "VIN1", "--format", fmt,
                           "--db", db)
        assert code == 0
        rows = list(csv.DictReader(io.StringIO(out))) if fmt == "csv" else json.loads(out)
        assert [(r["status"], str(r["tightening_id"] or "")) for r in rows
                if r["bolt"] == "SF-FL"] == [
            ("nok", "1"), ("nok", "2"), ("nok", "3"), ("locked", ""), ("released", ""),
            ("nok", "4"), ("ok", "5")], fmt


def test_a_bolt_skipped_by_a_command_is_exported_and_reported_skipped_not_missing(run, db,
                                                                                  tmp_path):
    """Issue 19: a bolt a person skipped (with a comment) showed as missing in the results
    export and the report, as a bolt forgotten.  Skipped with who and why, in the CSV, the
    JSON and the report; the vehicle is not complete with it; a skip given before the
    vehicle was reopened for rework no longer counts (the rework starts afresh)."""
    import csv
    import io
    from datetime import UTC, datetime

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=1)
        others = sorted(set(repo.vehicle_report("VIN1").missing))
        skipped = others[0]
        skipped_at = datetime.now(UTC)
        repo.ledger.record_command(at=skipped_at, user="sam", source="web",
                                   kind="skip", vin="VIN1", bolt=skipped,
                                   comment="no access, fixture in the way")
    code, out, err = run("db", "export", "--results", "--db", db)
    rows = {r["bolt"]: r for r in csv.DictReader(io.StringIO(out))}
    assert code == 0 and err == ""
    assert (rows[skipped]["status"], rows[skipped]["skipped_by"], rows[skipped]["comment"]) \
        == ("skipped", "sam", "no access, fixture in the way")
    # when it was skipped (every time column was empty: a quality engineer's trial)
    at = datetime.fromisoformat(rows[skipped]["recorded_at"])
    assert abs((at.replace(tzinfo=at.tzinfo or UTC) - skipped_at).total_seconds()) < 1
    assert rows[skipped]["torque_nm"] == "" and rows[skipped]["attempt"] == "0"
    assert all(rows[b]["status"] == "pending" and rows[b]["skipped_by"] == ""
               for b in others[1:])          # VIN1 is open: to do, not missing
    assert rows["SF-FL"]["status"] == "ok" and rows["SF-FL"]["skipped_by"] == ""
    code, out, _ = run("db", "export", "--results", "--format", "json", "--db", db)
    (row,) = [r for r in json.loads(out) if r["bolt"] == skipped]
    assert (row["status"], row["skipped_by"], row["comment"]) == (
        "skipped", "sam", "no access, fixture in the way")
    assert row["recorded_at"] == rows[skipped]["recorded_at"]
    target = tmp_path / "results.csv"
    code, out, _ = run("db", "export", "--results", "--out", str(target), "--db", db)
    assert len(others) == 2 and "1 rundown and 0 missing bolts (and 1 skipped bolt, 1 not run " \
        "down yet on 1 open vehicle) of 1 vehicle" in out
    code, out, _ = run("db", "report", "VIN1", "--db", db)
    assert code == 1     # not complete: a skipped bolt is not tightened
    head = out.splitlines()[0]
    assert f"{len(others) - 1} missing" in head and skipped not in head.split("missing")[1] \
        .split("skipped")[0]
    assert f", 1 skipped ({skipped} by sam: no access, fixture in the way)" in head
    line = next(ln for ln in out.splitlines() if ln.strip().startswith(skipped + " "))
    assert "SKIPPED" in line and "by sam: no access, fixture in the way" in line
    code, out, _ = run("db", "report", "VIN1", "--json", "--db", db)
    doc = json.loads(out)
    assert doc["skipped"] == [skipped] and skipped not in doc["missing"]
    assert doc["complete"] is False
    (bolt,) = [b for b in doc["bolts"] if b["bolt"] == skipped]
    assert (bolt["status"], bolt["skipped_by"], bolt["comment"]) == (
        "skipped", "sam", "no access, fixture in the way")
    assert bolt["skipped_at"] == rows[skipped]["recorded_at"]
    with Repository.open(db) as repo:     # closed, then reopened for rework: afresh
        repo.close_vehicle("VIN1")
        repo.start_vehicle("VIN1", "WAGON-B", reopen=True)
        assert repo.vehicle_report("VIN1").skipped == []
        assert skipped in repo.vehicle_report("VIN1").missing


def test_a_table_without_models_is_not_imported_and_an_idle_one_is_warned(run, db, tmp_path):
    """A sweep: importing `models: {}` retired every model of the station, without a word."""
    assert run("db", "import", EXAMPLE, "--db", db)[0] == 0
    empty = tmp_path / "empty.yaml"
    empty.write_text("psets: []\nmodels: {}\n")
    code, _, err = run("db", "import", empty, "--db", db)
    assert code == 2 and "would retire every model of the station; nothing imported" in err
    code, _, err = run("config", "check", empty)
    assert code == 0 and "warning:" in err and "tightens nothing" in err


def test_report_says_the_type_of_a_result_of_an_unknown_type(run, db):
    """An auditor's trial: a result of type 9 that held its bolt read "controller event:
    unknown result type, bolt held, tightening 3" in the report: its type said nowhere, and
    "held" after the outcome was entered.  Its code said; its words not "held"."""
    from db.kinds import UNKNOWN_TYPE_HELD
    from db.repository import Repository

    run("db", "import", EXAMPLE, "--db", db)
    with Repository.open(db) as repo:
        repo.start_vehicle("VIN1", "WAGON-B")
        repo.others.record_controller_event(
            result_type=9, what=UNKNOWN_TYPE_HELD, vin="VIN1", bolt="SF-FR",
            controller_vin=None, tightening_id=3, pset=1, ok=True, torque_nm=49.4,
            angle_deg=30.0, result_at=None)
    code, out, _ = run("db", "report", "VIN1", "--db", db)
    assert code == 1        # SF-FR held: the vehicle not complete
    assert ("controller event: unknown result type, not taken (type 9), tightening 3 pset 1 "
            "while the tool was on SF-FR: not a rundown") in out


def test_report_shows_controller_events_and_unreadable_results(run, db, tmp_path):
    from db.kinds import CUT_UNKNOWN, LOCK
    from db.repository import Repository
    from stationd.web.results import (
        CONTROLLER_EVENT_STATUS,
        LOCKED_STATUS,
        UNATTRIBUTED_STATUS,
        UNREADABLE_STATUS,
        Results,
        rundowns_csv,
    )

    run("db", "import", EXAMPLE, "--db", db)
    with Repository.open(db) as repo:
        repo.start_vehicle("VIN1", "WAGON-B")
        # SF-FL held by a result that did not read, then tightened: held then, no longer
        repo.others.record_unreadable(
            mid=61, revision=7, raw="00990061007    garbled",
            error="MID 0061 revision 7: parameter 02 missing",   # the driver's words
            vin="VIN1", bolt="SF-FL", controller_vin=None, tightening_id=5, pset=1,
            result_at=None)
        # SF-FR held by a link cut during its enable: no result, its note says why
        repo.others.record_controller_event(
            result_type=0, what=CUT_UNKNOWN, vin="VIN1", bolt="SF-FR", controller_vin=None,
            tightening_id=None, pset=1, ok=False, torque_nm=None, angle_deg=None,
            result_at=None, note="its result during the link cut not known: the controller "
            "refused to give them")
        # made at 17:27:47 on the controller's clock (fetched after a link cut, later)
        record(repo, "VIN1", "SF-FL", tightening_id=3,
               controller_at=datetime(2026, 11, 30, 17, 27, 47, tzinfo=UTC))
        repo.others.record_controller_event(
            result_type=3, what="batch increment", vin="VIN1", bolt="SF-FR",
            controller_vin=None, tightening_id=8, pset=1, ok=True, torque_nm=0.0,
            angle_deg=0.0, result_at=None)
        # TB-C held by tightening 4, released, then held again by tightening 9: each record
        # says whether its own hold is on (a reviewer: both said "held")
        repo.others.record_unreadable(
            mid=61, revision=7, raw="00990061007    first", error="parameter 03 missing",
            vin="VIN1", bolt="TB-C", controller_vin=None, tightening_id=4, pset=2,
            result_at=None)
        repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli",
                                   kind="release", vin="VIN1", bolt="TB-C",
                                   comment="checked: not tightened")
        repo.others.record_unreadable(
            mid=61, revision=7, raw="00990061007    garbage", error="parameter 01 missing",
            vin="VIN1", bolt="TB-C", controller_vin=None, tightening_id=9, pset=2,
            result_at=datetime(2026, 11, 30, 17, 27, 55, tzinfo=UTC))
        # the NOK policy's lock of TB-L, said in the export too (a quality trial: only in
        # db report)
        repo.ledger.record_command(at=datetime.now(UTC), user="station", source="NOK policy",
                                   kind=LOCK, vin="VIN1", bolt="TB-L",
                                   comment="3 NOK in a row")
        repo.others.record_unattributed(   # a quality trial: in db report, missing from the export
            vin="VIN1", controller_vin=None, tightening_id=10, pset=2, ok=True, torque_nm=49.5,
            angle_deg=39.0, result_at=None, reason="fetched after a later one came")
        runs = Results(repo).export("VIN1")
        doc = Results(repo).vehicle("VIN1")
    code, out, _ = run("db", "report", "VIN1", "--db", db)
    assert code == 1
    assert ("controller event: batch increment (type 3), tightening 8 pset 1 while the tool "
            "was on SF-FR: not a rundown") in out
    assert ("unreadable result: tightening 9 (MID 0061 revision 7, TB-C held): parameter 01 "
            "missing") in out
    # a hold ended since is not said as held; a link cut's hold says what it knows, not a
    # result's "tightening None ... (type 0)" (a supervisor's trial)
    assert ("unreadable result: tightening 5 (MID 0061 revision 7, SF-FL held then, no "
            "longer): parameter 02 missing") in out
    assert ("unreadable result: tightening 4 (MID 0061 revision 7, TB-C held then, no "
            "longer): parameter 03 missing") in out
    assert ("link cut while the tool was on SF-FR: its result during the link cut not known: "
            "the controller refused to give them; SF-FR held") in out
    assert "None" not in out and "type 0" not in out
    # a bolt's line names its last rundown's tightening id and time (a quality trial: only
    # in --json and the exports)
    [sffl] = [line for line in out.splitlines() if line.strip().startswith("SF-FL ")]
    assert "1 attempt, by -, tightening 3, at 20" in sffl and " UTC" in sffl, sffl
    # the held bolt says so on its own line and in the counts (a quality trial)
    assert ", 2 held (SF-FR, TB-C)" in out.splitlines()[0], out
    [tbc] = [line for line in out.splitlines() if line.strip().startswith("TB-C ")]
    assert "HELD: tightening 9 (its outcome to be entered)" in tbc, tbc
    code, out, _ = run("db", "report", "VIN1", "--db", db, "--json")
    obj = json.loads(out)
    assert [e["result_type"] for e in obj["controller_events"]] == [0, 3]
    assert obj["controller_events"][0]["note"].startswith("its result during the link cut")
    assert [x["raw"] for x in obj["unreadable_results"]] == ["00990061007    garbled",
                                                              "00990061007    first",
                                                              "00990061007    garbage"]
    [row] = [r for r in runs if r["status"] == UNREADABLE_STATUS and r["tightening_id"] == 9]
    assert row["bolt"] == "TB-C"
    # one clock per column on every row (an MES integrator's trial: the controller's time
    # in result_at on these rows, the station's on rundowns): the controller's, read, in
    # controller_at; when the station took it in result_at
    assert row["controller_at"].startswith("2026-11-30T17:27:55")
    assert row["result_at"] == row["recorded_at"]
    assert row["comment"] == "MID 0061 revision 7: parameter 01 missing"
    [made] = [r for r in runs if r["bolt"] == "SF-FL" and r["status"] != UNREADABLE_STATUS]
    assert made["controller_at"].startswith("2026-11-30T17:27:47"), made
    assert "2026-11-30T17:27:47+00:00" in rundowns_csv(runs)
    [loose] = [r for r in runs if r["status"] == UNATTRIBUTED_STATUS]
    assert (loose["bolt"], loose["tightening_id"], loose["torque_nm"]) == (None, 10, 49.5)
    assert loose["rundown"] is None and loose["result_at"] == loose["recorded_at"]
    assert "fetched after a later one came" in loose["comment"]
    assert "parameter 01 missing" in rundowns_csv(runs)
    assert ",unattributed," in rundowns_csv(runs)
    out_csv = tmp_path / "all.csv"
    code, out, _ = run("db", "export", "--results", "--db", db, "--out", str(out_csv))
    assert code == 0 and ("1 lock, 1 release, 3 unreadable results, 1 unattributed "
                          "result, 2 controller events") in out, out
    # the controller's results that are no rundown, each a row: a batch increment (an
    # auditor must see a bypass or a batch step), a link cut that left a result unknown
    events = [r for r in runs if r["status"] == CONTROLLER_EVENT_STATUS]
    assert [(r["bolt"], r["rundown"], r["tightening_id"]) for r in events] == [
        ("SF-FR", CUT_UNKNOWN, None), ("SF-FR", "batch increment", 8)]
    assert events[0]["comment"].startswith("its result during the link cut not known")
    assert events[1]["comment"] == "not a rundown; the tool was on SF-FR"
    [lock] = [r for r in runs if r["status"] == LOCKED_STATUS]
    assert (lock["bolt"], lock["comment"]) == ("TB-L", "3 NOK in a row")
    assert out.startswith(f"wrote {out_csv}: 1 rundown and "), out
    assert [x["bolt"] for x in doc["unreadable_results"]] == ["SF-FL", "TB-C", "TB-C"]
    assert [e["what"] for e in doc["controller_events"]] == [CUT_UNKNOWN, "batch increment"]


def _sim_station(tmp_path: Path) -> Path:
    """A copy of config/sim: its database (stationd-sim.db beside it) not made yet."""
    station = tmp_path / "sim"
    station.mkdir()
    for f in (ROOT / "config" / "sim").glob("*.yaml"):
        (station / f.name).write_text(f.read_text())
    return station / "station.yaml"


def _demo_database(run, temp: Path, station: Path, name: str = "abc") -> Path:
    """A running demo of ``station`` (this process stands in for it: its pid file) whose
    own database, in ``temp``, has VIN1 with one rundown: that database's file."""
    from db.repository import Repository
    from stationd.demo.leftovers import PREFIX, mark

    folder = temp / f"{PREFIX}{name}"
    (folder / "1").mkdir(parents=True)
    mark(folder, station)
    path = folder / "1" / "stationd.db"
    assert run("db", "import", EXAMPLE, "--db", url_of(path))[0] == 0
    with Repository.open(url_of(path)) as repo:
        repo.start_vehicle("VIN1", "WAGON-B")
        record(repo, "VIN1", "SF-FL")
    return path


def test_report_with_config_finds_a_running_demos_database(run, tmp_path, monkeypatch):
    """Issue 30: during a demo, `db report VIN --config STATION.yaml` said "no database at
    .../stationd-sim.db (import a bolt table first, or give --db or --config STATION.yaml)":
    the demo keeps its records in its own temporary folder, and the hint suggested the option
    already given.  A running demo's database is found by its station file now."""
    import tempfile

    station = _sim_station(tmp_path)
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    # no database, no demo: the hint names neither option again, and where a demo's are
    code, out, err = run("db", "report", "VIN1", "--config", station)
    line = _one_line(err)
    assert code == 2 and out == "" and f"no database at {station.parent}" in line
    assert "give --db or --config" not in line and "demo" in line and "/vehicles" in line
    # a demo of this station file running, its vehicle in its own database
    folder = _demo_database(run, temp, station).parents[1]
    code, out, err = run("db", "report", "VIN1", "--config", station)
    assert code == 1 and out.startswith("VIN1 (WAGON-B, open): bolts: 1 OK"), (out, err)
    assert _one_line(err) == (f"stationd: VIN1 is a running demo's vehicle: reading that "
                              f"demo's database (DEMO-1, {folder / '1' / 'stationd.db'}), "
                              f"not {station}'s")
    # a VIN neither has: said, the demo's database named
    code, out, err = run("db", "report", "NOPE", "--config", station)
    assert code == 2 and _one_line(err) == (
        f"stationd: error: vehicle 'NOPE' is in no database of {station}: none at "
        f"{station.parent / 'stationd-sim.db'} yet; nor is NOPE in the database of the running "
        f"demo of {station} (DEMO-1 {folder / '1' / 'stationd.db'})")
    # the station's own database made (it has no such vehicle): the demo's is still found
    assert run("db", "import", EXAMPLE, "--config", station)[0] == 0
    assert run("db", "report", "VIN1", "--config", station)[0] == 1
    code, out, err = run("db", "report", "NOPE", "--config", station)
    assert code == 2 and _one_line(err).startswith(
        f"stationd: error: vehicle 'NOPE' is not in the database of {station}; nor is NOPE")
    (station.parent / "stationd-sim.db").unlink()
    # the demo gone (its pid file names no live process): its folder is not read
    (folder / "demo.pid").write_text("999999999 -\n")
    code, _, err = run("db", "report", "VIN1", "--config", station)
    assert code == 2 and "no database at" in _one_line(err)


def test_export_and_figures_with_config_read_a_running_demos_database(run, tmp_path,
                                                                      monkeypatch):
    """During a demo, ``db report --config`` found the demo's records while ``db export
    --results`` and ``db spc`` with the same --config said only "no database at" (a new
    user's trial): they read the running demo's database too, saying so."""
    import tempfile

    station = _sim_station(tmp_path)
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    folder = _demo_database(run, temp, station).parents[1]
    said = (f"stationd: {station}'s database {station.parent / 'stationd-sim.db'} is not "
            f"there yet: reading the running demo's (DEMO-1, {folder / '1' / 'stationd.db'})")
    code, out, err = run("db", "export", "--results", "--config", station)
    assert code == 0 and "VIN1,WAGON-B,SF-FL" in out and _one_line(err) == said
    code, out, err = run("db", "spc", "--config", station)
    assert code == 0 and "SF-FL" in out and _one_line(err) == said
    # one vehicle's export finds it where the report does: the station's own database made
    # (without VIN1), the demo's is read for it (it said "not in the database")
    assert run("db", "import", EXAMPLE, "--config", station)[0] == 0
    code, out, err = run("db", "export", "--results", "--config", station, "--vin", "VIN1")
    assert code == 0 and "VIN1,WAGON-B,SF-FL" in out, (out, err)
    assert _one_line(err) == (f"stationd: VIN1 is a running demo's vehicle: reading that "
                              f"demo's database (DEMO-1, {folder / '1' / 'stationd.db'}), "
                              f"not {station}'s")
    (station.parent / "stationd-sim.db").unlink()
    # two demos of it: which to read is asked, each with its --db
    _demo_database(run, temp, station, "def")
    code, out, err = run("db", "spc", "--config", station)
    assert code == 2 and out == "" and "the running demos of it keep theirs: DEMO-1 --db " \
        f"sqlite:///{folder / '1' / 'stationd.db'}" in _one_line(err)


def test_report_counts_a_bolts_tightenings_and_loosenings_apart(run, db):
    """A loosening is no attempt at the bolt: a bolt reworked NOK, loosened, OK reads as two
    tightenings and one loosening (it read "3 attempts")."""
    from db.kinds import LOOSENING
    from db.repository import Repository

    run("db", "import", EXAMPLE, "--db", db)
    with Repository.open(db) as repo:
        repo.start_vehicle("VIN2", "WAGON-B")
        record(repo, "VIN2", "SF-FL", ok=False)
        record(repo, "VIN2", "SF-FL", kind=LOOSENING, torque_nm=12.0)
        record(repo, "VIN2", "SF-FL")
        record(repo, "VIN2", "SF-FR")
        record(repo, "VIN2", "SF-FR")
    _, out, _ = run("db", "report", "VIN2", "--db", db)
    [fl] = [line for line in out.splitlines() if line.strip().startswith("SF-FL ")]
    assert fl.split(", by")[0].endswith("v1, 2 tightenings, 1 loosening"), fl
    [fr] = [line for line in out.splitlines() if line.strip().startswith("SF-FR ")]
    assert "v1, 2 attempts" in fr, fr


def test_report_names_a_loosening_s_controller_id_as_a_loosening(run, db):
    """A bolt whose last rundown is a loosening: its line named the controller's id
    "tightening 12" (a supervisor's trial); it is "loosening 12", a tightening's stays
    "tightening N"."""
    from db.kinds import LOOSENING
    from db.repository import Repository

    run("db", "import", EXAMPLE, "--db", db)
    with Repository.open(db) as repo:
        repo.start_vehicle("VIN2", "WAGON-B")
        record(repo, "VIN2", "SF-FL", ok=False, tightening_id=11)
        record(repo, "VIN2", "SF-FL", kind=LOOSENING, torque_nm=12.0, tightening_id=12)
        record(repo, "VIN2", "SF-FR", tightening_id=13)
    _, out, _ = run("db", "report", "VIN2", "--db", db)
    [fl] = [line for line in out.splitlines() if line.strip().startswith("SF-FL ")]
    assert ", loosening 12, at " in fl and "tightening 12" not in fl, fl
    [fr] = [line for line in out.splitlines() if line.strip().startswith("SF-FR ")]
    assert ", tightening 13, at " in fr, fr


def test_a_vin_in_another_case_is_suggested_after_the_station_file_it_was_looked_for_in(
        run, tmp_path):
    """"vehicle 'vin1' is not in the database (did you mean VIN1?) of FILE" read as if the
    suggestion were of the file (a quality engineer's trial)."""
    from db.repository import Repository

    station = _sim_station(tmp_path)
    assert run("db", "import", EXAMPLE, "--config", station)[0] == 0
    with Repository.open(f"sqlite:///{station.parent / 'stationd-sim.db'}") as repo:
        repo.start_vehicle("VIN1", "WAGON-B")
    code, out, err = run("db", "report", "vin1", "--config", station)
    assert code == 2 and out == "" and _one_line(err) == (
        f"stationd: error: vehicle 'vin1' is not in the database of {station} (did you mean "
        "VIN1?)")


def test_a_bolt_held_for_a_lost_push_is_not_said_never_tightened(run, db):
    """A supervisor's trial: the vehicle's page said "not tightened" of a bolt held because
    tightening 41, fetched late (its push lost) and stored unattributed, may be its own.  The
    page and db report say alike that it is held and which result may be its own, with its
    values; a bolt neither held nor run down is "not tightened" (the page) and "-" (db
    report) as before, and another hold's says its result is not known."""
    from db.kinds import CUT_UNKNOWN, LOST_UNKNOWN, cut_unknown_note, lost_unknown_note
    from db.repository import Repository
    from stationd.web.results import Results

    run("db", "import", EXAMPLE, "--db", db)
    note = lost_unknown_note(41, 1, 1000.0)
    with Repository.open(db) as repo:
        repo.start_vehicle("VIN1", "WAGON-B")
        repo.others.record_unattributed(
            vin="VIN1", controller_vin=None, tightening_id=41, pset=1, ok=True,
            torque_nm=49.6, angle_deg=31.0, result_at=None,
            reason="fetched after a later one came, the link up")
        for bolt, what, held in (("SF-FL", LOST_UNKNOWN, note),
                                 ("SF-FR", CUT_UNKNOWN, cut_unknown_note("no answer"))):
            repo.others.record_controller_event(
                result_type=0, what=what, vin="VIN1", bolt=bolt, controller_vin=None,
                tightening_id=None, pset=1, ok=None, torque_nm=None, angle_deg=None,
                result_at=None, note=held)
        page = {b["bolt"]: b for b in Results(repo).vehicle("VIN1")["bolts"]}
    said = ("held: no rundown recorded to it, but tightening 41 may be its own (OK 49.6 Nm, "
            "31 deg, stored unattributed)")
    assert page["SF-FL"]["unrecorded"] == said
    assert page["SF-FR"]["unrecorded"] == "held: no rundown recorded to it, its result not known"
    assert page["TB-C"]["unrecorded"] == "not tightened"
    _, out, _ = run("db", "report", "VIN1", "--db", db)
    lines = {line.split()[0]: line for line in out.splitlines()[1:] if line.startswith("  ")}
    assert f"MISSING  {said}  " in lines["SF-FL"] and f"HELD: {note}" in lines["SF-FL"]
    assert f"MISSING  {page['SF-FR']['unrecorded']}  " in lines["SF-FR"]
    assert "MISSING  -  " in lines["TB-C"] and "not tightened" not in out
    # --json says it as the page does (an MES integrator's trial: it had no word of it)
    _, out, _ = run("db", "report", "VIN1", "--db", db, "--json")
    bolts = {b["bolt"]: b for b in json.loads(out)["bolts"]}
    assert {b: bolts[b].get("unrecorded") for b in ("SF-FL", "SF-FR", "TB-C")} == {
        b: page[b]["unrecorded"] for b in ("SF-FL", "SF-FR", "TB-C")}


def test_a_record_says_held_only_for_its_own_hold():
    """Whether a record's hold is on is its own note's, not its bolt's (a reviewer: the
    record of "tightening 4" said held while "tightening 41" held the bolt)."""
    from stationd.db_cli import HOLD_WORDS, _held_now

    holds = {"B1": "tightening 41", "B2": "tightening 7, a loosening with loosen pset 90"}
    assert _held_now("B1", holds, "tightening 4") == ", B1 held then, no longer"
    assert _held_now("B1", holds, "tightening 41") == ", B1 held"
    assert _held_now("B2", holds, "tightening 7", "; ") == "; B2 held"
    assert _held_now("B3", holds, "tightening 2") == ", B3 held then, no longer"
    assert _held_now(None, holds, "x") == ""
    # how it ended, where the vehicle's commands say (a supervisor's trial: "held then, no
    # longer", who ended it only in the list of commands): the first one since the hold
    from datetime import UTC, datetime
    from types import SimpleNamespace

    at = datetime(2026, 12, 2, 16, 48, 0, tzinfo=UTC)
    commands = [SimpleNamespace(kind="release", bolt="B1", user="eve",
                                at=datetime(2026, 12, 2, 16, 40, 0, tzinfo=UTC)),
                SimpleNamespace(kind="enter-outcome", bolt="B1", user="sam",
                                at=datetime(2026, 12, 2, 16, 52, 0, tzinfo=UTC)),
                SimpleNamespace(kind="release", bolt="B3", user="ann",
                                at=datetime(2026, 12, 2, 16, 53, 0, tzinfo=UTC))]
    assert _held_now("B1", holds, "tightening 4", "; ", at, commands) == \
        "; B1 held then: its outcome entered by sam at 2026-12-02 16:52:00 UTC"
    assert _held_now("B3", holds, "tightening 2", ", ", at, commands) == \
        ", B3 held then: released by ann at 2026-12-02 16:53:00 UTC"
    assert _held_now("B1", holds, "tightening 41", "; ", at, commands) == "; B1 held"
    # the station's own holds without a result, each named
    assert set(HOLD_WORDS) == {"result unknown after a link cut",
                               "result unknown after a lost push"}


def test_report_says_which_value_of_a_nok_rundown_is_out_of_its_limits(run, db):
    """``db report`` printed "NOK 48.1 Nm, 97.0 deg" and a quality engineer compared each
    value with the limits by hand (a newcomer's trial): a NOK rundown names the value out of
    its window and the limit, and a NOK within both is the controller's verdict."""
    from db.repository import Repository

    run("db", "import", EXAMPLE, "--db", db)
    with Repository.open(db) as repo:      # pset 2: torque 100-120 Nm, angle 20-80 deg
        repo.start_vehicle("VIN2", "WAGON-B")
        record(repo, "VIN2", "SF-FL", ok=False, torque_nm=124.5, angle_deg=12.0,
               tightening_id=41)
        record(repo, "VIN2", "SF-FL", ok=False, torque_nm=95.0, angle_deg=40.0,
               tightening_id=42)
        record(repo, "VIN2", "SF-FR", ok=False, torque_nm=110.0, angle_deg=40.0)
        record(repo, "VIN2", "TB-C", ok=True, torque_nm=110.0, angle_deg=40.0)
    code, out, _ = run("db", "report", "VIN2", "--db", db)
    assert code == 1                       # not complete
    lines = [line.strip() for line in out.splitlines()]
    [fl] = [line for line in lines if line.startswith("SF-FL ")]
    assert "NOK      95.0 Nm, 40.0 deg, v1 (torque 95.0 Nm < 100.0 min), 2 attempts" in fl, fl
    # each attempt with the controller's id (a quality trial: the last one's alone)
    assert "1. tightening NOK pset 2, 124.5 Nm, 12.0 deg (torque 124.5 Nm > 120.0 max; " \
           "angle 12 deg < 20 min), tightening 41, at " in out, out
    assert "2. tightening NOK pset 2, 95.0 Nm, 40.0 deg (torque 95.0 Nm < 100.0 min), " \
           "tightening 42, at " in out, out
    [fr] = [line for line in lines if line.startswith("SF-FR ")]
    assert "(both within limits: the controller's verdict)" in fr, fr
    [rl] = [line for line in lines if line.startswith("TB-C ")]
    assert "(" not in rl.split(", by")[0], rl
    _, out, _ = run("db", "report", "VIN2", "--db", db, "--json")
    rundowns = json.loads(out)["rundowns"]
    assert {"tightening_id", "result_at", "controller_at", "recorded_at"} <= set(rundowns[0])
    why = [(r["bolt"], r["nok_why"]) for r in rundowns]
    assert why == [("SF-FL", "torque 124.5 Nm > 120.0 max; angle 12 deg < 20 min"),
                   ("SF-FL", "torque 95.0 Nm < 100.0 min"),
                   ("SF-FR", "both within limits: the controller's verdict"), ("TB-C", None)]


def test_a_shift_s_export_keeps_a_vehicle_that_left_with_no_rundown_at_all(run, db):
    """A shift supervisor's export of the shift (``--since`` its start): a vehicle that
    passed the station in the shift with not one bolt tightened (every bolt missing: the
    worst vehicle of the shift) was not in it, the export keeping a vehicle's missing bolts
    only beside a rundown of its own since then; the vehicle's report says all missing."""
    import csv
    import io

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")      # the last shift's
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=1)
        repo.close_vehicle("VIN1")
    shift = datetime.now(UTC).isoformat()
    with Repository.open(db) as repo:
        repo.start_vehicle("VIN2", "WAGON-B")      # this shift's: nothing tightened
        repo.close_vehicle("VIN2")
        repo.start_vehicle("VIN3", "WAGON-B")      # this shift's: one bolt
        record(repo, "VIN3", "SF-FL", ok=True, tightening_id=2)
        repo.close_vehicle("VIN3")
        missing = repo.vehicle_report("VIN2").missing
    assert missing
    code, out, err = run("db", "export", "--results", "--since", shift, "--db", db)
    rows = list(csv.DictReader(io.StringIO(out)))
    assert code == 0, err
    assert sorted({r["vin"] for r in rows}) == ["VIN2", "VIN3"], rows
    assert [r["bolt"] for r in rows if r["vin"] == "VIN2"] == missing


def test_a_shift_s_hand_over_names_its_vehicles_those_not_ok_and_who_released_what(run, db):
    """A shift supervisor's trial: at the end of a shift, how many vehicles passed, which
    left with bolts not OK, who released a lock and why; the screens list the newest 200
    and ``db report`` one vehicle.  ``db shift`` answers for a window: a vehicle that left
    before it is not in it, one at the station is, open; exit 1 while one is not OK."""
    import json
    import time
    from datetime import UTC, datetime, timedelta

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN0", "WAGON-B")             # the shift before's
        repo.close_vehicle("VIN0")
        time.sleep(0.01)
        since = datetime.now(UTC)
        bolts = [b.bolt_id for b in repo.bolts_for_model("WAGON-B")]
        repo.start_vehicle("VIN1", "WAGON-B")
        for tid, bolt in enumerate(bolts, 1):
            record(repo, "VIN1", bolt, tightening_id=tid)
        repo.close_vehicle("VIN1")
        repo.start_vehicle("VIN2", "WAGON-B")
        for tid in (101, 102, 103):
            record(repo, "VIN2", bolts[0], ok=False, tightening_id=tid)
        repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli",
                                   kind="release", vin="VIN2", bolt=bolts[0],
                                   comment="joint cleaned")
        repo.close_vehicle("VIN2")
        repo.start_vehicle("VIN3", "WAGON-B")             # at the station still
        record(repo, "VIN3", bolts[0], tightening_id=201)
    code, out, err = run("db", "shift", "--since", since.isoformat(), "--db", db)
    assert code == 1 and not err, err
    lines = out.splitlines()
    assert "3 vehicles at the station: 1 complete, 1 NOK, 1 open" in lines[0]
    assert [line.split()[0] for line in lines[1:4]] == ["VIN1", "VIN2", "VIN3"]
    assert "complete" in lines[1] and lines[1].rstrip().endswith("complete")
    assert f"{bolts[0]} NOK, {len(bolts) - 1} missing ({bolts[1]}" in lines[2]
    assert "open" in lines[3] and f"missing ({bolts[1]}" in lines[3]
    assert f"release {bolts[0]} of VIN2 by sam (cli)" in out and "joint cleaned" in out
    code, out, _ = run("db", "shift", "--since", since.isoformat(), "--db", db, "--json")
    doc = json.loads(out)
    assert code == 1 and [(v["vin"], v["status"]) for v in doc["vehicles"]] == [
        ("VIN1", "complete"), ("VIN2", "NOK"), ("VIN3", "open")]
    assert [(c["kind"], c["vin"], c["comment"]) for c in doc["commands"]] == [
        ("release", "VIN2", "joint cleaned")]
    # the shift before: the first vehicle alone, complete or not (it left all missing)
    code, out, _ = run("db", "shift", "--since", (since - timedelta(hours=1)).isoformat(),
                       "--until", since.isoformat(), "--db", db)
    assert code == 1 and "1 vehicle at the station: 1 incomplete" in out and "VIN0" in out
    code, out, err = run("db", "shift", "--since", since.isoformat(), "--until",
                         (since - timedelta(hours=1)).isoformat(), "--db", db)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "is not before" in err


def test_a_shift_s_hand_over_says_locks_outcomes_refusals_and_counts_the_missing(run, db):
    """A supervisor's trial of the hand-over: a bolt left locked read "NOK" as one that
    simply ended NOK; a loosened bolt read "to loosen"; an entered outcome gave the comment
    alone, not the verdict; a release refused for a mistyped VIN was kept but not listed;
    a vehicle reopened for rework read "left -" as if on the lift; 47 missing bolts made a
    700-character line.  Each said now, the missing counted after the first five."""
    import json

    from db.entered import record_entered
    from db.kinds import LOCK, LOCK_SOURCE, LOCK_USER, LOOSENING, REFUSED
    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, ROOT / "config" / "sim" / "bolts.yaml")    # 50 bolts
        since = datetime.now(UTC) - timedelta(minutes=1)
        model = "SIM-1"
        bolts = [b.bolt_id for b in repo.bolts_for_model(model)]
        repo.start_vehicle("VIN1", model)
        for tid in (1, 2, 3):
            record(repo, "VIN1", bolts[0], ok=False, tightening_id=tid)
        repo.ledger.record_command(at=datetime.now(UTC), user=LOCK_USER, source=LOCK_SOURCE,
                                   kind=LOCK, vin="VIN1", bolt=bolts[0], comment="3 NOK")
        record(repo, "VIN1", bolts[1], ok=False, tightening_id=4)
        record(repo, "VIN1", bolts[1], tightening_id=5, kind=LOOSENING, torque_nm=8.0)
        at = datetime.now(UTC)
        record_entered(repo, vin="VIN1", bolt=bolts[2], ok=True, torque_nm=25.1,
                       angle_deg=31.0, at=at, user="pete", source="cli",
                       comment="controller shows OK")
        repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli",
                                   kind=REFUSED, vin="VIN9", bolt=bolts[0],
                                   comment="release: refused: not at the station")
        repo.start_vehicle("VIN2", model)
        for tid, bolt in enumerate(bolts, 10):
            record(repo, "VIN2", bolt, tightening_id=tid)
        repo.close_vehicle("VIN2")
        repo.reopen_vehicle("VIN2", at=datetime.now(UTC), user="sam", source="cli",
                            comment="rework")
    code, out, err = run("db", "shift", "--since", since.isoformat(), "--db", db)
    assert code == 1 and not err, err
    [vin1] = [x for x in out.splitlines() if x.strip().startswith("VIN1")]
    assert f"{bolts[0]} NOK and locked, {bolts[1]} loosened" in vin1, vin1
    assert f"{len(bolts) - 3} missing ({', '.join(bolts[3:8])} and {len(bolts) - 8} more)" \
        in vin1 and bolts[-1] not in vin1, vin1
    [vin2] = [x for x in out.splitlines() if x.strip().startswith("VIN2")]
    assert "left -" not in vin2 and "reopened" in vin2, vin2
    assert f"enter-outcome {bolts[2]} of VIN1 by pete (cli) at " in out
    assert "UTC: OK 25.1 Nm, 31.0 deg: controller shows OK" in out
    assert f"refused {bolts[0]} of VIN9 by sam (cli)" in out and "not at the station" in out
    doc = json.loads(run("db", "shift", "--since", since.isoformat(), "--db", db,
                         "--json")[1])
    assert [v["locked"] for v in doc["vehicles"]] == [[bolts[0]], []]
    assert [c["entered"] for c in doc["commands"] if c["kind"] == "enter-outcome"] == [
        "OK 25.1 Nm, 31.0 deg"]
    code, out, _ = run("db", "report", "VIN1", "--db", db)
    [row] = [x for x in out.splitlines() if x.strip().startswith(f"{bolts[0]} ")]
    assert "LOCKED" in row and "NOK" in row, row


def test_a_shift_s_hand_over_names_a_held_bolt_once(run, db):
    """A quality auditor's trial: a bolt held for a person (its result could not be read)
    read twice in a vehicle's line, "B2 missing, ..., B2 held"."""
    from datetime import UTC, datetime, timedelta

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        bolts = [b.bolt_id for b in repo.bolts_for_model("WAGON-B")]
        repo.start_vehicle("VIN1", "WAGON-B")
        repo.others.record_unreadable(mid=61, revision=7, raw="00230061007 garbled", error="short",
                                      vin="VIN1", bolt=bolts[0], controller_vin=None,
                                      tightening_id=7, pset=1, result_at=None)
    since = (datetime.now(UTC) - timedelta(hours=1)).isoformat()
    code, out, _ = run("db", "shift", "--since", since, "--db", db)
    [line] = [x for x in out.splitlines() if x.strip().startswith("VIN1")]
    assert code == 1 and f"{bolts[0]} missing and held" in line
    assert line.count(bolts[0]) == 1, line


def test_a_shift_s_hand_over_is_not_all_well_with_a_bolt_held_after_its_ok(run, db):
    """A bolt held for a person after its OK was recorded (a later result of it that could
    not be read: a gap's ids, a double hit): its last result is not known, its vehicle's
    close named it not OK, yet the hand-over read the vehicle complete and exited 0, as if
    nothing were to hand over."""
    import json
    from datetime import UTC, datetime, timedelta

    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        bolts = [b.bolt_id for b in repo.bolts_for_model("WAGON-B")]
        repo.start_vehicle("VIN1", "WAGON-B")
        for tid, bolt in enumerate(bolts, 1):
            record(repo, "VIN1", bolt, tightening_id=tid)
        repo.others.record_unreadable(mid=61, revision=7, raw="00230061007 garbled", error="short",
                                      vin="VIN1", bolt=bolts[0], controller_vin=None,
                                      tightening_id=99, pset=1, result_at=None)
        closed = repo.close_vehicle("VIN1")
    assert closed.held, "the close names the hold"
    since = (datetime.now(UTC) - timedelta(hours=1)).isoformat()
    code, out, _ = run("db", "shift", "--since", since, "--db", db)
    assert f"{bolts[0]} held" in out
    assert code == 1, out
    code, out, _ = run("db", "shift", "--since", since, "--db", db, "--json")
    assert code == 1 and json.loads(out)["vehicles"][0]["held"], out


def test_a_shift_given_in_local_time_is_said_in_utc(run, db):
    """``--since 06:00+02:00`` is 04:00 UTC: the hand-over's first line said "from
    06:00 ... UTC", two hours off, beside vehicles' times in UTC."""
    from db.repository import Repository
    from stationd.boltfile import import_bolts

    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
    code, out, err = run("db", "shift", "--since", "2026-11-30T06:00+02:00", "--until",
                         "2026-11-30T14:00+02:00", "--db", db)
    assert code == 0, err
    assert out.startswith("from 2026-11-30 04:00 to 2026-11-30 12:00 UTC"), out


def test_a_results_export_of_a_station_file_names_the_station_on_every_row(run, tmp_path):
    """An export a plant collects from several stations said every result's VIN, bolt and
    values but not which station made it (an MES integrator's trial: the same model's B07 at
    two stations): each row carries the station's id (``line.station_id``, else
    ``opcua.station_id``: what its records carry to the line and OPC UA), in a column of its
    own, last (a sheet reading the columns by place keeps working); empty where the database
    is named without its station file."""
    import csv
    import io

    from db.repository import Repository
    from stationd.web.results import CSV_FIELDS

    station = _sim_station(tmp_path)
    station.write_text(station.read_text() + "line: {url: 'postgresql+psycopg://u@127.0.0.1:1/l'"
                       ", station_id: ST-07}\n")
    path = station.parent / "stationd-sim.db"
    assert run("db", "import", EXAMPLE, "--db", url_of(path))[0] == 0
    with Repository.open(url_of(path)) as repo:
        repo.start_vehicle("VIN1", "WAGON-B")
        record(repo, "VIN1", "SF-FL", ok=False, tightening_id=1)
        record(repo, "VIN1", "SF-FL", ok=True, tightening_id=2)
    # (appended: a sheet reading the columns by place keeps working; targets after it)
    assert CSV_FIELDS[-3:] == ("station", "torque_target_nm", "angle_target_deg")
    code, out, err = run("db", "export", "--results", "--config", station)
    rows = list(csv.DictReader(io.StringIO(out)))
    assert code == 0 and len(rows) > 2, err
    assert {r["station"] for r in rows} == {"ST-07"}
    code, out, _ = run("db", "export", "--results", "--config", station, "--format", "json")
    assert code == 0 and {r["station"] for r in json.loads(out)} == {"ST-07"}
    code, out, _ = run("db", "export", "--results", "--db", url_of(path))
    assert code == 0 and {r["station"] for r in csv.DictReader(io.StringIO(out))} == {""}
