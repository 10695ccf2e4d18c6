"""What the station owes across a reload or restart, and results no bolt owns.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-27

Why: a reload (SIGHUP) during a rundown started a station that did not know the tool had
been enabled for a bolt: the result arriving on the new link was acknowledged and never
recorded.  ``tool_enables`` is written before the tool is enabled, so the next station knows
which bolt a late result belongs to; ``unattributed_results`` keeps a result no bolt owns
before it is acknowledged (it was only logged).
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | Sequence[str] | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "tool_enables",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("vin", sa.String(length=32), nullable=False),
        sa.Column("bolt", sa.String(length=32), nullable=False),
        sa.Column("pset", sa.Integer(), nullable=True),
        sa.Column("parameters_id", sa.Integer(), nullable=True),
        sa.Column("selection", sa.JSON(), nullable=False),
        sa.Column("enabled_at", sa.DateTime(), nullable=False),
        sa.Column("off_at", sa.DateTime(), nullable=True),
        sa.Column("settled_at", sa.DateTime(), nullable=True),
        sa.ForeignKeyConstraint(
            ["parameters_id"], ["process_parameters.id"],
            name=op.f("fk_tool_enables_parameters_id_process_parameters")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_tool_enables")),
    )
    op.create_table(
        "unattributed_results",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("vin", sa.String(length=32), nullable=True),
        sa.Column("controller_vin", sa.String(length=32), nullable=True),
        sa.Column("tightening_id", sa.Integer(), nullable=True),
        sa.Column("pset", sa.Integer(), nullable=True),
        sa.Column("status", sa.String(length=3), nullable=False),
        sa.Column("torque_nm", sa.Double(), nullable=True),
        sa.Column("angle_deg", sa.Double(), nullable=True),
        sa.Column("result_at", sa.DateTime(), nullable=True),
        sa.Column("recorded_at", sa.DateTime(), nullable=False),
        sa.Column("reason", sa.String(length=200), nullable=False),
        sa.CheckConstraint("status IN ('ok', 'nok')",
                           name=op.f("ck_unattributed_results_status")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_unattributed_results")),
    )


def downgrade() -> None:
    op.drop_table("unattributed_results")
    op.drop_table("tool_enables")
