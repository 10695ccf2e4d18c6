"""A rundown of the results feed (:meth:`db.ledger.Ledger.since`) as the companion model's
ResultDataType: JoiningResultMetaDataType + JoiningResultDataType (OPC 40450-1 1.01, the field
names of the vendored files).  Call after :func:`stationd.opcua.model.load_model`: the classes
are asyncua's, generated from the loaded definitions.

The curve, where one was kept (the controller's traces, :mod:`db.curves`), is the result
content's ``Trace`` as the model has it: a JoiningTraceDataType (TraceId, ResultId) whose
StepTraces each hold traces of one length on one time base (StepTraceContent: a
TraceContentDataType per quantity, its ``Values`` the samples, its PhysicalQuantity 1 TIME,
2 TORQUE, 3 ANGLE, 0 OTHER, and its EngineeringUnits; the time trace in seconds first when
the controller gave a sample period or the sample times; ``SamplingInterval`` in ms).  The
torque and angle traces of a tightening share their time base, so they are one StepTrace.
Since the result has no program steps of its own, one StepResult (``StepResults``) stands for
the rundown, naming that trace: a client that follows StepResultId / StepTraceId finds it.
The overall values carry their PhysicalQuantity too.  Every field is a plain structure or
array of the model: the standard's encoding, no workaround (tested with a client that builds
its classes from the server's definitions).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from db.kinds import LOOSENING, OK, TIGHTENING, UNKNOWN_TYPE_HELD, message_words
from db.ledger import CONTROLLER_EVENT as CONTROLLER_EVENT_KIND
from db.ledger import RUNDOWN as RUNDOWN_KIND
from db.ledger import UNATTRIBUTED as UNATTRIBUTED_KIND
from db.ledger import UNREADABLE as UNREADABLE_KIND
from db.ledger import Series, result_id
from drivers.wrench.base import ResultType
from stationd.opcua.uatypes import ua

#: the result type code of a loosening (Open Protocol's, kept with an unattributed result)
LOOSENING_TYPE = int(ResultType.LOOSENING)

CLASSIFICATION_SINGLE = 1
PQ_OTHER, PQ_TIME, PQ_TORQUE, PQ_ANGLE = 0, 1, 2, 3       # IJT Base PhysicalQuantity
TRACE_ANGLE, TRACE_TORQUE = 1, 2                          # Open Protocol trace types
EVALUATION_OK, EVALUATION_NOT_OK = 1, 2
#: a result whose message the station could not read: whether it was OK is not known
EVALUATION_NOT_DECIDABLE = 3
RESULT_STATE_COMPLETED = 1
ENTITY_VEHICLE, ENTITY_JOINT = 20, 23     # what the working group's clients use
#: the operator signed in at the station: the standard has no entity type for a person, and
#: keeps the negative ones for applications' own ("EntityType < 0 can be used")
ENTITY_OPERATOR = -1
#: who entered the result from the controller's own screen (its message could not be read):
#: present only on an entered result, so an MES tells it from a measured one by it
ENTITY_ENTERED_BY = -2
#: AssemblyType (the working group's test client: 1 ASSEMBLED, 2 DISASSEMBLED): a loosening
#: is told from a tightening by it, never left to read as one more OK joint
ASSEMBLED, DISASSEMBLED = 1, 2
UNECE = "http://www.opcfoundation.org/UA/units/un/cefact"
#: the joining technology of every result (the JoiningSystem's Identification says it too)
JOINING_TECHNOLOGY = "Tightening"


def message(rec: dict[str, Any]) -> str:
    """What a result event's Message says of the rundown ``rec`` (a feed record): its
    vehicle, bolt, kind and verdict, and the controller's tightening id, "WVW... B12:
    loosening OK (controller id 17)".  An MES that reads only the Message (no client decodes
    the metadata's AssemblyType without the types) must not take a loosening for one more
    tightened joint, nor an outcome a person entered for one the station measured, and finds
    the rundown on the controller by its id."""
    kind = LOOSENING if rec.get("rundown") == LOOSENING else TIGHTENING
    tid = rec.get("tightening_id")
    # the id after the verdict, in parentheses, in words without "tightening" (an MES that
    # looks for the word must not take a loosening for one; split on blanks the verdict
    # stays a word of its own)
    return f"{rec['vin']} {rec['bolt']}: {kind} {str(rec['status']).upper()}" + (
        f" (controller id {tid})" if tid is not None else "") + (
        f" (entered by {rec['entered_by']}, not measured)" if rec.get("entered_by") else "")


def other_message(kind: str, rec: dict[str, Any]) -> str:
    """What a result event's Message says of a controller result the station attributed to
    no bolt (``kind`` unattributed) or could not read (unreadable): "WVW...: tightening OK of
    no bolt (controller id 17)", "WVW... B12: result not readable (controller id 18): held
    for a supervisor".  An MES that reads only the Message tells it from a joint's rundown by
    the words "no bolt" / "not readable" where a bolt and a verdict stand in a rundown's."""
    vin, tid = rec.get("vin") or "no vehicle", rec.get("tightening_id")
    said = "" if tid is None else f" (controller id {tid})"
    if kind == CONTROLLER_EVENT_KIND:    # not taken (:func:`not_taken_result`)
        bolt = rec.get("bolt")
        what = f"result of unknown type {rec.get('result_type')}" \
            if rec.get("what") == UNKNOWN_TYPE_HELD else "OK"
        return f"{vin}{' ' + bolt if bolt else ''}: {what} not taken for a tightening{said}" + (
            ": held for a supervisor" if bolt else "")
    if kind == UNREADABLE_KIND:
        bolt = rec.get("bolt")
        return f"{vin}{' ' + bolt if bolt else ''}: result not readable{said}" + (
            ": held for a supervisor" if bolt else "")
    what = "loosening" if rec.get("result_type") == LOOSENING_TYPE else "tightening"
    return f"{vin}: {what} {str(rec['status']).upper()} of no bolt{said}"


