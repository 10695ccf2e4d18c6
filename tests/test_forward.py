"""Store and forward to the line's PostgreSQL (a real server the tests start): every record in
order, exactly once whatever is replayed, stations and replaced databases kept apart, the
backlog and its alarm while the line database is down, a record it refuses for good kept in a
visible quarantine without blocking the rest."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import psycopg
import pytest
from sqlalchemy import make_url, select

from db.curves import store_curve
from db.repository import Repository
from stationd.boltfile import import_bolts
from stationd.config import load_station_config
from stationd.errors import ConfigError
from stationd.forward import (
    HEARTBEAT_S,
    LINE_FEED,
    BacklogBytes,
    Forwarder,
    LineConfig,
    LineDb,
    LineDown,
    LineRefuses,
    payload_bytes,
)
from stationd.stationcheck import check_station
from stationd.yamlio import YamlNode
from tests.db.conftest import BASE, record
from tests.test_line_tables import _forward

ROOT = Path(__file__).resolve().parents[1]

AT = datetime(2026, 11, 27, 8, 0, tzinfo=UTC)


@pytest.fixture
def table(tmp_path):
    """The test bolt table (tests/db's)."""
    p = tmp_path / "bolts.yaml"
    p.write_text(BASE)
    return p


def _station(tmp_path, name, table, vin, results):
    repo = Repository.open(f"sqlite:///{tmp_path / name}")
    import_bolts(repo, table)
    repo.start_vehicle(vin, "SEDAN")
    for tid, bolt in results:
        record(repo, vin, bolt, tightening_id=tid)
    return repo


def _line_rows(url, station_id=None):
    line = LineDb(url)
    engine = line._connect()
    q = select(LINE_FEED.c.station_id, LINE_FEED.c.db_id, LINE_FEED.c.seq, LINE_FEED.c.kind,
               LINE_FEED.c.record).order_by(LINE_FEED.c.station_id, LINE_FEED.c.seq)
    if station_id is not None:
        q = q.where(LINE_FEED.c.station_id == station_id)
    with engine.connect() as c:
        rows = list(c.execute(q))
    line.dispose()
    return rows


def _backup(folder: Path, name: str, to: str) -> None:
    """``sqlite3 name ".backup to"``, as the README makes a station's backup."""
    import sqlite3

    src, dst = sqlite3.connect(folder / name), sqlite3.connect(folder / to)
    try:
        src.backup(dst)
    finally:
        src.close()
        dst.close()


def test_every_record_goes_once_in_order_and_a_replay_inserts_nothing(tmp_path, table,
                                                                       pg_url):
    repo = _station(tmp_path, "st1.db", table, "VINF1", [(1, "B1"), (2, "B2")])
    repo.ledger.record_command(at=AT, user="sam", source="cli", kind="skip", vin="VINF1",
                               bolt="B3", comment="no access")
    f = Forwarder(repo, LineConfig(pg_url, "ST-01"))
    assert f.step() == 3 and f.step() == 0
    rows = _line_rows(pg_url)
    assert [(r.seq, r.kind) for r in rows] == [(1, "rundown"), (2, "rundown"), (3, "command")]
    assert rows[0].record["tightening_id"] == 1 and rows[2].record["user"] == "sam"
    assert {r.db_id for r in rows} == {repo.ledger.db_id()}
    # a crash after the push and before the cursor was saved: the same entries again
    repo.ledger.set_meta("forwarded_seq", "0")
    again = Forwarder(repo, LineConfig(pg_url, "ST-01"))
    assert again.step() == 3 and again.forwarded == 0
    assert len(_line_rows(pg_url)) == 3
    st = again.status()
    assert (st["up"], st["backlog"], st["cursor"], st["alarm"]) == (True, 0, 3, None)
    repo.close()


def test_a_tightening_curve_goes_to_the_line_with_its_samples(tmp_path, table, pg_url):
    """The forwarder takes any kind of feed entry: a curve (two traces of tightening 1)
    arrives after its rundown, samples and all, as JSONB the plant can query."""
    repo = _station(tmp_path, "st.db", table, "VINC", [(1, "B1")])
    torque = [0.5, 12.25, 30.0]
    store_curve(repo, tightening_id=1, trace_type=1, unit="deg", values=[0.0, 45.0, 90.0],
                sample_period_s=0.002)
    store_curve(repo, tightening_id=1, trace_type=2, unit="Nm", values=torque,
                sample_period_s=0.002)
    f = Forwarder(repo, LineConfig(pg_url, "ST-C"))
    assert f.step() == 3
    rows = _line_rows(pg_url, "ST-C")
    assert [r.kind for r in rows] == ["rundown", "curve", "curve"]
    curve = rows[2].record
    assert (curve["tightening_id"], curve["vin"], curve["bolt"], curve["unit"]) == (
        1, "VINC", "B1", "Nm")
    assert curve["values"] == pytest.approx(torque)
    repo.close()


def test_stations_and_a_replaced_database_stay_apart(tmp_path, table, pg_url):
    a = _station(tmp_path, "a.db", table, "VINA", [(1, "B1")])
    b = _station(tmp_path, "b.db", table, "VINB", [(1, "B1"), (2, "B2")])
    new_a = _station(tmp_path, "a2.db", table, "VINA2", [(5, "B1")])  # re-commissioned
    for repo, sid in ((a, "ST-A"), (b, "ST-B"), (new_a, "ST-A")):
        assert Forwarder(repo, LineConfig(pg_url, sid)).step() > 0
    rows = _line_rows(pg_url)
    assert sorted((r.station_id, r.record["vin"]) for r in rows) == [
        ("ST-A", "VINA"), ("ST-A", "VINA2"), ("ST-B", "VINB"), ("ST-B", "VINB")]
    assert len({r.db_id for r in rows if r.station_id == "ST-A"}) == 2   # seq 1 twice, apart
    for repo in (a, b, new_a):
        repo.close()


def test_a_database_put_back_from_a_backup_goes_on_as_a_new_series_losing_nothing(
        tmp_path, table, pg_url, caplog):
    """A maintenance trial: a backup put back, the station made new records numbered again
    from where the copy ended, under the same database id; the line (keyed by station, id
    and sequence number, a replay inserting nothing) dropped them silently as records it
    had.  The first record that is another record on the line starts a new series (a new
    id): the line keeps the records the copy lacked and takes the new ones beside them; the
    records before keep their id, and a replay still inserts nothing."""
    repo = _station(tmp_path, "st.db", table, "VINR1", [(1, "B1"), (2, "B2")])
    f = Forwarder(repo, LineConfig(pg_url, "ST-R"))
    assert f.step() == 2
    old_id = repo.ledger.db_id()
    _backup(tmp_path, "st.db", "backup.db")
    record(repo, "VINR1", "B3", tightening_id=3)          # made after the backup ...
    record(repo, "VINR1", "B1", tightening_id=4)
    assert f.step() == 2                                 # ... and on the line
    repo.close()
    restored = Repository.open(f"sqlite:///{tmp_path / 'backup.db'}")   # put back
    for tid, bolt in ((30, "B3"), (40, "B1"), (50, "B2")):
        record(restored, "VINR1", bolt, tightening_id=tid)   # numbered 3, 4, 5 again
    _forward(restored, pg_url, "ST-R")
    rows = _line_rows(pg_url, "ST-R")
    assert sorted(r.record["tightening_id"] for r in rows) == [1, 2, 3, 4, 30, 40, 50], \
        "records lost on the line"
    new = restored.ledger.series()
    assert new.db_id != old_id and (new.from_seq, new.before) == (3, old_id)
    assert {r.record["tightening_id"] for r in rows if r.db_id == new.db_id} == {30, 40, 50}
    assert "put back from a copy" in caplog.text
    restored.ledger.set_meta("forwarded_seq", "0")       # a replay: nothing doubled
    replay = _forward(restored, pg_url, "ST-R")
    assert replay.forwarded == 0 and len(_line_rows(pg_url, "ST-R")) == 7
    restored.close()


def test_a_line_database_that_is_down_keeps_the_backlog_then_catches_up(tmp_path, table,
                                                                         pg_url, pg_server):
    repo = _station(tmp_path, "st.db", table, "VIND", [(1, "B1"), (2, "B2")])
    down = pg_url.replace(f":{pg_server.port}/", ":1/")       # nothing listens there
    f = Forwarder(repo, LineConfig(down, "ST-D", max_records=1))
    with pytest.raises(LineDown):
        f.step()
    st = f.status()
    assert st["up"] is False and st["cursor"] == 0 and st["backlog"] == 2
    assert st["last_error"] and "bound 1" in (st["alarm"] or "")
    record(repo, "VIND", "B3", tightening_id=3)              # the station goes on recording
    back = Forwarder(repo, LineConfig(pg_url, "ST-D", max_records=1))
    assert back.step() == 3
    assert [r.record["tightening_id"] for r in _line_rows(pg_url, "ST-D")] == [1, 2, 3]
    assert back.status()["alarm"] is None
    repo.close()


def test_with_nothing_to_send_the_forwarder_finds_out_whether_the_line_answers(tmp_path,
                                                                              table):
    """Issue 30: a station with an empty backlog (a fresh database, the demo's) tried the line
    database only with its first record: an unreachable one was not known, nor said, until
    then.  Now a step with nothing to send asks it, and keeps asking while it is down."""
    repo = Repository.open(f"sqlite:///{tmp_path / 'st.db'}")
    import_bolts(repo, table)
    f = Forwarder(repo, LineConfig("postgresql+psycopg://line@127.0.0.1:1/line", "ST-E"))
    assert f.status()["up"] is None                     # not tried yet
    for _ in range(2):                                  # down: asked again at the next step
        with pytest.raises(LineDown, match="Connection refused"):
            f.step()
        st = f.status()
        assert (st["up"], st["backlog"], st["cursor"]) == (False, 0, 0)
        # a connection that failed is not told as the line's tables' fault
        assert st["last_error"].startswith("connection failed: ")
    assert f.tries == 0                                 # no push was made
    repo.close()


def test_with_nothing_to_send_a_line_that_answers_is_up_and_its_tables_made(tmp_path, table,
                                                                            pg_url):
    repo = Repository.open(f"sqlite:///{tmp_path / 'st.db'}")
    import_bolts(repo, table)
    f = Forwarder(repo, LineConfig(pg_url, "ST-U"))
    assert f.step() == 0
    assert f.status()["up"] is True and f.last_error is None
    assert _line_rows(pg_url, "ST-U") == []             # the line's tables are there, empty
    f.line.dispose()
    repo.close()


def test_with_nothing_to_send_a_line_database_gone_is_found_within_a_heartbeat(
        tmp_path, table, pg_url, pg_server):
    """A station with nothing to send said the line database "up" for as long as it was
    stopped (a trial: 70 s, until the next record): it is asked every HEARTBEAT_S."""
    now = [1000.0]
    repo = Repository.open(f"sqlite:///{tmp_path / 'st.db'}")
    import_bolts(repo, table)
    f = Forwarder(repo, LineConfig(pg_url, "ST-H"), ticks=lambda: now[0])
    assert f.step() == 0 and f.status()["up"] is True
    name = make_url(pg_url).database
    with psycopg.connect(f"host=127.0.0.1 port={pg_server.port} user=postgres "
                         "dbname=postgres", autocommit=True) as c:   # the line database gone
        c.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                  "WHERE datname = %s", (name,))
        c.execute(f'DROP DATABASE "{name}"')
    now[0] += HEARTBEAT_S / 2
    assert f.step() == 0 and f.status()["up"] is True     # not asked again yet
    now[0] += HEARTBEAT_S / 2
    with pytest.raises(LineDown):
        f.step()
    st = f.status()
    assert st["up"] is False and st["last_error"]
    f.line.dispose()
    repo.close()


