"""The line database's typed tables (``line_rundowns``, ``line_commands``, ``line_gaps``,
``line_calibration_checks``, ``line_unattributed``) on a real PostgreSQL (the tests'
throw-away server): every record typed in the transaction that inserts it into
``line_feed``, once however often it is forwarded, also when an earlier stationd's forwarder
inserts it; a line database made by the earlier version upgraded in place with its records
typed; and the quality engineer's first three questions answered from the indexes."""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta

import psycopg
import pytest
from sqlalchemy import Engine, MetaData, Table, func, inspect, select, text
from sqlalchemy.dialects.postgresql import insert as pg_insert

from db.checks import record_check
from db.engine import make_engine
from db.entered import record_entered
from db.kinds import LOOSENING, NOK, OK, TIGHTENING
from db.ledger import (
    CHECK,
    CLOSING,
    COMMAND,
    CONTROLLER_EVENT,
    GAP,
    RUNDOWN,
    UNATTRIBUTED,
    UNREADABLE,
)
from db.repository import Repository
from stationd.boltfile import import_bolts
from stationd.cli import main
from stationd.forward import Forwarder, LineConfig, LineDb
from stationd.linedb import (
    LINE_CHECKS,
    LINE_CLOSINGS,
    LINE_COMMANDS,
    LINE_CONTROLLER_EVENTS,
    LINE_FEED,
    LINE_FEED_VIN,
    LINE_GAPS,
    LINE_PARAMETERS,
    LINE_RUNDOWNS,
    LINE_UNATTRIBUTED,
    LINE_UNREADABLE,
    TYPED,
    Typed,
    create_line_schema,
    operator_of,
    results,
    trigger_body,
)
from tests.db.conftest import BASE, record

VIN, OTHER = "9SDST0010TL000001", "9SDST0011TL000002"
AT = datetime(2026, 11, 27, 8, 0, tzinfo=UTC)

#: the README's three queries, as a quality engineer types them
ONE_VIN = """
SELECT at, station_id, bolt, kind, status, torque_nm, torque_min_nm, torque_max_nm,
       angle_deg, operator
FROM line_rundowns
WHERE vin = :vin
ORDER BY at"""
ONE_BOLT = """
SELECT at, station_id, vin, status, torque_nm, torque_min_nm, torque_max_nm, angle_deg
FROM line_rundowns
WHERE bolt = :bolt AND at >= :shift_start AND at < :shift_end
ORDER BY at"""
NOK_RATE = """
SELECT station_id, date_trunc('hour', at) AS hour, count(*) AS tightenings,
       count(*) FILTER (WHERE status = 'nok') AS nok,
       round(100.0 * count(*) FILTER (WHERE status = 'nok') / count(*), 1) AS nok_pct
FROM line_rundowns
WHERE kind = 'tightening' AND at >= :since AND at < :until
GROUP BY station_id, hour
ORDER BY station_id, hour"""

OUT_OF_WINDOW = """
SELECT station_id, vin, bolt, at, torque_nm, torque_min_nm, torque_max_nm, status
FROM line_rundowns
WHERE kind = 'tightening' AND (torque_nm < torque_min_nm OR torque_nm > torque_max_nm)"""
VEHICLE_STORY = """
SELECT at, station_id, 'command' AS what, kind, bolt, user_name AS who, comment
FROM line_commands WHERE vin = :vin
UNION ALL
SELECT at, station_id, 'rundown', kind || ' ' || status, bolt, operator, NULL
FROM line_rundowns WHERE vin = :vin
ORDER BY at"""


def _station(tmp_path, name):
    table = tmp_path / f"{name}.yaml"
    table.write_text(BASE)
    repo = Repository.open(f"sqlite:///{tmp_path / name}.db")
    import_bolts(repo, table)
    return repo


def forwarding_role(pg_url: str, port: int, role: str) -> None:
    """A login ``role`` granted what the README gives the stations' forwarding role: SELECT
    and INSERT on line_feed and line_parameters, no right to create."""
    db = pg_url.rsplit("/", 1)[1]
    with psycopg.connect(f"host=127.0.0.1 port={port} user=postgres dbname={db}",
                         autocommit=True) as c:
        c.execute(f"CREATE ROLE {role} LOGIN")
        c.execute("REVOKE CREATE ON SCHEMA public FROM PUBLIC")
        c.execute(f"GRANT SELECT, INSERT ON line_feed, line_parameters TO {role}")


def _forward(repo, url, sid):
    f = Forwarder(repo, LineConfig(url, sid))
    while f.step():
        pass
    f.line.dispose()
    return f


def _engine(url) -> Engine:
    return LineDb(url)._connect()


def _count(engine, table) -> int:
    with engine.connect() as c:
        return int(c.scalar(select(func.count()).select_from(table)) or 0)


def _typed_counts(engine) -> dict[str, int]:
    return {t.table.name: _count(engine, t.table) for t in TYPED}


def _feed_counts(engine) -> dict[str, int]:
    with engine.connect() as c:
        by_kind = dict(c.execute(select(LINE_FEED.c.kind, func.count())
                                 .group_by(LINE_FEED.c.kind)).all())
    return {t.table.name: int(by_kind.get(t.kind, 0)) for t in TYPED}


