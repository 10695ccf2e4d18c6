"""The screens' view model: the typed events folded into the snapshot the operator screen
shows.

Why a pure fold: the screen must show what the daemon decided, not re-decide it; folding the
same events the daemon publishes (no database, no clock, no I/O) makes the view testable
event by event and lets a browser that connects late start from a snapshot, then follow the
same events live.  ``View.apply`` is the only way state changes.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from db.kinds import (
    LOOSENED,
    LOOSENING,
    MISSING,
    NOK,
    OK,
    PENDING,
    SKIPPED,
    TO_LOOSEN,
    BoltStatus,
)
from stationd.reasons import Reason, Why
from stationd.station.events import (
    Because,
    BoltReleased,
    BoltsChanged,
    BoltSelected,
    BoltSkipped,
    BoltToLoosen,
    BoltView,
    ClosingSettled,
    DeviceHealth,
    DeviceIdentified,
    Localized,
    OperatorChanged,
    PairChecked,
    PairsUnchecked,
    ParamsRefusedEvent,
    ParamsSent,
    Refused,
    ResultRecorded,
    State,
    StateChanged,
    StationEvent,
    ToolDisabled,
    ToolEnabled,
    VehicleClosed,
    VehicleOpened,
    VehicleReopened,
    WrongBolt,
)
from stationd.station.inputs import DATABASE
from stationd.station.state import LOCALIZING, ON_A_BOLT, CoreStatus
from stationd.words import (
    check_words,
    fault_words,
    reason_words,
    state_words,
    stopped_words,
)


class Shown(StrEnum):
    """A bolt's state on the screen beyond its status (:class:`db.kinds.BoltStatus`, which
    the core, the events and the records share): where the operator's attention goes now."""

    NEXT = "next"               # the open bolt pointed out to go to
    SELECTED = "selected"       # its parameters sent
    TIGHTENING = "tightening"   # the tool on for it
    BLOCKED = "blocked"         # refused by the sequence's rules for now
    LOCKED = "locked"           # too many NOKs in a row (or held): refused until a release


#: what a bolt on the screen is: its status, or where attention goes now
BoltShown = BoltStatus | Shown

# a bolt's state on the screen; the label is what the operator reads next to the colour
BOLT_LABELS: dict[BoltShown, str] = {
    PENDING: "to do", Shown.NEXT: "next", Shown.SELECTED: "selected",
    Shown.TIGHTENING: "tighten", OK: "OK", NOK: "NOK", SKIPPED: "skipped",
    Shown.BLOCKED: "blocked",
    MISSING: "missing",         # a closed vehicle's bolt left untightened (the daemon's report)
    TO_LOOSEN: "loosen first",  # its loosen pset goes next (the NOK policy, a loosen command)
    LOOSENED: "loosened",       # loosened last: its tightening pset goes next
    Shown.LOCKED: "locked",     # too many NOKs in a row: refused until a release
}
# where the operator's attention is on an open bolt: the screen's, over the core's status
ATTENTION = (Shown.NEXT, Shown.SELECTED, Shown.TIGHTENING, Shown.BLOCKED)
# a bolt's words by its last rundown
RUNDOWN_WORDS: dict[BoltShown, str] = {NOK: "NOK: rework",
                                       LOOSENED: "loosened: tighten it again"}
# a bolt released from a hold (its result was not known), not run down since: drawn and said
# apart from "to do" while open, and its selection says so in amber
CHECK_FIRST = "check first"
CHECK_FIRST_WORDS = ("may be tightened already (released from a hold, its result not known): "
                     "check the controller before tightening")
# states a bolt can no longer be in once its vehicle closed: nothing is next or selected any
# more on a vehicle that left (the ones the daemon reports missing become "missing")
LIVE_STATES = (Shown.NEXT, Shown.SELECTED, Shown.TIGHTENING, Shown.BLOCKED)
# a bolt the closed vehicle left with, untightened (at its close, or once its result due came
# to nothing)
NOT_TIGHTENED = "not tightened when the vehicle left"
NAMES_SHOWN = 3   # bolts named in a closed vehicle's headline; the full list is its title
REASON_SHOWN = 110  # characters of a fault's reason in the headline (whole in its title)
LAST_RESULTS = 8
# refusals the operator must act on (amber): the wrench is seen, something about it or the
# sequence forbids sending; any other refusal while tracking means the wrench is simply not on
# a bolt (between bolts, out of view): a normal state, shown neutral, never as an alarm
ACT_ON = frozenset({Why.STALE, Why.AMBIGUOUS, Why.TILTED, Why.MUST_WAIT, Why.SKIPPED,
                    Why.DONE, Why.LOCKED, Why.HELD, Why.SIGN_IN})
NOT_AT_A_BOLT = "Bring the wrench to a bolt"
#: the same, where the station requires someone signed in and nobody is: the first thing to
#: do (a maintenance trial read "Bring the wrench to a bolt", and the wrench brought was
#: refused only then)
SIGN_IN_FIRST = "Nobody signed in: sign in to tighten"
TRACKING_STATES = tuple(s.value for s in LOCALIZING)   # where a refusal speaks of the wrench
# refusals that forbid their bolt (drawn "blocked"): the sequence's; a bolt the wrench is
# settling on ("B21: hold the wrench still on it (1 of 3 frames)") is not blocked (it was
# drawn so beside that headline); skipped and locked bolts have their own states
BLOCKS = frozenset({Why.MUST_WAIT})
# how much nearer to the wrench another open bolt must be to take the "next" pointer, mm
NEXT_HYSTERESIS_MM = 20.0
# a wrench refused with a position the vision found but will not use: seen, not out of view
WRENCH_SEEN = frozenset({Why.TILTED, Why.PAIRS_DISAGREE})
# how long stale frames before any fresh one read as the station starting (the cameras' first
# frames on their way), not as the stale-frame alarm: seconds of event time
STARTUP_GRACE_S = 30.0
STARTING_UP = "Starting: waiting for the cameras' first frames"


