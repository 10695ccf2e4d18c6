"""What the station tells the world: typed events the demo, the bench, the screens and the tests
consume (never strings to parse).

The daemon publishes one of these for everything that happened, in order, on an
:class:`EventBus`; consumers subscribe (the web screens, the demo's checker) or read the bounded
history (tests, the bench).  Every event is a frozen dataclass with a ``t`` (seconds on the
host's wall clock, ``time.time()`` scale) so it can be serialised as it is (``to_json``) and
shown in order.  Positions are in the vehicle frame, millimetres.

These are *outputs*.  The pure core's inputs (lift reads, localizations, acknowledgements,
results, device faults, ticks) and the actions it answers live in
:mod:`stationd.station.core`; the daemon turns the core's answers into these.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import time
from dataclasses import dataclass, field
from typing import Any

from db.kinds import BoltStatus
from drivers.identity import DeviceIdentity
from stationd.reasons import CoreFault, FaultWhy, Reason, Skip, Unattributed


def _now() -> float:
    return time.time()


@dataclass(frozen=True)
class StationEvent:
    """Base of every published event."""

    t: float = field(default_factory=_now, kw_only=True)

    @property
    def kind(self) -> str:
        """The event's name on the wire (``StateChanged`` -> ``state_changed``)."""
        name = type(self).__name__
        return "".join("_" + c.lower() if c.isupper() and i else c.lower()
                       for i, c in enumerate(name))

    def to_json(self) -> dict[str, Any]:
        """A JSON-safe dict: arrays to lists, enums to values, NaN/inf to None.  A field
        marked :data:`WORDED` is left out: its words are in the event's text field."""
        out: dict[str, Any] = {"kind": self.kind}
        for f in dataclasses.fields(self):
            if not f.metadata.get(WORDED):
                out[f.name] = jsonable(getattr(self, f.name))
        return out


#: a field's metadata: the typed value the core decided, whose words the shell's publication
#: writes into the event's text field (:func:`stationd.words.worded`); the JSON keeps the text
WORDED = "worded"


def jsonable(v: Any) -> Any:
    """``v`` as JSON can carry it: enums to their values, NaN and inf to None, tuples and
    sets to lists, arrays to lists, dataclasses (a reason and the reasons in it) to dicts."""
    if isinstance(v, enum.Enum):
        return v.value
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple | set | frozenset):
        items = sorted(v) if isinstance(v, set | frozenset) else v
        return [jsonable(x) for x in items]
    if hasattr(v, "tolist"):  # numpy arrays and scalars
        return jsonable(v.tolist())
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: jsonable(getattr(v, f.name)) for f in dataclasses.fields(v)}
    return v


# -- the station's state ----------------------------------------------------------------------
class State(enum.StrEnum):
    """The station's state (its value is the word the screens and STATUS= show)."""

    STARTING = "starting"
    WAITING_VEHICLE = "waiting for vehicle"
    TRACKING = "tracking"
    BOLT_SELECTED = "bolt selected"
    TIGHTENING = "tightening"
    FAULT = "fault"
    TEACHING = "teaching"


