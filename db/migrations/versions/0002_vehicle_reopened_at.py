"""Vehicles: when a closed vehicle was last reopened for rework.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-26

Why: a rework was known only to the daemon that reopened it; a daemon reloaded (SIGHUP) or
restarted mid-rework resumed the open vehicle as a first pass, and the operator's screen
and the status lost "rework".  The database keeps it, as it keeps the rest of a vehicle.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | Sequence[str] | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("vehicles") as batch:
        batch.add_column(sa.Column("reopened_at", sa.DateTime(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("vehicles") as batch:
        batch.drop_column("reopened_at")