def _unit(code: str, symbol: str, text: str) -> Any:
    """An engineering unit by its UNECE common code (Part 8: the UnitId is the code's bytes)."""
    uid = 0
    for c in code:
        uid = (uid << 8) | ord(c)
    return ua.EUInformation(NamespaceUri=UNECE, UnitId=uid,
                            DisplayName=ua.LocalizedText(symbol),
                            Description=ua.LocalizedText(text))


def _units() -> dict[str, Any]:
    return {"Nm": _unit("NU", "N·m", "newton metre"), "deg": _unit("DD", "°", "degree"),
            "s": _unit("SEC", "s", "second")}


def _other_unit(text: str) -> Any:
    """A unit the station has no UNECE code for (a trace kept in the controller's unit):
    named, UnitId -1 (Part 8: not available)."""
    return ua.EUInformation(NamespaceUri=UNECE, UnitId=-1, DisplayName=ua.LocalizedText(text),
                            Description=ua.LocalizedText(text))


def parse_result_id(series: Series, text: str) -> int | None:
    """The feed's sequence number in a ResultId of this database (:func:`result_id` with
    the id ``series`` gives that record, as the line keeps it); None for any other (a
    replaced database's, another series' of this one, or not one of this server's)."""
    head, sep, tail = text.rpartition(":")
    if not sep or not (tail.isascii() and tail.isdigit()) or not 0 < int(tail) < 2**63:
        return None
    return int(tail) if head == series.id_of(int(tail)) else None


def _time(text: str | None) -> datetime | None:
    if text is None:
        return None
    t = datetime.fromisoformat(text)
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def _value(name: str, measured: float | None, limits: dict[str, float] | None,
           unit: Any, ok: bool, quantity: int) -> Any:
    lim = limits or {}
    return ua.ResultValueDataType(
        MeasuredValue=float(measured) if measured is not None else float("nan"),
        Name=name,
        PhysicalQuantity=quantity,
        ResultEvaluation=_evaluation(value_ok(measured, lim, ok)),
        LowLimit=None if lim.get("min") is None else float(lim["min"]),
        High=None if lim.get("max") is None else float(lim["max"]),
        TargetValue=None if lim.get("target") is None else float(lim["target"]),
        EngineeringUnits=unit)


