"""The feed's entries found by their record: an index on (kind, ref); a vehicle's commands
by its VIN.

Revision ID: 0022
Revises: 0021
Create Date: 2026-12-01

Why: a results export names each row's record outside the station (``db_id:seq``, its feed
entry: ``Ledger.result_ids``), looked up by the record's kind and id; without an index each
vehicle's export read the whole feed (a year of rundowns, curves, commands), once for each
vehicle of ``db export --results``.  Each vehicle's report reads its commands (skips,
releases, loosen commands) by VIN: without an index the whole command list, for every
vehicle of an export or a shift's hand-over.
"""

from __future__ import annotations

from collections.abc import Sequence

from alembic import op

revision: str = "0022"
down_revision: str | Sequence[str] | None = "0021"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_index("ix_feed_kind_ref", "feed", ["kind", "ref"])
    op.create_index("ix_commands_vin", "commands", ["vin"])


def downgrade() -> None:
    op.drop_index("ix_commands_vin", table_name="commands")
    op.drop_index("ix_feed_kind_ref", table_name="feed")