def _every_kind(repo):
    """One record of each kind a typed table holds, on ``VIN``."""
    repo.start_vehicle(VIN, "SEDAN")
    record(repo, VIN, "B1", tightening_id=11, torque_nm=50.5, angle_deg=31.5,
           operator="olga", result_at=AT)
    record(repo, VIN, "B2", ok=False, tightening_id=12, torque_nm=21.0, angle_deg=12.5,
           offline=True)      # made while the link was down, fetched after
    record(repo, VIN, "B2", tightening_id=13, torque_nm=0.0, angle_deg=320.0,
           kind=LOOSENING, params_sent={"pset": 92, "torque": None, "angle": None,
                                        "loosen": True})
    repo.ledger.record_command(at=AT, user="sam", source="cli", kind="skip", vin=VIN,
                               bolt="B3", comment="no access")
    repo.others.record_gap(14, 16, VIN, "the controller no longer has them")
    record_check(repo, at=AT, pair="pair1", verdict="moved", reference="R1", offset_mm=1.5,
                 tolerance_mm=0.5, reason=None,
                 references={"R1": {"offset_mm": 1.5, "measured_mm": [1.0, 2.0, 3.0]}})
    repo.others.record_unattributed(vin=VIN, controller_vin="OTHERVIN", tightening_id=17, pset=3,
                                    ok=True, torque_nm=24.0, angle_deg=30.0, result_at=AT,
                                    reason="no bolt enabled", result_type=2)
    repo.others.record_controller_event(result_type=3, what="batch increment", vin=VIN, bolt="B3",
                                        controller_vin=VIN, tightening_id=18, pset=21, ok=True,
                                        torque_nm=None, angle_deg=None, result_at=AT)
    repo.others.record_unreadable(mid=61, revision=7, raw="00230061007 garbled", error="too short",
                                  vin=VIN, bolt="B3", controller_vin=None, tightening_id=19,
                                  pset=None, result_at=None)


def test_every_kind_of_record_lands_typed_with_its_columns_units_and_comments(tmp_path,
                                                                            pg_url):
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    repo.close_vehicle(VIN)      # B1 OK, B2 loosened last, B3 never run down
    _forward(repo, pg_url, "ST-A")
    engine = _engine(pg_url)
    assert _typed_counts(engine) == {"line_rundowns": 3, "line_commands": 1, "line_gaps": 1,
                                     "line_calibration_checks": 1, "line_unattributed": 1,
                                     "line_controller_events": 1,
                                     "line_unreadable_results": 1,
                                     "line_vehicle_closings": 1}
    r = LINE_RUNDOWNS.table.c
    with engine.connect() as c:
        rows = c.execute(select(LINE_RUNDOWNS.table).order_by(r.seq)).all()
        assert [(x.bolt, x.kind, x.status, x.tightening_id) for x in rows] == [
            ("B1", TIGHTENING, OK, 11), ("B2", TIGHTENING, NOK, 12), ("B2", LOOSENING, OK, 13)]
        b1 = rows[0]
        assert (b1.station_id, b1.vin, b1.model, b1.parameters_version, b1.pset) == (
            "ST-A", VIN, "SEDAN", 1, 1)
        assert (b1.torque_nm, b1.torque_target_nm, b1.torque_min_nm, b1.torque_max_nm,
                b1.torque_unit) == (50.5, 50.0, 45.0, 55.0, "Nm")
        assert (b1.angle_deg, b1.angle_min_deg, b1.angle_max_deg, b1.angle_unit) == (
            31.5, 15.0, 60.0, "deg")
        assert (rows[1].torque_min_nm, rows[1].angle_max_deg, rows[1].pset) == (
            23.0, 50.0, None)
        assert (b1.operator, rows[1].operator) == ("olga", None)
        assert [x.offline for x in rows] == [False, True, False]
        # a loosening ran its loosen pset, with the controller's own limits: none of the bolt's
        assert (rows[2].pset, rows[2].parameters_version, rows[2].torque_min_nm,
                rows[2].torque_max_nm, rows[2].angle_min_deg) == (92, 1, None, None, None)
        assert (b1.x_mm, b1.y_mm, b1.z_mm, b1.match_distance_mm) == (1.0, 2.0, 3.0, 1.5)
        assert b1.result_at == AT and b1.recorded_at.tzinfo is not None
        feed_at = c.scalar(select(LINE_FEED.c.at).where(LINE_FEED.c.seq == b1.seq))
        assert b1.at == feed_at and b1.db_id == repo.ledger.db_id()
        cmd = c.execute(select(LINE_COMMANDS.table)).one()
        assert (cmd.user_name, cmd.source, cmd.kind, cmd.vin, cmd.bolt, cmd.comment,
                cmd.command_at) == ("sam", "cli", "skip", VIN, "B3", "no access", AT)
        gap = c.execute(select(LINE_GAPS.table)).one()
        assert (gap.first_id, gap.last_id, gap.vin) == (14, 16, VIN)
        chk = c.execute(select(LINE_CHECKS.table)).one()
        assert (chk.pair, chk.verdict, chk.reference, chk.offset_mm, chk.tolerance_mm,
                chk.check_at) == ("pair1", "moved", "R1", 1.5, 0.5, AT)
        assert chk.measurements["R1"]["measured_mm"] == [1.0, 2.0, 3.0]
        # the README's further queries: out of the window; a vehicle's commands and rundowns
        assert [(x.bolt, x.torque_nm) for x in c.execute(text(OUT_OF_WINDOW))] == [
            ("B2", 21.0)]
        story = c.execute(text(VEHICLE_STORY), {"vin": VIN}).all()
        assert [(x.what, x.kind, x.who) for x in story] == [
            ("rundown", "tightening ok", "olga"), ("rundown", "tightening nok", None),
            ("rundown", "loosening ok", None), ("command", "skip", "sam")]
        un = c.execute(select(LINE_UNATTRIBUTED.table)).one()
        assert (un.vin, un.controller_vin, un.tightening_id, un.pset, un.status,
                un.reason, un.result_type) == (VIN, "OTHERVIN", 17, 3, OK, "no bolt enabled",
                                               2)        # a loosening, said as one
        ev = c.execute(select(LINE_CONTROLLER_EVENTS.table)).one()
        assert (ev.result_type, ev.what, ev.bolt, ev.tightening_id, ev.pset, ev.status,
                ev.torque_nm, ev.result_at) == (3, "batch increment", "B3", 18, 21, OK, None,
                                                AT)
        bad = c.execute(select(LINE_UNREADABLE.table)).one()
        assert (bad.mid, bad.revision, bad.raw, bad.error, bad.bolt, bad.tightening_id,
                bad.result_at) == (61, 7, "00230061007 garbled", "too short", "B3", 19, None)
        # the vehicle left with what it left undone (an MES integrator's trial: a vehicle
        # leaving with bolts not tightened never reached the line)
        gone = c.execute(select(LINE_CLOSINGS.table)).one()
        assert (gone.vin, gone.model, gone.how, gone.bolts, gone.ok, gone.nok, gone.missing,
                gone.skipped, gone.loosen) == (VIN, "SEDAN", "lowered", 3, 1, 0, 1, 0, 1)
        assert gone.not_ok == {"missing": ["B3"], "loosen": ["B2"], "held": ["B3"]}
        assert gone.closed_at.tzinfo is not None and gone.closed_at <= gone.at
        # real types and a comment on every column, for Grafana, Power BI and people
        types = dict(c.execute(text(
            "SELECT column_name, data_type FROM information_schema.columns "
            "WHERE table_name = 'line_rundowns'")).all())
        assert (types["torque_nm"], types["pset"], types["at"], types["tightening_id"]) == (
            "double precision", "integer", "timestamp with time zone", "bigint")
        for t in TYPED:
            missing = c.execute(text(
                "SELECT a.attname FROM pg_attribute a WHERE a.attrelid = CAST(:t AS regclass) "
                "AND a.attnum > 0 AND NOT a.attisdropped AND col_description(a.attrelid, "
                "a.attnum) IS NULL"), {"t": t.table.name}).scalars().all()
            assert missing == [], t.table.name
            assert c.scalar(text("SELECT obj_description(CAST(:t AS regclass), 'pg_class')"),
                            {"t": t.table.name})
    engine.dispose()
    repo.close()


