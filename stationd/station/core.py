"""The station's decisions, pure: typed input events in, typed actions out.

The daemon only does I/O and timing: it reads the lift, grabs and localizes, talks to the
controller and the database, and feeds what happened to :meth:`StationCore.feed`; it carries out
the actions returned, in order, and feeds their outcome back (an acknowledgement, a refusal, a
fault).  Every rule lives here, so every rule is testable without a device, a clock or a thread:
time comes in with the events (``t``, ``time.time()`` scale; a localization also carries its
frames' *exposure* instant).

The safety rules, each enforced in exactly one place below:

- parameters are sent only from TRACKING, for the bolt the matcher *took*, while the lift is
  ready, a vehicle is loaded (its VIN with the controller) and no device is in fault;
- the tool is enabled only after the controller acknowledged that bolt's parameters AND a
  localization from frames exposed after that acknowledgement still finds the wrench on it;
- the tool goes off at the first localization that does not confirm the bolt (stale, refused,
  elsewhere), when the lift is not ready, on any fault, and after each result; the selection
  itself is dropped after ``leave_frames`` such localizations in a row;
- every result is recorded once, to the bolt the tool was enabled for (also when it arrives
  within ``late_result_s`` after the tool went off: the trigger was pulled as the wrench left);
  any other result is acknowledged unrecorded (the controller keeps its own record);
- faults are kept per device; the station leaves FAULT when every faulty device is back;
- with reference markers configured, a bolt end is used only when every pair that made it is
  trusted: checked against the references since the start and since the vehicle arrived, and
  not moved (:mod:`stationd.station.trust`).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, assert_never

import numpy as np

from db.bolts import Parameters, Window
from db.kinds import LOOSENING, NOK, TIGHTENING, TO_LOOSEN
from drivers.keeper import FaultKind
from drivers.wrench.base import (
    ResultKind,
    ResultType,
    TighteningResult,
    UnreadableResult,
    result_kind,
)
from stationd.reasons import Reason, Why
from stationd.station.commands import (
    RIGHT,
    Answer,
    CheckCalibration,
    Command,
    Issuer,
    LoosenBolt,
    ReleaseBolt,
    ReopenVehicle,
    SignIn,
    SignOut,
    SkipBolt,
    TeachPoint,
    TeachStart,
    TeachStop,
    skip_note,
)
from stationd.station.events import (
    BoltLocked,
    BoltReleased,
    BoltSelected,
    BoltSkipped,
    BoltToLoosen,
    BoltView,
    ControllerResultEvent,
    DeviceHealth,
    Localized,
    Notice,
    OperatorChange,
    OperatorChanged,
    PairChecked,
    PairsUnchecked,
    ParamsRefusedEvent,
    ParamsSent,
    Refused,
    ResultRecorded,
    ResultUnattributed,
    ResultUnreadable,
    StateChanged,
    StationEvent,
    ToolDisabled,
    ToolEnabled,
    VehicleClosed,
    VehicleOpened,
    VehicleReopened,
)
from stationd.station.events import State as State  # the state lives with its event
from stationd.station.matching import BoltMatcher, BoltRule, Match, MatchParams
from stationd.station.policy import NokPolicy
from stationd.station.trust import MeasureReferences, PairTrust, RecordCheck, ReferencesChecked
from stationd.station.trust import answer as check_answer

#: a result this long after the tool went off is not the last bolt's late one: the tool cannot
#: tighten while disabled, and a controller reports within milliseconds
LATE_RESULT_S = 5.0
#: the controller stamps its results to the second, and its clock's offset is measured to
#: the second: a result fetched after a link cut is placed between the enable and the cut
#: within this much
CLOCK_SLACK_S = 2.0


class Device(enum.StrEnum):
    """The station's devices besides its camera pairs (a pair is named by the station file)."""

    LIFT = "lift"
    WRENCH = "wrench"
    VEHICLE = "vehicle"     # the vehicle at height: its data can fault (an unknown model)
    DATABASE = "database"


LIFT, WRENCH, VEHICLE, DATABASE = Device.LIFT, Device.WRENCH, Device.VEHICLE, Device.DATABASE


ON_A_BOLT = (State.BOLT_SELECTED, State.TIGHTENING)
LOCALIZING = (State.TRACKING, *ON_A_BOLT)
#: the states in which the cameras are read (teaching measures the wrench, sends nothing)
CAMERAS_ON = (*LOCALIZING, State.TEACHING)
#: steady localizations averaged for one taught bolt, and how many may be tried for them
TEACH_FRAMES, TEACH_TRIES = 10, 60
#: why a bolt is not tightened again after a NOK under the ``skip`` strategy
NOK_SKIPPED = "NOK, skipped by the NOK policy"
#: a taught bolt end whose localizations spread farther than this was not held still, mm
TEACH_STEADY_MM = 2.0
#: a teach point is answered within this long, s, measured or not (``stationd teach`` waits
#: 15 s for an answer: past it, it could only blame the connection)
TEACH_WAIT_S = 10.0
#: the targets sent with a loosen pset: none of the station's own (a loosen pset is a program
#: on the controller; a register-driven controller takes 0 as "the pset's own")
LOOSEN_TARGETS = Window(0.0, 0.0, 0.0)
#: why a bolt to loosen is not tightened when no loosen pset applies to it (a reload removed it)
NO_LOOSEN_PSET = "to be loosened, and the NOK policy gives it no loosen_pset"


# -- inputs -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Input:
    """Base of every input: ``t`` is when it happened (``time.time()`` scale)."""

    t: float


@dataclass(frozen=True)
class Started(Input):
    """The daemon is serving (devices may still be down)."""


@dataclass(frozen=True)
class LiftRead(Input):
    """One successful read of the lift PLC (the read itself proves the PLC is back);
    ``why`` is what the operator reads while it is not ready (the daemon passes
    ``LiftState.why_not_ready``: moving, the PLC's fault bit, not at height)."""

    ready: bool
    at_height: bool
    model_code: int
    vin: str | None
    why: str = "lift not at working height"


@dataclass(frozen=True)
class LocalizedIn(Input):
    """A localization of the wrench: ``point_mm`` (bolt end, vehicle frame) or ``reason`` why
    none; ``exposure_t`` is when its frames were exposed (the earliest of those used).
    ``evidence`` is the daemon's (marker crops), handed back with the selection it decided."""

    exposure_t: float
    point_mm: tuple[float, float, float] | None
    reason: Reason | None = None
    tilt_deg: float = 0.0
    evidence: Any = None
    pairs: tuple[str, ...] = ()   # the pairs whose views made the point (the check's rule)


@dataclass(frozen=True)
class ParamsAcked(Input):
    """The controller took ``bolt``'s parameters (``pset``); ``latency_ms``: the stages from
    the frames' exposure to this acknowledgement (for the screens and the benchmarks)."""

    bolt: str
    pset: int | None = None
    latency_ms: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class ParamsRefused(Input):
    bolt: str
    reason: str


@dataclass(frozen=True)
class ResultIn(Input):
    """A tightening result from the controller (``result`` has ``ok``, ``pset``,
    ``tightening_id``), not yet acknowledged; ``fetched``: asked for after a reconnect (the
    station missed it while the link was down)."""

    result: TighteningResult
    fetched: bool = False
    #: fetched: the newest tightening id the station had accounted for when it asked (the
    #: first result made during a link cut is the one after it)
    follows: int | None = None
    #: the controller's timestamp of the result on the station's clock (through the offset
    #: measured at connect); None when the controller's clock is not known
    made_at: float | None = None


@dataclass(frozen=True)
class UnreadableIn(Input):
    """A result message the driver could not read (kept whole), not yet acknowledged."""

    unreadable: UnreadableResult


@dataclass(frozen=True)
class DeviceFault(Input):
    """``device`` (lift, wrench, database, a pair's name) failed: ``kind`` (down, timeout,
    garbage, refused, ...) and a readable ``reason``."""

    device: str
    kind: FaultKind
    reason: str


@dataclass(frozen=True)
class DeviceBack(Input):
    """``device`` answers again; for the wrench, ``reconnects`` is its link's reconnect count
    (a change means a controller that may have forgotten the VIN)."""

    device: str
    reconnects: int | None = None


@dataclass(frozen=True)
class BoltSpec:
    """A bolt of the loaded vehicle; ``parameters_id`` is the parameter version the database
    gave (recorded with the bolt's result: the version actually sent)."""

    position: tuple[float, float, float]
    pset: int | None
    order: int | None = None
    batch: str | None = None
    parameters_id: int | None = None
    parameters: Parameters | None = None   # what goes to the controller for this bolt


@dataclass(frozen=True)
class VehicleLoaded(Input):
    """The database has the vehicle open: its bolts, those already done and those a command
    skipped since it was (re)opened (bolt -> why)."""

    vin: str
    model: str
    bolts: Mapping[str, BoltSpec]
    done: frozenset[str] = frozenset()
    rework: bool = False
    skipped: Mapping[str, str] = field(default_factory=dict)
    noks: Mapping[str, int] = field(default_factory=dict)   # NOKs in a row, since a release
    held: Mapping[str, str] = field(default_factory=dict)   # held by an unreadable result
    status: Mapping[str, str] = field(default_factory=dict)  # bolt -> ok, nok (its records)