def test_a_record_the_line_database_refuses_is_quarantined_not_blocking(tmp_path, table,
                                                                         pg_url):
    repo = _station(tmp_path, "st.db", table, "VINQ", [(1, "B1")])
    # PostgreSQL's jsonb takes no NUL character: a comment typed with one is refused for good
    repo.ledger.record_command(at=AT, user="sam", source="cli", kind="skip", vin="VINQ",
                               bolt="B2", comment="bad\x00comment")
    record(repo, "VINQ", "B3", tightening_id=3)
    f = Forwarder(repo, LineConfig(pg_url, "ST-Q"))
    assert f.step() == 3
    assert [r.seq for r in _line_rows(pg_url, "ST-Q")] == [1, 3]
    [q] = repo.ledger.quarantined()
    assert q["seq"] == 2 and q["kind"] == "command" and "Unicode" in q["reason"]
    assert f.status()["quarantined"] == 1 and f.status()["backlog"] == 0
    assert f.retry_quarantined() == (0, 1)                   # still refused, still kept
    repo.close()


def test_the_line_section_is_checked_with_its_line():
    cfg = LineConfig.from_node(YamlNode.parse(
        "url: postgresql+psycopg://stationd@line-db/line\nstation_id: ST-07\n"
        "backlog: {records: 500, size_mb: 20, age_h: 8}\n"))
    assert (cfg.station_id, cfg.max_records, cfg.max_mb, cfg.max_age_h) == (
        "ST-07", 500, 20.0, 8.0)
    for text, message in (("url: mysql://x/y\nstation_id: A\n", "PostgreSQL, not mysql"),
                          ("url: 'sqlite:///line.db'\nstation_id: A\n",
                           "PostgreSQL, not sqlite: give a postgresql[+]psycopg:// URL"),
                          ("url: postgresql+nosuchdriver://x/y\nstation_id: A\n",
                           "driver is psycopg 3"),
                          # Heroku's scheme: said "the line database is PostgreSQL, not
                          # postgres", which reads as a contradiction
                          ("url: postgres://x/y\nstation_id: A\n",
                           r"url: write postgresql\+psycopg://x/y \(postgres:// is not a "
                           r"driver SQLAlchemy has here\)$"),
                          ("url: postgresql://x/y\nstation_id: A\nbacklog: {size_mb: 0}\n",
                           "out of range"),
                          ("url: 'not a url'\nstation_id: A\n", "not a database URL"),
                          ("url: postgresql://x/y\n", "missing key: station_id"),
                          ("url: postgresql://x/y\nstation_id: A\nbacklog: {records: 0}\n",
                           "out of range"),
                          ("url: postgresql://x:99999/y\nstation_id: A\n", "port 99999")):
        with pytest.raises(ConfigError, match=message):
            LineConfig.from_node(YamlNode.parse(text, "station.yaml"))