def test_a_replay_and_a_second_forwarder_type_nothing_twice(tmp_path, pg_url):
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    _forward(repo, pg_url, "ST-A")
    engine = _engine(pg_url)
    once = _typed_counts(engine)
    repo.ledger.set_meta("forwarded_seq", "0")          # a replay after a crash
    _forward(repo, pg_url, "ST-A")
    f = Forwarder(repo, LineConfig(pg_url, "ST-A"))      # pushed again, a batch at a time
    entries = repo.ledger.since(0)
    assert f.line.push("ST-A", f.series.db_id, entries) == 0
    assert f.line.push("ST-A", f.series.db_id, entries[:2] + entries[:2]) == 0
    f.line.dispose()
    assert _typed_counts(engine) == once == _feed_counts(engine)
    record(repo, VIN, "B3", tightening_id=20)            # then one more: once
    _forward(repo, pg_url, "ST-A")
    assert _count(engine, LINE_RUNDOWNS.table) == once["line_rundowns"] + 1
    assert _typed_counts(engine) == _feed_counts(engine)
    engine.dispose()
    repo.close()


def _old_line_database(url):
    """The line database as the version before the typed tables made it: ``line_feed``,
    ``line_parameters`` and the VIN index, nothing else."""
    engine = make_engine(url)
    with engine.begin() as conn:
        LINE_FEED.create(conn)
        LINE_PARAMETERS.create(conn)
    assert LINE_FEED_VIN.name in {i["name"] for i in inspect(engine).get_indexes("line_feed")}
    return engine


def _old_push(engine, sid, db_id, entries):
    """What the earlier forwarder inserted: the ``line_feed`` rows alone."""
    rows = [{"station_id": sid, "db_id": db_id, "seq": e["seq"], "kind": e["kind"],
             "at": datetime.fromisoformat(e["at"]).replace(tzinfo=UTC),
             "record": e["record"], "operator": operator_of(e)} for e in entries]
    with engine.begin() as conn:
        conn.execute(pg_insert(LINE_FEED).on_conflict_do_nothing(), rows)


def test_a_line_database_made_by_the_earlier_version_is_upgraded_in_place(tmp_path, pg_url,
                                                                          capsys):
    """The earlier version's line database with a station's records: ``line results``
    says how to upgrade it; ``line init`` makes the typed tables and fills them from
    ``line_feed``; a station still on the earlier version goes on forwarding and its rows
    are typed; a new forwarder's too; ``line init`` again changes nothing."""
    old = _old_line_database(pg_url)
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    db_id = repo.ledger.db_id()
    _old_push(old, "ST-OLD", db_id, repo.ledger.since(0))
    config = tmp_path / "station.yaml"
    config.write_text(f"database: {{url: 'sqlite:///{tmp_path / 'a.db'}'}}\n"
                      f"line: {{url: '{pg_url}', station_id: ST-A}}\n")
    assert main(["line", "results", "--config", str(config)]) == 2
    err = capsys.readouterr().err
    assert "no line_rundowns (made by an earlier stationd)" in err and "line init" in err
    from stationd.web.line import LineRoutes, NotUpgraded
    page = LineRoutes()                                  # the /line page: the same (503)
    with pytest.raises(NotUpgraded):
        page._read(pg_url, VIN, None, None, 10)

    assert main(["line", "init", pg_url]) == 0
    assert [r["bolt"] for r in page._read(pg_url, VIN, None, "B2", 10)] == ["B2", "B2"]
    out = capsys.readouterr().out
    assert "made line_calibration_checks, line_commands, line_controller_events, line_gaps, " \
           "line_rundowns, line_unattributed, line_unreadable_results" in out
    assert "filled from line_feed: line_rundowns 3 rows, line_commands 1 row, " \
           "line_gaps 1 row, line_calibration_checks 1 row, line_unattributed 1 " \
           "row, line_controller_events 1 row, line_unreadable_results 1 row" in out
    assert _typed_counts(old) == _feed_counts(old)
    assert [r.bolt for r in results(old, vin=VIN)] == ["B2", "B2", "B1"]

    record(repo, VIN, "B3", tightening_id=21)            # a station not upgraded yet
    _old_push(old, "ST-OLD", db_id, repo.ledger.since(0)[-1:])
    record(repo, VIN, "B1", tightening_id=22)            # and an upgraded one
    _forward(repo, pg_url, "ST-NEW")
    assert _typed_counts(old) == _feed_counts(old)
    assert {(r.station_id, r.tightening_id) for r in results(old, vin=VIN)} >= {
        ("ST-OLD", 21), ("ST-NEW", 22), ("ST-NEW", 11)}

    assert main(["line", "init", pg_url]) == 0
    out = capsys.readouterr().out
    assert "every table there already" in out and "filled" not in out
    assert main(["line", "results", "--config", str(config), "--vin", VIN, "--station",
                 "ST-OLD", "--json"]) == 0
    rows = [json.loads(ln) for ln in capsys.readouterr().out.splitlines()]
    assert (rows[0]["bolt"], rows[0]["tightening_id"], rows[0]["torque_window_nm"]) == (
        "B3", 21, [120.0, 110.0, 130.0])
    old.dispose()
    repo.close()


