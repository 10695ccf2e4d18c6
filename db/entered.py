"""Outcomes a person entered for a held bolt: the result the controller could not send
readably, read on the controller's own screen by a supervisor and entered by them.

Why a module of its own: such an outcome is a rundown (it closes the bolt when OK and counts
as a NOK otherwise, also after a restart: :meth:`Repository.nok_streaks` and
:meth:`Repository.held_bolts` read it as any rundown), yet it was not measured by the
station.  It is written with the command that entered it, in one transaction (the command's
record is the audit trail, the rundown the result), and carries its provenance: who entered
it (``entered_by``), their comment, and the unreadable result it resolves (or, for a bolt
held by an OK result without a type outside its torque window, that result's tightening id).
Where the wrench was and the parameters sent are those of the tool enable the held result
answered (none stored: zeros and the bolt's current parameter version).  Its ``kind`` is the
held result's: a loosening where the bolt's loosen pset ran (the station knows which: the
selection it held the bolt under), so that an OK entered for it is the bolt loosened, to be
tightened again, in the records, the reports and the line database, never a tightening.
"""

from __future__ import annotations

import math
from datetime import datetime

from sqlalchemy import select
from sqlalchemy.exc import SQLAlchemyError

from db.engine import write_session
from db.errors import DatabaseError, DataError, NotFoundError
from db.importer import current_version, parameters_of, sent_bolt
from db.kinds import (
    ENTER_OUTCOME,
    HELD_WITH_RESULT,
    HELD_WITHOUT_RESULT,
    LOOSENING,
    RUNDOWN_KINDS,
    TIGHTENING,
    verdict,
)
from db.ledger import RUNDOWN, add_command, append
from db.models import (
    Bolt,
    ControllerEvent,
    ProcessParameters,
    TighteningRecord,
    ToolEnable,
    UnreadableRecord,
    Vehicle,
    utcnow,
)
from db.repository import Repository, _params_json