@dataclass
class BoltState:
    bolt: str
    x_mm: float
    y_mm: float
    pset: int | None
    order: int | None
    batch: str | None
    state: BoltShown = PENDING
    reason: str = ""
    #: its status as the core holds it (the state drawn is this, or the lock, or where the
    #: operator's attention is while it is open)
    status: BoltStatus = PENDING
    torque_nm: float | None = None
    angle_deg: float | None = None
    locked: bool = False        # too many NOKs in a row: a supervisor releases it
    loosen: bool = False        # its loosen pset goes next, before its tightening pset
    loosen_pset: int | None = None   # that loosen pset, as the station said it
    nok_count: int = 0          # NOKs in a row when it locked
    held: bool = False          # its result could not be read: an outcome entered, or a release
    #: the core's words of its lock and hold (NOKs in a row, the hold's note), None for none
    lock_count: int | None = None
    held_note: str | None = None
    #: its last rundown a NOK, as the vehicle's report says it (a release, a skip, a lock do
    #: not change it; the next rundown does, and a person's loosen command)
    ends_nok: bool = False
    #: it has a rundown: skipped, it is counted by its last rundown, not as skipped
    ran: bool = False
    #: released from a hold (its result was not known): it may be tightened already, and
    #: the operator checks the controller before tightening it again; until its next result,
    #: a skip or a new lock (a supervisor's trial: the screen said "to do", the bolt was
    #: tightened twice)
    check_first: bool = False
    #: what its last rundown's verdict went by: ``torque`` or ``angle`` out of its window,
    #: both, or None (within, or not known): the map's label shows the value that failed (an
    #: operator trial read "NOK 50.8", a torque within its window, for an angle of 0 deg)
    failed: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {"bolt": self.bolt, "x": self.x_mm, "y": self.y_mm, "pset": self.pset,
                "order": self.order, "batch": self.batch, "state": self.state,
                # the tool on for its loosen pset: the operator loosens, never "tighten"
                "label": "loosen" if self.loosen and self.state == Shown.TIGHTENING
                # held (its result not known) is no lock of NOKs: said apart (a trial)
                else "held" if self.held and self.state == Shown.LOCKED
                else CHECK_FIRST if self.check_first and self.state in (PENDING, Shown.NEXT)
                else BOLT_LABELS.get(self.state, self.state), "reason": self.reason,
                "torque_nm": self.torque_nm, "angle_deg": self.angle_deg,
                "locked": self.locked, "loosen": self.loosen,
                "loosen_pset": self.loosen_pset, "nok_count": self.nok_count,
                "held": self.held, "check_first": self.check_first, "failed": self.failed,
                "ends_nok": self.ends_nok}


