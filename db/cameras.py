"""Each stereo pair's cameras, pinned to the calibration they were first used with.

Why: a pair's calibration describes two particular cameras (their lenses, their sensors, how
they are mounted).  A camera replaced by another unit (or the two swapped), with the pair not
calibrated again, still gave frames of the right size, and the station localized the wrench
with the old unit's calibration: bolts found where they are not.  The serial number each side
reports is pinned the first time the pair opens under a calibration (its digest); under the
same calibration another serial is refused, and a new calibration pins anew.  A camera that
reports no serial number is not pinned (nothing to tell it by).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy.exc import SQLAlchemyError

from db.engine import write_session
from db.errors import DatabaseError
from db.models import CameraPin
from db.repository import Repository


@dataclass(frozen=True)
class Replaced:
    """A side whose camera is not the one its pair's calibration was pinned to."""

    side: str
    pinned: str          # the serial number the calibration was first used with
    pinned_at: datetime
    seen: str            # the serial number the camera reports now


def pin_cameras(repo: Repository, pair: str, calibration: str,
                serials: Mapping[str, str | None]) -> list[Replaced]:
    """Pin each side's serial (``serials``: side -> serial number, None: not reported) to
    ``pair``'s ``calibration`` where none is pinned yet; the sides whose camera differs from
    its pin.  One committed transaction; ``DatabaseError`` when the database fails."""
    try:
        with write_session(repo.engine) as s:
            out: list[Replaced] = []
            for side, serial in serials.items():
                if not serial:
                    continue
                pin = s.get(CameraPin, (pair, side, calibration))
                if pin is None:
                    s.add(CameraPin(pair=pair, side=side, calibration=calibration,
                                    serial=serial[:128]))
                elif pin.serial != serial[:128]:
                    out.append(Replaced(side, pin.serial, pin.pinned_at, serial))
            return out
    except SQLAlchemyError as exc:
        raise DatabaseError(f"cameras of {pair} not checked against their calibration: "
                            f"{str(exc).splitlines()[0]}") from None


__all__ = ["Replaced", "pin_cameras"]