def record_entered(repo: Repository, *, vin: str, bolt: str, ok: bool, torque_nm: float,
                   angle_deg: float, at: datetime, user: str, source: str,
                   comment: str, kind: str = TIGHTENING, pset: int | None = None) -> int:
    """The command and the rundown it enters for ``bolt`` of the open vehicle ``vin``, with
    their feed entries, committed together; return the rundown's id.  ``kind``: the held
    result's, ``tightening`` or ``loosening``; a loosening is stored as a measured one is,
    with what was sent: its loosen pset (``pset``, else the enable's), no targets of the
    station's.  ``DataError`` for a value that is not a finite number, an unknown kind, a
    naive time or a closed vehicle; ``NotFoundError`` for an unknown VIN or bolt;
    ``DatabaseError`` when the database fails."""
    if not (math.isfinite(torque_nm) and math.isfinite(angle_deg)):
        raise DataError("torque and angle: finite numbers")
    if kind not in RUNDOWN_KINDS:
        raise DataError(f"kind {kind!r}: one of {', '.join(RUNDOWN_KINDS)}")
    if at.tzinfo is None:
        raise DataError("at: a timestamp with a timezone (UTC) is needed")
    try:
        with write_session(repo.engine) as s:
            v = s.scalar(select(Vehicle).where(Vehicle.vin == vin))
            if v is None:
                raise NotFoundError(f"vehicle {vin!r} is not in the database")
            if v.ended_at is not None:
                raise DataError(f"vehicle {vin} is closed: an outcome cannot be entered")
            b = s.scalar(select(Bolt).where(Bolt.model_id == v.model_id, Bolt.code == bolt,
                                            Bolt.removed_at.is_(None)))
            if b is None:
                # retired since the station enabled the tool for it: its outcome is still
                # its own, as a measured result is
                b = sent_bolt(s, s.scalar(select(ToolEnable.parameters_id).where(
                    ToolEnable.vin == vin, ToolEnable.bolt == bolt)
                    .order_by(ToolEnable.id.desc()).limit(1)), v.model_id, bolt)
            if b is None:
                raise NotFoundError(f"bolt {bolt!r} is not a bolt of model {v.model.name}")
            add_command(s, at=at, user=user, source=source, kind=ENTER_OUTCOME, vin=vin,
                        bolt=bolt, comment=comment)
            held = s.scalar(select(UnreadableRecord).where(
                UnreadableRecord.vin == vin, UnreadableRecord.bolt == bolt)
                .order_by(UnreadableRecord.id.desc()).limit(1))
            # or held by an OK result without a type outside the torque window, read but not
            # taken for a tightening: its tightening id is the one entered for; or by a link
            # cut during its enable that left its result unknown (no id: none was read)
            not_taken = s.scalar(select(ControllerEvent).where(
                ControllerEvent.vin == vin, ControllerEvent.bolt == bolt,
                ControllerEvent.what.in_((*HELD_WITH_RESULT, *HELD_WITHOUT_RESULT)))
                .order_by(ControllerEvent.id.desc()).limit(1))
            if not_taken is not None and (held is None
                                          or not_taken.recorded_at >= held.recorded_at):
                held = None
            tightening_id = held.tightening_id if held is not None else \
                not_taken.tightening_id if not_taken is not None else None
            if tightening_id is not None and held is None and s.scalar(
                    select(TighteningRecord.id).where(
                        TighteningRecord.vehicle_id == v.id,
                        TighteningRecord.tightening_id == tightening_id,
                        TighteningRecord.entered_by.is_not(None)).limit(1)) is not None:
                # a lost push's result that held two bolts, entered as the other's outcome
                # already: one controller result is one bolt's (a reviewer: both carried it)
                tightening_id = None
            # the bolt is held since that result: no tool enable for it came after
            enable = s.scalar(select(ToolEnable).where(
                ToolEnable.vin == vin, ToolEnable.bolt == bolt)
                .order_by(ToolEnable.id.desc()).limit(1))
            version = s.get(ProcessParameters, enable.parameters_id) \
                if enable is not None and enable.parameters_id is not None else None
            if version is None or version.bolt_id != b.id:
                version = current_version(b)
            sel = enable.selection if enable is not None else {}
            # a loosening ran its loosen pset: the controller's program, not the bolt's targets
            # (the shape the station stores with a measured loosening)
            sent = _params_json(parameters_of(version)) if kind != LOOSENING else {
                "pset": pset if pset is not None or enable is None else enable.pset,
                "torque": None, "angle": None, "loosen": True}
            x, y, z = (float(c) for c in sel.get("point_mm", (0.0, 0.0, 0.0)))
            rec = TighteningRecord(
                vehicle_id=v.id, bolt_id=b.id, parameters_id=version.id, x_mm=x, y_mm=y,
                z_mm=z, match_distance_mm=float(sel.get("distance_mm", 0.0)),
                tilt_deg=float(sel.get("tilt_deg", 0.0)),
                params_sent=sent, acknowledged=True,
                status=verdict(ok), torque_nm=float(torque_nm),
                angle_deg=float(angle_deg),
                tightening_id=tightening_id,
                sent_at=enable.enabled_at if enable is not None else None,
                result_at=at, recorded_at=utcnow(), images=[], kind=kind,
                operator=sel.get("operator"), entered_by=user[:64],
                entered_comment=comment[:500],
                unreadable_id=held.id if held is not None else None,
                # the controller's own time of the result this outcome is (a quality
                # auditor's trial: the entered row had only when it was typed in)
                controller_at=held.result_at if held is not None else
                not_taken.result_at if not_taken is not None and tightening_id is not None
                else None)
            s.add(rec)
            s.flush()
            append(s, RUNDOWN, rec.id, rec.recorded_at)
            return int(rec.id)
    except SQLAlchemyError as exc:
        raise DatabaseError(f"the outcome entered for {bolt} of {vin} not stored: "
                            f"{str(exc).splitlines()[0]}") from None


__all__ = ["ENTER_OUTCOME", "record_entered"]
