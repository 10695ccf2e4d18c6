"""A hold the station stored where no result says it has no verdict: status NULL.

Revision ID: 0020
Revises: 0019
Create Date: 2026-12-01

Why: a bolt held because its result is not known (a link cut's, a lost push's, a check of
the controller's newest that could not be read) is stored as a controller event of the
station's own kind; its status was 'nok', so an MES counting status 'nok' counted each as a
NOK tightening (an MES integrator's trial).  The controller gave no verdict: the column
may be NULL now, and those stored before are set to NULL.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0020"
down_revision: str | Sequence[str] | None = "0019"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: db.kinds.HELD_WITHOUT_RESULT as this revision stores them (a migration keeps its own copy)
HELD = ("result unknown after a link cut", "result unknown after a lost push")


def _events() -> sa.TableClause:
    return sa.table("controller_events", sa.column("what", sa.String),
                    sa.column("status", sa.String))


def _table(status_nullable: bool) -> sa.Table:
    """The table as 0012 and 0015 made it (SQLite rebuilds it to change a column: given
    whole, so that ``stationd upgrade --sql`` can write the SQL without a database)."""
    return sa.Table(
        "controller_events", sa.MetaData(),
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("result_type", sa.Integer(), nullable=False),
        sa.Column("what", sa.String(length=32), nullable=False),
        sa.Column("vin", sa.String(length=32), nullable=True),
        sa.Column("bolt", sa.String(length=32), nullable=True),
        sa.Column("controller_vin", sa.String(length=32), nullable=True),
        sa.Column("tightening_id", sa.Integer(), nullable=True),
        sa.Column("pset", sa.Integer(), nullable=True),
        sa.Column("status", sa.String(length=3), nullable=status_nullable),
        sa.Column("torque_nm", sa.Double(), nullable=True),
        sa.Column("angle_deg", sa.Double(), nullable=True),
        sa.Column("result_at", sa.DateTime(), nullable=True),
        sa.Column("recorded_at", sa.DateTime(), nullable=False),
        sa.Column("note", sa.String(500), nullable=True),
        sa.CheckConstraint("status IN ('ok', 'nok')", name="ck_controller_events_status"),
        sa.PrimaryKeyConstraint("id", name="pk_controller_events"),
    )


def upgrade() -> None:
    with op.batch_alter_table("controller_events", copy_from=_table(False)) as batch:
        batch.alter_column("status", existing_type=sa.String(length=3), nullable=True)
    events = _events()
    op.execute(events.update().where(events.c.what.in_(HELD)).values(status=None))


def downgrade() -> None:
    events = _events()
    op.execute(events.update().where(events.c.status.is_(None)).values(status="nok"))
    with op.batch_alter_table("controller_events", copy_from=_table(True)) as batch:
        batch.alter_column("status", existing_type=sa.String(length=3), nullable=False)
