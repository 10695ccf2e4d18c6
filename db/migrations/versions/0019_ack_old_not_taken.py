"""The OK results not taken for a tightening, stored before they were published on OPC UA,
count as acknowledged there.

Revision ID: 0019
Revises: 0018
Create Date: 2026-12-01

Why: from this release an MES is also sent the OK results without a type whose torque lay
outside their bolt's window (controller events ``OK not taken``, their bolt held): perhaps
real tightenings, which an MES counting the controller's rundowns missed.  Those stored
before were never sent as they came; unacknowledged, a station's upgrade would have
RequestUnacknowledgedResults send its whole history of them at once.  They are marked
acknowledged by ``stationd upgrade`` (who, in ``acknowledged_by``).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime

import sqlalchemy as sa
from alembic import op

revision: str = "0019"
down_revision: str | Sequence[str] | None = "0018"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

BY = "stationd upgrade"
KIND = "controller_event"
#: db.kinds.NOT_TAKEN as this revision stores it (a migration keeps its own copy)
NOT_TAKEN = "untyped OK outside torque window"


def _not_taken() -> tuple[sa.TableClause, sa.Select[tuple[int]]]:
    feed = sa.table("feed", sa.column("seq", sa.Integer), sa.column("kind", sa.String),
                    sa.column("ref", sa.Integer))
    events = sa.table("controller_events", sa.column("id", sa.Integer),
                      sa.column("what", sa.String))
    return feed, sa.select(feed.c.seq).where(
        feed.c.kind == KIND, feed.c.ref.in_(sa.select(events.c.id).where(
            events.c.what == NOT_TAKEN)))


def upgrade() -> None:
    feed, seqs = _not_taken()
    acked = sa.table("opcua_acknowledged", sa.column("seq", sa.Integer),
                     sa.column("acknowledged_by", sa.String), sa.column("at", sa.DateTime))
    now = datetime.now(UTC).replace(tzinfo=None)    # naive UTC, as the models store it
    op.execute(acked.insert().from_select(
        ["seq", "acknowledged_by", "at"],
        sa.select(feed.c.seq, sa.literal(BY, sa.String), sa.literal(now, sa.DateTime))
        .where(feed.c.seq.in_(seqs), feed.c.seq.not_in(sa.select(acked.c.seq)))))


def downgrade() -> None:
    _, seqs = _not_taken()
    acked = sa.table("opcua_acknowledged", sa.column("seq", sa.Integer),
                     sa.column("acknowledged_by", sa.String))
    op.execute(acked.delete().where(acked.c.acknowledged_by == BY, acked.c.seq.in_(seqs)))
