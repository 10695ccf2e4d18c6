"""The results of no bolt and those not read, stored before they were published on OPC UA,
count as acknowledged there.

Revision ID: 0018
Revises: 0017
Create Date: 2026-12-01

Why: from this release an MES is sent, besides the rundowns, the results the station
attributed to no bolt and those it could not read (OPC UA result events, acknowledged like the
rundowns).  Those stored before were never sent as they came; unacknowledged, a station's
upgrade would have RequestUnacknowledgedResults send its whole history of them at once.  They
are marked acknowledged by ``stationd upgrade`` (who, in ``acknowledged_by``).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime

import sqlalchemy as sa
from alembic import op

revision: str = "0018"
down_revision: str | Sequence[str] | None = "0017"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

BY = "stationd upgrade"
KINDS = ("unattributed", "unreadable")


def upgrade() -> None:
    feed = sa.table("feed", sa.column("seq", sa.Integer), sa.column("kind", sa.String))
    acked = sa.table("opcua_acknowledged", sa.column("seq", sa.Integer),
                     sa.column("acknowledged_by", sa.String), sa.column("at", sa.DateTime))
    now = datetime.now(UTC).replace(tzinfo=None)    # naive UTC, as the models store it
    done = sa.select(acked.c.seq)
    op.execute(acked.insert().from_select(
        ["seq", "acknowledged_by", "at"],
        sa.select(feed.c.seq, sa.literal(BY, sa.String), sa.literal(now, sa.DateTime))
        .where(feed.c.kind.in_(KINDS), feed.c.seq.not_in(done))))


def downgrade() -> None:
    acked = sa.table("opcua_acknowledged", sa.column("acknowledged_by", sa.String))
    op.execute(acked.delete().where(acked.c.acknowledged_by == BY))
