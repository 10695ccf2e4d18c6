"""The controller's own time of each rundown.

Revision ID: 0014
Revises: 0013
Create Date: 2026-11-29

Why: a result the controller sends again (it was not acknowledged before a reload, a link
cut) is stored once, and telling a copy from another result under the same tightening id
(a controller replaced or reset numbers from 1 again, and its torque to 0.01 N m and angle
to whole degrees can coincide) needs the controller's own timestamp of the tightening
(Open Protocol MID 0061).  ``result_at`` of a rundown is the station's time of taking it;
the controller's is kept beside it.  Rundowns before this revision, entered outcomes and
those of a controller without a clock (register-driven) have none (NULL).
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0014"
down_revision: str | Sequence[str] | None = "0013"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # a nullable column: one ALTER on SQLite and PostgreSQL, no table rebuild
    op.add_column("tightening_records", sa.Column("controller_at", sa.DateTime(),
                                                  nullable=True))


def downgrade() -> None:
    # one ALTER as well (SQLite 3.35+ drops a column in place): a batch rebuild drops and
    # copies the table, which the curves' foreign keys to its rows refuse
    op.drop_column("tightening_records", "controller_at")
