"""The station file's ``line`` section: which line database the station forwards its records
to, as which station, and how much may wait (:class:`LineConfig`), with the checks of its URL.

Why apart from :mod:`stationd.forward`: the station file's reader (and every command that
reads a station file: ``stationd status --config``) needs the section, not the forwarder, its
database layer and PostgreSQL's driver (0.4 s of each command's start)."""

from __future__ import annotations

from dataclasses import dataclass

from stationd.yamlio import YamlNode

EXAMPLE_URL = "postgresql+psycopg://stationd@line-db/line"


def not_postgresql(url: str, backend: str) -> str:
    """Why ``url``, whose SQLAlchemy backend is ``backend`` (not PostgreSQL), cannot name the
    line database, in the words of what to write.  PostgreSQL under a scheme SQLAlchemy does
    not know (``postgres://``) is told as the station's database URLs are
    (:func:`db.engine.scheme_mistake`): "the line database is PostgreSQL, not postgres"
    read as a contradiction."""
    from db.engine import scheme_mistake

    fix = scheme_mistake(url, "postgresql")
    if fix is not None:
        return fix
    return (f"the line database is PostgreSQL, not {backend}: give a postgresql+psycopg:// "
            f"URL (e.g. {EXAMPLE_URL}); the station's own records are in database: url")


def line_url_problem(url: str) -> str | None:
    """Why ``url`` cannot name the line database, in the words of what to write; None when
    it can (built, not connected: a server that does not answer is not told here).  One check
    for the station file's ``line.url`` and ``stationd line init``.  SQLAlchemy is imported
    here, for a file with a line section: a command reading any other spends no time on it."""
    from sqlalchemy import make_url

    from db.engine import make_engine
    from db.errors import DbError

    try:
        parsed = make_url(url)
        backend, port = parsed.get_backend_name(), parsed.port
    except Exception:
        return f"not a database URL: {url!r} (e.g. {EXAMPLE_URL})"
    if port is not None and not 1 <= port <= 65535:
        # psycopg takes port 0 as "the default", and its error then names 5432
        return f"port {port} is not 1-65535"
    if backend != "postgresql":
        return not_postgresql(url, backend)
    try:   # a driver that is not installed is told now
        make_engine(url).dispose()
    except DbError as exc:
        return f"{exc}: the line database's driver is psycopg 3 (postgresql+psycopg://...)"
    return None


@dataclass(frozen=True)
class LineConfig:
    url: str
    station_id: str
    max_records: int = 100_000
    max_age_h: float = 72.0
    max_mb: float = 256.0        # the records' JSON, as the line database takes them

    @classmethod
    def from_node(cls, node: YamlNode) -> LineConfig:
        m = node.mapping(("url", "station_id", "backlog"), required=("url", "station_id"))
        url = m["url"].text()
        problem = line_url_problem(url)
        if problem is not None:
            raise m["url"].error(problem)
        sid = m["station_id"].text()
        if not 1 <= len(sid) <= 64 or not sid.isprintable():
            raise m["station_id"].error("1-64 printable characters")
        records, age, mb = cls.max_records, cls.max_age_h, cls.max_mb
        if "backlog" in m:
            b = m["backlog"].mapping(("records", "size_mb", "age_h"))
            records = b["records"].integer(lo=1, hi=10**9) if "records" in b else records
            mb = b["size_mb"].number(lo=0.01, hi=10**6) if "size_mb" in b else mb
            age = b["age_h"].number(lo=0.01, hi=24 * 365) if "age_h" in b else age
        return cls(url, sid, records, age, mb)