def test_a_forwarder_of_the_new_version_upgrades_the_line_database_on_its_first_connection(
        tmp_path, pg_url):
    old = _old_line_database(pg_url)
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    entries = repo.ledger.since(0)
    _old_push(old, "ST-A", repo.ledger.db_id(), entries[:4])
    _forward(repo, pg_url, "ST-A")                       # takes the rest, fills the first
    assert _typed_counts(old) == _feed_counts(old)
    assert sum(_typed_counts(old).values()) == len(entries)
    old.dispose()
    repo.close()


def test_a_role_granted_insert_on_line_feed_alone_has_its_records_typed(tmp_path, pg_url,
                                                                        pg_server):
    """The owner made the tables (``line init``); the stations forward as a role granted
    SELECT and INSERT on line_feed and line_parameters, as the README says: the trigger
    types their rows with the owner's rights, none is refused or quarantined."""
    assert main(["line", "init", pg_url]) == 0
    forwarding_role(pg_url, pg_server.port, "station_fw")
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    f = _forward(repo, pg_url.replace("postgres@", "station_fw@"), "ST-R")
    assert f.status()["quarantined"] == 0 and f.status()["backlog"] == 0
    engine = _engine(pg_url)
    assert _typed_counts(engine) == _feed_counts(engine)
    assert _count(engine, LINE_RUNDOWNS.table) == 3
    engine.dispose()
    repo.close()


def test_a_record_of_unexpected_shape_is_typed_with_nulls_never_refused(pg_url):
    """A typed row never refuses what line_feed takes (it would quarantine the record at the
    station): values of another JSON type are NULL; a time without an offset is UTC
    whatever the session's time zone."""
    line = LineDb(pg_url)
    odd = {"id": "x", "vin": 7, "bolt": "B9", "status": OK, "torque_nm": "high",
           "angle_deg": 1e300, "tightening_id": 12.7, "parameters": {"version": 2 ** 40},
           "position_mm": None, "result_at": "2026-11-27T08:00:00",
           "recorded_at": "2026-11-27T09:00:00+01:00"}
    assert line.push("ST-X", "db", [{"seq": 1, "kind": RUNDOWN, "at": AT.isoformat(),
                                     "record": odd}]) == 1
    engine = line._connect()
    with engine.begin() as c:
        c.execute(text("SET TIME ZONE 'America/New_York'"))
        row = c.execute(select(LINE_RUNDOWNS.table)).one()
    assert (row.record_id, row.vin, row.torque_nm, row.parameters_version, row.x_mm) == (
        None, None, None, None, None)
    assert (row.bolt, row.kind, row.angle_deg, row.tightening_id) == (
        "B9", TIGHTENING, 1e300, 13)
    assert row.result_at == AT and row.recorded_at == AT
    line.dispose()


def _rundown_entry(template, seq, at, vin, bolt, status, kind=TIGHTENING):
    rec = {**template, "id": seq, "vin": vin, "bolt": bolt, "status": status,
           "rundown": kind}
    return {"seq": seq, "kind": RUNDOWN, "at": at.isoformat(), "record": rec}


