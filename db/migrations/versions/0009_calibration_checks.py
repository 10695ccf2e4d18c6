"""Calibration checks: each camera pair measured against the reference markers.

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-27

Why: a pair knocked out of place is put in fault by the check; every check (its verdict and
each reference's offset) is kept, so when a pair moved, and by how much, can be shown and
forwarded to the line.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0009"
down_revision: str | Sequence[str] | None = "0008"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "calibration_checks",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("at", sa.DateTime(), nullable=False),
        sa.Column("pair", sa.String(length=64), nullable=False),
        sa.Column("verdict", sa.String(length=16), nullable=False),
        sa.Column("reference", sa.String(length=64), nullable=True),
        sa.Column("offset_mm", sa.Double(), nullable=True),
        sa.Column("tolerance_mm", sa.Double(), nullable=False),
        sa.Column("reason", sa.String(length=200), nullable=True),
        sa.Column("references", sa.JSON(), nullable=False),
        sa.Column("recorded_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_calibration_checks")),
    )
    op.create_index("ix_calibration_checks_pair", "calibration_checks", ["pair"])


def downgrade() -> None:
    op.drop_index("ix_calibration_checks_pair", table_name="calibration_checks")
    op.drop_table("calibration_checks")