def test_a_line_database_that_is_not_postgresql_is_refused_by_the_check_and_the_start(
        tmp_path):
    """An SQLite file as the line database would take the plant's records where nobody
    queries them: refused with the file, the line and what to write instead, by ``config
    check`` and by the loading a start or a reload does."""
    for f in (ROOT / "config" / "sim").iterdir():
        shutil.copy(f, tmp_path)
    station = tmp_path / "station.yaml"
    text = station.read_text()
    station.write_text(text + "line:\n  url: 'sqlite:///line.db'\n  station_id: ST-1\n")
    line = text.count("\n") + 2
    [error] = check_station(station).errors
    assert (error.path, error.line, error.key) == (str(station), line, "line.url")
    assert "the line database is PostgreSQL, not sqlite" in str(error)
    with pytest.raises(ConfigError, match=rf"station.yaml:{line}: line.url: the line database "
                                          "is PostgreSQL"):
        load_station_config(station, station=True)
    got = _cli("config", "check", str(station))
    assert got.returncode == 2 and f"station.yaml:{line}: line.url" in got.stderr + got.stdout
    assert "Traceback" not in got.stderr
    with pytest.raises(ValueError, match="PostgreSQL, not sqlite"):
        LineDb(f"sqlite:///{tmp_path / 'line.db'}")      # nor by code that skips the config


