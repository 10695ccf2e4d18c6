"""Results acknowledged over OPC UA.

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-27

Why: an MES acknowledges the results it stored (AcknowledgeResults, OPC 40450-1 1.01) and asks
for the others after an absence (RequestUnacknowledgedResults); the acknowledgement must
survive a restart of the station, so it lives beside the feed it refers to.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010"
down_revision: str | Sequence[str] | None = "0009"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "opcua_acknowledged",
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("acknowledged_by", sa.String(length=64), nullable=False),
        sa.Column("at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["seq"], ["feed.seq"],
                                name=op.f("fk_opcua_acknowledged_seq_feed")),
        sa.PrimaryKeyConstraint("seq", name=op.f("pk_opcua_acknowledged")),
    )


def downgrade() -> None:
    op.drop_table("opcua_acknowledged")