def test_the_three_quality_questions_are_answered_from_their_indexes(tmp_path, pg_url):
    """A shift at two stations, pushed as their forwarders push: one VIN across stations,
    one bolt over the shift and the NOK rate per station and hour, each query as the README
    gives it, each answered from an index (the planner told not to scan the table whole,
    so that a query no index serves shows as a sequential scan)."""
    repo = _station(tmp_path, "a")
    repo.start_vehicle(VIN, "SEDAN")
    record(repo, VIN, "B1", tightening_id=1)
    template = repo.ledger.since(0)[0]["record"]
    repo.close()
    shift = datetime(2026, 11, 27, 6, 0, tzinfo=UTC)
    line, seq = LineDb(pg_url), 0
    for station, noks in (("ST-A", {1, 5}), ("ST-B", {2})):
        entries = []
        for i in range(12):                              # every 20 min for 4 h
            seq += 1
            at = shift + timedelta(minutes=20 * i)
            vin = VIN if i == 4 else f"9SDST00{i:02d}TL{seq:06d}"
            entries.append(_rundown_entry(template, seq, at, vin, "B1" if i % 2 else "B2",
                                          NOK if i in noks else OK))
        seq += 1                                         # a loosening: not in the rate
        entries.append(_rundown_entry(template, seq, shift, OTHER, "B1", OK, LOOSENING))
        assert line.push(station, "db-" + station, entries) == 13
    engine = line._connect()
    with engine.connect() as c:
        got = c.execute(text(ONE_VIN), {"vin": VIN}).all()
        assert [(r.station_id, r.bolt) for r in got] == [("ST-A", "B2"), ("ST-B", "B2")]
        got = c.execute(text(ONE_BOLT), {"bolt": "B1", "shift_start": shift,
                                         "shift_end": shift + timedelta(hours=2)}).all()
        assert [(r.station_id, r.at) for r in got] == sorted(
            [(s, shift + timedelta(minutes=20 * i)) for s in ("ST-A", "ST-B")
             for i in (1, 3, 5)] + [("ST-A", shift), ("ST-B", shift)], key=lambda x: x[1])
        c.execute(text("SET TIME ZONE 'UTC'"))
        got = c.execute(text(NOK_RATE), {"since": shift,
                                         "until": shift + timedelta(hours=4)}).all()
        assert [(r.station_id, r.hour.hour, r.tightenings, r.nok) for r in got] == [
            ("ST-A", 6, 3, 1), ("ST-A", 7, 3, 1), ("ST-A", 8, 3, 0), ("ST-A", 9, 3, 0),
            ("ST-B", 6, 3, 1), ("ST-B", 7, 3, 0), ("ST-B", 8, 3, 0), ("ST-B", 9, 3, 0)]
        assert float(got[0].nok_pct) == pytest.approx(33.3)
        c.execute(text("ANALYZE line_rundowns"))
        c.execute(text("SET enable_seqscan = off"))
        end = shift + timedelta(hours=8)
        params = {"vin": VIN, "bolt": "B1", "shift_start": shift, "shift_end": end,
                  "since": shift, "until": end}
        # (the hourly rate: the time index, or on a table this small one station's)
        for sql, indexes in ((ONE_VIN, {"ix_line_rundowns_vin"}),
                             (ONE_BOLT, {"ix_line_rundowns_bolt"}),
                             (NOK_RATE, {"ix_line_rundowns_at", "ix_line_rundowns_station"})):
            plan = "\n".join(c.execute(text("EXPLAIN " + sql), params).scalars())
            assert any(i in plan for i in indexes) and "Seq Scan" not in plan, plan
    line.dispose()


def test_line_results_filters_a_bolt_over_a_shift(tmp_path, pg_url, capsys):
    repo = _station(tmp_path, "a")
    repo.start_vehicle(VIN, "SEDAN")
    record(repo, VIN, "B1", tightening_id=1)
    record(repo, VIN, "B2", tightening_id=2)
    _forward(repo, pg_url, "ST-A")
    config = tmp_path / "station.yaml"
    config.write_text(f"database: {{url: 'sqlite:///{tmp_path / 'a.db'}'}}\n"
                      f"line: {{url: '{pg_url}', station_id: ST-A}}\n")
    now = datetime.now(UTC)
    since = (now - timedelta(hours=8)).replace(tzinfo=None).isoformat()   # UTC, no offset
    assert main(["line", "results", "--config", str(config), "--bolt", "B2", "--since",
                 since, "--json"]) == 0
    [row] = [json.loads(ln) for ln in capsys.readouterr().out.splitlines()]
    assert (row["bolt"], row["tightening_id"]) == ("B2", 2)
    assert main(["line", "results", "--config", str(config), "--bolt", "B2", "--until",
                 since]) == 1
    assert "no rundowns of bolt B2" in capsys.readouterr().out
    assert main(["line", "results", "--config", str(config), "--since", "yesterday"]) == 2
    assert "--since 'yesterday': an ISO time" in capsys.readouterr().err
    repo.close()


def test_the_typed_tables_are_declared_once_for_the_kinds_of_the_feed():
    """Each typed table is one kind of the feed, keyed like line_feed, its SQL one
    expression per column (a new kind: one more entry)."""
    assert [t.kind for t in TYPED] == [RUNDOWN, COMMAND, GAP, CHECK, UNATTRIBUTED,
                                       CONTROLLER_EVENT, UNREADABLE, CLOSING]
    for t in TYPED:
        assert [c.name for c in t.table.primary_key] == ["station_id", "db_id", "seq"]
        assert len(t.exprs) == len(t.table.columns)
        assert all(c.comment for c in t.table.columns) and t.table.comment


def test_two_first_starts_make_the_trigger_once(pg_url):
    """Two processes making the schema at once (the advisory lock): one trigger, and a
    third call changes nothing."""
    from concurrent.futures import ThreadPoolExecutor

    engines = [make_engine(pg_url) for _ in range(3)]
    with ThreadPoolExecutor(2) as pool:
        changes = list(pool.map(create_line_schema, engines[:2]))
    assert sorted(ch.trigger for ch in changes) == [False, True]
    assert create_line_schema(engines[2]).trigger is False
    with engines[2].connect() as c:
        assert c.scalar(text("SELECT count(*) FROM pg_trigger WHERE tgname = "
                             "'line_feed_typed'")) == 1
    for e in engines:
        e.dispose()


#: the trigger's SQL at TYPED_VERSION: a change of TYPED changes it, and then the version must
#: go up too (else a line database that has the older SQL keeps it: see TYPED_VERSION)
TRIGGER_SHA256 = {1: "446e86d6658db69f57ddf73563842e00b690eac87fc392c5a61455dc994d1f49",
                  2: "eed0f0cfb83562bb0f0303ab2188f6dccda471d004a541bd82df27fe80f4d4e0",
                  3: "cc625563ef1638100ca531254b61e304c53501ab1577e943c670e801bf38891c",
                  4: "1ba6cb194967583b94b0dc24eec25ee14f5e0147b2cd15bb2173f5d957a56db6",
                  5: "4233cde999117d8e1c20d454e5b30b622b98ed280ff61e971f568e1d45c86c56",
                  6: "9639d9829aba29a1a8142382fe51424fe0626ec40653e16ef6b8ee6f3f11f416",
                  7: "70c7cfc062edd933aae313b131b6fdefadbac5e99b02fd897797a6a6118ff51c"}