def test_the_backlog_in_bytes_is_measured_once_per_entry_and_alarms_past_its_bound(
        tmp_path, table, pg_url, pg_server):
    repo = _station(tmp_path, "st.db", table, "VINB", [(1, "B1"), (2, "B2"), (3, "B3")])
    entries = repo.ledger.since(0)
    sizes = [payload_bytes(e) for e in entries]
    assert all(300 < n < 3000 for n in sizes)          # a rundown's JSON: hundreds of bytes
    down = pg_url.replace(f":{pg_server.port}/", ":1/")
    bound_mb = (sum(sizes) - 1) / 1e6                  # just under the three records
    f = Forwarder(repo, LineConfig(down, "ST-B", max_mb=bound_mb))
    with pytest.raises(LineDown):
        f.step()
    st = f.status()
    assert (st["backlog"], st["backlog_bytes"], st["backlog_bytes_partial"]) == (
        3, sum(sizes), False)
    assert "MB of records not forwarded (bound" in (st["alarm"] or "")
    # each entry is measured once: a status with nothing new reads no entry to size it
    read: list[int] = []
    since = repo.ledger.since

    def counting(seq: int, limit: int = 1000) -> list[dict[str, Any]]:
        got: list[dict[str, Any]] = since(seq, limit)
        read.extend(e["seq"] for e in got)
        return got

    assert f.size.measure(counting, repo.ledger.last_seq(), None) and read == []
    repo.ledger.record_command(at=AT, user="sam", source="cli", kind="skip", vin="VINB",
                               bolt="B3", comment="the station goes on recording")
    st = f.status(measure_s=0)                         # no time to measure: a lower bound
    assert (st["backlog"], st["backlog_bytes"], st["backlog_bytes_partial"]) == (
        4, sum(sizes), True)
    assert f.size.measure(counting, repo.ledger.last_seq(), None) and read == [4]
    fourth = payload_bytes(repo.ledger.since(3)[0])
    assert f.status()["backlog_bytes"] == sum(sizes) + fourth
    # the line database back: forwarded entries leave the measure, the alarm goes
    f.line = LineDb(pg_url)
    assert f.step() == 4
    st = f.status()
    assert (st["backlog"], st["backlog_bytes"], st["alarm"]) == (0, 0, None)
    f.line.dispose()
    repo.close()


def test_entries_forwarded_leave_the_measured_backlog(tmp_path, table):
    """Part of the backlog forwarded (a batch): exactly its entries' bytes are taken off."""
    repo = _station(tmp_path, "st.db", table, "VINP", [(1, "B1"), (2, "B2"), (3, "B3")])
    entries = repo.ledger.since(0)
    size = BacklogBytes(0)
    assert size.measure(repo.ledger.since, 3, budget_s=0) is False and size.total == 0
    assert size.measure(repo.ledger.since, 3, None)
    assert size.total == sum(payload_bytes(e) for e in entries)
    size.forwarded(entries[:1], 1)
    assert (size.head, size.total) == (3, sum(payload_bytes(e) for e in entries[1:]))
    size.forwarded(entries[1:], 3)
    assert (size.head, size.total) == (3, 0)
    repo.close()


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    root = Path(__file__).resolve().parents[1]
    return subprocess.run([sys.executable, "-m", "stationd", *args], capture_output=True,
                          text=True, cwd=root, timeout=60, check=False)


def _line_file(station: Path, db: Path, line_url: str) -> None:
    """A station file with only its database and its line."""
    station.write_text(f"database: {{url: 'sqlite:///{db}'}}\n"
                       f"line: {{url: '{line_url}', station_id: ST-L}}\n")


def _retry_is_unreachable(station: Path, db: Path, pg_url: str, port: int) -> None:
    """With the line database down (the station file pointing at a port nothing serves), a
    quarantine retry says so in one readable line, exit 3."""
    down = pg_url.replace(f":{port}/", ":1/")
    _line_file(station, db, down)
    got = _cli("line", "quarantine", "--config", str(station), "--retry")
    assert got.returncode == 3 and "Traceback" not in got.stderr
    assert got.stderr.startswith(f"stationd: line database {down} unreachable: "), got.stderr
    # the status says so too, beside the backlog it reads from the station's database
    got = _cli("line", "status", "--config", str(station))
    assert got.returncode == 3 and got.stderr == "", got
    said = got.stdout.splitlines()[1]
    assert said.startswith("line database: does not answer (connection failed: ") and \
        said.endswith("); the records wait in the station's database until it does"), said
    assert " waiting (" in got.stdout          # the backlog, read from the station's database
    got = _cli("line", "status", "--config", str(station), "--json")
    st = json.loads(got.stdout)
    assert got.returncode == 3 and st["answers"] is False and st["unreachable"]


def test_a_quarantine_retry_names_the_line_database_it_could_not_reach(tmp_path, table,
                                                                      capsys):
    """Issue 30: ``line quarantine --retry`` said "line database unreachable: ..." without
    which, where ``line results`` and ``line init`` name its URL."""
    from stationd.cli import main

    _station(tmp_path, "st.db", table, "VINQ", []).close()
    station = tmp_path / "station.yaml"
    down = "postgresql+psycopg://line@127.0.0.1:1/line"
    _line_file(station, tmp_path / "st.db", down)
    for command in (["quarantine", "--retry"], ["results"]):
        assert main(["line", *command, "--config", str(station)]) == 3
        err = capsys.readouterr().err
        assert err.startswith(f"stationd: line database {down} unreachable: connection "
                              "failed: ") and err.count("\n") == 1, (command, err)
    # line init alike: exit 3 and the URL as given (a new user's trial: exit 2, and the URL
    # with the connect_timeout the command adds)
    assert main(["line", "init", down]) == 3
    err = capsys.readouterr().err
    assert err.startswith(f"stationd: line database {down} unreachable: connection "
                          "failed: ") and err.count("\n") == 1, err


