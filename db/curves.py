"""Tightening curves: stored with their rundown, read back for the screens and the exports.

Why a module beside the repository: the curves are an addition the repository's write path
does not need (a curve is never a reason to refuse or delay a record), so they go through
the repository's engine here, each write one committed transaction like the repository's.

A curve is matched to its rundown by the controller's tightening id.  The result comes
first (the controller sends its MID 0061 before the traces), so the rundown is usually
recorded when its curves are stored and ``record_id`` is set then; a curve stored before
its rundown (or for a result recorded unattributed) keeps ``record_id`` None and is found
by its tightening id, among those recorded around the same time (a controller's ids start
again after a reset: the curve closest in time to the rundown wins).

Each curve gets a results-feed entry (kind ``curve``, :mod:`db.ledger`) in the transaction
that stores it, so the forwarder takes it to the line database like any record, samples
included, in order with the rundowns.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import select
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from db.engine import write_session
from db.errors import DatabaseError, DataError
from db.ledger import CURVE, append
from db.models import TighteningCurve, TighteningRecord, utcnow
from db.repository import Repository

#: trace type -> name (Open Protocol MID 0900)
TRACE_NAMES = {1: "angle", 2: "torque", 3: "current", 4: "gradient", 5: "stroke", 6: "force"}
#: a curve without a rundown id belongs to a rundown recorded this close in time
MATCH_WINDOW = timedelta(minutes=10)
MAX_SAMPLES = 100_000


def store_curve(repo: Repository, *, tightening_id: int, trace_type: int, unit: str,
                values: Sequence[float], sample_period_s: float | None = None,
                times_s: Sequence[float] | None = None, result_at: datetime | None = None,
                record_id: int | None = None) -> int:
    """Store one trace of tightening ``tightening_id``; return its id.  ``record_id``
    defaults to the newest rundown recorded with that tightening id (within
    ``MATCH_WINDOW``), if any.  Committed before it returns (SQLite: the write lock taken
    at BEGIN, as the repository's writes).  ``DataError`` for values that are not finite
    numbers, a naive ``result_at``, or an unknown ``record_id``; ``DatabaseError`` when the
    database fails."""
    vals = [float(v) for v in values]
    if len(vals) > MAX_SAMPLES or not all(math.isfinite(v) for v in vals):
        raise DataError(f"curve of tightening {tightening_id}: at most {MAX_SAMPLES} finite "
                        "values")
    times = None if times_s is None else [float(t) for t in times_s]
    if times is not None and len(times) != len(vals):
        raise DataError(f"curve of tightening {tightening_id}: {len(times)} sample times "
                        f"for {len(vals)} values")
    if result_at is not None and result_at.tzinfo is None:
        raise DataError("result_at: a timestamp with a timezone (UTC) is needed")
    try:
        return _store(repo, int(tightening_id), int(trace_type), str(unit)[:16], vals,
                      None if sample_period_s is None else float(sample_period_s), times,
                      result_at, record_id)
    except SQLAlchemyError as exc:
        raise DatabaseError(f"curve of tightening {tightening_id} not stored: "
                            f"{str(exc).splitlines()[0]}") from None


def _store(repo: Repository, tightening_id: int, trace_type: int, unit: str,
           vals: list[float], period: float | None, times: list[float] | None,
           result_at: datetime | None, record_id: int | None) -> int:
    with write_session(repo.engine) as s:
        now = utcnow()   # under the write lock: the feed entry's at (db.engine.write_session)
        if record_id is None:
            record_id = s.scalar(
                select(TighteningRecord.id)
                .where(TighteningRecord.tightening_id == tightening_id,
                       TighteningRecord.recorded_at >= now - MATCH_WINDOW)
                .order_by(TighteningRecord.recorded_at.desc(), TighteningRecord.id.desc())
                .limit(1))
        elif s.get(TighteningRecord, record_id) is None:
            raise DataError(f"no rundown record {record_id}")
        row = TighteningCurve(
            record_id=record_id, tightening_id=tightening_id, trace_type=trace_type,
            unit=unit, sample_period_s=period, values=vals, times_s=times,
            result_at=result_at, recorded_at=now)
        s.add(row)
        s.flush()
        append(s, CURVE, row.id, now)
        return row.id


def link_curves(repo: Repository, tightening_id: int, record_id: int) -> int:
    """Give the curves of ``tightening_id`` stored without a rundown (they came before it
    was written), within ``MATCH_WINDOW`` of now, the rundown ``record_id``; how many.
    Optional: reading finds them by tightening id anyway; linked, the row says it."""
    now = utcnow()
    try:
        with write_session(repo.engine, expire_on_commit=True) as s:
            rows = list(s.scalars(select(TighteningCurve).where(
                TighteningCurve.record_id.is_(None),
                TighteningCurve.tightening_id == int(tightening_id),
                TighteningCurve.recorded_at >= now - MATCH_WINDOW)))
            for c in rows:
                c.record_id = record_id
            return len(rows)
    except SQLAlchemyError as exc:
        raise DatabaseError(f"curves of tightening {tightening_id} not linked: "
                            f"{str(exc).splitlines()[0]}") from None


def curves_for(repo: Repository, *, record_id: int | None = None,
               tightening_id: int | None = None) -> list[dict[str, Any]]:
    """The curves of one rundown (by its record id: those stored with it, and those stored
    before it with its tightening id), or every curve stored with ``tightening_id``;
    oldest first."""
    if (record_id is None) == (tightening_id is None):
        raise ValueError("give record_id or tightening_id")
    with Session(repo.engine) as s:
        if record_id is not None:
            rec = s.get(TighteningRecord, record_id)
            if rec is None:
                return []
            return curves_of_records(s, [(rec.id, rec.tightening_id, rec.recorded_at)]
                                     ).get(rec.id, [])
        rows = s.scalars(select(TighteningCurve)
                         .where(TighteningCurve.tightening_id == int(tightening_id or 0))
                         .order_by(TighteningCurve.id))
        return [_json(c) for c in rows]


def curves_of_records(s: Session, records: Iterable[tuple[int, int | None, datetime]]
                      ) -> dict[int, list[dict[str, Any]]]:
    """For each rundown (record id, tightening id, recorded at): its curves, one per trace
    type (the newest), in a session the caller holds (the results screens' read)."""
    recs = list(records)
    if not recs:
        return {}
    ids = [r[0] for r in recs]
    tids = {r[1] for r in recs if r[1] is not None}
    linked = s.scalars(select(TighteningCurve).where(TighteningCurve.record_id.in_(ids))
                       .order_by(TighteningCurve.id))
    loose: Iterable[TighteningCurve] = s.scalars(select(TighteningCurve).where(
        TighteningCurve.record_id.is_(None),
        TighteningCurve.tightening_id.in_(tids)).order_by(TighteningCurve.id)) if tids else []
    out: dict[int, dict[int, TighteningCurve]] = {i: {} for i in ids}
    for c in loose:     # the rundown closest in time with that tightening id
        near = [r for r in recs if r[1] == c.tightening_id
                and abs(r[2] - c.recorded_at) <= MATCH_WINDOW]
        if near:
            best = min(near, key=lambda r: abs(r[2] - c.recorded_at))
            out[best[0]][c.trace_type] = c
    for c in linked:    # stored with the rundown: these win
        if c.record_id is not None:
            out[c.record_id][c.trace_type] = c
    return {i: [_json(c) for c in sorted(by.values(), key=lambda c: c.trace_type)]
            for i, by in out.items() if by}


def _json(c: TighteningCurve) -> dict[str, Any]:
    return {"id": c.id, "record_id": c.record_id, "tightening_id": c.tightening_id,
            "trace_type": c.trace_type, "name": TRACE_NAMES.get(c.trace_type,
                                                               f"trace {c.trace_type}"),
            "unit": c.unit, "sample_period_s": c.sample_period_s, "values": list(c.values),
            "times_s": None if c.times_s is None else list(c.times_s),
            "result_at": None if c.result_at is None else c.result_at.isoformat(),
            "recorded_at": c.recorded_at.isoformat()}