def test_a_held_bolts_reason_reaches_the_line_with_its_controller_event(tmp_path, pg_url):
    """A bolt held where no result says it (a lost push, a link cut) is stored as a
    controller event with a note naming the tightening that may be its own: the note is in
    the record and in ``line_controller_events.note`` (an MES integrator's trial: the line had
    "result unknown after a lost push", no tightening id and no word of which it was)."""
    from db.kinds import LOST_UNKNOWN, lost_unknown_note

    repo = _station(tmp_path, "a")
    repo.start_vehicle(VIN, "SEDAN")
    note = lost_unknown_note(28, 2, AT.timestamp())
    repo.others.record_controller_event(result_type=0, what=LOST_UNKNOWN, vin=VIN, bolt="B3",
                                        controller_vin=None, tightening_id=None, pset=2, ok=None,
                                        torque_nm=None, angle_deg=None, result_at=None, note=note)
    _forward(repo, pg_url, "ST-A")
    engine = _engine(pg_url)
    with engine.connect() as c:
        ev = c.execute(select(LINE_CONTROLLER_EVENTS.table)).one()
        assert (ev.what, ev.bolt, ev.note) == (LOST_UNKNOWN, "B3", note)
        # no verdict: not counted by a query of status 'nok' (an MES integrator's trial)
        assert ev.status is None
        assert "tightening 28 may be its own" in ev.note
        record = c.scalar(select(LINE_FEED.c.record).where(LINE_FEED.c.seq == ev.seq))
        assert record["note"] == note
    engine.dispose()


def test_the_trigger_version_goes_up_with_its_sql():
    import hashlib

    from stationd.linedb import TYPED_VERSION, installed_version, trigger_body

    assert hashlib.sha256(trigger_body().encode()).hexdigest() == TRIGGER_SHA256.get(
        TYPED_VERSION), "TYPED changed: raise TYPED_VERSION and pin the new SQL's hash here"
    assert installed_version(trigger_body()) == TYPED_VERSION
    assert installed_version(None) == installed_version("BEGIN RETURN NULL; END") == 0


def test_an_older_stationd_never_puts_back_an_older_trigger(pg_url):
    """A newer version's trigger is left as it is by this version (a line upgraded one
    station at a time: each older forwarder's start would put its SQL back); an older or
    unversioned one is replaced."""
    from stationd.linedb import TYPED_VERSION, installed_version

    engine = make_engine(pg_url)
    create_line_schema(engine)

    def put(version_line):
        with engine.begin() as c:
            c.execute(text("CREATE OR REPLACE FUNCTION line_feed_typed() RETURNS trigger "
                           f"LANGUAGE plpgsql AS $x${version_line}BEGIN RETURN NULL; END$x$"))

    def installed():
        with engine.connect() as c:
            return c.scalar(text("SELECT prosrc FROM pg_proc WHERE proname = "
                                 "'line_feed_typed'"))

    newer = f"\n-- stationd typed tables, version {TYPED_VERSION + 1}\n"
    put(newer)
    assert create_line_schema(engine).trigger is False and newer in installed()
    put("\n")                                            # not ours, or before versions
    assert create_line_schema(engine).trigger is True
    assert installed_version(installed()) == TYPED_VERSION
    engine.dispose()


def test_a_station_upgraded_before_its_line_database_goes_on_forwarding(tmp_path, pg_url,
                                                                         pg_server, capsys):
    """The earlier version's line database, its tables owned by the line engineer, the
    stations forwarding as a role granted SELECT and INSERT on them: a station of this
    version may not make the typed tables, and forwards to line_feed all the same (a
    warning, no backlog, nothing quarantined); the owner's ``line init`` then makes them and
    types every record; ``line init`` as the forwarding role says why it cannot."""
    _old_line_database(pg_url).dispose()
    db = pg_url.rsplit("/", 1)[1]
    with psycopg.connect(f"host=127.0.0.1 port={pg_server.port} user=postgres dbname={db}",
                         autocommit=True) as c:
        c.execute("CREATE ROLE station_up LOGIN")
        c.execute("REVOKE CREATE ON SCHEMA public FROM PUBLIC")
        c.execute("GRANT SELECT, INSERT ON line_feed, line_parameters TO station_up")
    role_url = pg_url.replace("postgres@", "station_up@")
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    f = _forward(repo, role_url, "ST-UP")
    st = f.status()
    assert (st["up"], st["backlog"], st["quarantined"]) == (True, 0, 0)
    engine = make_engine(pg_url)
    assert not inspect(engine).has_table("line_rundowns")
    assert main(["line", "init", role_url]) == 2
    assert "the typed tables: permission denied" in capsys.readouterr().err
    assert main(["line", "init", pg_url]) == 0
    assert "line_rundowns 3 rows" in capsys.readouterr().out
    record(repo, VIN, "B3", tightening_id=30)            # typed from now on, by the trigger
    _forward(repo, role_url, "ST-UP")
    assert _typed_counts(engine) == _feed_counts(engine)
    assert _count(engine, LINE_RUNDOWNS.table) == 4
    engine.dispose()
    repo.close()