def value_ok(measured: float | None, limits: dict[str, float], ok: bool) -> bool:
    """One value's own evaluation: within its limits (those sent with the parameters), or,
    where the value or both its limits are not known, the result's ``ok``.  Why: a NOK for
    an angle below its minimum gave the torque within its limits NotOK as well, and an MES
    counting torque failures counted it."""
    lo, hi = limits.get("min"), limits.get("max")
    if measured is None or (lo is None and hi is None):
        return ok
    return (lo is None or float(measured) >= float(lo)) and \
        (hi is None or float(measured) <= float(hi))


def _evaluation(ok: bool) -> Any:
    enum = ua.ResultEvaluationEnum
    return enum(EVALUATION_OK if ok else EVALUATION_NOT_OK)


def _content(curve: dict[str, Any], units: dict[str, Any]) -> Any:
    """One trace (a curve of :mod:`db.curves`) as a TraceContentDataType."""
    kind = int(curve["trace_type"])
    unit = str(curve.get("unit") or "")
    if kind == TRACE_TORQUE and unit == "Nm":
        name, quantity = "Torque", PQ_TORQUE
    elif kind == TRACE_ANGLE and unit == "deg":
        name, quantity = "Angle", PQ_ANGLE
    else:   # current, gradient, ... or a unit not converted: named, quantity OTHER
        name, quantity = str(curve.get("name") or f"trace {kind}"), PQ_OTHER
    return ua.TraceContentDataType(
        Values=[float(v) for v in curve["values"]], Name=name, PhysicalQuantity=quantity,
        EngineeringUnits=units.get(unit) or _other_unit(unit or "?"))


def _time_base(curve: dict[str, Any]) -> tuple[Any, ...]:
    n = len(curve["values"])
    if curve.get("times_s") is not None:
        return (n, "times", tuple(float(t) for t in curve["times_s"]))
    if curve.get("sample_period_s") is not None:
        return (n, "period", float(curve["sample_period_s"]))
    return (n, "none", None)


def trace(rid: str, curves: list[dict[str, Any]]) -> tuple[Any, str, str | None]:
    """The JoiningTraceDataType of the rundown ``rid`` from its ``curves`` (one per trace
    type), the StepResultId its step traces name and the first StepTraceId (see the
    module's docstring)."""
    units = _units()
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for c in sorted(curves, key=lambda c: int(c["trace_type"])):
        groups.setdefault(_time_base(c), []).append(c)
    step_id = f"{rid}:step:1"
    steps = []
    for n, ((points, how, base), group) in enumerate(groups.items(), 1):
        contents = [_content(c, units) for c in group]
        period_ms: float | None = None
        times: list[float] | None = None
        if how == "period":
            period_ms = base * 1000.0
            times = [i * base for i in range(points)]
        elif how == "times":
            times = list(base)
        if times is not None:
            contents.insert(0, ua.TraceContentDataType(
                Values=times, Name="Time", PhysicalQuantity=PQ_TIME,
                EngineeringUnits=units["s"]))
        steps.append(ua.StepTraceDataType(
            StepTraceId=f"{rid}:trace:{n}", StepResultId=step_id,
            NumberOfTracePoints=points, SamplingInterval=period_ms,
            StepTraceContent=contents))
    return (ua.JoiningTraceDataType(TraceId=f"{rid}:trace", ResultId=rid, StepTraces=steps),
            step_id, steps[0].StepTraceId if steps else None)


#: the ExtendedMetaData key of the controller's own number of the rundown (Open Protocol's
#: tightening id): what an MES matches against the controller's records
TIGHTENING_ID = "TighteningId"


#: the largest UInt32 (Open Protocol's tightening ids are 10 digits, a Modbus map may read
#: a signed register: a value outside 0..2^32-1 is not sent as one)
UINT32_MAX = 2 ** 32 - 1


def _extended(rec: dict[str, Any]) -> list[Any] | None:
    """The metadata no field of the result has: the controller's tightening id (a UInt32,
    as Open Protocol numbers them; none for an outcome entered by a person without one, nor
    for an id no UInt32 holds: encoding it failed the whole publish, and an MES's
    subscription stopped getting results)."""
    tid = rec.get("tightening_id")
    if tid is None or not 0 <= int(tid) <= UINT32_MAX:
        return None
    return [ua.KeyValueDataType(Key=TIGHTENING_ID,
                                Value=ua.Variant(int(tid), ua.VariantType.UInt32))]


