"""A line database given where a station's is read (``db report --db postgresql://.../line``)
is said to be one, never migrated into a station's (a quality trial: told "schema none ...:
open it once with write access", which would have put a station's schema into the line's
database)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from sqlalchemy import create_engine, inspect

from db.errors import DatabaseError
from db.repository import Repository
from tests.db.conftest import url_of


@pytest.mark.parametrize("read_only", [True, False], ids=["report", "import"])
def test_a_line_database_is_said_and_left_as_it_is(tmp_path: Path, read_only: bool):
    path = tmp_path / "line.db"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE line_rundowns (id INTEGER PRIMARY KEY)")
        conn.execute("CREATE TABLE line_feed (id INTEGER PRIMARY KEY)")
    with pytest.raises(DatabaseError, match=r"a line database \(its tables line_feed, "
                                            r"line_rundowns\), not a station's: read it with "
                                            r"`stationd line results"):
        Repository.open(url_of(path), read_only=read_only)
    engine = create_engine(url_of(path))
    assert sorted(inspect(engine).get_table_names()) == ["line_feed", "line_rundowns"]
    engine.dispose()
