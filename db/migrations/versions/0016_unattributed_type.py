"""The result type of a result no bolt owns.

Revision ID: 0016
Revises: 0015
Create Date: 2026-11-30

Why: a loosening made during a link cut and not proved any bolt's was stored unattributed
without its type, and the report, the export and the line database read it as a tightening
OK (an MES integrator's trial).  The code as the controller sent it, NULL where it sent none
(a revision without a type) and on rows stored before.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0016"
down_revision: str | Sequence[str] | None = "0015"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # a nullable column: one ALTER on SQLite and PostgreSQL, no table rebuild
    op.add_column("unattributed_results", sa.Column("result_type", sa.Integer, nullable=True))


def downgrade() -> None:
    op.drop_column("unattributed_results", "result_type")
