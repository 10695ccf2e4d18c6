"""The cameras each pair's calibration was first used with.

Revision ID: 0023
Revises: 0022
Create Date: 2026-12-03

Why: a camera replaced (another unit, or the left and right swapped) without calibrating the
pair again was trusted with the old camera's calibration, and its bolts localized where they
are not.  Each pair's side is pinned to the serial number it was first opened with under a
calibration (its digest); another serial under the same calibration is refused.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0023"
down_revision: str | Sequence[str] | None = "0022"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "camera_pins",
        sa.Column("pair", sa.String(64), primary_key=True),
        sa.Column("side", sa.String(8), primary_key=True),
        sa.Column("calibration", sa.String(64), primary_key=True),
        sa.Column("serial", sa.String(128), nullable=False),
        sa.Column("pinned_at", sa.DateTime(), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("camera_pins")
