"""The operator signed in at the station, with each rundown.

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-27

Why: every rundown is recorded with its user (the operator signed in at the station when its
tool was enabled), as the commands are; records before this revision, and rundowns made with
nobody signed in, have none (NULL, shown as such).
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0011"
down_revision: str | Sequence[str] | None = "0010"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # a nullable column: one ALTER on SQLite and PostgreSQL, no table rebuild
    op.add_column("tightening_records", sa.Column("operator", sa.String(length=64),
                                                  nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("tightening_records") as batch:
        batch.drop_column("operator")