class Because(enum.Enum):
    """Why the station is in its state, or why the tool went off: the kind of a
    :class:`StateReason` (the fields it uses in parentheses).  The words are
    :func:`stationd.words.state_words`'s: the journal, STATUS=, the screens and OPC UA say
    them alike, none reads them back."""

    # the station and its devices
    OPENING = "opening"                  # starting: the devices being opened
    FAULT = "fault"                      # devices in fault (faults: each one's own words,
    #                                      or the station's own fault, typed)
    RECOVERED = "recovered"              # every device back: waiting for the lift
    STARTED = "started"                  # the tool off at a start, until a bolt is confirmed
    CONTROLLER_BACK = "controller back"  # the tool off as the controller is back
    # the vehicle and the lift
    WAITING_LIFT = "waiting lift"        # started: waiting for the lift
    LIFT_NOT_READY = "lift not ready"    # (note: the lift's own words: moving, not at height)
    LOADING = "loading"                  # a vehicle at height being loaded (vin)
    TRACKING = "tracking"                # a vehicle loaded: following the wrench
    # a bolt and the tool
    SELECTED = "selected"                # parameters sent (bolt, pset; loosen: its loosen
    #                                      pset, a loosening first)
    ACKNOWLEDGED = "acknowledged"        # the controller took them: the wrench confirmed next
    #                                      (bolt)
    RESULT_OWED = "result owed"          # confirmed, the tool kept off: another bolt's result
    #                                      may still come (bolt; owed: that bolt)
    CUT_OWED = "cut owed"                # confirmed, the tool kept off: the results made
    #                                      during a link cut not fetched yet (bolt; owed:
    #                                      the bolt enabled when the link went down)
    TIGHTENING = "tightening"            # the tool on (bolt)
    NOT_CONFIRMED = "not confirmed"      # the tool off: the wrench not confirmed on it (bolt)
    SELECTED_UNCONFIRMED = "selected unconfirmed"  # still selected, tool off (bolt)
    WRENCH_LEFT = "wrench left"          # the selection dropped (bolt)
    LATE_ACK = "late ack"                # the tool off: an acknowledgement after the
    #                                      selection (bolt)
    # results
    RUNDOWN = "rundown"                  # the tool off: its result came (bolt; loosen: a
    #                                      loosening)
    PUSH_AFTER_LOST = "push after lost"  # the tool off: a rundown's result came, after
    #                                      others the controller did not push, fetched
    #                                      first (bolt)
    RESULT = "result"                    # back to tracking after it (bolt, ok, loosen)
    UNREADABLE = "unreadable"            # the tool off: its result could not be read (bolt)
    UNREADABLE_HELD = "unreadable held"  # ... and the bolt held, the selection dropped (bolt)
    NOT_TAKEN = "not taken"              # the tool off: an OK without a type outside the
    #                                      bolt's torque window (bolt)
    NOT_TAKEN_HELD = "not taken held"    # ... and the bolt held, the selection dropped (bolt)
    UNKNOWN_HELD = "unknown held"        # the bolt selected held, its result not known (a
    #                                      link cut's, a lost push's): the selection dropped
    # commands
    SKIPPED = "skipped"                  # the bolt selected was skipped (bolt, skip: why,
    #                                      as the matcher keeps it)
    LOOSEN_ORDERED = "loosen ordered"    # a loosen command for the bolt selected (bolt)
    OPERATOR = "operator"                # the operator changed on a bolt (how)
    # teach-in
    TEACH_MODE = "teach mode"            # the tool off: teach mode starts
    TEACHING = "teaching"                # (model, user; bolt: the one being measured)
    TEACH_ENDED = "teach ended"          # teach mode off: waiting for the lift
    TEACH_ENDED_TRACKING = "teach ended, tracking"   # teach mode off, a vehicle at height


@dataclass(frozen=True)
class StateReason:
    """Why the station is in its state (also why the tool went off): its kind and the
    details that apply (the others stay None).  Typed, not words: the core decides, and
    :func:`stationd.words.state_words` says it at the edges."""

    kind: Because
    _: dataclasses.KW_ONLY
    bolt: str | None = None
    vin: str | None = None
    pset: int | None = None
    loosen: bool = False                # a loosen pset sent, or a loosening's result
    ok: bool | None = None              # a result's verdict
    how: OperatorChange | None = None   # how the operator changed
    model: str | None = None            # the model taught
    user: str | None = None             # who teaches
    #: (device, why: its own words or the station's typed fault) for each device in fault,
    #: in the order they failed
    faults: tuple[tuple[str, FaultWhy], ...] = ()
    skip: Skip | None = None            # why the bolt selected was skipped
    owed: str | None = None             # the bolt whose result may still come
    note: str | None = None             # words from elsewhere (the lift)


@dataclass(frozen=True)
class StateChanged(StationEvent):
    """The cycle's state or its reason changed."""

    state: State
    reason: StateReason


