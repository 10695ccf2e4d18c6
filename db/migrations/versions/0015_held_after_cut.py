"""A note on a controller event: why a bolt is held where no result says it.

Revision ID: 0015
Revises: 0014
Create Date: 2026-11-30

Why: the link to the controller went down while the tool was enabled for a bolt, and what
the controller did meanwhile could not be known after the reconnect (it refused to give its
results, its clock was unknown when its ids had started again, one result of that pset could
not be placed): the bolt is held for a person, as for a result that did not read.  A hold
outlives a restart, so it is stored: a controller event of the station's own kind
(:data:`db.kinds.CUT_UNKNOWN`) without a result, its note saying why.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0015"
down_revision: str | Sequence[str] | None = "0014"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # a nullable column: one ALTER on SQLite and PostgreSQL, no table rebuild
    op.add_column("controller_events", sa.Column("note", sa.String(500), nullable=True))


def downgrade() -> None:
    op.drop_column("controller_events", "note")