def test_the_line_commands_show_the_backlog_and_retry_or_export_the_quarantine(
        tmp_path, table, pg_url, pg_server):
    repo = _station(tmp_path, "st.db", table, "VINL", [(1, "B1")])
    repo.ledger.record_command(at=AT, user="sam", source="cli", kind="skip", vin="VINL",
                               bolt="B2", comment="bad\x00comment")
    repo.close()
    station = tmp_path / "station.yaml"
    _line_file(station, tmp_path / "st.db", pg_url)
    got = _cli("line", "status", "--config", str(station), "--json")
    assert got.returncode == 1, got.stderr
    assert json.loads(got.stdout)["backlog"] == 2
    with Repository.open(f"sqlite:///{tmp_path / 'st.db'}") as r:
        size = sum(payload_bytes(e) for e in r.ledger.since(0))
    assert json.loads(got.stdout)["backlog_bytes"] == size
    got = _cli("line", "status", "--config", str(station))
    assert f"2 waiting ({size / 1e6:.2f} MB)" in got.stdout
    assert "line database: answers" in got.stdout.splitlines()
    with Repository.open(f"sqlite:///{tmp_path / 'st.db'}") as r:
        Forwarder(r, LineConfig(pg_url, "ST-L")).step()
    got = _cli("line", "status", "--config", str(station))
    assert got.returncode == 1 and "0 waiting" in got.stdout and "1 quarantined" in got.stdout
    got = _cli("line", "quarantine", "--config", str(station))
    assert got.returncode == 1 and "record 2 (command" in got.stdout
    out = tmp_path / "quarantine.json"
    got = _cli("line", "quarantine", "--config", str(station), "--retry", "--export", str(out))
    assert got.returncode == 1 and "0 taken by the line database, 1 still refused" in got.stdout
    assert json.loads(out.read_text())[0]["record"]["user"] == "sam"
    got = _cli("line", "quarantine", "--config", str(station), "--export", str(out))
    assert got.returncode == 2 and "exists" in got.stderr
    nowhere = tmp_path / "nodir" / "q.json"
    got = _cli("line", "quarantine", "--config", str(station), "--export", str(nowhere))
    assert got.returncode == 2 and got.stderr.strip().endswith(
        "(create it first, or give another --export)"), got.stderr
    _retry_is_unreachable(station, tmp_path / "st.db", pg_url, pg_server.port)


def test_the_line_commands_never_make_a_station_database_and_say_an_empty_quarantine(
        tmp_path, table, pg_url, pg_server):
    """A newcomer's `line status` on a station file whose database did not exist made one and
    said "0 of 0 waiting" (a wrong path read as everything forwarded); an empty quarantine
    printed nothing, and its retry with the line database down said exit 0.  The status says
    the station recorded nothing yet (or names another file) and asks the line database."""
    station = tmp_path / "station.yaml"
    missing = tmp_path / "nowhere.db"
    _line_file(station, missing, pg_url)
    got = _cli("line", "status", "--config", str(station))
    said = got.stdout.splitlines()
    assert got.returncode == 0 and got.stderr == "", got
    assert said[0] == (f"no database at {missing} yet: the station has recorded nothing, so "
                       f"nothing waits (or {station}'s database.url names another file)")
    assert said[1].endswith(": answers") and not missing.exists()
    # its quarantine is said empty as the status says it (it said "no database", exit 2:
    # a newcomer's trial); a retry, or an export, of a database not made is refused
    got = _cli("line", "quarantine", "--config", str(station))
    assert got.returncode == 0 and got.stderr == "", got
    assert got.stdout == (f"no database at {missing} yet: the station has recorded nothing, "
                          f"so nothing is quarantined (or {station}'s database.url names "
                          "another file)\n")
    for args in (("quarantine", "--retry"), ("quarantine", "--export",
                                             str(tmp_path / "q.json"))):
        got = _cli("line", *args, "--config", str(station))
        assert got.returncode == 2 and "no database at" in got.stderr, (args, got)
        assert "recorded nothing yet" in got.stderr and "--db" not in got.stderr
        assert not missing.exists()
    _station(tmp_path, "st.db", table, "VINE", [(1, "B1")]).close()
    _line_file(station, tmp_path / "st.db", pg_url)
    got = _cli("line", "quarantine", "--config", str(station))
    assert got.returncode == 0 and "nothing quarantined" in got.stdout
    _retry_is_unreachable(station, tmp_path / "st.db", pg_url, pg_server.port)


def test_two_hundred_rundowns_made_while_the_server_is_stopped_arrive_once_in_order(
        tmp_path, table, pg_url, pg_server):
    repo = _station(tmp_path, "st.db", table, "VIN200", [])
    f = Forwarder(repo, LineConfig(pg_url, "ST-200"))
    pg_server.pause()                           # the line's PostgreSQL stopped
    try:
        for tid in range(1, 201):              # the station goes on recording
            record(repo, "VIN200", "B1" if tid % 2 else "B2", ok=tid % 7 != 0,
                   tightening_id=tid)
        with pytest.raises(LineDown):
            f.step()
        assert f.status()["backlog"] == 200
    finally:
        pg_server.resume()
    while f.step():
        pass
    tids = [r.record["tightening_id"] for r in _line_rows(pg_url, "ST-200")]
    assert tids == list(range(1, 201))          # every one, once, in order
    repo.close()