@dataclass(frozen=True)
class DeviceHealth(StationEvent):
    """A device's health changed: ``device`` is ``lift``, ``wrench``, ``database`` or a camera
    pair's name; ``ok`` False with the fault's ``kind`` (``down``, ``timeout``, ``garbage``,
    ``refused``, ...) and readable ``reason``; ``ok`` True when it answers again.

    ``fault``: the station's own fault, typed, as the core decided it (the vehicle at height
    is not the one loaded, parameters refused).  The core writes no words: it publishes
    ``fault`` with ``reason`` empty, and the shell's publication (:func:`stationd.words.worded`,
    the one path to the bus) writes its words into ``reason``.  Why a text field filled at
    publication rather than the typed value alone: every reader (the journal, the screens,
    OPC UA's ErrorMessage, ``stationd status``) reads ``reason`` for a device's own fault as
    for the station's, as before, and the event's JSON is unchanged (``fault`` is left out of
    it).  A device's own fault (a driver's text) comes in ``reason`` as it was said."""

    device: str
    ok: bool
    kind: str = ""
    reason: str = ""
    fault: CoreFault | None = field(default=None, kw_only=True, metadata={WORDED: True})


@dataclass(frozen=True)
class LineLinkChanged(StationEvent):
    """The link to the line database went up or down (``up``; ``reason``: the forwarder's
    last error), or its backlog alarm changed.  Not a :class:`DeviceHealth`: a lost line
    database is never a fault of the station (the screens would turn red); the OPC UA
    server shows it as the line asset's health."""

    up: bool
    reason: str = ""
    alarm: str | None = None


@dataclass(frozen=True)
class DeviceIdentified(StationEvent):
    """What a device said it is when it (re)connected: the controller's name, cell and
    channel, supplier, software versions (Open Protocol MID 0002).  ``identity``: its words
    (the devices panel, the status); ``identification``: the same, typed (OPC UA's
    Identification: manufacturer, serial number ...); None: words only."""

    device: str
    identity: str
    identification: DeviceIdentity | None = None


# -- the vehicle --------------------------------------------------------------------------------
@dataclass(frozen=True)
class BoltView:
    """A bolt as the screens draw it."""

    bolt: str
    x_mm: float
    y_mm: float
    z_mm: float
    pset: int | None
    order: int | None = None
    batch: str | None = None
    status: BoltStatus = BoltStatus.PENDING   # pending | ok | nok | skipped | loosen | loosened
    #: its last rundown a NOK, as the vehicle's report counts it ("ending NOK"), whatever it
    #: is drawn as now (to be loosened first, skipped, locked)
    last_nok: bool = False
    #: it has a rundown (the report counts a skipped bolt as skipped only without one)
    ran: bool = False
    #: released from a hold (its result not known), not run down since: it may be tightened
    #: already, the operator checks the controller first
    check_first: bool = False
    #: to be loosened first (status ``loosen``): the loosen pset that goes next (the screen
    #: says "loosen first P90" after a reload or a rework as live)
    loosen_pset: int | None = None
    #: locked after this many NOKs in a row (None: not locked): refused until a release
    locked: int | None = None
    #: held: its result is not known (the note says which result; None: not held), refused
    #: until a supervisor enters its outcome or releases it
    held: str | None = None


@dataclass(frozen=True)
class BoltsChanged(StationEvent):
    """Bolts of the loaded vehicle ``vin`` whose state the core changed, each as the core holds
    it now (:meth:`stationd.station.state.CoreState.bolt_views`; the snapshot:
    :attr:`stationd.station.state.CoreStatus.bolts`).  Published after the input that changed
    them, after that input's own events (the news: a lock, a release, a result, with their
    words).  Why: the core is the one writer of a bolt's state; a screen sets its bolts to
    these and decides nothing of their status, locks, holds or loosening (the screens kept a
    second state machine, which had to re-derive each of the core's rules)."""

    vin: str
    bolts: tuple[BoltView, ...]


@dataclass(frozen=True)
class VehicleOpened(StationEvent):
    """A vehicle is at the station: its bolts, and which are done already (a restart or a
    rework resumes a vehicle)."""

    vin: str
    model: str
    bolts: tuple[BoltView, ...]
    rework: bool = False


@dataclass(frozen=True)
class VehicleClosed(StationEvent):
    """A vehicle left (the lift went down): its bolts not tightened (``missing``, skipped
    ones too) and those whose last rundown is a NOK, as its records say then.  ``due``: the
    bolts whose result was still due from the controller as it left (the tool ran, or its
    late-result window, its check or a link cut's catch-up still ran): neither missing nor
    NOK, their verdict follows (:class:`ClosingSettled`).  A supervisor's trial: the last
    bolt said "ending NOK" as the lift went down, its OK result recorded a moment later."""

    vin: str
    missing: tuple[str, ...]
    nok: tuple[str, ...]
    due: tuple[str, ...] = ()