@dataclass(frozen=True)
class ToolOn(Input):
    """The controller enabled the tool for ``bolt`` (the outcome of :class:`EnableTool`)."""

    bolt: str


@dataclass(frozen=True)
class Written(Input):
    """The database took ``record`` (with the crops ``images``): it may be acknowledged."""

    record: Record
    images: tuple[str, ...] = ()


@dataclass(frozen=True)
class VehicleEnded(Input):
    """The database closed ``vin``: the bolts missing and NOK when it left."""

    vin: str
    missing: tuple[str, ...] = ()
    nok: tuple[str, ...] = ()


@dataclass(frozen=True)
class VehicleRejected(Input):
    """The vehicle at height cannot be opened: ``closed`` when its VIN was closed before."""

    vin: str | None
    reason: str
    closed: bool = False


@dataclass(frozen=True)
class VinSent(Input):
    """The VIN went to the controller (or the controller cannot take one: nothing to wait for)."""

    vin: str


@dataclass(frozen=True)
class Tick(Input):
    """Time passes (expires the late-result window)."""


@dataclass(frozen=True)
class CommandIn(Input):
    """A person's command (``request`` numbers it for the answer)."""

    request: int
    command: Command
    issuer: Issuer


@dataclass(frozen=True)
class ModelsKnown(Input):
    """The vehicle models of the station's bolt tables (what ``teach start`` may name)."""

    models: frozenset[str]


@dataclass(frozen=True)
class OperatorBack(Input):
    """At a start or a reload: ``user`` signed in at ``since`` and did not sign out (the
    commands' records say so), and is still a user of the station file."""

    user: str
    since: float


@dataclass(frozen=True)
class CommandDone(Input):
    """The shell carried out a command's :class:`RecordCommand`: recorded (``reason`` None)
    or refused by the database (an unknown VIN, a vehicle not closed, a failed write)."""

    request: int
    reason: Reason | None = None


Event = (Started | LiftRead | LocalizedIn | ParamsAcked | ParamsRefused | ResultIn | UnreadableIn
         | DeviceFault | DeviceBack | VehicleLoaded | VehicleRejected | VinSent | Tick
         | CommandIn | CommandDone | ToolOn | Written | VehicleEnded | ModelsKnown
         | ReferencesChecked | OperatorBack)


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


@dataclass(frozen=True)
class Owed:
    """What a station owes the next one (a reload, a restart): the tool was enabled for
    ``selection`` and went off at ``off_at`` (the new station's start when it stopped with the
    tool on); a result of its pset within ``late_result_s`` of that belongs to that bolt."""

    selection: Selection
    off_at: float


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
    """The tool off, with the station's words; ``why`` when a refusal turned it off."""

    reason: str
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
    vin: str


@dataclass(frozen=True)
class Record:
    """Store ``result`` for ``bolt`` of ``vin``, then acknowledge it to the controller."""

    vin: str
    bolt: str
    result: TighteningResult
    selection: Selection | None
    late: bool = False
    kind: str = TIGHTENING     # or LOOSENING (:func:`rundown_kind`)


@dataclass(frozen=True)
class Acknowledge:
    """Tell the controller a result already stored may be forgotten (a resent copy)."""

    result: TighteningResult


@dataclass(frozen=True)
class StoreUnattributed:
    """Store a result no bolt owns (``vin``: the vehicle loaded, if any), then acknowledge it:
    a tightening the controller made is never acknowledged into nothing."""

    result: TighteningResult
    vin: str | None
    reason: str


@dataclass(frozen=True)
class StoreControllerEvent:
    """Store a result that is not a rundown (``what``: its type in words; ``bolt``: the one
    the tool was enabled for, still open), then acknowledge it."""

    result: TighteningResult
    vin: str | None
    bolt: str | None
    what: str


@dataclass(frozen=True)
class StoreUnreadable:
    """Store an unreadable result whole (``bolt``: the one it may belong to, now held;
    ``selection``: the enable it answers, settled), then acknowledge it."""

    unreadable: UnreadableResult
    vin: str | None
    bolt: str | None
    selection: Selection | None


@dataclass(frozen=True)
class _Cut:
    """The link to the controller went down while the tool was enabled for ``selection``
    (enabled at ``enabled_at``, the cut seen at ``cut_at``): a result fetched after the
    reconnect that the controller's own data places there is that bolt's."""

    selection: Selection
    enabled_at: float
    cut_at: float


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
class Reply:
    """The answer goes back to who gave the command (and to the journal)."""

    answer: Answer


Action = (SendParams | EnableTool | DisableTool | SendVin | LoadVehicle | CloseVehicle | Record
          | Acknowledge | StoreUnattributed | StoreControllerEvent | StoreUnreadable | Publish
          | RecordCommand | Reply | MeasureReferences | RecordCheck)


@dataclass
class _Teach:
    """Teach mode: the model, who started it, and the bolt being measured (its command and
    the steady localizations so far)."""

    model: str
    user: str
    measuring: CommandIn | None = None
    points: list[tuple[float, float, float]] = field(default_factory=list)
    tries: int = 0
    since: float = 0.0     # only frames exposed after the engineer asked count
    frames: int = 0        # localizations heard since (none: the cameras give nothing)
    #: what the last localization without a fresh wrench said (no frame, not in view,
    #: stale): a refusal with no steady localization names it
    missed: Reason | None = None

    def reason(self) -> str:
        doing = f"measuring {self.measuring.command.bolt}" if self.measuring is not None \
            and isinstance(self.measuring.command, TeachPoint) else "hold the tool on a bolt"
        return f"teaching {self.model} ({self.user}): {doing}"


