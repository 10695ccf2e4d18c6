"""Tightening ids the station could not get from the controller.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-27

Why: after a reconnect the station asks the controller for every tightening it missed
(Open Protocol MID 0064); one the controller no longer has is recorded as a gap, visibly,
never silently.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | Sequence[str] | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "result_gaps",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("first_id", sa.Integer(), nullable=False),
        sa.Column("last_id", sa.Integer(), nullable=False),
        sa.Column("vin", sa.String(length=32), nullable=True),
        sa.Column("reason", sa.String(length=200), nullable=False),
        sa.Column("found_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_result_gaps")),
    )


def downgrade() -> None:
    op.drop_table("result_gaps")