@dataclass(frozen=True)
class ClosingSettled(StationEvent):
    """The results due as ``vin`` left (:attr:`VehicleClosed.due`) are ``settled``: each
    recorded to its bolt of that vehicle, or no longer to come (its window over and nothing
    found, or its bolt held for a person).  The vehicle's closing verdict as its records say
    now (``missing``, ``nok``), the bolts still due (``due``) aside."""

    vin: str
    missing: tuple[str, ...]
    nok: tuple[str, ...]
    due: tuple[str, ...] = ()
    settled: tuple[str, ...] = ()


@dataclass(frozen=True)
class VehicleReopened(StationEvent):
    """A closed vehicle reopened for rework by ``user``: it opens (as a rework) when it is
    at the station at height, at once when it still is."""

    vin: str
    user: str


# -- tracking and selection ----------------------------------------------------------------------
@dataclass(frozen=True)
class Localized(StationEvent):
    """One localization of the wrench, published at most a few times a second for the screens:
    the bolt end (None when refused, with ``reason``), the tilt, the nearest bolt, the age
    counted from the frames' exposure, and which bolts the rules allow next."""

    point_mm: tuple[float, float, float] | None
    tilt_deg: float | None
    reason: Reason | None
    candidate: str | None
    distance_mm: float | None
    age_ms: float
    allowed: tuple[str, ...] = ()


@dataclass(frozen=True)
class Refused(StationEvent):
    """Nothing is sent, and why (stale, ambiguous, tilted, order rule, lift, fault...): emitted
    when the reason changes (its kind and bolts, not its measurements), not frame after frame."""

    reason: Reason
    bolt: str | None = None


@dataclass(frozen=True)
class BoltSelected(StationEvent):
    """The wrench is taken on ``bolt``: ``pset`` goes to the controller (``loosen``: the
    bolt's loosen pset, a loosening comes first)."""

    bolt: str
    pset: int | None
    point_mm: tuple[float, float, float]
    distance_mm: float
    tilt_deg: float
    loosen: bool = False


@dataclass(frozen=True)
class ParamsSent(StationEvent):
    """The controller acknowledged ``bolt``'s parameters; latency from the exposure of the
    frames that decided it, by stage (ms)."""

    bolt: str
    pset: int | None
    latency_ms: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class ParamsRefusedEvent(StationEvent):
    bolt: str
    reason: str


@dataclass(frozen=True)
class ToolEnabled(StationEvent):
    bolt: str


@dataclass(frozen=True)
class ToolDisabled(StationEvent):
    """The tool went off: ``reason`` (the station's, typed like the state's), ``why`` when a
    refusal turned it off (the wrench not confirmed on its bolt: stale, elsewhere, ...)."""

    reason: StateReason
    bolt: str | None = None
    why: Reason | None = None


@dataclass(frozen=True)
class BoltSkipped(StationEvent):
    """``bolt`` is not tightened at this station for this vehicle (reported missing):
    ``skip``, why, typed as the core decided it (the NOK policy, a loosen pset missing, the
    controller's refusal, a person's command); ``reason``, the same in words
    (:func:`stationd.words.skip_words`: ``olga's command (no access)``).

    The core writes no words: it publishes ``skip`` with ``reason`` empty, and the shell's
    publication (:func:`stationd.words.worded`) writes them.  Why a text field filled at
    publication rather than the typed value alone: the screens read ``reason`` as before and
    the event's JSON is unchanged (``skip`` is left out of it)."""

    bolt: str
    reason: str = ""
    skip: Skip | None = field(default=None, kw_only=True, metadata={WORDED: True})


@dataclass(frozen=True)
class BoltLocked(StationEvent):
    """``count`` NOKs in a row on ``bolt``: the tool is refused there until a release.
    ``held``: locked instead because its result could not be read (``count`` 0; the note
    says which result): a supervisor checks it on the controller, then releases it."""

    bolt: str
    count: int
    held: str | None = None