def rundown_result(db_id: str, station_id: str, entry: dict[str, Any], *,
                   simulated: bool = False, curves: list[dict[str, Any]] | None = None) -> Any:
    """The ResultDataType of the feed ``entry`` of kind ``rundown``, with its ``curves``
    (:mod:`db.curves`' or the feed's, one per trace type) as its trace when it has any."""
    rec = entry["record"]
    ok = rec["status"] == OK
    loosening = rec.get("rundown") == LOOSENING
    entities = [
        ua.EntityDataType(Name="VIN", EntityId=rec["vin"], EntityType=ENTITY_VEHICLE,
                          IsExternal=True),
        ua.EntityDataType(Name="Joint", EntityId=rec["bolt"], EntityType=ENTITY_JOINT,
                          IsExternal=False),
    ]
    if rec.get("operator"):
        entities.append(ua.EntityDataType(
            Name="Operator", EntityId=rec["operator"], EntityType=ENTITY_OPERATOR,
            IsExternal=False, Description="the operator signed in at the station"))
    entered = rec.get("entered_by")
    if entered:
        entities.append(ua.EntityDataType(
            Name="EnteredBy", EntityId=entered, EntityType=ENTITY_ENTERED_BY,
            IsExternal=False, Description="entered from the controller's screen, not "
            "measured: its result could not be read" + (
                f" ({rec['entered_comment']})" if rec.get("entered_comment") else "")))
    sent = rec.get("params_sent") or {}
    pset = sent.get("pset")
    meta = _meta(
        db_id, entry, simulated=simulated, evaluation=EVALUATION_OK if ok else
        EVALUATION_NOT_OK, loosening=loosening, entities=entities, pset=pset,
        # made while the link to the controller was down, fetched at the reconnect: its
        # CreationTime is when the station took it (absent, as the standard's default false)
        offline=bool(rec.get("offline")),
        name=f"{rec['vin']} {rec['bolt']}" + (" loosening" if loosening else "")
        + (" entered" if entered else ""),
        description=f"{'loosening' if loosening else 'tightening'} of {rec['bolt']}"
        + ("" if pset is None else f" with pset {pset}") + (
            f", entered by {entered} from the controller's screen (not measured)"
            if entered else ""))
    # a loosening ran the controller's own program (its limits are the controller's): none
    # of the bolt's window, as the feed and the line database say it (an MES integrator's
    # trial: a loosening under the tightening pset read its 44 Nm as NotOK against 45-55)
    content = ua.JoiningResultDataType(OverallResultValues=_overall(
        rec, None if loosening else sent.get("torque"),
        None if loosening else sent.get("angle"), ok))
    if curves:
        rid = meta.ResultId
        content.Trace, step_id, trace_id = trace(rid, curves)
        content.StepResults = [ua.StepResultDataType(
            StepResultId=step_id, Name="Rundown", ResultEvaluation=_evaluation(ok),
            StepTraceId=trace_id)]
    return ua.ResultDataType(ResultMetaData=meta, ResultContent=[ua.Variant(content)])


def _meta(db_id: str, entry: dict[str, Any], *, simulated: bool, name: str,
          description: str, evaluation: int, loosening: bool, entities: list[Any],
          pset: Any, offline: bool = False) -> Any:
    """The metadata of a result of the feed ``entry``: a rundown's (:func:`rundown_result`)
    or a controller result's that is no joint's rundown (``pset``: its recipe, None where
    not known; ``offline``: made while the link to the controller was down)."""
    rec = entry["record"]
    return ua.JoiningResultMetaDataType(
        ResultId=result_id(db_id, entry["seq"]), IsPartial=False, IsSimulated=simulated,
        ResultState=RESULT_STATE_COMPLETED,
        # on the station's clock for every kind: a rundown's result_at is when the station
        # took it, the others' is the controller's own (to the second, its clock apart: an
        # MES integrator's trial found the two clocks mixed), so theirs is when stored
        CreationTime=(_time(rec.get("result_at")) if entry["kind"] == RUNDOWN_KIND else None)
        or _time(rec.get("recorded_at")) or _time(entry["at"]),
        ResultEvaluation=ua.ResultEvaluationEnum(evaluation),
        IsGeneratedOffline=True if offline else None,
        ProductId=rec.get("vin") or None,
        InternalRecipeId=None if pset is None else str(pset),
        SequenceNumber=int(entry["seq"]), Name=name,
        Description=ua.LocalizedText(description),
        Classification=CLASSIFICATION_SINGLE,
        # the technology of the system that made it (its Identification says the same):
        # mandatory for a joining result in the working group's reading of 40450-1
        JoiningTechnology=ua.LocalizedText(JOINING_TECHNOLOGY),
        AssemblyType=DISASSEMBLED if loosening else ASSEMBLED,
        AssociatedEntities=entities, ExtendedMetaData=_extended(rec))