@dataclass
class View:
    """What the operator screen shows, built from the events in order."""

    state: str = State.STARTING   # until the daemon says otherwise
    reason: str = ""              # the state's reason in words
    #: and its kind: a reader that acts on the reason switches on it, never parses words
    reason_kind: Because | None = None
    vin: str | None = None
    loaded: bool = False          # ``vin`` is open at the station (opened, not closed since)
    model: str | None = None
    rework: bool = False
    bolts: dict[str, BoltState] = field(default_factory=dict)
    wrench: dict[str, Any] | None = None
    refused: str = ""            # why nothing is sent now ("" when parameters may go out)
    act: bool = False            # ... and the operator resolves it (amber), by its kind
    refused_why: Reason | None = None
    devices: dict[str, dict[str, Any]] = field(default_factory=dict)
    identities: dict[str, str] = field(default_factory=dict)   # device -> what it said it is
    # each pair's calibration check (``PairChecked``, ``PairsUnchecked``): trusted or not,
    # the verdict (ok, moved, not checked) and the words; none without reference markers
    checks: dict[str, dict[str, Any]] = field(default_factory=dict)
    results: list[dict[str, Any]] = field(default_factory=list)
    selected: str | None = None
    selected_loosen: int | None = None   # the loosen pset sent for the selected bolt
    closed: dict[str, Any] | None = None
    reopened: tuple[str, str] | None = None   # (VIN, by whom): reopened, not at the station yet
    alarm: str = ""              # a wrong bolt reported by the simulation's checker
    # the devices the station was configured with (lift, wrench, each pair), given by the
    # server: the daemon reports a device's health only when it faults or comes back, so a
    # configured device with no report is "ok" once the station is past its start (the daemon
    # tries every device once before its first state; one that fails is reported as a fault)
    configured: tuple[str, ...] = ()
    # the station has tried its devices: the daemon opens the database first and only then
    # every device (``Station.open``), and its core's first state (after ``Started``) comes
    # after that; the one state published before, ``run._open``'s "fault: database" while the
    # database does not open, arrives with the database reported down and does not count
    opened: bool = False
    # fresh frames came since the station started (``_frames_seen``); the event time of the
    # first stale localization before them and of the last localization
    fresh: bool = False
    stale_since: float | None = None
    last_t: float = 0.0
    located: Localized | None = None   # the last localization (what "next" is pointed from)
    # who is signed in at the station (None: nobody) and whether the station requires one
    operator: str | None = None
    operator_required: bool = False

    def apply(self, e: StationEvent) -> None:
        """Fold one event in: each kind to its handler (the others change nothing shown)."""
        match e:
            case StateChanged():
                self._state(e)
            case DeviceIdentified():
                self.identities[e.device] = e.identity
            case DeviceHealth():
                self.devices[e.device] = _health(e.ok, e.kind, e.reason)
            case PairChecked():
                self.checks[e.pair] = {"trusted": e.trusted, "verdict": e.verdict,
                                       "words": check_words(e)}
            case PairsUnchecked():
                for r in e.reasons:
                    if r.pair is not None:
                        self.checks[r.pair] = {"trusted": False, "verdict": "not checked",
                                               "words": reason_words(r)}
            case VehicleOpened():
                self._open(e)
            case VehicleClosed():
                self._close(e)
            case ClosingSettled():
                self._settled(e)
            case VehicleReopened():
                self._reopened(e)
            case Localized():
                self._localized(e)
            case Refused():
                self._refused(e)
            case BoltSelected():
                self._selected(e)
            case ParamsSent():
                self._refuse("")
            case ParamsRefusedEvent():
                self._refuse(f"{e.bolt}: controller refused the parameters: {e.reason}",
                             act=True)
                self._set(e.bolt, Shown.BLOCKED, e.reason)
            case ToolEnabled():
                self._set(e.bolt, Shown.TIGHTENING)
            case ToolDisabled():
                self._tool_off(e)
            case BoltsChanged() if self.loaded and e.vin == self.vin:
                for bolt in e.bolts:
                    self._bolt_is(bolt)
            # the news of a bolt after its state (BoltsChanged): its words
            case BoltSkipped() if self._drawn(e.bolt, SKIPPED):
                self.bolts[e.bolt].reason = e.reason
            case BoltReleased() if self._drawn(e.bolt, PENDING, Shown.NEXT, TO_LOOSEN,
                                               LOOSENED, OK, NOK):
                b = self.bolts[e.bolt]
                b.reason = f"released by {e.user}" + (
                    f": {CHECK_FIRST_WORDS}" if b.check_first else "")
            case BoltToLoosen() if self._drawn(e.bolt, TO_LOOSEN):
                self.bolts[e.bolt].reason = reason_words(e.reason)
            case ResultRecorded():
                self._result(e)
            case OperatorChanged():
                self.operator, self.operator_required = e.user, e.required
                if e.user is not None and self.refused_why is not None \
                        and self.refused_why.kind is Why.SIGN_IN:
                    self._refuse("")     # signed in: the next frames decide
            case WrongBolt():
                self.alarm = f"parameters sent for {e.bolt} while the wrench was on {e.truth}"

    def seed(self, now: CoreStatus) -> None:
        """Take what the core decided, as of now (its snapshot), over the events folded so
        far: the state and its reason, which devices are in fault and which are not, what
        each device said it is, who is signed in, which pairs the calibration check trusts,
        the vehicle loaded (its VIN, model and bolts).  Why: the
        events a view starts from are the bus's bounded history; a screens' server started
        hours into a run (its port freed late) must not show a fault gone from that history
        as healthy, or the station as starting.  The events published after the snapshot are
        folded on it as before."""
        self.state, self.reason = now.state, state_words(now.reason)
        self.reason_kind = now.reason.kind
        if now.state not in TRACKING_STATES:
            self._refuse("")
        for device, why in now.faults.items():
            self.devices[device] = _health(False, now.fault_kinds.get(device, ""),
                                           fault_words(why))
        for device, health in list(self.devices.items()):
            if not health["ok"] and device not in now.faults:
                self.devices[device] = _health(True)
        if now.state != State.STARTING and DATABASE not in now.faults:
            self.opened = True
        self.identities.update(now.identities)
        self.operator, self.operator_required = now.operator, now.operator_required
        if now.untrusted is not None:   # the calibration check's trust, as the core has it
            for pair, distrust in now.untrusted.items():
                self.checks[pair] = {"trusted": False,
                                     "verdict": "moved" if distrust.kind is Why.PAIR_MOVED
                                     else "not checked", "words": reason_words(distrust)}
            for pair, check in self.checks.items():
                if not check["trusted"] and pair not in now.untrusted:
                    self.checks[pair] = {**check, "trusted": True}
        if now.vin != (self.vin if self.loaded else None):
            # the vehicle opened is gone from the history: as the core holds it, or none
            if now.vin is not None:
                self.vin, self.model = now.vin, now.model
                self._bolts_are(now.bolts)
            self.loaded = now.vin is not None
        elif now.vin is not None:
            for v in now.bolts:   # its bolts as the core holds them now
                self._bolt_is(v)

    def _state(self, e: StateChanged) -> None:
        self.state, self.reason, self.reason_kind = e.state, state_words(e.reason), e.reason.kind
        if e.state == State.STARTING:
            # a station (re)starting on its configuration: the last one's device
            # reports are not about these devices (a reload kept a fixed wrench "down")
            self.devices, self.opened, self.checks = {}, False, {}
            self.fresh, self.stale_since = False, None
        # the devices are tried once the database opened: a fault of it said before its
        # health event (a first start on a database down) leaves them "not opened yet" (a
        # technician's trial: the lift and the controller, never tried, read "ok")
        if e.state != State.STARTING and self.devices.get(DATABASE, {}).get("ok", True) \
                and all(d != DATABASE for d, _ in e.reason.faults):
            self.opened = True
        if e.state not in TRACKING_STATES:
            # a refusal is about the wrench while tracking: a station waiting for its
            # vehicle (or in fault) says that, not the last vehicle's "bring the wrench"
            self._refuse("")
        if e.state not in ON_A_BOLT and self.selected is not None:
            # the core dropped its selection (a result, the wrench gone, a fault): not a
            # result's record, which a slow database brings after the bolt's next selection
            # (a reviewer: it dropped that one)
            self.selected = self.selected_loosen = None
            self._unselect()

    def _reopened(self, e: VehicleReopened) -> None:
        # no longer "closed": it opens as a rework when raised at the station (then
        # VehicleOpened says so); until then the headline must not say closed
        if self.closed is not None and self.closed["vin"] == e.vin:
            self.closed = None
        self.reopened = (e.vin, e.user)

    def _refused(self, e: Refused) -> None:
        b = self.bolts.get(e.bolt or "")
        if b is not None and b.check_first and e.reason.kind is Why.NOT_STABLE:
            # settling on a bolt that may be tightened already: said now, in amber, not
            # only once it is selected (a supervisor's trial: neutral while it settled)
            self._refuse(f"{reason_words(e.reason)}: {CHECK_FIRST_WORDS}", e.reason, act=True)
        else:
            self._refuse(reason_words(e.reason), e.reason)
        if e.bolt in self.bolts and self.bolts[e.bolt].state in (PENDING, Shown.NEXT) \
                and e.reason.kind in BLOCKS:
            self._set(e.bolt, Shown.BLOCKED, self.refused)

    def _selected(self, e: BoltSelected) -> None:
        self._unselect()
        self.selected = e.bolt
        self.selected_loosen = e.pset if e.loosen else None
        if e.loosen and e.bolt in self.bolts:
            self.bolts[e.bolt].loosen_pset = e.pset
        self._refuse("")
        self._set(e.bolt, Shown.SELECTED, (f"loosen pset {e.pset}: loosen first" if e.loosen
                                       else f"pset {e.pset}") if e.pset is not None else "")
        if self.located is not None:    # the bolt pointed out was taken: point out another
            self._point_out_next(self.located)

    def _tool_off(self, e: ToolDisabled) -> None:
        b = self.bolts.get(e.bolt or self.selected or "")
        if b is not None and b.state in (Shown.SELECTED, Shown.TIGHTENING):
            self._set(b.bolt, PENDING)
        said = state_words(e.reason)
        if e.why is not None:
            self._refuse(f"{said} ({reason_words(e.why)})", e.why)
        elif said:   # a NOK rundown is for the operator to act on (amber), never neutral
            self._refuse(said, act=e.reason.kind is Because.RUNDOWN and e.reason.ok is False)

    def _bolt_is(self, v: BoltView) -> None:
        """Bolt ``v.bolt`` is as the core holds it (:class:`BoltsChanged`): its status, lock,
        hold, loosening and what the report counts are the core's; where the operator's
        attention is (next, selected, the tool on, blocked) stays the screen's while its
        status stays.  Drawn anew, its words are its state's; the news after it (a skip, a
        release, a loosen command, a result) gives its own."""
        b = self.bolts.get(v.bolt)
        if b is None:
            return
        was = b.state, b.status, b.locked, b.held, b.nok_count
        b.locked, b.held = v.locked is not None or v.held is not None, v.held is not None
        b.nok_count, b.check_first = v.locked or 0, v.check_first
        b.lock_count, b.held_note = v.locked, v.held
        b.loosen, b.ends_nok, b.ran = v.status == TO_LOOSEN, v.last_nok, v.ran
        if v.loosen_pset is not None:
            b.loosen_pset = v.loosen_pset
        if b.locked:
            b.state = Shown.LOCKED
        elif v.status != b.status or b.state not in ATTENTION:
            b.state = v.status
        b.status = v.status
        if (b.state, b.status, b.locked, b.held, b.nok_count) != was:
            b.reason = _state_words(b, v)
        if self.selected == b.bolt and b.state not in (Shown.SELECTED, Shown.TIGHTENING):
            self.selected, self.selected_loosen = None, None   # the core dropped it

    def _drawn(self, bolt: str | None, *states: BoltShown) -> bool:
        """Bolt ``bolt`` is shown, in one of ``states``."""
        b = self.bolts.get(bolt or "")
        return b is not None and b.state in states

    def _open(self, e: VehicleOpened) -> None:
        # the vehicle loaded opened again without leaving (a reload reopens the one on the
        # lift): its last results stay (an operator trial: the panel was empty after a
        # SIGHUP, B11's NOKs gone from it); another vehicle, or a rework, starts afresh
        if not (self.loaded and self.vin == e.vin):
            self.results = []
        self.vin, self.model, self.rework, self.loaded = e.vin, e.model, e.rework, True
        self.closed, self.selected, self.wrench, self.refused = None, None, None, ""
        self.reopened = None
        self.located = None
        self._bolts_are(e.bolts)

    def _bolts_are(self, views: tuple[BoltView, ...]) -> None:
        """The loaded vehicle's bolts drawn afresh as the core holds them (its opening, or
        the core's snapshot where the opening is gone from the history)."""
        self.bolts = {v.bolt: BoltState(v.bolt, v.x_mm, v.y_mm, v.pset, v.order, v.batch)
                      for v in views}
        for v in views:
            self._bolt_is(v)
            self.bolts[v.bolt].reason = _state_words(self.bolts[v.bolt], v)

    def _close(self, e: VehicleClosed) -> None:
        # a bolt skipped by a person is not missing: the headline said "46 missing" beside
        # the counters' "2 skipped" and the report's 44 (a supervisor's trial)
        skipped = {b.bolt for b in self.bolts.values() if b.state == SKIPPED} \
            if e.vin == self.vin else set()
        self.closed = {"vin": e.vin, "missing": [b for b in e.missing if b not in skipped],
                       "skipped": [b for b in e.missing if b in skipped], "nok": list(e.nok),
                       "due": list(e.due)}
        if e.vin == self.vin:
            self.loaded = False
        self.reopened = None
        self.wrench, self.selected = None, None
        if e.vin != self.vin:
            return
        missing, nok, due = set(e.missing), set(e.nok), set(e.due)
        for b in self.bolts.values():
            if b.bolt in due:   # its result still to come: neither missing nor NOK yet
                b.state, b.reason = PENDING, "its result due from the controller"
            elif b.state == Shown.LOCKED:   # the report's word decides (a held bolt done
                # before its hold, by a gap's doubt: OK, as its records say; a reviewer)
                b.state = NOK if b.bolt in nok else MISSING if b.bolt in missing else b.status
                b.reason = f"{'held' if b.held else 'locked'} when the vehicle left"
            elif b.bolt in missing and b.state not in (NOK, SKIPPED):   # skipped: said so
                b.state, b.reason = MISSING, NOT_TIGHTENED
            elif b.state in LIVE_STATES:
                b.state, b.reason = PENDING, ""

    def _settled(self, e: ClosingSettled) -> None:
        """The results due as the shown closed vehicle left are settled: its close line as
        its records say now; a bolt no result came for is missing.  Another vehicle's (the
        screens moved on): nothing shown changes."""
        c = self.closed
        if c is None or c["vin"] != e.vin:
            return
        skipped = set(c["skipped"])
        c["missing"] = [b for b in e.missing if b not in skipped]
        c["nok"], c["due"] = list(e.nok), list(e.due)
        if e.vin != self.vin:
            return
        for name in e.settled:
            b = self.bolts.get(name)
            if b is not None and name in e.missing and b.state == PENDING:
                b.state, b.reason = MISSING, NOT_TIGHTENED

    def _localized(self, e: Localized) -> None:
        if e.point_mm is None:
            # no position: none is drawn (a grey crosshair left where the wrench was last
            # seen, on B47, was read as the wrench on B47 beside "not in view"); the panel
            # says whether it is out of view or seen and refused (tilted: the headline's
            # reason), from the same reason the headline gives
            seen = e.reason is not None and e.reason.kind in WRENCH_SEEN
            self.wrench = {"lost": True, "seen": seen,
                           "reason": reason_words(e.reason, full=True) if e.reason else "",
                           "words": reason_words(e.reason) if e.reason else ""}
        else:
            self.wrench = {"x": e.point_mm[0], "y": e.point_mm[1], "z": e.point_mm[2],
                           "tilt": e.tilt_deg, "candidate": e.candidate,
                           "distance": e.distance_mm, "age_ms": e.age_ms, "lost": False,
                           "reason": reason_words(e.reason) if e.reason else ""}
        self._frames_seen(e)
        self.located = e
        self._point_out_next(e)

    def _point_out_next(self, e: Localized) -> None:
        """One open bolt the rules allow now is "next", the others "to do": without an order
        in the bolt table every open bolt is allowed, and 50 blue "next" bolts point out
        none.  The one pointed out is the nearest to the wrench while it is in view; while
        it is not, the one pointed out last (the wrench leaving the view for a frame does not
        move the pointer), else the table's first.  A bolt blocked by a refusal stays blocked
        until the rules allow it."""
        allowed = set(e.allowed)
        shown = (PENDING, Shown.NEXT, Shown.BLOCKED)
        candidates = [b for b in self.bolts.values() if b.state in shown and b.bolt in allowed]
        pointed: BoltState | None = None
        last = next((b for b in candidates if b.state == Shown.NEXT), None)
        if candidates and e.point_mm is not None:
            x, y = e.point_mm[0], e.point_mm[1]

            def far(b: BoltState) -> float:
                return math.hypot(b.x_mm - x, b.y_mm - y)
            pointed = min(candidates, key=far)
            # a wrench midway between two bolts does not flip the pointer (and redraw the
            # map) at every localization: the last one stays until another is clearly nearer
            if last is not None and far(last) - far(pointed) < NEXT_HYSTERESIS_MM:
                pointed = last
        elif candidates:
            pointed = last or candidates[0]
        for b in self.bolts.values():
            if b.state not in shown or (b.state == Shown.BLOCKED and b.bolt not in allowed):
                continue
            self._set(b.bolt, Shown.NEXT if b is pointed else PENDING)

    def _frames_seen(self, e: Localized) -> None:
        """Whether fresh frames came since the station started: until they do, a stale
        localization is the cameras' first frames on their way (a demo's start: 7.5 s old),
        not the stale-frame alarm, for at most :data:`STARTUP_GRACE_S`."""
        if e.reason is None or e.reason.kind is not Why.STALE:
            self.fresh = True
        elif not self.fresh and self.stale_since is None:
            self.stale_since = e.t
        self.last_t = e.t

    def _result(self, e: ResultRecorded) -> None:
        if e.vin == self.vin and e.bolt in self.bolts:
            b = self.bolts[e.bolt]
            b.torque_nm, b.angle_deg = e.torque_nm, e.angle_deg
            b.failed = None if e.ok else _failed(e)
            if not self.loaded:
                # a late result of the vehicle that left (the core holds its bolts no more):
                # as its records say now (a loosening NOK is the bolt NOK: a reviewer)
                said: BoltStatus = (LOOSENED if e.ok else NOK) if e.kind == LOOSENING \
                    else OK if e.ok else NOK
                b.state, b.status, b.ran, b.ends_nok = said, said, True, not e.ok
            else:   # its state the core's (BoltsChanged, the rundown's end): its words
                said = (LOOSENED if e.ok else TO_LOOSEN) if e.kind == LOOSENING \
                    else OK if e.ok else NOK
            if b.state == said:
                b.reason = "loosening NOK" if said == TO_LOOSEN else RUNDOWN_WORDS.get(said, "")
        c = self.closed
        if c is not None and c["vin"] == e.vin and e.kind != LOOSENING:   # stored late:
            c["missing"] = [b for b in c["missing"] if b != e.bolt]       # its close line
            c["nok"] = [b for b in c["nok"] if b != e.bolt] + ([] if e.ok else [e.bolt])
            c["due"] = [b for b in c["due"] if b != e.bolt]
        self.results.insert(0, {
            "t": e.t, "vin": e.vin, "bolt": e.bolt, "ok": e.ok, "pset": e.pset,
            "torque_nm": e.torque_nm, "torque_min": e.torque_min, "torque_max": e.torque_max,
            "angle_deg": e.angle_deg, "angle_min": e.angle_min, "angle_max": e.angle_max,
            "late": e.late, "kind": e.kind, "operator": e.operator,
            "entered_by": e.entered_by})
        del self.results[LAST_RESULTS:]

    def _refuse(self, words: str, why: Reason | None = None, *, act: bool = False) -> None:
        """Why nothing is sent now, in words, and whether the operator acts on it (its kind,
        or ``act``)."""
        self.refused, self.refused_why = words, why
        self.act = act or (why is not None and why.kind in ACT_ON)

    def _set(self, bolt: str, state: BoltShown, reason: str = "") -> None:
        """Where the operator's attention is on ``bolt``: ``state`` next, selected, the tool
        on, blocked; ``PENDING``: none, the bolt drawn as the core holds it (to do, NOK,
        loosened, to be loosened first: a reviewer found a NOK bolt left without a rundown
        drawn "to do").  A bolt the core holds skipped or locked draws no attention (the
        controller's refusal drew a skipped bolt "blocked" for good: a reviewer)."""
        b = self.bolts.get(bolt)
        if b is None or (state in ATTENTION and (b.locked or b.status == SKIPPED)):
            return
        if state == PENDING and b.status != PENDING:
            state = b.status
            reason = reason or ("loosen first" if state == TO_LOOSEN
                                else RUNDOWN_WORDS.get(state, ""))
        elif b.check_first and state in (PENDING, Shown.NEXT):
            reason = reason or CHECK_FIRST_WORDS
        b.state, b.reason = state, reason

    def _unselect(self) -> None:
        for b in self.bolts.values():
            if b.state in (Shown.SELECTED, Shown.TIGHTENING):
                self._set(b.bolt, PENDING)

    # -- what the screens read ----------------------------------------------------------
    def counters(self) -> dict[str, int]:
        """The header's counts as the vehicle's report counts its bolts: done (OK), ending
        NOK (the last rundown a NOK, whether the bolt is locked, released or skipped since),
        skipped (without a rundown: one with is counted by its last); and held (its result not
        known: a new user's trial, the header never said it where ``stationd status`` did)."""
        bolts = self.bolts.values()
        return {"total": len(bolts), "done": sum(b.status == OK for b in bolts),
                "nok": sum(b.ends_nok for b in bolts),
                "skipped": sum(b.state == SKIPPED and not b.ran for b in bolts),
                "held": sum(b.held for b in bolts)}

    def locks(self) -> list[str]:
        """Each locked bolt in the operator's words (the screen adds who may release)."""
        return [b.reason for b in self.bolts.values() if b.state == Shown.LOCKED]

    def lock_lines(self) -> list[dict[str, str]]:
        """:meth:`locks` as the operator screen's panel lists them: each without what to do
        (the panel says it once, below them: enter the outcome or release, and who may), the
        whole words its hover title (a new user's trial at 1280x800: three locks' full words
        pushed the commands below the screen)."""
        return [{"text": stopped_words(b.bolt, b.lock_count, b.held_note, instruct=False),
                 "title": b.reason} for b in self.bolts.values() if b.state == Shown.LOCKED]

    def holds(self) -> list[str]:
        """Of :meth:`locks`, the bolts held (a result not known: an unreadable one, a link
        cut's, a lost push's), not locked by their NOKs, in the operator's words."""
        return [b.reason for b in self.bolts.values() if b.state == Shown.LOCKED and b.held]

    def device_health(self) -> dict[str, dict[str, Any]]:
        """Every configured device, then any other that reported: reported health wins; an
        unreported configured device is "opening" ("not opened yet", neutral) until the
        station has tried its devices (``opened``), "ok" after (one that failed reported).
        A pair the calibration check measures carries its trust (``check``: ``trusted``,
        ``verdict`` ok / moved / not checked, ``words``): a pair can be up and not trusted."""
        up = self.opened
        # the devices wait for the database (a technician read them as never reported)
        waiting = "not opened yet" + (
            ": the database opens first" if not self.devices.get(DATABASE, {}).get("ok", True)
            else "")
        out: dict[str, dict[str, Any]] = {
            d: {"ok": up, "kind": "" if up else "opening",
                "reason": "" if up else waiting, "reported": False}
            for d in self.configured}
        for d, h in self.devices.items():
            out[d] = {**h, "reported": True}
        for d, who in self.identities.items():
            if d in out:
                out[d]["identity"] = who
        for d, check in self.checks.items():   # a pair's trust: beside its health
            if d in out:
                out[d]["check"] = dict(check)
        return out

    def in_fault(self) -> bool:
        """The station in fault, or a device that reports one (the lift PLC's fault bit
        too): ``/healthz``'s 503, ``stationd status``'s exit 1 and the headline's red."""
        return self.state == State.FAULT or any(not h["ok"] for h in self.devices.values())

    def tone(self) -> str:
        """How the headline reads: ``stop`` (red: a fault or a wrong bolt, the station
        stops), ``act`` (amber: a refusal the operator resolves: stale, ambiguous, tilted,
        order rule, skipped), ``idle`` (neutral: the wrench is not on a bolt), ``go`` (a bolt
        selected), ``nok`` (red: the vehicle closed with a NOK bolt, with or without missing
        ones: a joint out of its limits left the station, the worse of the two for quality),
        ``missing`` (amber: it closed with bolts not tightened, or results due), ``done``,
        else "".  ``nok`` is not ``stop``: the station itself is healthy (/healthz stays ok)."""
        if self.alarm or self.in_fault():
            return "stop"
        if self.refused:
            return "act" if self.act and not self.starting_up() else "idle"
        if self.selected is not None:
            b = self.bolts.get(self.selected)
            return "act" if b is not None and b.check_first else "go"
        if self.closed is not None:
            return ("nok" if self.closed["nok"] else "missing"
                    if self.closed["missing"] or self.closed["skipped"]
                    or self.closed["due"] else "done")
        c = self.counters()
        if c["total"] and c["done"] == c["total"]:
            return "done"
        return ""

    def headline(self, full: bool = False) -> str:
        """The large words: why nothing is sent, else what to do.  A fault's reason is cut
        to :data:`REASON_SHOWN` characters (``full``: not; the hover title and the devices
        panel have it whole): a pair's reason carries both cameras' URLs and errors, 400
        characters, nine lines of large type over the bolt map on a panel PC."""
        cut = (lambda s: s) if full else _for_panel
        faults = [f"{d}: {cut(h['reason'] or h['kind'])}"
                  for d, h in sorted(self.devices.items()) if not h["ok"]]
        if self.alarm:
            return f"WRONG BOLT: {self.alarm}"
        if self.state == State.FAULT and len(faults) > 1:
            # several devices down: the first in large words, the others named (each one's
            # reason is in the devices panel); the whole list would not fit 3 lines
            others = [d for d, h in sorted(self.devices.items()) if not h["ok"]][1:]
            return f"FAULT: {faults[0]} (and {', '.join(others)}: see Devices)"
        if self.state == State.FAULT:
            return "FAULT: " + (cut(self.reason) or "; ".join(faults) or "see the journal")
        if faults:
            return "FAULT: " + cut("; ".join(faults))
        if self.refused:
            if self.starting_up():
                age = self.refused_why.age_ms if self.refused_why is not None else None
                return "Starting: the cameras' first frames are late" + (
                    f" ({age:.0f} ms old)" if age else "")
            if not self.act and self._not_at_a_bolt():
                return SIGN_IN_FIRST if self.operator_required and self.operator is None \
                    else NOT_AT_A_BOLT
            return self.refused
        if self.selected is not None:
            if self.selected_loosen is not None:   # the loosen step: never "tighten"
                return f"{self.selected}: loosen first (loosen pset {self.selected_loosen})"
            b = self.bolts.get(self.selected)
            pset = f" (pset {b.pset})" if b is not None and b.pset is not None else ""
            if b is not None and b.check_first:   # its tool goes on: the operator is told
                return f"{self.selected}{pset}: {CHECK_FIRST_WORDS}"
            return f"{self.selected}{pset}: tighten"
        if self.closed is not None:
            return self._closed_line(NAMES_SHOWN)
        # a vehicle reopened: said unless another one is open on the lift (that one, its
        # locked bolts, come first: another's rework notice hid them from the operator)
        if self.reopened is not None and (not self.loaded or self.vin == self.reopened[0]):
            vin, user = self.reopened
            return f"{vin} reopened for rework by {user}: it opens when raised at the station"
        if self.state in TRACKING_STATES and not self.fresh and self.stale_since is None:
            return STARTING_UP    # tracking, and no frame localized since the start yet
        return self.reason or self.state

    def _closed_line(self, shown: int | None) -> str:
        """``VIN closed: 38 missing (B01, B02, B03, ...); NOK B04``: the count and the first
        ``shown`` names (a panel PC fits no 38 names in large type), every name with None."""
        c = self.closed
        assert c is not None  # noqa: S101 - called when closed
        parts = [_named(c["missing"], "missing", shown), _named(c["skipped"], "skipped", shown),
                 _named(c["nok"], "NOK", shown),
                 _named(c["due"], "result due", shown)]
        return f"{c['vin']} closed: " + ("; ".join(x for x in parts if x) or "all bolts OK")

    def headline_title(self) -> str:
        """The headline in full (its hover title): a closed vehicle's every name, a fault's
        whole reason."""
        if self.closed is not None and self.headline() == self._closed_line(NAMES_SHOWN):
            return self._closed_line(None)
        return self.headline(full=True)

    def starting_up(self) -> bool:
        """The refusal is stale frames and no fresh frame came since the station started,
        for at most :data:`STARTUP_GRACE_S`: the station is starting, not alarming."""
        why = self.refused_why
        return (why is not None and why.kind is Why.STALE and not self.fresh
                and self.stale_since is not None
                and self.last_t - self.stale_since <= STARTUP_GRACE_S)

    def wrench_line(self) -> str:
        """The wrench panel's line, from the same localization as the map's crosshair and the
        headline's reason: out of view (no crosshair), seen and refused (why), or where."""
        w = self.wrench
        if w is None:
            return "not localized"
        if w.get("lost"):
            return f"seen, not used: {w['words']}" if w.get("seen") else \
                "not in view (details: Cameras)"
        near = f", near {w['candidate']} ({w['distance']:.1f} mm)" \
            if w.get("candidate") and w.get("distance") is not None else ""
        tilt = f", tilt {w['tilt']:.1f}\u00b0" if w.get("tilt") is not None else ""
        return f"X {w['x']:.0f}  Y {w['y']:.0f}  Z {w['z']:.0f} mm{tilt}{near}"

    def _not_at_a_bolt(self) -> bool:
        """The wrench is out of view, or seen but near no bolt."""
        w = self.wrench
        near_none = self.refused_why is not None and self.refused_why.kind is Why.NO_BOLT_NEAR
        return w is None or bool(w.get("lost")) or near_none

    def to_json(self) -> dict[str, Any]:
        return {
            "state": self.state, "reason": self.reason,
            "reason_kind": None if self.reason_kind is None else self.reason_kind.value,
            "headline": self.headline(),
            "headline_title": self.headline_title(),
            "tone": self.tone(),
            "refused": self.refused, "alarm": self.alarm,
            # at_station: opened and not closed since (a closed one's bolts stay shown)
            "vehicle": None if self.vin is None else {
                "vin": self.vin, "model": self.model, "rework": self.rework,
                "at_station": self.loaded,
                # reopened for rework by this person, not raised at the station yet
                "reopened_by": self.reopened[1] if self.reopened is not None
                and self.reopened[0] == self.vin else None},
            "bolts": [b.to_json() for b in self.bolts.values()],
            "selected": self.selected, "wrench": self.wrench, "counters": self.counters(),
            "wrench_line": self.wrench_line(),
            "devices": self.device_health(), "results": self.results, "closed": self.closed,
            "locks": self.locks(), "lock_lines": self.lock_lines(),
            "operator": {"user": self.operator, "required": self.operator_required},
        }