@dataclass(frozen=True)
class BoltToLoosen(StationEvent):
    """``bolt`` gets its loosen pset next (``reason``: a LOOSEN_FIRST with the pset, after a
    NOK under the loosen strategy or a loosen command of ``user``); its tightening pset only
    after a loosening result."""

    bolt: str
    reason: Reason
    user: str | None = None


@dataclass(frozen=True)
class BoltReleased(StationEvent):
    """A locked bolt released by ``user``: it may be tightened again.  ``unknown``: what was
    released is a hold (its result not known: unreadable, a link cut's, a lost push's), so the
    bolt may be tightened already, and the operator who goes to it is told to check the
    controller first (a supervisor's trial: only the supervisor was warned, the operator's
    screen said "to do" and the bolt was tightened twice)."""

    bolt: str
    user: str
    unknown: bool = False


class OperatorChange(enum.StrEnum):
    """How the operator signed in at the station changed (typed: the journal's words are
    chosen by it, never read back from text)."""

    SIGNED_IN = "signed in"
    SIGNED_OUT = "signed out"
    IDLE = "idle"                        # signed out by the station after operator_idle_s
    STILL_SIGNED_IN = "still signed in"  # at a start or reload, from the commands on disk
    NOBODY = "nobody signed in"          # at a start, with nobody signed in


@dataclass(frozen=True)
class OperatorChanged(StationEvent):
    """Who is signed in at the station now (``user`` None: nobody), whether the station
    requires someone to tighten (``access.operator_required``), who was before, and how it
    changed (``how``: signed in, signed out, idle, restored at a start, or the station's
    start with nobody)."""

    user: str | None
    required: bool = False
    previous: str | None = None
    how: OperatorChange = OperatorChange.NOBODY
    by: str | None = None     # who gave the sign-out (another user than ``previous``)


@dataclass(frozen=True)
class PairChecked(StationEvent):
    """A pair checked against the reference markers: its verdict (ok, moved, not checked),
    the worst reference and its offset (mm) against the tolerance, each reference's offset
    (None: not measured), and whether the pair is trusted now (``why`` when not)."""

    pair: str
    verdict: str
    reference: str | None = None
    offset_mm: float | None = None
    tolerance_mm: float | None = None
    offsets_mm: dict[str, float | None] = field(default_factory=dict)
    trusted: bool = False
    why: Reason | None = None


@dataclass(frozen=True)
class PairsUnchecked(StationEvent):
    """Pairs no longer trusted until their next check (a start, a reload, a vehicle's
    arrival): one ``PAIR_UNCHECKED`` reason per pair, with why.  A moved pair is not among
    them: it stays moved until a check finds it in place."""

    reasons: tuple[Reason, ...]


# -- results ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ResultRecorded(StationEvent):
    """A tightening result stored for ``bolt`` of ``vin`` (then acknowledged), or an outcome a
    person entered for a held bolt (``entered_by``; ``tightening_id`` 0: the record links the
    unreadable result)."""

    vin: str
    bolt: str
    ok: bool
    torque_nm: float
    angle_deg: float
    tightening_id: int
    pset: int | None = None
    torque_min: float | None = None
    torque_max: float | None = None
    angle_min: float | None = None
    angle_max: float | None = None
    late: bool = False
    images: tuple[str, ...] = ()
    kind: str = "tightening"         # or "loosening" (db.kinds): never the bolt done
    operator: str | None = None      # who was signed in at the station (None: nobody)
    #: who entered it from the controller's own screen (its result could not be read; None:
    #: measured, as the controller sent it)
    entered_by: str | None = None


@dataclass(frozen=True)
class ResultUnattributed(StationEvent):
    """A result no bolt can own (no tool enabled for its pset): acknowledged, not recorded."""

    tightening_id: int
    pset: int | None
    ok: bool


@dataclass(frozen=True)
class ControllerResultEvent(StationEvent):
    """A result from the controller that is not a rundown (a batch increment or decrement, a
    bypassed pset, an aborted job, a reference setup, or a type the station does not know):
    stored as a controller event; no bolt closed, opened or counted.  ``bolt``: the one the
    tool was enabled for (still open), if any.

    ``what``: the station's own kind (:data:`db.kinds.NOT_TAKEN`), or empty from the core:
    then the shell's publication (:func:`stationd.words.worded`) writes the name of
    ``result_type`` in words (``batch increment``, ``result type 9 (unknown)``), so the
    event reads as before while the core builds no words."""

    result_type: int
    what: str
    tightening_id: int
    pset: int | None
    ok: bool
    bolt: str | None = None


