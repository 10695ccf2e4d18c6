"""Alembic migrations of the process-parameter database (run by ``db.migrate.upgrade``)."""
