"""Alembic environment: run by ``alembic.command`` with a Config built in code.

There is no alembic.ini: ``db.migrate.alembic_config`` sets the script location and either
hands over an open connection (``config.attributes["connection"]``, how the repository
migrates on open, inside its own transaction) or a URL (``sqlalchemy.url``, for developers
running ``db.migrate.make_revision`` or offline SQL generation).
"""

from __future__ import annotations

from alembic import context
from sqlalchemy.engine import Connection

from db.engine import DEFAULT_URL, make_engine, writer
from db.models import Base

config = context.config
target_metadata = Base.metadata


def _configure(connection: Connection) -> None:
    # render_as_batch: SQLite cannot ALTER most things; batch mode rebuilds the table instead
    context.configure(connection=connection, target_metadata=target_metadata,
                      render_as_batch=True, compare_type=True)
    with context.begin_transaction():
        context.run_migrations()


def run_offline() -> None:
    context.configure(url=config.get_main_option("sqlalchemy.url") or DEFAULT_URL,
                      target_metadata=target_metadata, literal_binds=True,
                      render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


def run_online() -> None:
    connection = config.attributes.get("connection")
    if isinstance(connection, Connection):
        _configure(connection)
        return
    engine = make_engine(config.get_main_option("sqlalchemy.url") or DEFAULT_URL)
    try:
        with writer(engine).connect() as conn:
            _configure(conn)
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_offline()
else:
    run_online()