def _state_words(b: BoltState, v: BoltView) -> str:
    """The words of bolt ``b`` drawn anew as the core holds it (``v``): its lock or hold,
    the loosening it waits for, a check first, or its last rundown's."""
    if b.state == Shown.LOCKED:
        # a lock of NOKs on a held bolt keeps the hold (its result is still not known), said
        # with it: the hold's outcome entered, or a release, ends both
        return stopped_words(v.bolt, v.locked, v.held)
    if b.state == TO_LOOSEN:
        return reason_words(Reason(Why.LOOSEN_FIRST, bolt=v.bolt, pset=v.loosen_pset))
    if b.check_first and b.state in (PENDING, Shown.NEXT):
        return CHECK_FIRST_WORDS
    return RUNDOWN_WORDS.get(b.state, "")


def _failed(e: ResultRecorded) -> str | None:
    """Which of a NOK's values lies out of its window: ``torque``, ``angle``, ``torque and
    angle``, or None (both within, or not known: the controller's verdict alone)."""
    def out(v: float | None, lo: float | None, hi: float | None) -> bool:
        return v is not None and ((lo is not None and v < lo) or (hi is not None and v > hi))
    which = [name for name, v, lo, hi in (("torque", e.torque_nm, e.torque_min, e.torque_max),
                                          ("angle", e.angle_deg, e.angle_min, e.angle_max))
             if out(v, lo, hi)]
    return " and ".join(which) or None


