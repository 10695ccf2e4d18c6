"""Every close of a vehicle, with what it left undone: its own record, in the results feed.

Revision ID: 0021
Revises: 0020
Create Date: 2026-12-01

Why: a vehicle that left the station with bolts not tightened was said in the journal and
the vehicle's report, but never reached the line database nor anything an MES reads (an
MES integrator's trial: incomplete vehicles could not be listed from the line); and a reopen
cleared the vehicle's end, so when it first left was lost.  Each close is kept (when, how,
the bolts' counts and the bolts not OK by name) and joins the feed.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0021"
down_revision: str | Sequence[str] | None = "0020"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "vehicle_closings",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("vehicle_id", sa.Integer(), nullable=False),
        sa.Column("closed_at", sa.DateTime(), nullable=False),
        sa.Column("how", sa.String(length=16), nullable=False),
        sa.Column("bolts", sa.Integer(), nullable=False),
        sa.Column("ok", sa.Integer(), nullable=False),
        sa.Column("nok", sa.Integer(), nullable=False),
        sa.Column("missing", sa.Integer(), nullable=False),
        sa.Column("skipped", sa.Integer(), nullable=False),
        sa.Column("loosen", sa.Integer(), nullable=False),
        sa.Column("not_ok", sa.JSON(), nullable=False),
        sa.ForeignKeyConstraint(["vehicle_id"], ["vehicles.id"],
                                name=op.f("fk_vehicle_closings_vehicle_id_vehicles")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_vehicle_closings")),
    )
    op.create_index("ix_vehicle_closings_vehicle", "vehicle_closings", ["vehicle_id"])


def downgrade() -> None:
    # their feed entries go with them (a feed entry refers to a row of its kind's table)
    feed = sa.table("feed", sa.column("kind", sa.String))
    op.execute(feed.delete().where(feed.c.kind == "closing"))
    op.drop_index("ix_vehicle_closings_vehicle", table_name="vehicle_closings")
    op.drop_table("vehicle_closings")
