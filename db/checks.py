"""Calibration checks: each camera pair's check against the reference markers, stored and read.

Why a module beside the repository: a check is not part of a vehicle's records (the
repository's write path); like the curves it goes through the repository's engine, each
write one committed transaction that also gives it its results-feed entry, so the line
database and the MES get it with the rundowns, in order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from db.engine import write_session
from db.errors import DatabaseError, DataError
from db.ledger import CHECK, append
from db.models import CalibrationCheck
from db.repository import Repository

VERDICTS = ("ok", "moved", "not checked")


def _finite(v: float | None, what: str) -> float | None:
    if v is None:
        return None
    f = float(v)
    if not math.isfinite(f):
        raise DataError(f"{what}: {v!r} is not a finite number")
    return f


def record_check(repo: Repository, *, at: datetime, pair: str, verdict: str,
                 reference: str | None, offset_mm: float | None, tolerance_mm: float,
                 reason: str | None, references: Mapping[str, Mapping[str, Any]]) -> int:
    """Store one pair's check with its feed entry; return its id.  Committed before it
    returns.  ``DataError`` for an unknown verdict, a naive time or a value that is not a
    finite number; ``DatabaseError`` when the database fails."""
    if verdict not in VERDICTS:
        raise DataError(f"verdict {verdict!r}: one of {', '.join(VERDICTS)}")
    if at.tzinfo is None:
        raise DataError("at: a timestamp with a timezone (UTC) is needed")
    refs = {str(k): {"offset_mm": _finite(v.get("offset_mm"), f"{k} offset_mm"),
                     "measured_mm": None if v.get("measured_mm") is None else
                     [_finite(x, f"{k} measured_mm") for x in v["measured_mm"]],
                     "why": v.get("why"), "note": v.get("note")}
            for k, v in references.items()}
    row = CalibrationCheck(at=at, pair=pair[:64], verdict=verdict,
                           reference=None if reference is None else reference[:64],
                           offset_mm=_finite(offset_mm, "offset_mm"),
                           tolerance_mm=_finite(tolerance_mm, "tolerance_mm"),
                           reason=None if reason is None else reason[:200], references=refs)
    try:
        with write_session(repo.engine) as s:
            s.add(row)
            s.flush()
            append(s, CHECK, row.id, row.recorded_at)
            return int(row.id)
    except SQLAlchemyError as exc:
        raise DatabaseError(f"calibration check of {pair} not stored: "
                            f"{str(exc).splitlines()[0]}") from None


def checks(repo: Repository, pair: str | None = None, limit: int = 1000
           ) -> list[dict[str, Any]]:
    """The checks (of ``pair``, or all), newest first, at most ``limit``."""
    with Session(repo.engine) as s:
        q = select(CalibrationCheck).order_by(CalibrationCheck.id.desc()).limit(limit)
        if pair is not None:
            q = q.where(CalibrationCheck.pair == pair)
        return [{"id": k.id, "at": k.at, "pair": k.pair, "verdict": k.verdict,
                 "reference": k.reference, "offset_mm": k.offset_mm,
                 "tolerance_mm": k.tolerance_mm, "reason": k.reason,
                 "references": k.references} for k in s.scalars(q)]


__all__ = ["VERDICTS", "checks", "record_check"]
