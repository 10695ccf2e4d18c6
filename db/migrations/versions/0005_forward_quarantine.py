"""Feed entries the line database refused for good.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-27

Why: the forwarder to the line's PostgreSQL must never be blocked by one record the server
will not take; such a record waits here, with the server's reason, for a retry or an export.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | Sequence[str] | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "forward_quarantine",
        sa.Column("seq", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("reason", sa.String(length=500), nullable=False),
        sa.Column("at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("seq", name=op.f("pk_forward_quarantine")),
    )


def downgrade() -> None:
    op.drop_table("forward_quarantine")