@dataclass(frozen=True)
class ResultUnreadable(StationEvent):
    """A result message the station could not read, stored whole; ``bolt``: the one it may
    belong to (held for a supervisor), if any."""

    error: str
    revision: int
    tightening_id: int | None = None
    bolt: str | None = None


# -- the cameras (commissioning screen) ---------------------------------------------------------
@dataclass(frozen=True)
class PairFrames(StationEvent):
    """A pair's latest grab, for the commissioning screen: exposure time, per-side detection
    summary (found, centre, ellipses, ROI, sharpness, reason).  Frames themselves are fetched
    on demand from the daemon's latest-frame store, never pushed."""

    pair: str
    exposure_t: float
    sides: dict[str, dict[str, Any]] = field(default_factory=dict)


class Said(enum.Enum):
    """What a notice says: its kind (the fields it uses in parentheses).  The words are
    :func:`stationd.words.notice_words`'s, the level (:attr:`Notice.level`) the kind's.
    Beside its event, not in :mod:`stationd.reasons`: only the core says notices, while
    refusals come also from the matcher and the vision below it."""

    # the calibration check
    NO_REFERENCES = "no references"      # no references configured: every pair trusted
    PAIR_DISTRUSTED = "pair distrusted"  # a pair no longer trusted on a selected bolt (pair,
    #                                      bolt)
    # results from the controller
    IDS_AGAIN = "ids again"              # a known id with other values (tightening_id)
    SENT_AGAIN = "sent again"            # a result the database had already: a copy the
    #                                      controller sent again, stored once
    #                                      (tightening_id; bolt: the one it was stored
    #                                      for; vin: its vehicle, if not the one here)
    UNATTRIBUTED = "unattributed"        # a result no bolt owns (tightening_id, pset;
    #                                      unattributed: why, as stored with it)
    CONTROLLER_EVENT = "controller event"  # not a rundown (result_type: its type code;
    #                                        bolt: the one still open)
    UNKNOWN_TYPE = "unknown type"        # a result type the station does not know
    #                                      (result_type, bolt as above)
    GAP = "gap"                          # tightenings missed (tightening_id..last_id,
    #                                      link_up, note: why they cannot be fetched)
    NOT_STORED = "not stored"            # the database refused a record (tightening_id, bolt,
    #                                      note: the database's error)
    UNREADABLE = "unreadable"            # a result no bolt it could belong to could not be
    #                                      read (note: the driver's error)
    HELD = "held"                        # a bolt held: its result could not be read (bolt,
    #                                      note: which result)
    NOT_TAKEN = "not taken"              # an OK without a type outside the bolt's window
    #                                      (bolt, torque_nm, torque_min, torque_max,
    #                                      tightening_id)
    UNKNOWN_TYPE_HELD = "unknown type held"  # a result of a type the station does not know
    #                                          under a bolt's enable: that bolt held (bolt,
    #                                          result_type, tightening_id)
    CUT_RECORDED = "cut recorded"        # made during a link cut, recorded to its bolt
    #                                      (tightening_id, bolt)
    CUT_NOTHING = "cut nothing"          # none made during the link cut: every result since
    #                                      fetched (bolt: the one enabled then)
    CUT_UNKNOWN = "cut unknown"          # the bolt enabled during a link cut held: what the
    #                                      controller did then is not known (bolt, note)
    LATE_RESULT = "late result"          # recorded outside a tightening (bolt)
    TYPED_COPY = "typed copy"            # a result fetched without its type, its bolt
    #                                      held, then pushed with its type, made under that
    #                                      bolt's enable: recorded to it, its hold ended
    #                                      (tightening_id, bolt)
    OTHER_VIN = "other vin"              # recorded to the bolt its tool was on for, the
    #                                      controller's VIN another than the vehicle's
    #                                      (tightening_id, bolt, vin: the vehicle's, note:
    #                                      the controller's)
    LOST_RECORDED = "lost recorded"      # its push lost, fetched when a later one came:
    #                                      made under the bolt's own enable, recorded to it
    #                                      (tightening_id, bolt)
    LOST_CHECKED = "lost checked"        # its push lost, fetched as its bolt's late-result
    #                                      window ended: recorded to it (tightening_id, bolt)
    LOST_FOUND_ON = "lost found on"      # its push lost, fetched by a check with the tool
    #                                      on: recorded to it, the tool off (tightening_id, bolt)
    LOOSEN_PSET_TIGHTENED = "loosen pset tightened"  # (bolt, pset)
    LOOSENED = "loosened"                # a loosening OK: the tightening pset next (bolt)
    LOOSENING_NOK = "loosening nok"      # (bolt, count: NOKs in a row)
    LOCKED = "locked"                    # too many NOKs in a row (bolt, count)
    NOK_AFTER_LOCK = "nok after lock"    # a NOK heard late, made after its bolt had reached
    #                                      max_nok (bolt, tightening_id, count: NOKs in a
    #                                      row now, locked_at: the count it locked at)
    ENTERED_OK = "entered ok"            # an outcome entered for a held bolt (bolt,
    ENTERED_NOK = "entered nok"          # torque_nm, angle_deg, user; note: the hold's)
    ENTERED_LOOSENING_OK = "entered loosening ok"    # the same for a held loosening (its
    ENTERED_LOOSENING_NOK = "entered loosening nok"  # result came under the loosen pset,
    #                                                  pset): never the bolt done
    # the vehicle and the tool
    REWORK_REOPENED = "rework reopened"  # a closed VIN reopened as a rework (vin)
    LATE_ACK = "late ack"                # an acknowledgement after the selection (bolt)