def _overall(rec: dict[str, Any], torque: dict[str, float] | None,
             angle: dict[str, float] | None, ok: bool) -> list[Any]:
    """The torque and angle of a result, each with its limits (None: not known) and its
    own evaluation."""
    return [_value("Torque", rec.get("torque_nm"), torque,
                   _unit("NU", "N·m", "newton metre"), ok, PQ_TORQUE),
            _value("Angle", rec.get("angle_deg"), angle, _unit("DD", "°", "degree"), ok,
                   PQ_ANGLE)]


def _vehicle(rec: dict[str, Any], why: str) -> list[Any]:
    """The vehicle entity of a result that is no joint's rundown (``why``: which vehicle it
    is), none where no vehicle was at the station."""
    vin = rec.get("vin")
    return [] if not vin else [ua.EntityDataType(
        Name="VIN", EntityId=vin, EntityType=ENTITY_VEHICLE, IsExternal=True,
        Description=why)]


def _held_joint(rec: dict[str, Any], why: str) -> list[Any]:
    """The entities of a result that held a bolt (not read, or not taken): the vehicle at the
    station when it came, and the bolt held, as its Joint (``why``), where there was one."""
    entities = _vehicle(rec, "the vehicle at the station when it came")
    if rec.get("bolt"):
        entities.append(ua.EntityDataType(
            Name="Joint", EntityId=rec["bolt"], EntityType=ENTITY_JOINT, IsExternal=False,
            Description=why))
    return entities


def unattributed_result(db_id: str, entry: dict[str, Any], *, simulated: bool = False) -> Any:
    """The ResultDataType of the feed ``entry`` of kind ``unattributed``: a rundown the
    controller made that the station attributed to no bolt (why in its Description), its
    vehicle the one it was filed under, no joint.  Why published: an MES counting the
    controller's rundowns from the station's results missed these (a rundown outside any
    tool enable, a result fetched late that nothing proves a bolt's)."""
    rec = entry["record"]
    ok = rec["status"] == OK
    loosening = rec.get("result_type") == LOOSENING_TYPE
    kind = LOOSENING if loosening else TIGHTENING
    pset = "" if rec.get("pset") is None else f" with pset {rec['pset']}"
    meta = _meta(
        db_id, entry, simulated=simulated, evaluation=EVALUATION_OK if ok else
        EVALUATION_NOT_OK, loosening=loosening, pset=rec.get("pset"),
        name=f"{rec.get('vin') or 'no vehicle'} unattributed",
        description=f"{kind}{pset} attributed to no bolt: {rec.get('reason') or 'not said'}",
        entities=_vehicle(rec, "the vehicle the result was filed under; no bolt is its"))
    content = ua.JoiningResultDataType(OverallResultValues=_overall(rec, None, None, ok))
    return ua.ResultDataType(ResultMetaData=meta, ResultContent=[ua.Variant(content)])


def unreadable_result(db_id: str, entry: dict[str, Any], *, simulated: bool = False) -> Any:
    """The ResultDataType of the feed ``entry`` of kind ``unreadable``: a result message the
    station could not read (kept whole in its records), its evaluation NotDecidable, no
    values; the bolt it was held against, where one was, is its joint (held for a
    supervisor, who checks it on the controller).  Why published: an MES saw nothing of it,
    the bolt neither done nor said held."""
    rec = entry["record"]
    bolt = rec.get("bolt")
    entities = _held_joint(rec, "the bolt it may be the result of: held for a supervisor")
    meta = _meta(
        db_id, entry, simulated=simulated, evaluation=EVALUATION_NOT_DECIDABLE,
        loosening=False, entities=entities, pset=rec.get("pset"),
        name=f"{rec.get('vin') or 'no vehicle'}{' ' + bolt if bolt else ''} not readable",
        description=message_words(int(rec.get("mid") or 0), int(rec.get("revision") or 0))
                    + f" not readable: {rec.get('error')}"
                    + (f"; {bolt} held for a supervisor" if bolt else ""))
    return ua.ResultDataType(ResultMetaData=meta,
                             ResultContent=[ua.Variant(ua.JoiningResultDataType())])


