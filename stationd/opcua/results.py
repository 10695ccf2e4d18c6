"""A rundown of the results feed (:meth:`db.ledger.Ledger.since`) as the companion model's
ResultDataType: JoiningResultMetaDataType + JoiningResultDataType (OPC 40450-1 1.01, the field
names of the vendored files).  Call after :func:`stationd.opcua.model.load_model`: the classes
are asyncua's, generated from the loaded definitions."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from stationd.opcua.uatypes import ua

CLASSIFICATION_SINGLE = 1
EVALUATION_OK, EVALUATION_NOT_OK = 1, 2
RESULT_STATE_COMPLETED = 1
ENTITY_VEHICLE, ENTITY_JOINT = 20, 23     # what the working group's clients use
UNECE = "http://www.opcfoundation.org/UA/units/un/cefact"


def _unit(code: str, symbol: str, text: str) -> Any:
    """An engineering unit by its UNECE common code (Part 8: the UnitId is the code's bytes)."""
    uid = 0
    for c in code:
        uid = (uid << 8) | ord(c)
    return ua.EUInformation(NamespaceUri=UNECE, UnitId=uid,
                            DisplayName=ua.LocalizedText(symbol),
                            Description=ua.LocalizedText(text))


def result_id(db_id: str, seq: int) -> str:
    """The ResultId of feed entry ``seq``: unique across a replaced station database."""
    return f"{db_id}:{seq}"


def parse_result_id(db_id: str, text: str) -> int | None:
    """The feed's sequence number in a ResultId of this database (:func:`result_id`); None
    for any other (a replaced database's, or not one of this server's)."""
    head, sep, tail = text.rpartition(":")
    if not sep or head != db_id or not (tail.isascii() and tail.isdigit()):
        return None
    if not 0 < int(tail) < 2**63:
        return None
    return int(tail)


def _time(text: str | None) -> datetime | None:
    if text is None:
        return None
    t = datetime.fromisoformat(text)
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def _value(name: str, measured: float | None, limits: dict[str, float] | None,
           unit: Any, ok: bool) -> Any:
    lim = limits or {}
    return ua.ResultValueDataType(
        MeasuredValue=float(measured) if measured is not None else float("nan"),
        Name=name,
        ResultEvaluation=_evaluation(ok),
        LowLimit=None if lim.get("min") is None else float(lim["min"]),
        High=None if lim.get("max") is None else float(lim["max"]),
        TargetValue=None if lim.get("target") is None else float(lim["target"]),
        EngineeringUnits=unit)


def _evaluation(ok: bool) -> Any:
    enum = ua.ResultEvaluationEnum
    return enum(EVALUATION_OK if ok else EVALUATION_NOT_OK)


def rundown_result(db_id: str, station_id: str, entry: dict[str, Any], *,
                   simulated: bool = False) -> Any:
    """The ResultDataType of the feed ``entry`` of kind ``rundown``."""
    rec = entry["record"]
    ok = rec["status"] == "ok"
    sent = rec.get("params_sent") or {}
    pset = sent.get("pset")
    created = _time(rec.get("result_at")) or _time(rec.get("recorded_at")) or \
        _time(entry["at"])
    meta = ua.JoiningResultMetaDataType(
        ResultId=result_id(db_id, entry["seq"]),
        IsPartial=False,
        IsSimulated=simulated,
        ResultState=RESULT_STATE_COMPLETED,
        CreationTime=created,
        ResultEvaluation=_evaluation(ok),
        ProductId=rec["vin"],
        InternalRecipeId=None if pset is None else str(pset),
        SequenceNumber=int(entry["seq"]),
        Name=f"{rec['vin']} {rec['bolt']}",
        Classification=CLASSIFICATION_SINGLE,
        AssociatedEntities=[
            ua.EntityDataType(Name="VIN", EntityId=rec["vin"], EntityType=ENTITY_VEHICLE,
                              IsExternal=True),
            ua.EntityDataType(Name="Joint", EntityId=rec["bolt"], EntityType=ENTITY_JOINT,
                              IsExternal=False),
        ])
    content = ua.JoiningResultDataType(OverallResultValues=[
        _value("Torque", rec.get("torque_nm"), sent.get("torque"),
               _unit("NU", "N·m", "newton metre"), ok),
        _value("Angle", rec.get("angle_deg"), sent.get("angle"),
               _unit("DD", "°", "degree"), ok),
    ])
    return ua.ResultDataType(ResultMetaData=meta, ResultContent=[ua.Variant(content)])


__all__ = ["CLASSIFICATION_SINGLE", "ENTITY_JOINT", "ENTITY_VEHICLE", "EVALUATION_NOT_OK",
           "EVALUATION_OK", "parse_result_id", "result_id", "rundown_result"]