def _health(ok: bool, kind: str = "", reason: str = "") -> dict[str, Any]:
    """A device's health as the view keeps it (a DeviceHealth folded, or the core's snapshot
    seeded)."""
    return {"ok": ok, "kind": kind, "reason": reason}


def _named(names: list[str], what: str, shown: int | None) -> str:
    """``missing B01, B02`` for a few, ``38 missing (B01, B02, B03, ...)`` for more."""
    if not names:
        return ""
    if shown is None or len(names) <= shown:
        return f"{what} {', '.join(names)}"
    return f"{len(names)} {what} ({', '.join(names[:shown])}, ...)"


def fold(events: list[StationEvent] | tuple[StationEvent, ...],
         configured: tuple[str, ...] = ()) -> View:
    """A view built from ``events`` in order (a fresh screen starts from the bus history)."""
    v = View(configured=tuple(configured))
    for e in events:
        v.apply(e)
    return v


#: a device's URL where its reason begins ("wrench: openprotocol://10.0.0.5:4545: ..."):
#: the devices panel shows it; in the headline's large type it took the room of the words
#: an operator acts on ("connection refused ... (controller off, or ...")
_URL_LEAD = re.compile(r"^((?:[\w.-]+: )?)[a-z][a-z0-9+.-]*://[^\s]*?: ")


def _for_panel(text: str) -> str:
    """A fault's reason as the headline's large type shows it: without the device's URL
    where it begins, then cut (:func:`_shortened`)."""
    return _shortened(_URL_LEAD.sub(r"\1", text, count=1))


def _shortened(text: str, limit: int = REASON_SHOWN) -> str:
    """``text`` cut at the last word boundary before ``limit`` characters, with an ellipsis
    (unchanged when it fits)."""
    if len(text) <= limit:
        return text
    head = text[:limit - 1]
    space = head.rfind(" ")
    return (head[:space] if space > limit // 2 else head).rstrip(" ,;:(") + "\u2026"
