"""Outcomes entered by a person, each a rundown of its own provenance.

Revision ID: 0013
Revises: 0012
Create Date: 2026-11-30

Why: a bolt whose result the controller could not send readably is held; a supervisor may
resolve it with the outcome read on the controller's own screen.  That outcome is a rundown
(it closes the bolt, or counts as a NOK) that was not measured by the station: who entered
it, their comment and the unreadable result it resolves are kept with it, so a report, an
export or an MES tells it from a measured one.  Measured rundowns have none (NULL).
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0013"
down_revision: str | Sequence[str] | None = "0012"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # nullable columns: one ALTER each on SQLite and PostgreSQL, no table rebuild
    op.add_column("tightening_records", sa.Column("entered_by", sa.String(length=64),
                                                  nullable=True))
    op.add_column("tightening_records", sa.Column("entered_comment", sa.String(length=500),
                                                  nullable=True))
    op.add_column("tightening_records", sa.Column("unreadable_id", sa.Integer(),
                                                  nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("tightening_records") as batch:
        batch.drop_column("unreadable_id")
        batch.drop_column("entered_comment")
        batch.drop_column("entered_by")
