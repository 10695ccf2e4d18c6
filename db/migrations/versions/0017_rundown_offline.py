"""Whether a rundown was made while the link to the controller was down.

Revision ID: 0017
Revises: 0016
Create Date: 2026-11-30

Why: a result fetched after a link cut (Open Protocol MID 0064) is taken by the station at the
reconnect; an MES reading it on OPC UA could not tell it from one pushed as it was made (an
MES integrator's trial).  True for such a rundown (published with IsGeneratedOffline), False
for every other, those stored before included.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0017"
down_revision: str | Sequence[str] | None = "0016"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # a column with a default: one ALTER on SQLite and PostgreSQL, no table rebuild
    op.add_column("tightening_records", sa.Column("offline", sa.Boolean, nullable=False,
                                                  server_default=sa.false()))


def downgrade() -> None:
    op.drop_column("tightening_records", "offline")
