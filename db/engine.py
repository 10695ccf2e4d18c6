"""The database engine: any SQLAlchemy URL, with SQLite set up for a station that must not lose
a record.

SQLite (the default, ``sqlite:///stationd.db``) gets, on every new connection:

- ``journal_mode=WAL``: readers (``stationd db report``) never block the daemon's writes, and a
  killed writer leaves a database that opens with every committed transaction in it;
- ``synchronous=FULL``: a commit is on disk (WAL fsynced) when it returns, so a power cut
  right after ``record_tightening`` returns loses nothing either;
- ``foreign_keys=ON``: SQLite checks references only when asked, per connection;
- ``busy_timeout``: a second process waits for the write lock instead of failing at once.

Python 3.11's sqlite3 starts transactions lazily (not before a SELECT), so the read part of a
read-modify-write would run outside the transaction.  The driver's own BEGIN is switched off and
SQLAlchemy emits it: plain ``BEGIN`` for reads, ``BEGIN IMMEDIATE`` (the write lock taken at the
start) on the engine returned by :func:`writer`, so an import never acts on a stale read.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any, Protocol

from sqlalchemy import Engine, create_engine, event, make_url
from sqlalchemy.engine import Connection
from sqlalchemy.exc import ArgumentError, NoSuchModuleError
from sqlalchemy.orm import Session

from db.errors import DataError

DEFAULT_URL = "sqlite:///stationd.db"
BUSY_TIMEOUT_MS = 10_000
_IMMEDIATE = "stationd_begin_immediate"


class Transactions(Protocol):
    """The repository's transactions (``Repository._session``), given to the parts it is made
    of: ``write`` takes the write lock as it begins; committed when the block ends, rolled
    back if it raises (a :class:`db.errors.DatabaseError` then)."""

    def __call__(self, write: bool) -> AbstractContextManager[Session]: ...


def make_engine(url: str = DEFAULT_URL, *, read_only: bool = False) -> Engine:
    """An engine for ``url``; a malformed URL or an unknown driver is an :class:`DataError`.

    ``read_only``: an SQLite file is opened with ``mode=ro`` (a reader that may not write the
    file, e.g. an engineer reading the service user's database: SQLite reads a WAL database so
    while its ``-wal`` and ``-shm`` files exist, as they do while the daemon runs)."""
    try:
        parsed = make_url(url)
        name = parsed.database
        if read_only and parsed.get_backend_name() == "sqlite" and name \
                and name != ":memory:" and not name.startswith("file:"):
            parsed = parsed.set(database=f"file:{Path(name).resolve()}",
                                query={"mode": "ro", "uri": "true"})
        engine = create_engine(parsed)
    except (ArgumentError, NoSuchModuleError, ValueError) as exc:
        raise DataError(f"database URL {url!r}: {_url_mistake(url) or exc}") from None
    except ImportError as exc:
        hint = _url_mistake(url, loaded=True) or f"driver not installed ({exc.name})"
        raise DataError(f"database URL {url!r}: {hint}") from None
    if engine.dialect.name == "sqlite":
        _setup_sqlite(engine, read_only=read_only)
    return engine


#: what a database URL looks like, for a message about one that is not
URL_FORMS = ("sqlite:///NAME.db: an SQLite file relative to the current folder, "
             "sqlite:////ABS/PATH.db: an absolute one, postgresql+psycopg://USER@HOST/NAME: "
             "PostgreSQL")
#: URL schemes people write that SQLAlchemy does not know (or whose default driver is not
#: installed: psycopg 3 is, psycopg2 is not), and what they mean
SCHEMES = {"postgres": "postgresql+psycopg", "postgresql": "postgresql+psycopg",
           "psql": "postgresql+psycopg", "sqlite3": "sqlite"}


def scheme_mistake(url: str, kind: str | None = None) -> str | None:
    """``url`` written with a scheme people write that SQLAlchemy has no driver for here
    (:data:`SCHEMES`: ``postgres://``, Heroku's), in the words of what to write: "write
    postgresql+psycopg://... (postgres:// is not a driver SQLAlchemy has here)"; None for
    any other URL.  ``kind``: only a scheme meaning that kind of database ("postgresql": a
    caller that takes PostgreSQL alone, the line database)."""
    scheme, sep, rest = url.partition("://")
    fix = SCHEMES.get(scheme.lower()) if sep else None
    if fix is None or (kind is not None and fix.partition("+")[0] != kind):
        return None
    return f"write {fix}://{rest} ({scheme}:// is not a driver SQLAlchemy has here)"


def _url_mistake(url: str, *, loaded: bool = False) -> str | None:
    """What is wrong with a URL SQLAlchemy refused, in the words of what to write: a file
    name without a scheme, a scheme it does not know (``postgres://``, Heroku's), PostgreSQL
    without the installed driver.  ``loaded``: the dialect exists (its driver did not
    import): only a known mistake is told.  None: SQLAlchemy's own message says it."""
    scheme, sep, _ = url.partition("://")
    if not sep:
        return f"not a URL: write sqlite:///{url} for an SQLite file ({URL_FORMS})"
    fix = scheme_mistake(url)
    if fix is not None:
        return fix
    if not loaded and "+" not in scheme:
        return f"no database kind {scheme!r} ({URL_FORMS})"
    return None


def writer(engine: Engine) -> Engine:
    """The same engine (same pool), whose transactions take SQLite's write lock at BEGIN."""
    return engine.execution_options(**{_IMMEDIATE: True})


@contextmanager
def write_session(engine: Engine, *, expire_on_commit: bool = False) -> Iterator[Session]:
    """One write transaction on ``engine`` (a :func:`writer`'s or not), committed when the
    block ends, rolled back if it raises, holding SQLite's write lock from its start: the
    session would begin only at its first statement, and a time the body read before it (a
    record's ``recorded_at``, its feed entry's ``at``), by a write that then waited for the
    lock, was dated before the record numbered ahead of it."""
    with Session(writer(engine), expire_on_commit=expire_on_commit) as s, s.begin():
        s.connection()   # BEGIN IMMEDIATE now
        yield s


def _setup_sqlite(engine: Engine, *, read_only: bool = False) -> None:
    memory = engine.url.database in (None, "", ":memory:")

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None  # SQLAlchemy emits BEGIN (see _on_begin)
        cursor = dbapi_connection.cursor()
        try:
            if not memory and not read_only:   # setting it is a write
                cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute("PRAGMA synchronous=FULL")
            cursor.execute("PRAGMA foreign_keys=ON")
            cursor.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
        finally:
            cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn: Connection) -> None:
        immediate = conn.get_execution_options().get(_IMMEDIATE, False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")
