"""The results feed's ``at`` follows its sequence numbers: a record's feed entry is numbered
and dated under the database's write lock, so a writer that waited for the lock is dated
after the one that held it.  Readers rely on it: OPC UA's RequestResults by time starts after
``Ledger.seq_before(FromTime)``, the last number dated before that time, and stops at the
first entry dated after ToTime."""

from __future__ import annotations

import sqlite3
import threading
import time
from contextlib import closing
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.curves import store_curve
from db.models import FeedEntry
from tests.db.conftest import record


def _feed(repo):
    with Session(repo.engine) as s:
        return [(e.seq, e.kind, e.at) for e in s.scalars(select(FeedEntry)
                                                           .order_by(FeedEntry.seq))]


def test_a_curve_that_waited_for_the_write_lock_is_not_dated_before_the_record_that_held_it(
        sedan):
    """The controller's curve comes with its result; the station stores the curve in a pool
    of its own (stationd.shell.controller's _curves_pool) while the result's writer, or
    another process (a command from the CLI), holds SQLite's write lock.  The curve's time is
    read before its transaction begins (db.curves.store_curve's ``now``) and, since 42cdc2c,
    is its feed entry's ``at``: the curve, numbered after the record that held the lock, is
    dated before it."""
    rec = record(sedan, "VIN1", "B1", tightening_id=7)
    assert rec
    feed = _while_another_writer_holds_the_lock(sedan, lambda: store_curve(
        sedan, tightening_id=7, trace_type=1, unit="deg", values=[0.0, 1.0],
        sample_period_s=0.002), rec)
    assert [k for _, k, _ in feed][-2:] == ["rundown", "curve"]
    ats = [at for _, _, at in feed]
    assert ats == sorted(ats), \
        f"the feed's at goes back with its sequence numbers: {[(s, k, str(a)) for s, k, a in feed]}"


def _while_another_writer_holds_the_lock(repo, store, ref):
    """``store`` run in a thread while another connection holds the write lock and stores a
    feed entry (kind rundown, ``ref``) dated meanwhile; the feed as it ends."""
    path = repo.engine.url.database
    with closing(sqlite3.connect(path, isolation_level=None)) as other:
        other.execute("PRAGMA busy_timeout=10000")
        other.execute("BEGIN IMMEDIATE")
        done: list[object] = []
        t = threading.Thread(target=lambda: done.append(store()))
        t.start()
        time.sleep(0.3)
        held_at = datetime.now(UTC).replace(tzinfo=None)
        other.execute("INSERT INTO feed (kind, ref, at) VALUES ('rundown', ?, ?)",
                      (ref, held_at.isoformat(sep=" ")))
        other.execute("COMMIT")
    t.join(15)
    assert done, "not stored"
    return _feed(repo)


def test_a_result_without_an_id_or_a_hold_that_waited_for_the_lock_is_not_dated_before_it(
        sedan):
    """The repository's writes read their recorded_at (their feed entry's at since 42cdc2c)
    as they build the row; where nothing is read before it (an unattributed result without
    a tightening id; a hold without a result, CUT_UNKNOWN), that is before BEGIN IMMEDIATE
    took the lock: the feed dated back against its numbers, as a curve's."""
    from db.kinds import CUT_UNKNOWN

    rec = record(sedan, "VIN1", "B1", tightening_id=7)
    feed = _while_another_writer_holds_the_lock(sedan, lambda: sedan.others.record_unattributed(
        vin="VIN1", controller_vin=None, tightening_id=None, pset=1, ok=True, torque_nm=50.0,
        angle_deg=30.0, result_at=None, reason="test"), rec)
    feed = _while_another_writer_holds_the_lock(sedan, lambda: sedan.others.record_controller_event(
        result_type=1, what=CUT_UNKNOWN, vin="VIN1", bolt="B2", controller_vin=None,
        tightening_id=None, pset=1, ok=None, torque_nm=None, angle_deg=None, result_at=None,
        note="held"), rec)
    ats = [at for _, _, at in feed]
    assert ats == sorted(ats), \
        f"the feed's at goes back with its sequence numbers: {[(s, k, str(a)) for s, k, a in feed]}"
