"""The line database's column comments, read back from a real PostgreSQL as ``\\d+``,
Grafana and Power BI show them: the torque units written ``Nm`` (never "nm", which reads as
nanometres), ``line_rundowns.result_at`` said on the station's clock as the README says and
the data show (the controller's own time is not forwarded); and an earlier version's wrong
comments in a line database made before brought up to date by the owner's ``line init``,
left alone (never refused) by a forwarding role that may not write them."""

from __future__ import annotations

import re

from sqlalchemy import Engine, text

from db.engine import make_engine
from stationd.cli import main
from stationd.linedb import LINE_RUNDOWNS, TYPED
from tests.test_line_tables import _count, _every_kind, _forward, _station, forwarding_role

#: what an earlier version wrote on line_rundowns (the trial user's ``\d+``)
OLD = {"result_at": "the controller's time of the result (its clock)",
       "torque_min_nm": "the torque window's min in force (nm; NULL: none)"}


def _comments(engine: Engine) -> dict[tuple[str, str], str | None]:
    """Every column comment of the typed tables, by (table, column), as the server has it."""
    with engine.connect() as c:
        return {(t, col): comment for t, col, comment in c.execute(text(
            "SELECT c.relname, a.attname, col_description(c.oid, a.attnum) FROM pg_class c "
            "JOIN pg_attribute a ON a.attrelid = c.oid AND a.attnum > 0 AND NOT "
            "a.attisdropped WHERE c.relname = ANY(:names)"),
            {"names": [t.table.name for t in TYPED]})}


def test_every_column_comment_says_nm_as_newton_metres_and_result_at_on_whose_clock(pg_url):
    assert main(["line", "init", pg_url]) == 0
    engine = make_engine(pg_url)
    comments = _comments(engine)
    engine.dispose()
    assert len(comments) == sum(len(t.table.columns) for t in TYPED)
    for (table, column), comment in comments.items():
        assert comment, (table, column)
        assert not re.search(r"\bnm\b", comment), (table, column, comment)   # nanometres
        if column.startswith("torque") and column.endswith("_nm"):
            assert "(Nm" in comment, (table, column, comment)
        if column.startswith("angle") and column.endswith("_deg"):
            assert "(degrees" in comment, (table, column, comment)
    rundown = comments[("line_rundowns", "result_at")]
    assert rundown is not None and "the station took the result, on its clock" in rundown
    assert "not the controller's time" in rundown, rundown
    for table in ("line_unattributed", "line_controller_events", "line_unreadable_results"):
        other = comments[(table, "result_at")]   # these do hold the controller's time
        assert other is not None and other.startswith("the controller's time"), (table, other)
    assert comments[("line_rundowns", "torque_max_nm")] == \
        "the torque window's max in force (Nm; NULL: none)"


def _write_old(url: str) -> None:
    engine = make_engine(url)
    with engine.begin() as c:
        for column, comment in OLD.items():   # COMMENT takes a literal, no parameter
            quoted = comment.replace("'", "''")
            c.execute(text(f"COMMENT ON COLUMN line_rundowns.{column} IS '{quoted}'"))
    engine.dispose()


def test_line_init_brings_an_earlier_versions_comments_up_to_date(tmp_path, pg_url,
                                                                   pg_server, capsys):
    """A line database an earlier version made, with its wrong comments; the stations
    forward as a role granted SELECT and INSERT only: the forwarder leaves the comments (it
    may not write them) and forwards all the same, as does one that owns the tables; the
    owner's ``line init`` corrects them and says which; a second one changes nothing."""
    assert main(["line", "init", pg_url]) == 0
    _write_old(pg_url)
    forwarding_role(pg_url, pg_server.port, "station_cm")
    repo = _station(tmp_path, "a")
    _every_kind(repo)
    f = _forward(repo, pg_url.replace("postgres@", "station_cm@"), "ST-C")
    st = f.status()
    assert (st["up"], st["backlog"], st["quarantined"]) == (True, 0, 0)
    engine = make_engine(pg_url)
    assert _count(engine, LINE_RUNDOWNS.table) == 3      # typed, by the owner's trigger
    assert _comments(engine)[("line_rundowns", "result_at")] == OLD["result_at"]
    # nor does a forwarder that owns the tables: only line init writes them (a forwarder at
    # every start wrote back over a DBA's words, an older station over a newer one's)
    owner = _station(tmp_path, "b")
    _forward(owner, pg_url, "ST-O")
    owner.close()
    assert _comments(engine)[("line_rundowns", "result_at")] == OLD["result_at"]
    capsys.readouterr()

    assert main(["line", "init", pg_url]) == 0
    out = capsys.readouterr().out
    assert "comments brought up to date: line_rundowns.torque_min_nm, " \
           "line_rundowns.result_at\n" in out, out
    comments = _comments(engine)
    c = LINE_RUNDOWNS.table.c
    assert comments[("line_rundowns", "result_at")] == c.result_at.comment
    assert comments[("line_rundowns", "torque_min_nm")] == c.torque_min_nm.comment
    assert main(["line", "init", pg_url]) == 0
    out = capsys.readouterr().out
    assert "every table there already" in out and "comments" not in out, out
    engine.dispose()
    repo.close()
