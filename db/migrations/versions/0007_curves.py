"""Tightening curves.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-27

Why: quality looks at the torque-angle curve first after a NOK; the controller sends its
traces (Open Protocol MID 0900) and the station keeps each with its rundown.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | Sequence[str] | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "curves",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("record_id", sa.Integer(), nullable=True),
        sa.Column("tightening_id", sa.Integer(), nullable=False),
        sa.Column("trace_type", sa.Integer(), nullable=False),
        sa.Column("unit", sa.String(length=16), nullable=False),
        sa.Column("sample_period_s", sa.Double(), nullable=True),
        sa.Column("values", sa.JSON(), nullable=False),
        sa.Column("times_s", sa.JSON(), nullable=True),
        sa.Column("result_at", sa.DateTime(), nullable=True),
        sa.Column("recorded_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["record_id"], ["tightening_records.id"],
                                name=op.f("fk_curves_record_id_tightening_records")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_curves")),
    )
    op.create_index("ix_curves_tightening_id", "curves", ["tightening_id"])
    op.create_index("ix_curves_record_id", "curves", ["record_id"])


def downgrade() -> None:
    op.drop_index("ix_curves_record_id", table_name="curves")
    op.drop_index("ix_curves_tightening_id", table_name="curves")
    op.drop_table("curves")
