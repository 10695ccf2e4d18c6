"""A throw-away PostgreSQL server for the tests: the runtime's own (:mod:`stationd.pgserver`,
also what ``stationd bench line`` starts), so the tests and the benchmark start it one way.
Where no server can be started (the package is not installed), the tests that need one are
skipped with that reason (``PgServer().missing``)."""

from __future__ import annotations

from stationd.pgserver import PgServer

__all__ = ["PgServer"]