def not_taken_result(db_id: str, entry: dict[str, Any], *, simulated: bool = False) -> Any:
    """The ResultDataType of the feed ``entry`` of a controller event that is an OK result
    without a type whose torque lies outside its bolt's window (:data:`db.kinds.NOT_TAKEN`):
    perhaps no tightening at all (a batch increment or a bypass reads so at a revision
    without types), perhaps a real one with other limits on the controller; or a result of
    a type the station does not know under a bolt's enable (:data:`db.kinds.UNKNOWN_TYPE_HELD`).
    Its evaluation NotDecidable (the controller's OK is not the station's: an MES reading OK
    for the joint would count it tightened), its values as sent, the bolt held for a
    supervisor as its joint.  Why published: an MES counting the controller's rundowns
    missed it, and saw the bolt neither done nor said held."""
    rec = entry["record"]
    bolt = rec.get("bolt")
    entities = _held_joint(rec, "the bolt the tool was enabled for: held for a supervisor")
    pset = "" if rec.get("pset") is None else f" of pset {rec['pset']}"
    what = f"a result of type {rec.get('result_type')}{pset}, a type the station does not " \
        "know" if rec.get("what") == UNKNOWN_TYPE_HELD else \
        f"an OK without a result type{pset}, its torque outside {bolt or 'the bolt'}'s window"
    meta = _meta(
        db_id, entry, simulated=simulated, evaluation=EVALUATION_NOT_DECIDABLE,
        loosening=False, entities=entities, pset=rec.get("pset"),
        name=f"{rec.get('vin') or 'no vehicle'}{' ' + bolt if bolt else ''} not taken",
        description=f"{what}: not taken for a tightening"
                    + (f"; {bolt} held for a supervisor" if bolt else ""))
    values = _overall(rec, None, None, True)
    for v in values:      # the controller's OK, not the station's: not decided either
        v.ResultEvaluation = ua.ResultEvaluationEnum(EVALUATION_NOT_DECIDABLE)
    content = ua.JoiningResultDataType(OverallResultValues=values)
    return ua.ResultDataType(ResultMetaData=meta, ResultContent=[ua.Variant(content)])


def any_result(db_id: str, entry: dict[str, Any], *, simulated: bool = False,
               curves: list[dict[str, Any]] | None = None) -> Any:
    """The ResultDataType of any result entry of the feed (:data:`RESULT_KINDS`)."""
    if entry["kind"] == UNATTRIBUTED_KIND:
        return unattributed_result(db_id, entry, simulated=simulated)
    if entry["kind"] == UNREADABLE_KIND:
        return unreadable_result(db_id, entry, simulated=simulated)
    if entry["kind"] == CONTROLLER_EVENT_KIND:
        return not_taken_result(db_id, entry, simulated=simulated)
    return rundown_result(db_id, "", entry, simulated=simulated, curves=curves)


def any_message(entry: dict[str, Any]) -> str:
    """The Message of the result event of any result entry of the feed."""
    if entry["kind"] in (UNATTRIBUTED_KIND, UNREADABLE_KIND, CONTROLLER_EVENT_KIND):
        return other_message(entry["kind"], entry["record"])
    return message(entry["record"])


__all__ = ["ASSEMBLED", "CLASSIFICATION_SINGLE", "DISASSEMBLED", "ENTITY_ENTERED_BY",
           "ENTITY_JOINT",
           "ENTITY_OPERATOR", "ENTITY_VEHICLE", "EVALUATION_NOT_OK",
           "EVALUATION_OK", "JOINING_TECHNOLOGY", "PQ_ANGLE", "PQ_OTHER", "PQ_TIME",
           "PQ_TORQUE", "TIGHTENING_ID", "message", "parse_result_id", "result_id",
           "rundown_result", "trace", "value_ok"]