_FORWARD_SLOWLY = """
import sys
import time
import stationd.forward as fw
from db.repository import Repository
fw.BATCH = 10                                   # many small transactions: a kill lands mid-way
f = fw.Forwarder(Repository.open(sys.argv[1]), fw.LineConfig(sys.argv[2], "ST-K"))
n = 0
while f.step():
    n += 1
    if n == 10:                                 # 100 forwarded: said, then slower, so the
        print("mid-way", flush=True)            # kill lands before the last of 1000 however
    if n >= 10:                                 # loaded the machine (it read 1000 under
        time.sleep(0.2)                         # load: the kill came after the end)
"""


def test_a_forwarder_killed_mid_way_loses_and_doubles_nothing(tmp_path, table, pg_url):
    """kill -9 between two of its transactions (or inside one): the next forwarder starts from
    what the line database has, and the key (station, db_id, seq) keeps a replay harmless."""
    repo = _station(tmp_path, "st.db", table, "VINK", [])
    for tid in range(1, 1001):
        record(repo, "VINK", "B1" if tid % 2 else "B2", tightening_id=tid)
    p = subprocess.Popen([sys.executable, "-c", _FORWARD_SLOWLY,
                          f"sqlite:///{tmp_path / 'st.db'}", pg_url], cwd=ROOT,
                         stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout is not None
        assert p.stdout.readline().strip() == "mid-way"   # (EOF: it died first)
        p.kill()                                # SIGKILL: no cleanup of any kind
        p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
    part = len(_line_rows(pg_url, "ST-K"))
    assert 0 < part < 1000, f"the kill did not land mid-way ({part} forwarded)"
    f = Forwarder(repo, LineConfig(pg_url, "ST-K"))
    while f.step():
        pass
    tids = [r.record["tightening_id"] for r in _line_rows(pg_url, "ST-K")]
    assert tids == list(range(1, 1001))
    repo.close()


def _has_line_table(url: str) -> bool:
    from sqlalchemy import inspect

    line = LineDb(url)
    try:
        return bool(inspect(line._connect()).has_table(LINE_FEED.name))
    finally:
        line.dispose()


def _as_role(pg_url: str, role: str, grant: bool = False) -> str:
    """``pg_url``'s database with the line's tables made by its own role (the owner), and
    the URL of ``role``: a role that may connect but, as in a new user's trial, has no
    privilege on those tables (``grant``: the README's grant for a forwarding role)."""
    from sqlalchemy import create_engine, make_url, text

    _has_line_table(pg_url)                     # the owner makes the tables
    owner = create_engine(pg_url, isolation_level="AUTOCOMMIT")
    try:
        with owner.connect() as c:
            if c.execute(text("SELECT 1 FROM pg_roles WHERE rolname = :r"),
                         {"r": role}).first() is None:
                c.execute(text(f'CREATE ROLE "{role}" LOGIN'))
            if grant:
                c.execute(text(f'GRANT SELECT, INSERT ON line_feed, line_parameters TO "{role}"'))
    finally:
        owner.dispose()
    return make_url(pg_url).set(username=role).render_as_string(hide_password=False)


def _owner_sql(pg_url: str, sql: str) -> None:
    from sqlalchemy import create_engine, text

    owner = create_engine(pg_url, isolation_level="AUTOCOMMIT")
    try:
        with owner.connect() as c:
            c.execute(text(sql))
    finally:
        owner.dispose()


def test_a_role_that_may_not_write_keeps_the_records_in_the_backlog_never_quarantined(
        tmp_path, table, pg_url):
    """The trial's data loss: a role that connects but has no privilege on the line's tables
    (another role made them) had every record "refused for good" and quarantined.  It is the
    line database down for this role: the records wait, the link names the role, the
    privilege and the grant, and once granted every record arrives, none quarantined."""
    other = _as_role(pg_url, "fwd_noprivs")
    repo = _station(tmp_path, "st.db", table, "VINP", [(1, "B1"), (2, "B2")])
    f = Forwarder(repo, LineConfig(other, "ST-P"))
    for _ in range(2):                           # retried, never quarantined
        with pytest.raises(LineRefuses):
            f.step()
    st = f.status()
    assert (st["up"], st["cursor"], st["backlog"], st["quarantined"]) == (False, 0, 2, 0)
    assert st["last_error"] == (
        "role fwd_noprivs lacks INSERT and SELECT on line_feed, INSERT on line_parameters: "
        "the forwarders cannot write (as the tables' owner: GRANT SELECT, INSERT ON "
        "line_feed, line_parameters TO fwd_noprivs)")
    assert repo.ledger.quarantined() == []
    _as_role(pg_url, "fwd_noprivs", grant=True)
    assert f.step() == 2 and f.status()["up"] is True
    assert [r.seq for r in _line_rows(pg_url, "ST-P")] == [1, 2]
    assert repo.ledger.quarantined() == []
    f.line.dispose()
    repo.close()


def test_a_grant_revoked_while_forwarding_is_the_line_down_not_a_refused_record(
        tmp_path, table, pg_url):
    """The privilege goes while the forwarder's connection is up (its check passed): the
    insert's insufficient_privilege is classified where "for good" is decided, as the line
    database down; a quarantined record's retry keeps it quarantined, with its own reason."""
    other = _as_role(pg_url, "fwd_revoked", grant=True)
    repo = _station(tmp_path, "st.db", table, "VINR", [(1, "B1")])
    repo.ledger.record_command(at=AT, user="sam", source="cli", kind="skip", vin="VINR",
                               bolt="B2", comment="bad\x00comment")    # refused for good
    f = Forwarder(repo, LineConfig(other, "ST-R"))
    assert f.step() == 2 and [q["seq"] for q in repo.ledger.quarantined()] == [2]
    _owner_sql(pg_url, 'REVOKE INSERT ON line_feed FROM "fwd_revoked"')
    record(repo, "VINR", "B3", tightening_id=3)
    with pytest.raises(LineRefuses, match=r"^role fwd_revoked lacks INSERT on line_feed: "):
        f.step()
    assert (f.cursor, f.status()["backlog"], f.up) == (2, 1, False)
    with pytest.raises(LineRefuses):
        f.retry_quarantined()
    [q] = repo.ledger.quarantined()
    assert q["seq"] == 2 and "Unicode" in q["reason"]           # its own reason kept
    _owner_sql(pg_url, 'GRANT INSERT ON line_feed TO "fwd_revoked"')
    assert f.step() == 1 and [r.seq for r in _line_rows(pg_url, "ST-R")] == [1, 3]
    f.line.dispose()
    repo.close()


def test_for_good_is_a_records_content_never_the_roles_rights_or_a_read_only_server(pg_url):
    """The one decision, on the server's own errors: a value jsonb does not take is refused
    for good; a privilege the role lacks (42501), a read-only transaction (25006) and an
    authorization error (class 28: at a connection, where the server says it) are the line
    database's state."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.exc import DBAPIError

    from stationd.forward import refused_for_good

    other = _as_role(pg_url, "fwd_classify")
    owner = create_engine(pg_url)
    role = create_engine(other)

    def error(engine, *sql: str) -> DBAPIError:
        with engine.connect() as c, pytest.raises(DBAPIError) as got:
            for s in sql:
                c.execute(text(s))
        return got.value

    try:
        nul = error(owner, "SELECT '\"a\\u0000b\"'::jsonb")
        denied = error(role, "INSERT INTO line_parameters (station_id, db_id, model, bolt, "
                       "version, first_seq) VALUES ('S', 'D', 'M', 'B', 1, 1)")
        read_only = error(owner, "SET TRANSACTION READ ONLY", "CREATE TEMP TABLE t (x int)")
        assert [e.orig.sqlstate for e in (nul, denied, read_only)] == [
            "22P05", "42501", "25006"]
        assert refused_for_good(nul)
        assert not refused_for_good(denied) and not refused_for_good(read_only)

        class RefusedError(Exception):
            sqlstate = "28000"     # invalid_authorization_specification

        assert not refused_for_good(DBAPIError("INSERT", None, RefusedError("not permitted")))
        # the line's state, not the record's: a deadlock or serialization failure (a retry
        # resolves it), the line's tables not made yet (line init)
        for code in ("40001", "40P01", "42P01", "42703", "42883"):
            state = type("StateError", (Exception,), {"sqlstate": code})
            assert not refused_for_good(DBAPIError("INSERT", None, state("later"))), code
    finally:
        owner.dispose()
        role.dispose()


def test_line_init_and_status_say_a_role_that_may_not_write_not_ready_or_answers(
        tmp_path, table, pg_url, capsys):
    """The trial: with a role that connects but has no privilege on tables another role made,
    ``line init`` said "every table there already (...: ready for the stations'
    forwarders)", exit 0, and ``line status`` "answers", exit 0.  Each now says which
    privilege is missing on which table and the grant, non-zero."""
    from stationd.cli import main

    other = _as_role(pg_url, "fwd_trial")
    shown = other                                  # no password: shown as it is
    # exit 3, as line status's (a new user's trial: init said 2 where status said 3); the
    # URL as given (it said the connect_timeout the command adds)
    assert main(["line", "init", other]) == 3
    out, err = capsys.readouterr()
    assert out == "" and err == (
        f"stationd: line database {shown}: role fwd_trial lacks "
        "INSERT and SELECT on line_feed, INSERT on line_parameters: the forwarders cannot "
        "write (as the tables' owner: GRANT SELECT, INSERT ON line_feed, line_parameters "
        "TO fwd_trial)\n")
    _station(tmp_path, "st.db", table, "VINT", [(1, "B1")]).close()
    station = tmp_path / "station.yaml"
    _line_file(station, tmp_path / "st.db", other)
    got = _cli("line", "status", "--config", str(station))
    assert got.returncode == 3 and got.stderr == "", got
    said = got.stdout.splitlines()[1]
    assert said == ("line database: the forwarders cannot write (role fwd_trial lacks INSERT "
                    "and SELECT on line_feed, INSERT on line_parameters: the forwarders cannot "
                    "write (as the tables' owner: GRANT SELECT, INSERT ON line_feed, "
                    "line_parameters TO fwd_trial)); the records wait in the station's "
                    "database until they can"), said
    assert "answers" not in got.stdout and "1 waiting" in got.stdout
    st = json.loads(_cli("line", "status", "--config", str(station), "--json").stdout)
    assert st["cannot_write"].startswith("role fwd_trial lacks ") and st["answers"] is True
    got = _cli("line", "quarantine", "--config", str(station), "--retry")
    assert got.returncode == 3 and got.stderr.startswith(
        f"stationd: line database {shown}: role fwd_trial lacks INSERT"), got.stderr
    _as_role(pg_url, "fwd_trial", grant=True)                # granted: ready, and it answers
    assert main(["line", "init", other]) == 0
    assert "ready for the stations' forwarders" in capsys.readouterr().out
    got = _cli("line", "status", "--config", str(station))
    assert got.returncode == 1 and "line database: answers" in got.stdout.splitlines()


def test_two_backups_put_back_in_turn_keep_each_record_under_its_first_series(
        tmp_path, table, pg_url):
    """As test_a_database_put_back_from_a_backup_goes_on_as_a_new_series_losing_nothing,
    twice: the second renewal keeps only the id just before it (Series.before), so the
    records below the first renewal, under the database's first id on the line, go from
    then on under the second id.  A replay of them (a crash between a push and the cursor
    saved, as that test models it; or a quarantined one retried) is then no replay: each
    is inserted again, under another id, the line holding it twice."""
    repo = _station(tmp_path, "st.db", table, "VINT1", [(1, "B1"), (2, "B2")])
    f = Forwarder(repo, LineConfig(pg_url, "ST-T"))
    assert f.step() == 2
    _backup(tmp_path, "st.db", "b1.db")
    record(repo, "VINT1", "B3", tightening_id=3)
    assert f.step() == 1
    repo.close()
    first = Repository.open(f"sqlite:///{tmp_path / 'b1.db'}")         # put back: 1
    record(first, "VINT1", "B3", tightening_id=30)                       # seq 3 again
    _forward(first, pg_url, "ST-T")
    first.close()
    _backup(tmp_path, "b1.db", "b2.db")
    first = Repository.open(f"sqlite:///{tmp_path / 'b1.db'}")
    record(first, "VINT1", "B1", tightening_id=40)                       # seq 4
    _forward(first, pg_url, "ST-T")
    first.close()
    second = Repository.open(f"sqlite:///{tmp_path / 'b2.db'}")        # put back: 2
    record(second, "VINT1", "B1", tightening_id=400)                     # seq 4 again
    _forward(second, pg_url, "ST-T")
    rows = _line_rows(pg_url, "ST-T")
    assert sorted(r.record["tightening_id"] for r in rows) == [1, 2, 3, 30, 40, 400]
    second.ledger.set_meta("forwarded_seq", "0")                         # a replay
    replay = _forward(second, pg_url, "ST-T")
    rows = _line_rows(pg_url, "ST-T")
    shown = [(r.db_id[:8], r.seq, r.record["tightening_id"]) for r in rows]
    assert replay.forwarded == 0 and len(rows) == 6, \
        f"records 1 and 2 inserted again under another id: {shown}"
    second.close()


def test_a_quarantined_record_that_is_another_on_the_line_stays_quarantined(tmp_path, table,
                                                                          pg_url):
    """A reviewer: a record kept in quarantine, retried (``line quarantine --retry``) after
    its database was put back from a backup, is another record on the line at its number:
    the retry raised (a traceback).  It stays in quarantine, said why; nothing written."""
    repo = _station(tmp_path, "st.db", table, "VINQ1", [(1, "B1")])
    _backup(tmp_path, "st.db", "backup.db")
    record(repo, "VINQ1", "B2", tightening_id=2)
    assert Forwarder(repo, LineConfig(pg_url, "ST-Q")).step() == 2
    repo.close()
    restored = Repository.open(f"sqlite:///{tmp_path / 'backup.db'}")
    record(restored, "VINQ1", "B3", tightening_id=20)           # numbered 2 again
    restored.ledger.quarantine(2, "refused for good before")     # as if refused then
    f = Forwarder(restored, LineConfig(pg_url, "ST-Q"))
    assert f.retry_quarantined() == (0, 1)
    [kept] = restored.ledger.quarantined()
    assert kept["seq"] == 2
    assert sorted(r.record["tightening_id"] for r in _line_rows(pg_url, "ST-Q")) == [1, 2]
    restored.close()


def test_a_result_garbled_with_a_control_character_reaches_the_line_unreadable(tmp_path, table,
                                                                             pg_url):
    """Line noise turned a byte of a MID 0061 into a NUL: the result does not read and is
    kept whole as unreadable, its raw text with the byte escaped (``\\x00``, as a non-ASCII
    byte is), so that it reaches the line database like any record.  Before: its text held
    the NUL itself, which PostgreSQL's jsonb refuses: quarantined for good, every retry
    refused, the line never heard of it."""
    from drivers.wrench.openprotocol.message import decode
    from drivers.wrench.openprotocol.reading import receive

    good = ("02310061001         010001020103PF6000                   04VIN123"
            "                   050006005070004080002091101111120045001300550014005000150050"
            "121600010170020018000901900095202026-12-02:01:00:00212026-12-01:01:00:002222300"
            "00000041")
    assert len(good) == 231
    u = receive(decode((good[:150] + "\x00" + good[151:]).encode()))
    assert u.tightening_id == 41
    repo = _station(tmp_path, "st.db", table, "VINQ", [(1, "B1")])
    repo.others.record_unreadable(mid=u.mid, revision=u.revision, raw=u.raw, error=u.error,
                                  vin="VINQ", bolt="B2", controller_vin=None,
                                  tightening_id=u.tightening_id, pset=u.pset, result_at=None,
                                  header_len=u.header_len)
    f = Forwarder(repo, LineConfig(pg_url, "ST-Q"))
    assert f.step() == 2
    assert [(r.seq, r.kind) for r in _line_rows(pg_url, "ST-Q")] == [(1, "rundown"),
                                                                      (2, "unreadable")]
    assert repo.ledger.quarantined() == []
    assert "\\x00" in u.raw and u.raw.isprintable()
    repo.close()