def test_a_kind_typed_in_a_later_version_is_filled_from_what_line_feed_holds(tmp_path,
                                                                             pg_url):
    """The step a new kind takes: a line database at the version before (no
    line_controller_events, the trigger's SQL older) with such records already in
    line_feed; the next schema check makes the table, fills it and types from then on."""
    engine = make_engine(pg_url)
    create_line_schema(engine)
    with engine.begin() as c:
        c.execute(text("DROP TABLE line_controller_events"))
        c.execute(text("CREATE OR REPLACE FUNCTION line_feed_typed() RETURNS trigger "
                       "LANGUAGE plpgsql AS $x$\n-- stationd typed tables, version 1\n"
                       "BEGIN RETURN NULL; END$x$"))
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    line = LineDb(pg_url)
    line._engine = engine                                # as a forwarder of version 1 did
    assert line.push("ST-A", repo.ledger.db_id(), repo.ledger.since(0)) == 9
    change = create_line_schema(engine)
    assert change.made == ("line_controller_events",) and change.trigger
    assert ("line_controller_events", 1) in change.filled
    repo.others.record_controller_event(result_type=5, what="bypass", vin=VIN, bolt=None,
                                        controller_vin=None, tightening_id=40, pset=None, ok=True,
                                        torque_nm=None, angle_deg=None, result_at=None)
    _forward(repo, pg_url, "ST-A")
    with engine.connect() as c:
        assert c.execute(select(LINE_CONTROLLER_EVENTS.table.c.what).order_by(
            LINE_CONTROLLER_EVENTS.table.c.seq)).scalars().all() == ["batch increment",
                                                                     "bypass"]
    engine.dispose()
    repo.close()


def _version_2() -> tuple[Typed, ...]:
    """The typed tables as version 2 declared them: ``line_rundowns`` without the entered
    outcome's columns (each table's :attr:`Typed.added` left out)."""
    out = []
    for t in TYPED:
        if t is LINE_CLOSINGS:    # version 7's
            continue
        keep = [(c, e) for c, e in zip(t.table.columns, t.exprs, strict=True)
                if c.name not in t.added]
        table = Table(t.table.name, MetaData(), *(c._copy() for c, _ in keep))
        out.append(Typed(t.kind, table, tuple(e for _, e in keep)))
    return tuple(out)


def _line_database_at_version_2(url) -> Engine:
    """A line database as stationd's version 2 of the typed tables left it: its trigger's
    SQL the one pinned for version 2, ``line_rundowns`` without the entered columns."""
    import hashlib

    body = trigger_body(_version_2(), 2)
    assert hashlib.sha256(body.encode()).hexdigest() == TRIGGER_SHA256[2]
    engine = make_engine(url)
    create_line_schema(engine)
    with engine.begin() as c:
        c.execute(text("ALTER TABLE line_rundowns DROP COLUMN entered_by, DROP COLUMN "
                       "entered_comment, DROP COLUMN unreadable_record_id, DROP COLUMN "
                       "offline"))
        c.execute(text("CREATE OR REPLACE FUNCTION line_feed_typed() RETURNS trigger "
                       "LANGUAGE plpgsql SECURITY DEFINER SET search_path FROM CURRENT AS "
                       f"$typed${body}$typed$"))
    return engine


def _entered(repo, bolt: str, tightening_id: int, comment: str) -> tuple[int, int]:
    """An unreadable result for ``bolt`` and the outcome sam entered for it: their ids."""
    uid = repo.others.record_unreadable(mid=61, revision=7, raw=f"00230061007 garbled {bolt}",
                                        error="too short", vin=VIN, bolt=bolt, controller_vin=None,
                                        tightening_id=tightening_id, pset=None, result_at=None)
    rid = record_entered(repo, vin=VIN, bolt=bolt, ok=True, torque_nm=49.6, angle_deg=31.0,
                         at=datetime.now(UTC), user="sam", source="cli", comment=comment)
    return uid, rid


def _entered_rows(engine):
    r = LINE_RUNDOWNS.table.c
    u = LINE_UNREADABLE.table.c
    with engine.connect() as c:
        return c.execute(
            select(r.bolt, r.tightening_id, r.entered_by, r.entered_comment, u.raw)
            .select_from(LINE_RUNDOWNS.table.outerjoin(LINE_UNREADABLE.table, (
                u.station_id == r.station_id) & (u.db_id == r.db_id)
                & (u.record_id == r.unreadable_record_id)))
            .order_by(r.seq)).all()


