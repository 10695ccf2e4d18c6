"""The database layer's own errors: ``db`` imports nothing from ``stationd``.

The station maps them: commands print any :class:`DbError` as one line (exit 2), the daemon
turns a :class:`DatabaseError` into a fault of the database and a :class:`DataError` (a closed
VIN, a bolt the table does not hold) into the case it stands for.
"""

from __future__ import annotations


class DbError(Exception):
    """Base of every error of the database layer."""


class DatabaseError(DbError):
    """The database cannot be opened, read or written (locked, full, corrupt, unreachable)."""


class DataError(DbError):
    """A request the data refuses: a malformed URL or value, a vehicle already closed."""


class VehicleClosedError(DataError):
    """A vehicle whose record was closed comes back (rework): ``vin``, ``closed_at``."""

    def __init__(self, message: str, *, vin: str) -> None:
        super().__init__(message)
        self.vin = vin


class NotFoundError(DataError):
    """A VIN, model or bolt that the database does not hold."""