#: the kinds the journal writes as warnings (NOT_STORED as an error; the others as info)
_WARNINGS = frozenset({
    Said.PAIR_DISTRUSTED, Said.IDS_AGAIN, Said.UNATTRIBUTED, Said.UNKNOWN_TYPE, Said.GAP,
    Said.UNREADABLE, Said.HELD, Said.CUT_UNKNOWN, Said.NOT_TAKEN, Said.UNKNOWN_TYPE_HELD,
    Said.LOOSEN_PSET_TIGHTENED,
    Said.LOOSENING_NOK, Said.LOCKED, Said.NOK_AFTER_LOCK, Said.ENTERED_NOK,
    Said.ENTERED_LOOSENING_NOK, Said.OTHER_VIN})


@dataclass(frozen=True)
class Notice(StationEvent):
    """A line for the journal and the operator's log (warnings included): its kind and the
    details that apply (the others stay None).  Typed, not words: the core decides what is
    said, :func:`stationd.words.notice_words` how."""

    said: Said
    _: dataclasses.KW_ONLY
    bolt: str | None = None
    pair: str | None = None
    vin: str | None = None
    user: str | None = None
    tightening_id: int | None = None
    last_id: int | None = None          # the last of a range of ids (a gap)
    link_up: bool = False               # a gap made with the link up (never pushed)
    pset: int | None = None
    count: int | None = None
    torque_nm: float | None = None
    angle_deg: float | None = None
    torque_min: float | None = None     # the bolt's torque window (Nm)
    torque_max: float | None = None
    note: str | None = None             # words from elsewhere (a device, the database) or a
    #                                     record's own (a hold's note)
    result_type: int | None = None      # a controller event's type code
    unattributed: Unattributed | None = None  # why a result is stored unattributed
    locked_at: int | None = None        # the NOKs in a row its bolt locked at

    @property
    def level(self) -> str:
        """``info``, ``warning`` or ``error``: the kind's; a controller event is a warning
        only while a bolt is still open (the operator has to know the tool did not close
        it)."""
        if self.said is Said.NOT_STORED:
            return "error"
        if self.said in _WARNINGS or (self.said is Said.CONTROLLER_EVENT
                                      and self.bolt is not None):
            return "warning"
        return "info"


@dataclass(frozen=True)
class WrongBolt(StationEvent):
    """Only published by the simulation's checker: parameters were sent for ``bolt`` while
    the simulated wrench was really on ``truth`` (None: on no bolt).  Must never happen."""

    bolt: str
    truth: str | None


# -- the bus ------------------------------------------------------------------------------------
