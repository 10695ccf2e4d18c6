"""Commands people gave the station, the results feed, and the database's own id.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-27

Why: commands (skip a bolt, reopen a vehicle) are accepted by the station's rules with who
gave them: the audit trail needs them on disk.  A reader that must not miss a record (a
forwarder to a line database, an MES) reads them "since N" from one sequence; and a
station's records stay unique on a line when its local database is replaced, by the id each
database gets when it is created.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | Sequence[str] | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "commands",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("at", sa.DateTime(), nullable=False),
        sa.Column("user", sa.String(length=64), nullable=False),
        sa.Column("source", sa.String(length=100), nullable=False),
        sa.Column("kind", sa.String(length=32), nullable=False),
        sa.Column("vin", sa.String(length=32), nullable=True),
        sa.Column("bolt", sa.String(length=32), nullable=True),
        sa.Column("comment", sa.String(length=500), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_commands")),
    )
    op.create_table(
        "feed",
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("ref", sa.Integer(), nullable=False),
        sa.Column("at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("seq", name=op.f("pk_feed")),
        sqlite_autoincrement=True,
    )
    meta = op.create_table(
        "meta",
        sa.Column("key", sa.String(length=32), nullable=False),
        sa.Column("value", sa.String(length=200), nullable=False),
        sa.PrimaryKeyConstraint("key", name=op.f("pk_meta")),
    )
    op.bulk_insert(meta, [{"key": "db_id", "value": str(uuid.uuid4())}])
    # the records already there join the feed in the order they were written
    op.execute("INSERT INTO feed (kind, ref, at) SELECT 'rundown', id, recorded_at "
               "FROM tightening_records ORDER BY recorded_at, id")
    op.execute("INSERT INTO feed (kind, ref, at) SELECT 'unattributed', id, recorded_at "
               "FROM unattributed_results ORDER BY recorded_at, id")


def downgrade() -> None:
    for table in ("meta", "feed", "commands"):
        op.drop_table(table)