def test_an_entered_outcome_has_its_own_columns_in_a_line_database_upgraded_in_place(
        tmp_path, pg_url, capsys):
    """A line database of version 2 holding an entered outcome (typed by its trigger, so
    without who entered it): ``line init`` adds ``entered_by``, ``entered_comment`` and
    ``unreadable_record_id`` to ``line_rundowns``, fills them from line_feed, brings the
    trigger up to date; the next entered outcome is typed with them; ``line results`` and the
    line page's rows say who entered it; a second ``line init`` changes nothing."""
    old = _line_database_at_version_2(pg_url)
    repo = _station(tmp_path, "a")
    repo.start_vehicle(VIN, "SEDAN")
    record(repo, VIN, "B1", tightening_id=11, operator="olga")
    _entered(repo, "B2", 12, "read on the controller")
    line = LineDb(pg_url)
    line._engine = old                                   # as a forwarder of version 2 did
    assert line.push("ST-A", repo.ledger.db_id(), repo.ledger.since(0)) == 4
    assert "entered_by" not in {c["name"] for c in inspect(old).get_columns("line_rundowns")}
    assert _count(old, LINE_RUNDOWNS.table) == 2

    assert main(["line", "init", pg_url]) == 0
    out = capsys.readouterr().out
    # (offline, of version 5, added with them: both rows have it, false)
    assert "added to line_rundowns: entered_by, entered_comment, unreadable_record_id, " \
           "offline (2 rows given their values from line_feed)" in out, out
    assert "trigger that types line_feed's new rows: made or brought up to date" in out
    cols = [c["name"] for c in inspect(old).get_columns("line_rundowns")]
    assert cols == [c.name for c in LINE_RUNDOWNS.table.columns]   # one order, any version
    assert [tuple(x) for x in _entered_rows(old)] == [
        ("B1", 11, None, None, None),
        ("B2", 12, "sam", "read on the controller", "00230061007 garbled B2")]

    _entered(repo, "B3", 13, "torque read on the screen")    # typed by the new trigger
    _forward(repo, pg_url, "ST-A")
    assert _entered_rows(old)[-1] == ("B3", 13, "sam", "torque read on the screen",
                                      "00230061007 garbled B3")
    assert _typed_counts(old) == _feed_counts(old)
    with old.connect() as c:                              # its columns commented too
        assert c.scalar(text("SELECT col_description('line_rundowns'::regclass, "
                             "(SELECT attnum FROM pg_attribute WHERE attrelid = "
                             "'line_rundowns'::regclass AND attname = 'entered_by'))"))

    config = tmp_path / "station.yaml"
    config.write_text(f"database: {{url: 'sqlite:///{tmp_path / 'a.db'}'}}\n"
                      f"line: {{url: '{pg_url}', station_id: ST-A}}\n")
    assert main(["line", "results", "--config", str(config), "--vin", VIN, "--json"]) == 0
    rows = {(r := json.loads(ln))["bolt"]: r for ln in capsys.readouterr().out.splitlines()}
    assert (rows["B2"]["entered_by"], rows["B2"]["entered_comment"]) == (
        "sam", "read on the controller")
    assert rows["B2"]["unreadable_record_id"] is not None
    assert (rows["B1"]["entered_by"], rows["B1"]["unreadable_record_id"]) == (None, None)
    assert main(["line", "results", "--config", str(config), "--vin", VIN]) == 0
    lines = capsys.readouterr().out.splitlines()
    [b1] = [ln for ln in lines if " B1 " in ln]
    [b2] = [ln for ln in lines if " B2 " in ln]
    assert "OK (entered by sam)" in b2 and "entered" not in b1
    from stationd.web.line import LineRoutes
    page = {r["bolt"]: r for r in LineRoutes()._read(pg_url, VIN, None, None, 10)}
    assert (page["B3"]["entered_by"], page["B1"]["entered_by"]) == ("sam", None)

    assert main(["line", "init", pg_url]) == 0
    out = capsys.readouterr().out
    assert "every table there already" in out and "added" not in out
    old.dispose()
    repo.close()


def test_a_forwarding_role_on_a_version_2_line_database_forwards_and_the_owner_upgrades_it(
        tmp_path, pg_url, pg_server, capsys):
    """The stations forward as a role granted SELECT and INSERT only: a station of this
    version may not add the columns, and forwards all the same (its entered outcome typed by
    the version-2 trigger, without who entered it); the owner's ``line init`` adds them and
    gives that row its values."""
    _line_database_at_version_2(pg_url).dispose()
    db = pg_url.rsplit("/", 1)[1]
    with psycopg.connect(f"host=127.0.0.1 port={pg_server.port} user=postgres dbname={db}",
                         autocommit=True) as c:
        c.execute("CREATE ROLE station_v2 LOGIN")
        c.execute("REVOKE CREATE ON SCHEMA public FROM PUBLIC")
        c.execute("GRANT SELECT, INSERT ON line_feed, line_parameters TO station_v2")
    repo = _station(tmp_path, "a")
    repo.start_vehicle(VIN, "SEDAN")
    _entered(repo, "B2", 12, "read on the controller")
    f = _forward(repo, pg_url.replace("postgres@", "station_v2@"), "ST-R")
    st = f.status()
    assert (st["up"], st["backlog"], st["quarantined"]) == (True, 0, 0)
    engine = make_engine(pg_url)
    assert "entered_by" not in {c["name"] for c in inspect(engine).get_columns(
        "line_rundowns")}
    assert _count(engine, LINE_RUNDOWNS.table) == 1      # typed, by the version-2 trigger
    assert main(["line", "init", pg_url]) == 0
    assert "(1 row given their values from line_feed)" in capsys.readouterr().out
    assert [tuple(x) for x in _entered_rows(engine)] == [
        ("B2", 12, "sam", "read on the controller", "00230061007 garbled B2")]
    engine.dispose()
    repo.close()


def test_a_first_line_init_names_each_table_once(pg_url, capsys):
    """A new line database's ``line init`` listed its nine tables twice in one line (made
    ..., then the same nine "ready"): once now."""
    from stationd.cli import main

    assert main(["line", "init", pg_url]) == 0
    [first, *_] = capsys.readouterr().out.splitlines()
    assert first.count("line_rundowns") == 1, first
    assert first.endswith(": ready for the stations' forwarders") and " made " in first


def test_line_status_before_the_station_recorded_anything_still_asks_the_line(tmp_path,
                                                                               capsys):
    """A station with no database yet (nothing recorded): ``line status`` said only "no
    database at ...", exit 2, nothing of whether the line database answers (a trial)."""
    from stationd.cli import main

    station = tmp_path / "station.yaml"
    station.write_text(f"database: {{url: 'sqlite:///{tmp_path / 'none.db'}'}}\n"
                       "line: {url: 'postgresql+psycopg://u@127.0.0.1:1/line', "
                       "station_id: ST-L}\n")
    code = main(["line", "status", "--config", str(station)])
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert code == 3 and err == "", (out, err)
    assert lines[0].startswith(f"no database at {tmp_path / 'none.db'} yet: the station has "
                               "recorded nothing, so nothing waits")
    assert lines[1].startswith("line database postgresql+psycopg://u@127.0.0.1:1/line"), lines
    assert "does not answer (" in lines[1]
    assert not (tmp_path / "none.db").exists()          # looked at, never made
