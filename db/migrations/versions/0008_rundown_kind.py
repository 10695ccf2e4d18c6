"""Rundown kind: tightening or loosening.

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-27

Why: the NOK policy's loosen strategy and the loosen command make the station record
loosenings, and a loosening must never pass for a tightening (a bolt loosened last is not
done).  Every record before this revision was a tightening.
"""

from __future__ import annotations

from collections.abc import Sequence

from alembic import op

revision: str = "0008"
down_revision: str | Sequence[str] | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # one ALTER with the column's constraint (SQLite and PostgreSQL both take it): no table
    # rebuild, so the offline SQL can be generated too
    op.execute("ALTER TABLE tightening_records ADD COLUMN kind VARCHAR(10) DEFAULT "
               "'tightening' NOT NULL CONSTRAINT ck_tightening_records_kind "
               "CHECK (kind IN ('tightening', 'loosening'))")


def downgrade() -> None:
    with op.batch_alter_table("tightening_records") as batch:
        batch.drop_constraint(op.f("ck_tightening_records_kind"), type_="check")
        batch.drop_column("kind")
