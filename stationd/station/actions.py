"""The core's actions: what the shell is to do (send parameters, enable or disable the tool,
record a rundown, publish an event, answer a command), typed, returned in order by
:meth:`stationd.station.core.StationCore.feed`.

Why a module of their own: the shell (:mod:`stationd.shell.effects`) carries out exactly these,
and nothing else may reach a device or the database."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from db.bolts import Parameters
from db.kinds import CUT_UNKNOWN, TIGHTENING
from drivers.wrench.base import Received, TighteningResult, UnreadableResult
from stationd.reasons import Reason, Unattributed
from stationd.station.commands import (
    Answer,
    Command,
    Issuer,
)
from stationd.station.events import StateReason, StationEvent
from stationd.station.trust import MeasureReferences, RecordCheck


# -- actions ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Selection:
    """What decided a bolt's selection, kept with its record: the vehicle and the parameter
    version travel with it, so a result arriving after a reload or restart is recorded to the
    vehicle and version the tool was enabled for."""

    bolt: str
    pset: int | None
    point_mm: tuple[float, float, float]
    tilt_deg: float
    distance_mm: float
    exposure_t: float
    decided_t: float
    evidence: Any = None
    vin: str = ""
    parameters_id: int | None = None
    loosen: bool = False    # ``pset`` is the bolt's loosen pset: a loosening was asked for
    operator: str | None = None   # who was signed in at the station (None: nobody)
    #: the bolt's torque window (min, max Nm) when it was selected: an OK without a type is
    #: checked against it also once its vehicle has left (None: not known)
    torque_window: tuple[float, float] | None = None


def torque_window(parameters: Parameters | None) -> tuple[float, float] | None:
    """A bolt's torque window (min, max Nm) from its process parameters, None where it has
    none: kept with its selection (:attr:`Selection.torque_window`)."""
    if parameters is None:
        return None
    return float(parameters.torque.min), float(parameters.torque.max)


@dataclass(frozen=True)
class Owed:
    """What a station owes the next one (a reload, a restart): the tool was enabled for
    ``selection`` and went off at ``off_at`` (the new station's start when it stopped with the
    tool on); a result of its pset within ``late_result_s`` of that belongs to that bolt
    (or, with ``cut_rundown``, its result is in and the tool may have run again)."""

    selection: Selection
    off_at: float
    #: when the tool was enabled (noted just before), on the station's clock
    enabled_at: float | None = None
    #: its late-result window still runs: a result of its pset pushed now is its own
    in_window: bool = True
    #: answered already by a rundown made during a link cut (its tightening id, and when it
    #: was stored): the catch-up that fetched it may have been cut short by the stop, so a
    #: rundown fetched now, made by then, may be that tool's again (its bolt held)
    cut_rundown: tuple[int, float] | None = None


@dataclass(frozen=True)
class SendParams:
    """Send ``parameters`` (the bolt's, as the database gave them with the vehicle) for the
    selected bolt: the shell keeps no bolt table of its own.  ``loosen``: they are the bolt's
    loosen pset with :data:`LOOSEN_TARGETS` (the controller's program loosens), sent the same
    way."""

    bolt: str
    selection: Selection
    parameters: Parameters | None = None
    loosen: bool = False


@dataclass(frozen=True)
class EnableTool:
    """Enable the tool for ``selection`` (noted on disk first: what the station owes)."""

    bolt: str
    selection: Selection


@dataclass(frozen=True)
class DisableTool:
    """The tool off, with why (typed as the state's reason, the same as the bus's
    :class:`~stationd.station.events.ToolDisabled`); ``why`` when a refusal turned it off."""

    reason: StateReason
    bolt: str | None = None
    why: Reason | None = None


@dataclass(frozen=True)
class SendVin:
    vin: str


@dataclass(frozen=True)
class LoadVehicle:
    """Open (``reopen``: reopen a closed one, a rework) the vehicle at height."""

    model_code: int
    vin: str
    reopen: bool = False


@dataclass(frozen=True)
class CloseVehicle:
    """Close ``vin``: the lift left the working height.  ``after_lift_outage``: the PLC said
    so in its first read after an outage (a restarted PLC may have forgotten the vehicle
    still on the lift): the journal says so, with how to reopen it."""

    vin: str
    after_lift_outage: bool = False
    #: its bolts whose result is still due from the controller (the tool ran, or may have,
    #: as it left): said so, neither missing nor NOK, their verdict follows
    due: tuple[str, ...] = ()


@dataclass(frozen=True)
class SettleClosing:
    """The results due as ``vin`` closed (:attr:`CloseVehicle.due`) of the bolts ``settled``
    are in its records, or no longer to come: its closing verdict again, from its records
    (``due``: the bolts still due)."""

    vin: str
    settled: tuple[str, ...]
    due: tuple[str, ...] = ()


@dataclass(frozen=True)
class Record:
    """Store ``result`` for ``bolt`` of ``vin``, then acknowledge it to the controller.

    ``t`` is when the station took the result: the time of the input the core decided on
    (:class:`~stationd.station.inputs.ResultIn`'s), stored as the rundown's ``result_at``.
    The times of one decision are in causal order: what the result causes (the NOK policy's
    lock, :class:`NoteLock`, a hold, a notice) is decided at that same input's time or a later
    one's, so it is never dated before the rundown; the rundown's ``recorded_at`` (and its feed
    entry's ``at``, the same instant) is when the database took it, after ``t``."""

    vin: str
    bolt: str
    result: TighteningResult
    selection: Selection | None
    late: bool = False
    kind: str = TIGHTENING     # or LOOSENING (:func:`rundown_kind`)
    #: made while the link to the controller was down, fetched after the reconnect (a result
    #: fetched with the link up, a push lost, is not)
    offline: bool = False
    #: when the station took the result, on its clock (see above; keyword-only, required)
    t: float = field(kw_only=True)


@dataclass(frozen=True)
class Acknowledge:
    """Tell the controller a result already stored may be forgotten (a resent copy)."""

    result: Received


@dataclass(frozen=True)
class StoreUnattributed:
    """Store a result no bolt owns (``vin``: the vehicle loaded, if any), then acknowledge it:
    a tightening the controller made is never acknowledged into nothing.  ``why`` is typed;
    the record's reason is its words (:func:`stationd.words.unattributed_words`), written by
    the shell as it stores it: the text stored is the one the core wrote before."""

    result: TighteningResult
    vin: str | None
    why: Unattributed


@dataclass(frozen=True)
class StoreGap:
    """Store a gap in the controller's numbering (tightenings ``first``..``last`` missed;
    ``vin``: the vehicle loaded, if any), for quality to look up on the controller."""

    first: int
    last: int
    vin: str | None
    reason: str


@dataclass(frozen=True)
class StoreControllerEvent:
    """Store a result that is not a rundown (``bolt``: the one the tool was enabled for,
    still open), then acknowledge it.  ``what``: the station's own kind for it
    (:data:`db.kinds.NOT_TAKEN`, a stored identifier the database looks up); None: the
    result's type, named in words by the shell as it stores it
    (:func:`stationd.words.result_type_words`: the core builds no words).  ``selection``:
    the enable it answers, settled with it (an OK without a type outside the bolt's torque
    window: the bolt is held for a person instead); None: the enable still waits for its
    result."""

    result: TighteningResult
    vin: str | None
    bolt: str | None
    what: str | None = None
    selection: Selection | None = None


@dataclass(frozen=True)
class StoreUnreadable:
    """Store an unreadable result whole (``bolt``: the one it may belong to, now held;
    ``selection``: the enable it answers, settled), then acknowledge it."""

    unreadable: UnreadableResult
    vin: str | None
    bolt: str | None
    selection: Selection | None


@dataclass(frozen=True)
class Publish:
    event: StationEvent


@dataclass(frozen=True)
class RecordCommand:
    """Record an accepted command with its user (a reopen also reopens the vehicle in the
    database), then feed :class:`CommandDone`: a command takes effect only once on disk."""

    request: int
    command: Command
    issuer: Issuer
    t: float


@dataclass(frozen=True)
class RecordRefusal:
    """Keep a refused command that would have changed a bolt or a vehicle in the records
    (:data:`db.kinds.REFUSED`, with ``reason``): the audit trail shows the attempt.  Written
    after the answer went back; one not written is said in the journal, nothing more."""

    command: Command
    issuer: Issuer
    reason: Reason
    t: float


@dataclass(frozen=True)
class SettleEnable:
    """The tool enable for ``selection`` is owed nothing more, without a record: every result
    the controller made since was fetched after a link cut, and none was its."""

    selection: Selection


@dataclass(frozen=True)
class CheckNewest:
    """An enable's late-result window ended without its result, the link up: the controller
    is asked for its newest result (its push may have been lost: the operator left the bolt,
    or the car left with it), and the ids the station never heard are fetched.  Why: else
    only the next result pushed revealed it, a car later where it was a car's last bolt (a
    supervisor's trial: the car closed with the bolt missing, its hold came with the next).
    ``serial``: that enable's, echoed in the answer (:class:`~stationd.station.inputs.
    NewestChecked`).  ``tool_on``: asked while the tool is on and its enable has no result
    yet (every :data:`~stationd.station.state.CHECK_ON_S`): a rundown whose push was lost
    is found then, its tool not left on for the operator to run the bolt down again; the
    tool on is no reason not to ask, and the enable is not ended by the answer."""

    serial: int | None = None
    tool_on: bool = False


@dataclass(frozen=True)
class StoreCutUnknown:
    """Store that ``bolt`` of ``vin`` is held because the link to the controller went down
    while the tool was enabled for it (``selection``, settled with it) and what the controller
    did meanwhile is not known (``note``, the hold's): no result says it, and a hold outlives
    a restart."""

    vin: str
    bolt: str
    note: str
    selection: Selection
    #: the controller event's kind it is stored as (:data:`db.kinds.LOST_UNKNOWN`: a result
    #: whose push was lost may be this enable's)
    what: str = CUT_UNKNOWN
    #: that result's tightening id (stored unattributed): an outcome a person enters for
    #: the bolt is that result's, and says so (one tightening, not two, in the records)
    tightening_id: int | None = None


@dataclass(frozen=True)
class NoteLock:
    """Record that the NOK policy locked ``bolt`` of ``vin`` after ``count`` NOKs in a row:
    read back with the vehicle, the lock stands until a person releases it, whatever
    ``max_nok`` a reload or a restart brings (the streak alone is read against it).  ``t``:
    when the core decided it, the time of the input it decided on (the NOK's, whose rundown
    carries the same time as its ``result_at``: :class:`Record`), stored as the lock's time."""

    vin: str
    bolt: str
    count: int
    t: float


@dataclass(frozen=True)
class Reply:
    """The answer goes back to who gave the command (and to the journal)."""

    answer: Answer


Action = (SendParams | EnableTool | DisableTool | SendVin | LoadVehicle | CloseVehicle | Record
          | SettleClosing | Acknowledge | StoreUnattributed | StoreGap | StoreControllerEvent
          | StoreUnreadable
          | StoreCutUnknown | SettleEnable | CheckNewest | Publish
          | RecordCommand | RecordRefusal | NoteLock | Reply | MeasureReferences | RecordCheck)
