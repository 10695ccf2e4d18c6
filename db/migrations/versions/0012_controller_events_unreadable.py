"""Controller events and unreadable results, each a record kind of its own.

Revision ID: 0012
Revises: 0011
Create Date: 2026-11-29

Why: a result from the controller that is not a rundown (a batch increment, a bypass, an
aborted job, a reference setup, a type the station does not know) must never close a bolt,
yet what happened on the controller is kept; a result the station could not read is kept
whole (its text, revision and the parse error) before the controller is told to forget it.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0012"
down_revision: str | Sequence[str] | None = "0011"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "controller_events",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("result_type", sa.Integer(), nullable=False),
        sa.Column("what", sa.String(length=32), nullable=False),
        sa.Column("vin", sa.String(length=32), nullable=True),
        sa.Column("bolt", sa.String(length=32), nullable=True),
        sa.Column("controller_vin", sa.String(length=32), nullable=True),
        sa.Column("tightening_id", sa.Integer(), nullable=True),
        sa.Column("pset", sa.Integer(), nullable=True),
        sa.Column("status", sa.String(length=3), nullable=False),
        sa.Column("torque_nm", sa.Double(), nullable=True),
        sa.Column("angle_deg", sa.Double(), nullable=True),
        sa.Column("result_at", sa.DateTime(), nullable=True),
        sa.Column("recorded_at", sa.DateTime(), nullable=False),
        sa.CheckConstraint("status IN ('ok', 'nok')",
                           name=op.f("ck_controller_events_status")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_controller_events")),
    )
    op.create_table(
        "unreadable_results",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("mid", sa.Integer(), nullable=False),
        sa.Column("revision", sa.Integer(), nullable=False),
        sa.Column("raw", sa.Text(), nullable=False),
        sa.Column("error", sa.String(length=500), nullable=False),
        sa.Column("vin", sa.String(length=32), nullable=True),
        sa.Column("bolt", sa.String(length=32), nullable=True),
        sa.Column("controller_vin", sa.String(length=32), nullable=True),
        sa.Column("tightening_id", sa.Integer(), nullable=True),
        sa.Column("pset", sa.Integer(), nullable=True),
        sa.Column("result_at", sa.DateTime(), nullable=True),
        sa.Column("recorded_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_unreadable_results")),
    )


def downgrade() -> None:
    op.drop_table("unreadable_results")
    op.drop_table("controller_events")