@dataclass
class StationCore:
    """One station's rules.  ``rework``: a vehicle whose VIN was closed comes back -> reopen it
    (its history kept) rather than a named fault that clears when the lift lowers."""

    params: MatchParams = field(default_factory=MatchParams)
    leave_frames: int = 3
    rework: bool = True
    late_result_s: float = LATE_RESULT_S
    nok: NokPolicy = field(default_factory=NokPolicy)
    state: State = State.STARTING
    reason: str = "starting"
    bolt: str | None = None
    matcher: BoltMatcher | None = None
    vin: str | None = None
    model: str | None = None
    faults: dict[str, tuple[str, str]] = field(default_factory=dict)  # device -> kind, reason
    tool_on: bool = False
    _specs: dict[str, BoltSpec] = field(default_factory=dict, repr=False)
    _lift: LiftRead | None = field(default=None, repr=False)
    _loading: bool = field(default=False, repr=False)
    _load_code: int | None = field(default=None, repr=False)   # the model code loaded
    _selection: Selection | None = field(default=None, repr=False)
    _acked_at: float | None = field(default=None, repr=False)
    _away: int = field(default=0, repr=False)
    _enabled: Selection | None = field(default=None, repr=False)  # tool last enabled for
    _off_at: float | None = field(default=None, repr=False)
    _enabled_at: float | None = field(default=None, repr=False)
    _cut: _Cut | None = field(default=None, repr=False)   # a link cut during an enable
    # the station's start or the controller's last fault: a result fetched afterwards was
    # made before it, so never under an enable that came later
    _link_lost_at: float = field(default=float("-inf"), repr=False)
    # tightening id -> what the result said (a resent copy says the same; a controller whose
    # ids started again says something else under the same id, and is not a copy)
    _recorded: dict[int, object] = field(default_factory=dict, repr=False)
    _wrench_epoch: int = field(default=0, repr=False)
    _wrench_reconnects: int | None = field(default=None, repr=False)
    _vin_for: tuple[str, int] | None = field(default=None, repr=False)
    _vin_pending: bool = field(default=False, repr=False)
    _last_refusal: tuple[object, ...] | None = field(default=None, repr=False)
    # frames exposed at or before this (a rundown's end) never select: the wrench may have
    # moved since, and the next bolt's evidence must all come from after it
    _not_before: float = field(default=float("-inf"), repr=False)
    _commands: dict[int, CommandIn] = field(default_factory=dict, repr=False)  # recording
    _noks: dict[str, int] = field(default_factory=dict, repr=False)   # NOKs in a row per bolt
    _teach: _Teach | None = field(default=None, repr=False)
    _closed_vin: str | None = field(default=None, repr=False)   # a closed VIN at height
    #: the models of the station's bolt tables (None: not told, teach start not checked)
    models: frozenset[str] | None = None
    # bolts that get their loosen pset next (a NOK under ``loosen``, a loosen command), and
    # those whose last rundown is a NOK tightening (a loosen command may undo them)
    _loosen: set[str] = field(default_factory=set, repr=False)
    _nok_last: set[str] = field(default_factory=set, repr=False)
    #: the calibration check's state (None: no reference markers configured, every pair
    #: trusted as before): :mod:`stationd.station.trust`
    trust: PairTrust | None = None
    #: no parameters are sent while nobody is signed in (``access.operator_required``)
    operator_required: bool = False
    #: the operator is signed out after this long without a selection or a rundown, s
    #: (``access.operator_idle_s``; None: never)
    operator_idle_s: float | None = None
    #: who is signed in at the station (None: nobody): every rundown is recorded with them
    operator: str | None = None
    _operator_seen: float = field(default=0.0, repr=False)   # their last sign-in or work

    # -- the one entry point ---------------------------------------------------------------
    def feed(self, ev: Event) -> list[Action]:
        """Everything that happened goes in here; what to do comes out, in order."""
        before = (self.state, self.reason)
        acts = self._dispatch(ev)
        acts += self._vin_due()
        if (self.state, self.reason) != before:  # first: follow-ups may change it again
            acts.insert(0, Publish(StateChanged(self.state, self.reason, t=ev.t)))
        return acts

    def _dispatch(self, ev: Event) -> list[Action]:
        """Each input to its handler, spelled out so that the type checker and a reader can
        follow it (an input of the Event union without a case fails the type check)."""
        match ev:
            case Started():
                return self._on_Started(ev)
            case LiftRead():
                return self._on_LiftRead(ev)
            case VehicleLoaded():
                return self._on_VehicleLoaded(ev)
            case VehicleRejected():
                return self._on_VehicleRejected(ev)
            case LocalizedIn():
                return self._on_LocalizedIn(ev)
            case ParamsAcked():
                return self._on_ParamsAcked(ev)
            case ToolOn():
                return self._on_ToolOn(ev)
            case Written():
                return self._on_Written(ev)
            case VehicleEnded():
                return self._on_VehicleEnded(ev)
            case ParamsRefused():
                return self._on_ParamsRefused(ev)
            case ResultIn():
                return self._on_ResultIn(ev)
            case UnreadableIn():
                return self._on_UnreadableIn(ev)
            case CommandIn():
                return self._on_CommandIn(ev)
            case CommandDone():
                return self._on_CommandDone(ev)
            case DeviceFault():
                return self._on_DeviceFault(ev)
            case DeviceBack():
                return self._on_DeviceBack(ev)
            case ModelsKnown():
                return self._on_ModelsKnown(ev)
            case VinSent():
                return self._on_VinSent(ev)
            case Tick():
                return self._on_Tick(ev)
            case OperatorBack():
                return self._on_OperatorBack(ev)
            case ReferencesChecked():
                return self._on_ReferencesChecked(ev)
        assert_never(ev)

    @property
    def selection(self) -> Selection | None:
        return self._selection

    def resume(self, owed: Owed) -> None:
        """Take over what the last station owed (before :class:`Started`): its result, within
        the late-result window, is recorded to the bolt the tool was enabled for."""
        self._enabled, self._off_at = owed.selection, owed.off_at

    def allowed(self) -> tuple[str, ...]:
        """The bolts the sequence allows now (not done, skipped, locked, held or blocked)."""
        m = self.matcher
        if m is None:
            return ()
        return tuple(b for b in m.bolts if b not in m.done and b not in m.skipped
                     and b not in m.locked and b not in m.held and m.why_blocked(b) is None)

    # -- handlers --------------------------------------------------------------------------
    def _on_Started(self, ev: Started) -> list[Action]:  # noqa: N802 - named after the event
        if self.state is not State.STARTING:
            return []
        self._link_lost_at = ev.t
        self._to(State.FAULT if self.faults else State.WAITING_VEHICLE,
                 self._fault_reason() if self.faults else "waiting for the lift")
        # the last station may have been killed with the tool on: off until a bolt is confirmed
        return [*_disable("station started: the tool stays off until a bolt is confirmed",
                          t=ev.t), *self._check_at_start(ev.t),
                Publish(OperatorChanged(self.operator, self.operator_required,
                                        how=OperatorChange.STILL_SIGNED_IN if self.operator
                                        else OperatorChange.NOBODY, t=ev.t))]

    def _on_LiftRead(self, ev: LiftRead) -> list[Action]:  # noqa: N802
        acts: list[Action] = []
        self._lift = ev
        if LIFT in self.faults:
            acts += self._back(ev.t, LIFT)
        if VEHICLE in self.faults and not ev.at_height:
            self._closed_vin = None
            acts += self._back(ev.t, VEHICLE)   # a vehicle fault lasts while that vehicle is up
        if self.vin is not None and not ev.at_height:
            acts += self._drop(ev.t, State.WAITING_VEHICLE, ev.why)
            acts.append(CloseVehicle(self.vin))
            self._forget_vehicle()
        changed = self._vehicle_changed(ev)
        if changed is not None and VEHICLE not in self.faults:
            # the PLC now names another vehicle (or model) with the lift still at height:
            # the loaded bolts are not this car's; nothing more is sent until the lift goes
            # down (which closes the loaded vehicle and clears this fault)
            acts += self._fault(ev.t, VEHICLE, FaultKind.CHANGED, changed)
        if self.state in (State.STARTING, State.FAULT):
            return acts
        if not ev.ready:
            if self.state in ON_A_BOLT or self.state is State.TRACKING:
                acts += self._drop(ev.t, State.WAITING_VEHICLE, ev.why)
            else:
                self._to(State.WAITING_VEHICLE, ev.why)
            return acts
        if self.vin is None:
            if not self._loading:
                self._loading = True
                vin = ev.vin or f"SEQ-{int(ev.t)}"
                self._load_code = ev.model_code
                acts.append(LoadVehicle(ev.model_code, vin))
                self._to(State.WAITING_VEHICLE, f"loading vehicle {vin}")
            return acts
        if self.state is State.WAITING_VEHICLE:
            self._to(State.TRACKING, "tracking the wrench")
        return acts

    def _vehicle_changed(self, ev: LiftRead) -> str | None:
        """Why the vehicle at height is not the one loaded (its VIN or model code changed),
        else None."""
        if self.vin is None or not ev.at_height:
            return None
        if ev.vin and ev.vin != self.vin:
            return (f"the PLC reports VIN {ev.vin} at height, the station has {self.vin} "
                    "loaded: lower the lift")
        if self._load_code is not None and ev.model_code != self._load_code:
            return (f"the PLC reports model code {ev.model_code} at height, {self.vin} was "
                    f"loaded as {self._load_code}: lower the lift")
        return None

    def _on_VehicleLoaded(self, ev: VehicleLoaded) -> list[Action]:  # noqa: N802
        self._loading = False
        self.vin, self.model = ev.vin, ev.model
        self._specs = dict(ev.bolts)
        self._recorded = {}
        self.matcher = BoltMatcher(
            {k: np.asarray(b.position, dtype=np.float64) for k, b in ev.bolts.items()},
            self.params, set(ev.done), dict(ev.skipped),
            rules={k: BoltRule(b.order, b.batch) for k, b in ev.bolts.items()})
        self._noks = {k: n for k, n in ev.noks.items() if k in ev.bolts and n > 0}
        for k, n in self._noks.items():   # the NOK policy's state comes back with the vehicle
            rule = self.nok.rule(k, ev.bolts[k].pset)
            if n >= rule.max_nok:
                self.matcher.locked[k] = n
            elif rule.strategy == "skip":
                self.matcher.skipped.setdefault(k, NOK_SKIPPED)
        self._loosen_back(ev)
        self.matcher.held = {k: note for k, note in ev.held.items() if k in ev.bolts}
        opened = VehicleOpened(ev.vin, ev.model, tuple(
            BoltView(k, *b.position, pset=b.pset, order=b.order, batch=b.batch,
                     status=TO_LOOSEN if k in self._loosen else ev.status.get(k)
                     or ("skipped" if k in ev.skipped else "pending"))
            for k, b in ev.bolts.items()), rework=ev.rework, t=ev.t)
        if self.state is State.WAITING_VEHICLE and self._lift is not None and self._lift.ready:
            self._to(State.TRACKING, "tracking the wrench")
        held = [Publish(BoltLocked(k, 0, held=note, t=ev.t))
                for k, note in self.matcher.held.items()]
        return [Publish(opened), *held, *self._check_on_arrival(ev.t, ev.vin)]

    def _loosen_back(self, ev: VehicleLoaded) -> None:
        """The loosen strategy's state comes back with the vehicle: a bolt whose last rundown
        is a NOK under ``loosen`` (also a NOK loosening), or with a loosen command since its
        last rundown, gets its loosen pset next; one that no loosen pset applies to any more
        is skipped (its tightening pset would hit a tightened joint again)."""
        assert self.matcher is not None  # noqa: S101 - loaded just now
        self._loosen, self._nok_last = set(), set()
        for k, status in ev.status.items():
            if k not in ev.bolts:
                continue
            rule = self.nok.rule(k, ev.bolts[k].pset)
            if status == NOK:
                self._nok_last.add(k)
                if rule.count_in_batch:   # the NOK counts in its batch (the policy's choice)
                    self.matcher.counted.add(k)
            if status == TO_LOOSEN or (status == NOK and rule.strategy == "loosen"):
                if rule.loosen_pset is None:
                    self.matcher.skipped.setdefault(k, NO_LOOSEN_PSET)
                else:
                    self._loosen.add(k)

    def _on_VehicleRejected(self, ev: VehicleRejected) -> list[Action]:  # noqa: N802
        if ev.closed and self.rework and ev.vin is not None and self._lift is not None:
            return [Publish(Notice(f"VIN {ev.vin} already closed: reopened as a rework "
                                   "(its records kept)", t=ev.t)),
                    LoadVehicle(self._lift.model_code, ev.vin, reopen=True)]
        self._loading = False
        why = ev.reason
        self._closed_vin = ev.vin if ev.closed else None
        if ev.closed:
            why = f"VIN {ev.vin} already closed: rework needs the vehicle reopened " \
                  f"({ev.reason}); lower the lift to clear"
        return self._fault(ev.t, VEHICLE, FaultKind.REJECTED, why)

    def _on_LocalizedIn(self, ev: LocalizedIn) -> list[Action]:  # noqa: N802
        ev = self._trusted(ev)
        if self._teach is not None:
            return self._taught(ev, self._teach)
        if self.state not in LOCALIZING or self.matcher is None:
            return []
        if self.state is State.TRACKING and ev.exposure_t <= self._not_before:
            return []   # exposed before the last rundown ended: where the wrench *was*
        age = ev.t - ev.exposure_t
        m = self.matcher.update(np.asarray(ev.point_mm), age) if ev.point_mm is not None \
            else self.matcher.refuse(ev.reason or Reason(Why.NOT_LOCALIZED))
        acts: list[Action] = [Publish(Localized(
            ev.point_mm, ev.tilt_deg if ev.point_mm is not None else None, m.reason,
            m.candidate, m.distance_mm, age * 1e3, self.allowed(), t=ev.t))]
        if self.state is State.TRACKING:
            return acts + self._track(ev, m)
        on_bolt = m.candidate == self.bolt and age <= self.params.max_age_s
        if on_bolt:
            self._away = 0
            if self.state is State.BOLT_SELECTED and self._acked_at is not None \
                    and ev.exposure_t > self._acked_at and self.bolt is not None:
                self._to(State.TIGHTENING, f"tightening bolt {self.bolt}")
                sel = self._selection
                assert sel is not None  # noqa: S101 - a bolt is selected
                self.tool_on, self._enabled, self._off_at = True, sel, None
                self._enabled_at, self._cut = ev.t, None
                acts.append(EnableTool(self.bolt, sel))
            return acts
        self._away += 1
        # why not on it: the refusal, or the bolt it is on instead (a reason of its own kind)
        why = m.reason or Reason(Why.ELSEWHERE, bolt=m.candidate)
        if self.tool_on:
            acts += self._tool_off(ev.t, f"wrench not confirmed on bolt {self.bolt}", why)
            self._to(State.BOLT_SELECTED, f"bolt {self.bolt} selected; wrench not confirmed")
        if self._away >= self.leave_frames:
            acts += self._drop(ev.t, State.TRACKING, f"wrench left bolt {self.bolt}", why)
        return acts

    def _taught(self, ev: LocalizedIn, teach: _Teach) -> list[Action]:
        """Teach mode: fresh localizations of the bolt being measured are collected; after
        ``TEACH_FRAMES`` of them its mean and dispersion are the answer."""
        age = ev.t - ev.exposure_t
        acts: list[Action] = [Publish(Localized(ev.point_mm, ev.tilt_deg, ev.reason, None,
                                                None, age * 1e3, (), t=ev.t))]
        c = teach.measuring
        if c is None or self.faults:
            return acts
        if ev.exposure_t <= teach.since:
            return acts   # exposed before the engineer asked: the tool may have been moving
        teach.frames += 1
        if ev.point_mm is not None and age <= self.params.max_age_s:
            teach.points.append(ev.point_mm)
        else:
            teach.tries += 1
            teach.missed = ev.reason if ev.reason is not None else \
                Reason(Why.STALE, age_ms=age * 1e3, limit=self.params.max_age_s * 1e3)
        if len(teach.points) >= TEACH_FRAMES:
            p = np.asarray(teach.points, dtype=np.float64)
            mean = p.mean(axis=0)
            spread = float(np.linalg.norm(p - mean, axis=1).max())
            teach.measuring, teach.points, teach.tries, teach.missed = None, [], 0, None
            self.reason = teach.reason()
            if spread > TEACH_STEADY_MM:   # moved while measured: not a position
                return [*acts, Reply(Answer(c.request, c.command, c.issuer, Reason(
                    Why.NOT_STEADY, distance_mm=spread, limit=TEACH_STEADY_MM)))]
            # the matching tolerance: what the edges compare the taught bolt with CAD against
            result = {"position_mm": [float(v) for v in mean], "dispersion_mm": spread,
                      "frames": TEACH_FRAMES, "tolerance_mm": self.params.tolerance_mm}
            return [*acts, Reply(Answer(c.request, c.command, c.issuer, result=result))]
        if teach.tries >= TEACH_TRIES:
            why = Reason(Why.NOT_STEADY, count=len(teach.points), needed=TEACH_FRAMES,
                         cause=teach.missed, limit=teach.tries)
            teach.measuring, teach.points, teach.tries, teach.missed = None, [], 0, None
            self.reason = teach.reason()
            return [*acts, Reply(Answer(c.request, c.command, c.issuer, why))]
        return acts

    def _track(self, ev: LocalizedIn, m: Match) -> list[Action]:
        assert self.matcher is not None  # noqa: S101 - tracking has a vehicle
        if m.bolt is None:
            # once per change of kind and bolts: "stale (812 ms)" and "(790 ms)" are one
            if m.reason is not None and m.reason.key() != self._last_refusal:
                self._last_refusal = m.reason.key()
                return [Publish(Refused(m.reason, m.candidate, t=ev.t))]
            return []
        ready = self._lift is not None and self._lift.ready
        if self.faults or not ready or self.vin is None \
                or self._vin_for != (self.vin, self._wrench_epoch) or ev.point_mm is None:
            self.matcher.reset()   # never reached: TRACKING implies all of these; belt and braces
            return []
        if self.operator_required and self.operator is None:
            # the station requires an operator: nothing is sent for anybody's tool (the
            # streak is kept: a sign-in selects at the next frame of a wrench held still)
            why = Reason(Why.SIGN_IN, bolt=m.bolt)
            if why.key() != self._last_refusal:
                self._last_refusal = why.key()
                return [Publish(Refused(why, m.bolt, t=ev.t))]
            return []
        spec = self._specs[m.bolt]
        pset, params, loosen = spec.pset, spec.parameters, m.bolt in self._loosen
        if loosen:   # the loosen strategy: its loosen pset, never the tightening one, first
            pset = self.nok.rule(m.bolt, spec.pset).loosen_pset
            if pset is None:    # never: a bolt is to loosen only with a loosen pset
                self.matcher.reset()
                return []
            params = Parameters(pset, LOOSEN_TARGETS)
        sel = Selection(m.bolt, pset, ev.point_mm, ev.tilt_deg, float(m.distance_mm or 0.0),
                        ev.exposure_t, ev.t, ev.evidence, self.vin, spec.parameters_id, loosen,
                        self.operator)
        self._operator_seen = ev.t
        self.bolt, self._selection, self._acked_at, self._away = m.bolt, sel, None, 0
        self._last_refusal = None
        self.matcher.reset()
        self._to(State.BOLT_SELECTED, f"bolt {m.bolt} selected" + (
            f": loosen first (pset {pset})" if loosen else ""))
        return [Publish(BoltSelected(m.bolt, pset, ev.point_mm, sel.distance_mm,
                                     ev.tilt_deg, loosen, t=ev.t)),
                SendParams(m.bolt, sel, params, loosen)]

    def _on_ParamsAcked(self, ev: ParamsAcked) -> list[Action]:  # noqa: N802
        acts: list[Action] = [Publish(ParamsSent(ev.bolt, ev.pset, dict(ev.latency_ms),
                                                 t=ev.t))]
        if self.state is State.BOLT_SELECTED and ev.bolt == self.bolt and self._acked_at is None:
            self._acked_at = ev.t   # the tool waits for a frame exposed after this
            self.reason = f"bolt {ev.bolt} acknowledged; confirming the wrench is on it"
            return acts
        return [*acts, *_disable(f"late acknowledgement for {ev.bolt} ignored", ev.bolt,
                                 t=ev.t),
                Publish(Notice(f"late acknowledgement for {ev.bolt} ignored", t=ev.t))]

    def _on_ToolOn(self, ev: ToolOn) -> list[Action]:  # noqa: N802
        return [Publish(ToolEnabled(ev.bolt, t=ev.t))]

    def _on_Written(self, ev: Written) -> list[Action]:  # noqa: N802
        """A result on disk: published for the screens, then the controller may forget it."""
        a, r = ev.record, ev.record.result
        return [Publish(ResultRecorded(
            a.vin, a.bolt, bool(r.ok), float(r.torque_nm), float(r.angle_deg),
            int(r.tightening_id), int(r.pset), float(r.torque_min_nm), float(r.torque_max_nm),
            float(r.angle_min_deg), float(r.angle_max_deg), a.late, tuple(ev.images), a.kind,
            a.selection.operator if a.selection is not None else None, t=ev.t)),
            Acknowledge(r)]

    def _on_VehicleEnded(self, ev: VehicleEnded) -> list[Action]:  # noqa: N802
        return [Publish(VehicleClosed(ev.vin, ev.missing, ev.nok, t=ev.t))]

    def _on_ParamsRefused(self, ev: ParamsRefused) -> list[Action]:  # noqa: N802
        """The bolt is skipped for this vehicle (reported missing) so that the same refused
        parameters are not sent again and again; the controller is in fault until it answers."""
        why = f"controller refused its parameters ({ev.reason})"
        acts: list[Action] = [Publish(ParamsRefusedEvent(ev.bolt, ev.reason, t=ev.t))]
        if self.matcher is not None and ev.bolt in self.matcher.bolts:
            self.matcher.skipped[ev.bolt] = why
            acts.append(Publish(BoltSkipped(ev.bolt, why, t=ev.t)))
        return acts + self._fault(ev.t, WRENCH, FaultKind.REFUSED,
                                  f"controller refused the parameters for {ev.bolt}: "
                                  f"{ev.reason}")

    def _on_ResultIn(self, ev: ResultIn) -> list[Action]:  # noqa: N802
        """A result: a controller event (never a rundown) by its type; else recorded to the
        bolt the tool was enabled for (its pset, while on or within the late-result window,
        or after a link cut where the controller's own data places it there), else stored
        unattributed with why."""
        r = ev.result
        tid = int(r.tightening_id)
        if self._recorded.get(tid, None) == _said(r):
            return [Acknowledge(r)]   # sent again by the controller: stored once already
        again: list[Action] = [] if tid not in self._recorded else [Publish(Notice(
            f"tightening id {tid} again with other values: the controller's ids started "
            "again (a new or reset controller?); taken as a new result", "warning", t=ev.t))]
        return again + self._result_in(ev, tid)

    def _result_in(self, ev: ResultIn, tid: int) -> list[Action]:
        r = ev.result
        en = self._enabled
        kind = result_kind(type_code(r), en is not None and en.loosen)
        if kind in (ResultKind.EVENT, ResultKind.UNKNOWN):
            return self._controller_event(ev, kind)
        ours = en is not None and (en.pset is None or int(r.pset) == en.pset) and not (
            ev.fetched and self._enabled_at is not None
            and self._enabled_at > self._link_lost_at)
        if ours and en is not None and en.vin and self._result_owed(ev.t):
            return self._attribute(ev, en)
        proved, not_proved = self._made_during_cut(ev)
        if proved is not None:
            return self._attribute(ev, proved, cut=True)
        why = f"result {tid} (pset {r.pset}) " + (
            "fetched after a reconnect" if ev.fetched else "outside any tightening")
        if not_proved:
            why += f" ({not_proved})"
        return [StoreUnattributed(r, self.vin, why),
                Publish(ResultUnattributed(tid, int(r.pset), bool(r.ok), t=ev.t)),
                Publish(Notice(f"{why}: not attributable to a bolt, stored unattributed",
                               "warning", t=ev.t))]

    def _result_owed(self, t: float) -> bool:
        """The tool is on, or went off less than the late-result window before ``t``: its
        enable's result may still come."""
        return self.tool_on or (self._off_at is not None
                                and t - self._off_at < self.late_result_s)

    def _made_during_cut(self, ev: ResultIn) -> tuple[Selection | None, str]:
        """The selection a result fetched after a link cut belongs to, when the controller's
        own data proves it (its pset the one sent, its VIN the one sent where it echoes one,
        its tightening id the first after the last the station accounted for, its
        timestamp between the enable and the cut); else None and what did not agree."""
        cut, r = self._cut, ev.result
        if not ev.fetched or cut is None:
            return None, ""
        en = cut.selection
        echoed = str(r.vin or "").strip()
        if en.pset is None or int(r.pset) != en.pset:
            return None, f"pset {r.pset}, not {en.pset} sent for {en.bolt}"
        if echoed and echoed != en.vin:
            return None, f"VIN {echoed}, not {en.vin}"
        if ev.follows is None or int(r.tightening_id) != ev.follows + 1:
            return None, (f"not the first tightening after {ev.follows}" if ev.follows
                          is not None else "the last tightening id accounted for unknown")
        if ev.made_at is None:
            return None, "the controller's clock is not known"
        if not cut.enabled_at - CLOCK_SLACK_S <= ev.made_at <= cut.cut_at + CLOCK_SLACK_S:
            return None, f"made outside the enable of {en.bolt} and the link cut"
        return en, ""

    def _controller_event(self, ev: ResultIn, kind: ResultKind) -> list[Action]:
        """A result that is not a tightening or a loosening (a batch increment a line lead
        pressed, a bypassed pset, an aborted job, a reference setup, or a type the station
        does not know): stored as a controller event, said, and nothing else: no bolt is
        closed, opened or counted, and the tool stays as the station decided."""
        r, code = ev.result, type_code(ev.result)
        self._recorded[int(r.tightening_id)] = _said(r)
        what = result_type_words(code)
        bolt = self.bolt if self.tool_on else None
        note = f"{what} on the controller: not a tightening" + (
            f", {bolt} still open" if bolt is not None else "")
        if kind is ResultKind.UNKNOWN:
            note += "; check the controller's result there"
        return [StoreControllerEvent(r, self.vin, bolt, what),
                Publish(ControllerResultEvent(code or 0, what, int(r.tightening_id),
                                              int(r.pset), bool(r.ok), bolt, t=ev.t)),
                Publish(Notice(note, "warning" if bolt is not None
                               or kind is ResultKind.UNKNOWN else "info", t=ev.t))]

    def _on_UnreadableIn(self, ev: UnreadableIn) -> list[Action]:  # noqa: N802
        """A result the driver could not read: stored whole; the bolt it may belong to (the
        tool's, while on or within the late-result window, or the one of a link cut for a
        fetched one; of the same pset where one could be read) is held until a supervisor
        has checked the result on the controller and releases it."""
        u = ev.unreadable
        if u.tightening_id is not None and self._recorded.get(u.tightening_id) == u.raw:
            return []     # its copy is stored already (the acknowledgement was owed by it)
        en = self._enabled if self._result_owed(ev.t) else None
        if u.fetched:
            en = self._cut.selection if self._cut is not None else None
        if en is not None and u.pset is not None and en.pset is not None \
                and u.pset != en.pset:
            en = None        # its pset could be read, and it is not the one sent
        if u.tightening_id is not None:
            self._recorded[u.tightening_id] = u.raw
        bolt = en.bolt if en is not None and en.vin else None
        acts: list[Action] = []
        if bolt is not None and self.tool_on:
            acts += self._tool_off(ev.t, f"bolt {bolt}: its result could not be read")
        acts.append(StoreUnreadable(u, en.vin if en is not None and bolt else self.vin, bolt,
                                    en if bolt else None))
        acts.append(Publish(ResultUnreadable(u.error, u.revision, u.tightening_id, bolt,
                                             t=ev.t)))
        if bolt is None or en is None:
            return [*acts, Publish(Notice(
                f"a result from the controller could not be read ({u.error}): stored whole; "
                "no bolt it could belong to", "warning", t=ev.t))]
        self._enabled = self._enabled if self._enabled is not en else None
        if self._cut is not None and self._cut.selection is en:
            self._cut = None
        if self.matcher is not None and self.vin == en.vin and bolt in self.matcher.bolts:
            acts += self._hold(ev.t, bolt, f"tightening {u.tightening_id}"
                               if u.tightening_id is not None
                               else f"MID {u.mid:04d} revision {u.revision}")
        if self.bolt == bolt:
            acts += self._drop(ev.t, State.TRACKING, f"bolt {bolt}: its result could not be "
                               "read; held for a supervisor")
        return acts

    def _hold(self, t: float, bolt: str, note: str) -> list[Action]:
        """``bolt`` is refused until a supervisor releases it: its result is not known."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self.matcher.held[bolt] = note
        self.matcher.reset()
        return [Publish(BoltLocked(bolt, 0, held=note, t=t)),
                Publish(Notice(f"{bolt}: the controller's result could not be read ({note}): "
                               "check it on the controller, then release", "warning", t=t))]

    def _attribute(self, ev: ResultIn, en: Selection, cut: bool = False) -> list[Action]:
        """The result of the tightening the tool was enabled for: recorded to that bolt (of
        the vehicle it was enabled on, also after a reload or restart, or fetched after a
        link cut that the controller's data places it in, ``cut``)."""
        r = ev.result
        late = not self.tool_on or cut
        kind = LOOSENING if result_kind(type_code(r), en.loosen) is ResultKind.LOOSENING \
            else TIGHTENING
        acts: list[Action] = []
        if self.tool_on and not cut:
            acts += self._tool_off(ev.t, f"bolt {en.bolt} " + (
                "tightened" if kind == TIGHTENING else "loosened"))
        acts.append(Record(en.vin, en.bolt, r, en, late, kind))
        if cut:
            acts.append(Publish(Notice(
                f"tightening {r.tightening_id} made during the link cut, fetched after it: "
                f"recorded to {en.bolt} (its pset, VIN, tightening id and time agree)",
                t=ev.t)))
        elif late:
            acts.append(Publish(Notice(f"result for {en.bolt} outside a tightening: "
                                       "recorded, not matched", t=ev.t)))
        self._recorded[int(r.tightening_id)] = _said(r)
        if cut:
            self._cut = None
            if self._enabled is en:
                self._enabled = None
        else:
            self._enabled = None
        if en.operator is not None and en.operator == self.operator:
            self._operator_seen = max(self._operator_seen, ev.t)
        if self.matcher is not None and self.vin == en.vin:
            if kind == LOOSENING:
                acts += self._after_loosening(ev.t, en, bool(r.ok))
            elif bool(r.ok):
                if en.loosen:
                    acts.append(Publish(Notice(
                        f"{en.bolt}: the loosen pset {en.pset} reported a tightening: the "
                        "bolt counts as tightened; check that pset's program", "warning",
                        t=ev.t)))
                self.matcher.mark_done(en.bolt)
                self._noks.pop(en.bolt, None)
                self._loosen.discard(en.bolt)
                self._nok_last.discard(en.bolt)
                self.matcher.counted.discard(en.bolt)
            else:
                self._nok_last.add(en.bolt)
                acts += self._after_nok(ev.t, en)
            self.matcher.reset()     # a new selection: a new streak, from new frames
        self._not_before = max(self._not_before, ev.t)
        if self.bolt == en.bolt:
            self.bolt, self._selection, self._acked_at, self._away = None, None, None, 0
            if self.state in ON_A_BOLT:
                what = "loosening " if kind == LOOSENING else ""
                self._to(State.TRACKING,
                         f"bolt {en.bolt} {what}{'OK' if r.ok else 'NOK'}; tracking")
        return acts

    def _on_CommandIn(self, ev: CommandIn) -> list[Action]:  # noqa: N802
        """A command is checked against the rules now and takes effect once recorded."""
        why = self._refusal(ev.command, ev.issuer)
        if why is not None:
            return [Reply(Answer(ev.request, ev.command, ev.issuer, why))]
        if isinstance(ev.command, SignOut):   # its record names who is signed out
            ev = replace(ev, command=replace(ev.command, user=self.operator))
        self._commands[ev.request] = ev
        return [RecordCommand(ev.request, ev.command, ev.issuer, ev.t)]

    def _refusal(self, cmd: Command, who: Issuer) -> Reason | None:
        """Why ``cmd`` may not be carried out now, or None."""
        right = RIGHT.get(type(cmd))
        if right is not None and right not in who.rights:
            return Reason(Why.NO_RIGHT, right=right.value)
        if isinstance(cmd, SignIn):
            return Reason(Why.SIGNED_IN, user=who.user) if self.operator == who.user else None
        if isinstance(cmd, SignOut):
            return Reason(Why.NOT_SIGNED_IN) if self.operator is None else None
        if isinstance(cmd, CheckCalibration):
            return None if self.trust is not None else Reason(Why.NO_REFERENCES)
        if isinstance(cmd, TeachStart | TeachPoint | TeachStop):
            return self._teach_refusal(cmd)
        if self._teach is not None:
            return Reason(Why.TEACHING, note=self._teach.reason())
        if isinstance(cmd, ReopenVehicle):
            if cmd.vin == self.vin:
                return Reason(Why.ALREADY_OPEN, vin=cmd.vin)
            return None   # the database knows whether it is closed (CommandDone)
        if self.vin is None or self.matcher is None:
            # a vehicle raised while a device is in fault is not loaded until it is back
            return Reason(Why.DEVICE_FAULT, note=self._fault_reason()) if self.faults \
                else Reason(Why.NO_VEHICLE)
        if cmd.vin != self.vin:
            return Reason(Why.OTHER_VEHICLE, vin=cmd.vin)
        if cmd.bolt not in self.matcher.bolts:
            return Reason(Why.UNKNOWN_BOLT, bolt=cmd.bolt, vin=cmd.vin)
        if isinstance(cmd, LoosenBolt):
            return self._loosen_refusal(cmd)
        if isinstance(cmd, ReleaseBolt):
            return None if cmd.bolt in self.matcher.locked or cmd.bolt in self.matcher.held \
                else Reason(Why.NOT_LOCKED, bolt=cmd.bolt)
        if cmd.bolt in self.matcher.done:
            return Reason(Why.DONE, bolt=cmd.bolt)
        if cmd.bolt in self.matcher.skipped:
            return Reason(Why.SKIPPED, bolt=cmd.bolt, note=self.matcher.skipped[cmd.bolt])
        if self.tool_on and self.bolt == cmd.bolt:
            return Reason(Why.TOOL_ON_BOLT, bolt=cmd.bolt)
        return None

    def _loosen_refusal(self, cmd: LoosenBolt) -> Reason | None:
        """A loosen is for a bolt tightened (OK, or NOK last) that a loosen pset applies to,
        not locked, skipped, to be loosened already, or being tightened now."""
        m = self.matcher
        assert m is not None  # noqa: S101 - checked by the caller
        b = cmd.bolt
        loosen_pset = self.nok.rule(b, self._specs[b].pset).loosen_pset
        if loosen_pset is None:
            return Reason(Why.NO_LOOSEN_PSET, bolt=b)
        if b in self._loosen:
            return Reason(Why.LOOSEN_FIRST, bolt=b, pset=loosen_pset)
        if b in m.locked:
            return Reason(Why.LOCKED, bolt=b, count=m.locked[b])
        if b in m.skipped:
            return Reason(Why.SKIPPED, bolt=b, note=m.skipped[b])
        if self.tool_on and self.bolt == b:
            return Reason(Why.TOOL_ON_BOLT, bolt=b)
        if b not in m.done and b not in self._nok_last:
            return Reason(Why.NOTHING_TO_LOOSEN, bolt=b)
        return None

    def _teach_refusal(self, cmd: TeachStart | TeachPoint | TeachStop) -> Reason | None:
        t = self._teach
        if isinstance(cmd, TeachStart):
            if t is not None:
                return Reason(Why.TEACHING, note=t.reason())
            if self.models is not None and cmd.model not in self.models:
                return Reason(Why.UNKNOWN_MODEL, note=cmd.model)
            if self.tool_on:
                return Reason(Why.TOOL_ON_BOLT, bolt=self.bolt)
            return None
        if t is None:
            return Reason(Why.NOT_TEACHING)
        if isinstance(cmd, TeachPoint) and t.measuring is not None:
            return Reason(Why.TEACHING, note=t.reason())
        if isinstance(cmd, TeachPoint) and self.faults:   # no frames would come: said now
            return Reason(Why.DEVICE_FAULT, note=self._fault_reason())
        return None

    def _teach_done(self, t: float, c: CommandIn) -> list[Action]:
        """A recorded teach command takes effect: the mode on (the tool off, the selection
        dropped), a bolt's measuring started (answered once measured), or the mode off."""
        cmd = c.command
        if isinstance(cmd, TeachStart):
            acts = self._drop(t, State.TEACHING, "teach mode")
            self._teach = _Teach(cmd.model, c.issuer.user)
            self._to(State.TEACHING, self._teach.reason())
            return [*acts, Reply(Answer(c.request, cmd, c.issuer))]
        if self._teach is None:
            return [Reply(Answer(c.request, cmd, c.issuer, Reason(Why.NOT_TEACHING)))]
        if isinstance(cmd, TeachPoint):
            self._teach.measuring, self._teach.points, self._teach.tries = c, [], 0
            self._teach.since, self._teach.frames = c.t, 0
            self.reason = self._teach.reason()
            return []
        self._teach = None
        self._to(State.WAITING_VEHICLE, "teach mode ended; waiting for the lift")
        return [Reply(Answer(c.request, cmd, c.issuer))]

    def _on_CommandDone(self, ev: CommandDone) -> list[Action]:  # noqa: N802
        c = self._commands.pop(ev.request, None)
        if c is None:
            return []
        answer = Answer(ev.request, c.command, c.issuer, ev.reason)
        if ev.reason is not None:
            return [Reply(answer)]
        cmd = c.command
        if isinstance(cmd, CheckCalibration):
            return self._check_asked(ev.t, c)
        if isinstance(cmd, TeachStart | TeachPoint | TeachStop):
            return self._teach_done(ev.t, c)
        if isinstance(cmd, SignIn | SignOut):
            user = c.issuer.user if isinstance(cmd, SignIn) else None
            how = OperatorChange.SIGNED_IN if user is not None else OperatorChange.SIGNED_OUT
            by = c.issuer.user if user is None and c.issuer.user != self.operator else None
            return [*self._operator_is(ev.t, user, how, by), Reply(answer)]
        acts: list[Action] = []
        if isinstance(cmd, SkipBolt):
            acts += self._skip(ev.t, cmd, c.issuer)
        elif isinstance(cmd, ReleaseBolt):
            held = self.matcher is not None and self.vin == cmd.vin \
                and self.matcher.held.pop(cmd.bolt, None) is not None
            if held:
                acts.append(Publish(BoltReleased(cmd.bolt, c.issuer.user, t=ev.t)))
            if self.matcher is not None and self.vin == cmd.vin \
                    and self.matcher.locked.pop(cmd.bolt, None) is not None:
                self._noks.pop(cmd.bolt, None)
                acts.append(Publish(BoltReleased(cmd.bolt, c.issuer.user, t=ev.t)))
                if cmd.bolt in self._loosen:   # released, still to be loosened first
                    acts.append(self._to_loosen(ev.t, cmd.bolt))
        elif isinstance(cmd, LoosenBolt):
            acts += self._loosen_ordered(ev.t, cmd, c.issuer)
        elif isinstance(cmd, ReopenVehicle):
            acts.append(Publish(VehicleReopened(cmd.vin, c.issuer.user, t=ev.t)))
            if cmd.vin == self._closed_vin and VEHICLE in self.faults:
                # the closed vehicle at height, reopened: its fault clears and the next lift
                # read loads it (open now)
                self._closed_vin, self._loading = None, False
                acts += self._back(ev.t, VEHICLE)
        return [*acts, Reply(answer)]

    def _skip(self, t: float, cmd: SkipBolt, who: Issuer) -> list[Action]:
        """The bolt is not tightened at this station for this vehicle; a selection of it ends
        (the tool goes off)."""
        if self.matcher is None or self.vin != cmd.vin or cmd.bolt not in self.matcher.bolts:
            return []   # the vehicle left while the command was being recorded
        why = skip_note(who.user, cmd.comment)
        self.matcher.skipped[cmd.bolt] = why
        acts: list[Action] = [Publish(BoltSkipped(cmd.bolt, why, t=t))]
        if self.bolt == cmd.bolt:
            acts += self._drop(t, State.TRACKING, f"bolt {cmd.bolt} {why}")
        return acts

    def _loosen_ordered(self, t: float, cmd: LoosenBolt, who: Issuer) -> list[Action]:
        """A recorded loosen command: the bolt is no longer done and gets its loosen pset
        next; a selection of it ends (its tightening pset may have been sent)."""
        if self.matcher is None or self.vin != cmd.vin or cmd.bolt not in self.matcher.bolts:
            return []   # the vehicle left while the command was being recorded
        self.matcher.done.discard(cmd.bolt)
        self._loosen.add(cmd.bolt)
        acts = [self._to_loosen(t, cmd.bolt, who.user, skip_note(who.user, cmd.comment))]
        if self.bolt == cmd.bolt:
            acts += self._drop(t, State.TRACKING, f"bolt {cmd.bolt}: loosen first")
        return acts

    def _to_loosen(self, t: float, bolt: str, user: str | None = None,
                   note: str | None = None) -> Action:
        pset = self.nok.rule(bolt, self._specs[bolt].pset).loosen_pset
        return Publish(BoltToLoosen(bolt, Reason(Why.LOOSEN_FIRST, bolt=bolt, pset=pset,
                                                 note=note), user, t=t))

    def _after_loosening(self, t: float, en: Selection, ok: bool) -> list[Action]:
        """A loosening is never the bolt done (it undoes a tightening).  OK: the bolt's
        tightening pset goes next; NOK: it counts as a NOK of the bolt (the joint did not come
        loose: ``max_nok`` of them lock it) and a bolt to loosen stays so."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self.matcher.done.discard(en.bolt)
        self._nok_last.discard(en.bolt)
        self.matcher.counted.discard(en.bolt)   # undone: no longer counts in its batch
        if ok:
            self._loosen.discard(en.bolt)
            return [Publish(Notice(f"{en.bolt} loosened: its tightening pset goes next",
                                   t=t))]
        n = self._noks[en.bolt] = self._noks.get(en.bolt, 0) + 1
        rule = self.nok.rule(en.bolt, self._specs[en.bolt].pset)
        if n >= rule.max_nok:
            return self._lock(t, en.bolt, n)
        return [Publish(Notice(f"{en.bolt}: loosening NOK ({n} NOK in a row)", "warning",
                               t=t))]

    def _lock(self, t: float, bolt: str, n: int) -> list[Action]:
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self.matcher.locked[bolt] = n
        return [Publish(BoltLocked(bolt, n, t=t)),
                Publish(Notice(f"{bolt} locked after {n} NOK in a row: a supervisor "
                               "releases it", "warning", t=t))]

    def _after_nok(self, t: float, en: Selection) -> list[Action]:
        """The NOK policy: the bolt locks after ``max_nok`` in a row; with ``loosen`` it gets
        its loosen pset next (also once released); with ``skip`` it is marked NOK and skipped
        for this vehicle; with ``repeat`` it is open again."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        n = self._noks[en.bolt] = self._noks.get(en.bolt, 0) + 1
        rule = self.nok.rule(en.bolt, self._specs[en.bolt].pset
                             if en.bolt in self._specs else en.pset)
        if rule.strategy == "loosen" and rule.loosen_pset is not None:
            self._loosen.add(en.bolt)
        if rule.count_in_batch:     # the sequence goes on without an OK of this bolt
            self.matcher.counted.add(en.bolt)
        if n >= rule.max_nok:
            return self._lock(t, en.bolt, n)
        if en.bolt in self._loosen:
            return [self._to_loosen(t, en.bolt)]
        if rule.strategy == "skip":
            why = NOK_SKIPPED
            self.matcher.skipped[en.bolt] = why
            return [Publish(BoltSkipped(en.bolt, why, t=t))]
        return []

    def _on_DeviceFault(self, ev: DeviceFault) -> list[Action]:  # noqa: N802
        if ev.device == WRENCH:
            self._vin_pending = False
            self._link_lost_at = ev.t
            if self._enabled is not None and self._enabled_at is not None and self._cut is None \
                    and self._result_owed(ev.t):
                # the tool's result may come only after the reconnect: where it belongs is
                # then proved by the controller's own data (:meth:`_made_during_cut`)
                self._cut = _Cut(self._enabled, self._enabled_at, ev.t)
        if ev.device == DATABASE:
            # the load under way failed (the only database call the core waits for): the
            # vehicle is loaded again once the database is back and the lift still ready
            self._loading = False
        return self._fault(ev.t, ev.device, ev.kind, ev.reason)

    def _on_DeviceBack(self, ev: DeviceBack) -> list[Action]:  # noqa: N802
        if ev.device == WRENCH and ev.reconnects is not None \
                and ev.reconnects != self._wrench_reconnects:
            if self._wrench_reconnects is not None:
                self._wrench_epoch += 1   # a reconnected controller may have lost the VIN
            self._wrench_reconnects = ev.reconnects
        acts: list[Action] = []
        if ev.device == WRENCH and WRENCH in self.faults:
            # the DisableTool sent at the fault may never have arrived: off, whatever it did
            acts += _disable("controller back: the tool stays off until a bolt is confirmed",
                             t=ev.t)
        return acts + self._back(ev.t, ev.device)

    def _on_ModelsKnown(self, ev: ModelsKnown) -> list[Action]:  # noqa: N802
        self.models = frozenset(ev.models)
        return []

    def _on_VinSent(self, ev: VinSent) -> list[Action]:  # noqa: N802
        self._vin_pending = False
        if ev.vin == self.vin:
            self._vin_for = (ev.vin, self._wrench_epoch)
        return []

    def _on_Tick(self, ev: Tick) -> list[Action]:  # noqa: N802
        if self._off_at is not None and ev.t - self._off_at >= self.late_result_s:
            self._enabled, self._off_at = None, None
        return self._teach_overdue(ev.t) + self._check_due(ev.t) + self._operator_idle(ev.t)

    # -- the operator signed in at the station ---------------------------------------------
    def _on_OperatorBack(self, ev: OperatorBack) -> list[Action]:  # noqa: N802
        """Signed in before a start or reload: still signed in (said at :class:`Started`),
        unless idle too long already."""
        if self.operator_idle_s is not None and ev.t - ev.since >= self.operator_idle_s:
            return []
        self.operator, self._operator_seen = ev.user, ev.since
        return []

    def _operator_is(self, t: float, user: str | None, how: OperatorChange,
                     by: str | None = None) -> list[Action]:
        """``user`` (None: nobody) is the operator from now on.  A bolt selected for the last
        one is left (the tool off): its rundown would carry the wrong name."""
        previous, self.operator, self._operator_seen = self.operator, user, t
        acts: list[Action] = []
        if previous != user and (self.state in ON_A_BOLT or self.tool_on):
            acts += self._drop(t, State.TRACKING, f"operator {how}")
        self._last_refusal = None   # a refusal to nobody is said again to the next one
        return [*acts, Publish(OperatorChanged(user, self.operator_required, previous, how,
                                               by, t=t))]

    def _operator_idle(self, t: float) -> list[Action]:
        """The operator idle for ``operator_idle_s`` (no selection, no rundown) is signed
        out, and that is recorded as their sign-out by the station (nobody waits for it:
        request 0)."""
        idle, user = self.operator_idle_s, self.operator
        if idle is None or user is None or self.tool_on or self.state in ON_A_BOLT \
                or t - self._operator_seen < idle:
            return []
        out = SignOut(f"idle for {idle:g} s", user)
        return [*self._operator_is(t, None, OperatorChange.IDLE),
                RecordCommand(0, out, Issuer(user, frozenset(), "station (idle)"), t)]

    def _teach_overdue(self, t: float) -> list[Action]:
        """A teach point not measured in :data:`TEACH_WAIT_S` is answered with what happened:
        no localization at all, or too few steady ones (the engineer is waiting)."""
        teach = self._teach
        if teach is None or teach.measuring is None or t - teach.since < TEACH_WAIT_S:
            return []
        why = Reason(Why.NO_FRAMES, limit=TEACH_WAIT_S) if teach.frames == 0 else \
            Reason(Why.NOT_STEADY, count=len(teach.points), needed=TEACH_FRAMES,
                   cause=teach.missed, limit=teach.tries)
        return self._teach_answered(teach, why)

    def _teach_answered(self, teach: _Teach, why: Reason) -> list[Action]:
        """The bolt being measured is answered with ``why`` (not taught); teach mode stays."""
        c = teach.measuring
        teach.measuring, teach.points, teach.tries, teach.frames = None, [], 0, 0
        teach.missed = None
        if c is None:
            return []
        if self.state is State.TEACHING:
            self.reason = teach.reason()
        return [Reply(Answer(c.request, c.command, c.issuer, why))]

    # -- the calibration check (the rules: stationd.station.trust) -------------------------
    def _measure(self, t: float, why: str, request: int | None = None) -> list[Action]:
        assert self.trust is not None  # noqa: S101 - only called with references
        self.trust.asked(t)
        at_height = self._lift is not None and self._lift.at_height
        return [MeasureReferences(self.trust.pairs, at_height, why, request, t)]

    def _check_at_start(self, t: float) -> list[Action]:
        """No pair is trusted until checked: a check at once (without references: said)."""
        if self.trust is None:
            return [Publish(Notice("no calibration check configured (no references in the "
                                   "station file): every pair is trusted", t=t))]
        return [*self._unchecked(t), *self._measure(t, "station started")]

    def _check_on_arrival(self, t: float, vin: str) -> list[Action]:
        """A vehicle arrives: its pairs are trusted again only once checked for it."""
        if self.trust is None:
            return []
        self.trust.distrust(f"checking for vehicle {vin}", t)
        return [*self._unchecked(t), *self._measure(t, f"vehicle {vin} arrived")]

    def _unchecked(self, t: float) -> list[Action]:
        """The screens told which pairs wait for a check, and why."""
        assert self.trust is not None  # noqa: S101 - only called with references
        reasons = tuple(r for r in self.trust.why.values()
                        if r is not None and r.kind is Why.PAIR_UNCHECKED)
        return [Publish(PairsUnchecked(reasons, t=t))] if reasons else []

    def _check_due(self, t: float) -> list[Action]:
        if self.trust is None or self.state is State.STARTING:
            return []
        idle = not self.tool_on and self.state not in ON_A_BOLT and self._teach is None
        if self.trust.due(t, idle=idle, vehicle=self.vin is not None):
            return self._measure(t, "periodic check")
        return []

    def _check_asked(self, t: float, c: CommandIn) -> list[Action]:
        """A person asked for a check (recorded): measured now, answered with the verdicts."""
        assert self.trust is not None  # noqa: S101 - refused without references
        self.trust.requests.append(c.request)
        self._commands[c.request] = c   # kept for the answer
        return self._measure(t, f"asked by {c.issuer.user}", c.request)

    def _trusted(self, ev: LocalizedIn) -> LocalizedIn:
        """A bolt end made by a pair that is not trusted is a refusal with that pair's reason
        (the localization leaves such pairs out already: this is the rule itself)."""
        if self.trust is None or ev.point_mm is None:
            return ev
        why = self.trust.refusal(ev.pairs)
        return ev if why is None else replace(ev, point_mm=None, reason=why)

    def _on_ReferencesChecked(self, ev: ReferencesChecked) -> list[Action]:  # noqa: N802
        if self.trust is None:
            return []
        acts: list[Action] = []
        for check, before, after in self.trust.answered(ev.t, ev.checks, ev.asked_t):
            acts.append(Publish(PairChecked(
                check.pair, check.verdict.value, check.reference, check.offset_mm,
                check.tolerance_mm, {m.name: m.offset_mm for m in check.measures},
                after is None, after, t=ev.t)))
            acts.append(RecordCheck(check, ev.t))
            if after is not None and self.bolt is not None and self.tool_on \
                    and before is None:
                # the tool stays on only on a confirmed bolt: the next localization decides,
                # and one made by this pair is refused now
                acts.append(Publish(Notice(f"{check.pair} no longer trusted while bolt "
                                           f"{self.bolt} is selected", "warning", t=ev.t)))
        waiting = [ev.request] if ev.request is not None else []
        for request in waiting:
            if request in self.trust.requests:
                self.trust.requests.remove(request)
            c = self._commands.pop(request, None)
            if c is not None:
                acts.append(Reply(Answer(request, c.command, c.issuer,
                                         result=check_answer(ev.checks))))
        return acts

    # -- rules shared by the handlers ------------------------------------------------------
    def _vin_due(self) -> list[Action]:
        """The controller tags its results with the VIN: sent once per vehicle and again after
        the controller reconnected (a power cycle forgets it)."""
        if self.vin is None or WRENCH in self.faults or self._vin_pending:
            return []
        if self._vin_for == (self.vin, self._wrench_epoch):
            return []
        self._vin_pending = True
        return [SendVin(self.vin)]

    def _fault(self, t: float, device: str, kind: FaultKind, reason: str) -> list[Action]:
        acts: list[Action] = []
        if self.faults.get(device) != (kind, reason):
            acts.append(Publish(DeviceHealth(device, False, kind, reason, t=t)))
        self.faults[device] = (kind, reason)
        acts += self._drop(t, State.FAULT, self._fault_reason())
        if self._teach is not None and self._teach.measuring is not None:
            # a bolt being taught is measured only without faults: answered now, with them
            acts += self._teach_answered(self._teach, Reason(Why.DEVICE_FAULT,
                                                             note=self._fault_reason()))
        return acts

    def _back(self, t: float, device: str) -> list[Action]:
        if device not in self.faults:
            return []
        del self.faults[device]
        acts: list[Action] = [Publish(DeviceHealth(device, True, t=t))]
        if self.state is State.FAULT:
            if self.faults:
                self.reason = self._fault_reason()
            else:
                self._to(State.WAITING_VEHICLE, "recovered; waiting for the lift")
        return acts

    def _fault_reason(self) -> str:
        return "; ".join(f"{d}: {r}" for d, (_, r) in self.faults.items())

    def _tool_off(self, t: float, reason: str, why: Reason | None = None) -> list[Action]:
        was = self.tool_on
        self.tool_on = False
        if was:
            self._off_at = t
        return _disable(reason, self.bolt, why, t=t)

    def _drop(self, t: float, state: State, reason: str,
              why: Reason | None = None) -> list[Action]:
        """Leave a bolt: the tool goes off first, whatever happens next."""
        acts: list[Action] = []
        if self.state in ON_A_BOLT or self.tool_on:
            acts += self._tool_off(t, reason, why)
        self.bolt, self._selection, self._acked_at, self._away = None, None, None, 0
        if self.matcher is not None:
            self.matcher.reset()
        self._to(state, reason)
        return acts

    def _forget_vehicle(self) -> None:
        self._cut = None
        self.vin, self.model, self.matcher, self._specs = None, None, None, {}
        self._loosen, self._nok_last = set(), set()
        self._loading, self._enabled, self._off_at = False, None, None
        self._vin_for, self._vin_pending, self._last_refusal = None, False, None

    def _to(self, state: State, reason: str) -> None:
        """The one place the state changes: with any device in fault the state is FAULT, and
        in teach mode TEACHING, so no rule elsewhere can leave them by accident."""
        if self.faults:
            state, reason = State.FAULT, self._fault_reason()
        elif self._teach is not None:
            state, reason = State.TEACHING, self._teach.reason()
        self.state, self.reason = state, reason


def _said(result: TighteningResult) -> object:
    """What a result says besides its id: equal for a copy the controller sends again,
    different for another result under the same id (a controller whose ids started again)."""
    return (type_code(result), getattr(result, "pset", None), getattr(result, "ok", None),
            getattr(result, "torque_nm", None), getattr(result, "angle_deg", None),
            getattr(result, "timestamp", None))


def type_code(result: TighteningResult) -> int | None:
    """A result's type code as the controller sent it (Open Protocol MID 0061 revision 3+,
    parameter 49), None where its revision (or the backend) carries none."""
    code = getattr(result, "result_type_code", None)
    if code is not None:
        return int(code)
    t = getattr(result, "result_type", None)
    return None if t is None else int(t)


def rundown_kind(result: TighteningResult, sent_loosen: bool) -> str:
    """A rundown's kind (db.kinds): its own type where its revision carries it, else what
    the station sent (a loosen pset or the tightening one).  The type wins: a controller
    reversed by hand reports the loosening it made, whatever was sent.  Only for results
    that are rundowns (:func:`result_kind` says which are not)."""
    return LOOSENING if result_kind(type_code(result), sent_loosen) is ResultKind.LOOSENING \
        else TIGHTENING


_TYPE_WORDS = {ResultType.BATCH_INCREMENT: "batch increment",
               ResultType.BATCH_DECREMENT: "batch decrement",
               ResultType.BYPASS_PSET: "bypass parameter set", ResultType.ABORT_JOB: "abort job",
               ResultType.REFERENCE_SETUP: "reference setup",
               ResultType.TIGHTENING: "tightening", ResultType.LOOSENING: "loosening",
               ResultType.SYNC_TIGHTENING: "synchronized tightening"}


def result_type_words(code: int | None) -> str:
    """A result type as the controller's screen would name it; an unknown code by number."""
    try:
        return _TYPE_WORDS[ResultType(code)] if code is not None else "result"
    except ValueError:
        return f"result type {code} (unknown)"


def _disable(reason: str, bolt: str | None = None, why: Reason | None = None, *,
             t: float) -> list[Action]:
    """The tool off: said on the bus (the screens, the journal), then done."""
    return [Publish(ToolDisabled(reason, bolt, why, t=t)), DisableTool(reason, bolt, why)]
