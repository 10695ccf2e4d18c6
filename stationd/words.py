"""Typed reasons and answers in words, for the edges only (the journal, the screens, the
command line).  One place, so a screen in another language replaces this module's tables, not
the station's rules."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

from db.kinds import (
    CHECK_NOTE_HEAD,
    GAP_NOTE_MARK,
    NOK,
    NOT_TAKEN_NOTE,
    held_result_id,
    id_span,
    is_not_taken_note,
    is_unknown_note,
)
from drivers.counting import counted
from drivers.wrench.base import ResultType
from stationd.reasons import (
    CoreFault,
    CoreFaultKind,
    FaultWhy,
    Reason,
    Skip,
    SkipKind,
    Unattributed,
    UnattributedKind,
    Unchecked,
    UncheckedKind,
    Unproved,
    UnprovedKind,
    Wait,
    WaitKind,
    Why,
)
from stationd.station.actions import StoreControllerEvent
from stationd.station.commands import (
    KIND,
    Answer,
    Command,
    EnterOutcome,
    LoosenBolt,
    ReleaseBolt,
    ReopenVehicle,
    SignOut,
    SkipBolt,
    TeachPoint,
    TeachStart,
)
from stationd.station.events import (
    Because,
    BoltSkipped,
    ControllerResultEvent,
    DeviceHealth,
    Notice,
    OperatorChange,
    OperatorChanged,
    PairChecked,
    Said,
    State,
    StateReason,
    StationEvent,
)
from stationd.station.gaps import GapPlan, NoFetch
from stationd.station.results import type_code
from stationd.station.trust import Asked, CheckAsked

#: what a held bolt asks of a person, in that order: its outcome entered when the controller
#: shows it; a release tightens the bolt again (a new user's trial read "release or enter"
#: as two equal choices, released, and the bolt, good already, was tightened twice)
CHECK_ON_CONTROLLER = ("check it on the controller, then enter its outcome, or release it to "
                       "tighten it again")


def _mm(v: float | None) -> str:
    return "?" if v is None else f"{v:.1f}"


#: who ends a lock of NOKs, said after it
LOCK_RELEASE = "a supervisor releases it"


def _locked(bolt: str | None, count: int | None, instruct: bool = True) -> str:
    """A bolt locked by its NOKs: the refusal and the notice say it alike; ``instruct``
    False leaves out who ends it (:func:`stopped_words`)."""
    said = f"{bolt} locked after {count} NOK in a row"
    return f"{said}: {LOCK_RELEASE}" if instruct else said


def stopped_words(bolt: str, count: int | None, note: str | None, *,
                  instruct: bool = True) -> str:
    """A bolt stopped for a person: locked by ``count`` NOKs in a row, held for a result not
    known (``note``), or both, said together (a release or an entered outcome ends both).
    ``instruct`` False: without what to do after each, for the screens' panel of locks that
    says it once below them (a new user's trial at 1280x800: three locks' whole words pushed
    the commands below the screen)."""
    locked = "" if count is None else _locked(bolt, count, instruct)
    held = "" if note is None else _unread(bolt, note, instruct)
    return "; ".join(w for w in (locked, held) if w)


def _unread(bolt: str | None, note: str | None, instruct: bool = True) -> str:
    """A bolt held for a result that could not be read, or for one never in hand (a link
    cut's, a lost push's: "could not be read" was wrong there, a supervisor's trial), or for
    one read and not taken (a type the station does not know, another pset's: an
    integrator's trial read "could not be read" there too): the refusal and the notice
    alike."""
    if is_not_taken_note(note):
        said, sep = f"{bolt}: {note}: not taken as a tightening", ";"
    elif is_unknown_note(note):
        said, sep = f"{bolt}: {note}", ":"
    else:
        said, sep = f"{bolt}: the controller's result could not be read ({note})", ":"
    return f"{said}{sep} {CHECK_ON_CONTROLLER}" if instruct else said


def _command(user: str | None, comment: str | None) -> str:
    """A person's command, as a skip and a loosen say who ordered it: ``olga's command (no
    access)``."""
    return f"{user}'s command" + (f" ({comment})" if comment else "")


_SKIP: dict[SkipKind, Callable[[Skip], str]] = {
    SkipKind.NOK_POLICY: lambda s: "NOK, skipped by the NOK policy",
    SkipKind.NO_LOOSEN_PSET: lambda s: "to be loosened, and the NOK policy gives it no "
                                       "loosen_pset",
    SkipKind.REFUSED: lambda s: f"controller refused its parameters ({s.reason})",
    SkipKind.COMMAND: lambda s: _command(s.user, s.comment),
}


def skip_words(skip: Skip) -> str:
    """Why a bolt is skipped, as the screens, the refusals and the state's reason say it:
    ``olga's command (no access)``, ``NOK, skipped by the NOK policy``."""
    return _SKIP[skip.kind](skip)


_FAULT: dict[CoreFaultKind, Callable[[CoreFault], str]] = {
    CoreFaultKind.VIN_CHANGED: lambda f: (f"the PLC reports VIN {f.plc_vin} at height, the "
                                          f"station has {f.vin} loaded: lower the lift"),
    CoreFaultKind.MODEL_CHANGED: lambda f: (f"the PLC reports model code {f.plc_code} at "
                                            f"height, {f.vin} was loaded as {f.code}: lower "
                                            "the lift"),
    CoreFaultKind.CLOSED: lambda f: (f"VIN {f.vin} already closed: rework needs the vehicle "
                                     f"reopened ({f.note}); lower the lift to clear"),
    CoreFaultKind.PARAMS_REFUSED: lambda f: (f"controller refused the parameters for "
                                             f"{f.bolt}: {f.note}"),
    CoreFaultKind.LIFT_REPORTS_FAULT: lambda f: ("the lift PLC reports a fault of the lift "
                                                 "(its fault bit): nothing is tightened until "
                                                 "it is cleared at the lift"),
}


def fault_words(why: FaultWhy) -> str:
    """Why a device is in fault: its own words as they came, or the station's own fault in
    words (``the PLC reports VIN V2 at height, the station has V1 loaded: lower the lift``)."""
    return why if isinstance(why, str) else _FAULT[why.kind](why)


_WAIT: dict[WaitKind, Callable[[Wait], str]] = {
    WaitKind.BATCH: lambda w: "; ".join(f"finish batch {name} first: {', '.join(rest)} "
                                        "remaining" for name, rest in w.batches),
    WaitKind.ORDER: lambda w: (f"order {w.order}"
                               + (f" in batch {w.batch}" if w.batch is not None else "")
                               + f" needs {', '.join(w.bolts)} done first"),
}


def wait_words(wait: Wait) -> str:
    """Which rule of the sequence a bolt waits for: ``order 2 in batch subframe needs A1, A2
    done first``, ``finish batch subframe first: A2, A3 remaining``."""
    return _WAIT[wait.kind](wait)


def _waited(wait: Wait | None) -> str:
    """A wait's words, where a refusal may lack it (``None``: never from the matcher)."""
    return "None" if wait is None else wait_words(wait)


def _not_measured(u: Unchecked) -> str:
    """A check that measured no reference: the worst one and why, and the check's own
    words (``reference R1 not found (no frame)``)."""
    why = u.measure or "nothing measured"
    return (f"reference {u.reference} {why}" if u.reference else why) + (
        f" ({u.note})" if u.note else "")


_UNCHECKED: dict[UncheckedKind, Callable[[Unchecked], str]] = {
    UncheckedKind.SINCE_START: lambda u: "not checked since the start",
    UncheckedKind.ARRIVAL: lambda u: f"checking for vehicle {u.vin}",
    UncheckedKind.PAIRS_UNKNOWN: lambda u: "which pairs saw the wrench is not known",
    UncheckedKind.NO_MARKER: lambda u: "it sees no reference marker",
    UncheckedKind.NOT_MEASURED: _not_measured,
}


def unchecked_words(unchecked: Unchecked) -> str:
    """Why a pair is not checked against the references: ``checking for vehicle VIN1``,
    ``reference R1 not found``."""
    return _UNCHECKED[unchecked.kind](unchecked)


def _unchecked(unchecked: Unchecked | None) -> str:
    """An unchecked pair's why, where a refusal may lack it (``None``: never from the
    core)."""
    return "None" if unchecked is None else unchecked_words(unchecked)


_ASKED: dict[Asked, Callable[[CheckAsked], str]] = {
    Asked.STARTED: lambda a: "station started",
    Asked.ARRIVED: lambda a: f"vehicle {a.vin} arrived",
    Asked.PERIODIC: lambda a: "periodic check",
    Asked.COMMAND: lambda a: f"asked by {a.user}",
}


def check_asked_words(asked: CheckAsked) -> str:
    """Why a calibration check is measured: ``vehicle VIN1 arrived``, ``asked by eve``."""
    return _ASKED[asked.kind](asked)


_UNPROVED: dict[UnprovedKind, Callable[[Unproved], str]] = {
    UnprovedKind.PSET: lambda u: f"pset {u.pset}, not {u.sent_pset} sent for {u.bolt}",
    UnprovedKind.VIN: lambda u: f"VIN {u.vin}, not {u.sent_vin}",
    UnprovedKind.NOT_FIRST: lambda u: f"not the first tightening after {u.follows}",
    UnprovedKind.FOLLOWS_UNKNOWN: lambda u: "the last tightening id accounted for unknown",
    UnprovedKind.CLOCK_UNKNOWN: lambda u: "the controller's clock is not known",
    UnprovedKind.OUTSIDE_CUT: lambda u: f"made outside the enable of {u.bolt} and the link cut",
    UnprovedKind.NO_CUT: lambda u: ("no tool enable left without its result by the link "
                                    "cut"),
    UnprovedKind.RAN_AGAIN: lambda u: (f"made during the link cut after {u.bolt}'s rundown "
                                       f"{u.follows}: the tool ran again, on {u.bolt} or "
                                       f"another bolt; {u.bolt} held"),
}


def unproved_words(unproved: Unproved) -> str:
    """What did not prove a fetched result the cut enable's: ``VIN V9, not V1``."""
    return _UNPROVED[unproved.kind](unproved)


_CAME: dict[UnattributedKind, str] = {
    UnattributedKind.OUTSIDE: "outside any tightening",
    UnattributedKind.FETCHED_LIVE: "fetched after a later one came, the link up",
    # (a trial: "after a later one came" of one fetched by the check, and none came)
    UnattributedKind.FETCHED_CHECKED: "fetched as an enable's late-result window ended, the "
                                      "link up",
    UnattributedKind.FETCHED: "fetched after a reconnect",
    UnattributedKind.UNREAD_READ: "fetched after a later one came, the link up",
    UnattributedKind.OTHER_PSET: "pushed while the tool was on",
}


def unattributed_words(why: Unattributed) -> str:
    """Why a result is stored unattributed, as its record's reason keeps it and the journal
    says it: ``result 12 (pset 3) fetched after a reconnect (VIN V9, not V1)``."""
    said = f"result {why.tightening_id} (pset {why.pset}) {_CAME[why.kind]}" + (
        f" ({unproved_words(why.unproved)})" if why.unproved is not None else "")
    if why.kind is UnattributedKind.OTHER_PSET:
        said = (f"result {why.tightening_id} (pset {why.pset}) pushed while the tool was on "
                f"for {why.bolt} with another pset: run with another program (one selected on "
                f"the controller?), or none of {why.bolt}'s: {why.bolt} held")
    if why.kind is UnattributedKind.UNREAD_READ and why.between is not None:
        before, after = why.between
        said += (f": the result of {why.bolt} that could not be read (the one id between "
                 f"tightenings {before} and {after}), now read; {why.bolt} stays held until "
                 "its outcome is entered")
    return said


_TYPE_WORDS = {ResultType.BATCH_INCREMENT: "batch increment",
               ResultType.BATCH_DECREMENT: "batch decrement",
               ResultType.BYPASS_PSET: "bypass parameter set", ResultType.ABORT_JOB: "abort job",
               ResultType.REFERENCE_SETUP: "reference setup",
               ResultType.TIGHTENING: "tightening", ResultType.LOOSENING: "loosening",
               ResultType.SYNC_TIGHTENING: "synchronized tightening"}


def nok_why(run: Mapping[str, Any]) -> str:
    """Why a NOK rundown (a row of the records: its values and the limits of its parameter
    version) is NOK, as the demo says it: "torque 56.1 Nm > 55.0 max", each value out of its
    window; "both within limits: the controller's verdict"; "" for an OK, a loosening (no
    window) or a rundown without values.  Why: ``db report`` printed "NOK 48.1 Nm, 97.0 deg"
    and a quality engineer compared each value with the limits by hand (a newcomer's
    trial), where the vehicle's page said which was out."""
    if run.get("status") != NOK or run.get("torque_nm") is None:
        return ""
    out = []
    for name, unit, fmt, value, lo, hi in (
            ("torque", "Nm", ".1f", run.get("torque_nm"), run.get("torque_min_nm"),
             run.get("torque_max_nm")),
            ("angle", "deg", ".0f", run.get("angle_deg"), run.get("angle_min_deg"),
             run.get("angle_max_deg"))):
        if value is None:
            continue
        if lo is not None and value < lo:
            out.append(f"{name} {value:{fmt}} {unit} < {lo:{fmt}} min")
        elif hi is not None and value > hi:
            out.append(f"{name} {value:{fmt}} {unit} > {hi:{fmt}} max")
    if out:
        return "; ".join(out)
    limits = ("torque_min_nm", "torque_max_nm", "angle_min_deg", "angle_max_deg")
    return "both within limits: the controller's verdict" \
        if any(run.get(k) is not None for k in limits) else ""


def result_type_words(code: int | None) -> str:
    """A result type as the controller's screen would name it; an unknown code by number.
    The name a controller event is stored, published and said with."""
    try:
        return _TYPE_WORDS[ResultType(code)] if code is not None else "result"
    except ValueError:
        return f"result type {code} (unknown)"


def stored_what(action: StoreControllerEvent) -> str:
    """What a controller event is stored as: the station's own kind where the core gave one
    (``not taken``), else its type's name (``batch increment``)."""
    return action.what if action.what is not None else result_type_words(
        type_code(action.result))


_NO_FETCH: dict[NoFetch, Callable[[GapPlan], str]] = {
    NoFetch.NOTHING_RECORDED: lambda p: ("no tightening recorded yet: counting from the "
                                         f"controller's newest, {p.newest}"),
    NoFetch.IDS_RESTARTED: lambda p: (f"the controller's newest tightening ({p.newest}) is "
                                      f"older than the last recorded ({p.last_recorded}): "
                                      "its ids restarted"),
}


def gap_plan_words(plan: GapPlan) -> str:
    """Why nothing is fetched after a reconnect, for the journal (empty: something is, or
    nothing is missing)."""
    return "" if plan.why is None else _NO_FETCH[plan.why](plan)


def comment_words(cmd: Command) -> str:
    """A command's comment as it is recorded and said: its person's, or for the station's
    own sign-out of an idle operator, how long they were idle (``idle for 600 s``)."""
    if isinstance(cmd, SignOut) and cmd.idle_s is not None and not cmd.comment:
        return f"idle for {cmd.idle_s:g} s"
    return cmd.comment


def worded(event: StationEvent) -> StationEvent:
    """The event with its words written from the typed value the core decided (a skip's
    ``reason`` from its ``skip``, a device's health's ``reason`` from its ``fault``, a
    controller event's ``what`` from its type code): what the shell publishes, so that every
    reader of the bus (the screens, OPC UA, the journal) reads the same text as before; any
    other event as it is."""
    if isinstance(event, BoltSkipped) and event.skip is not None and not event.reason:
        return replace(event, reason=skip_words(event.skip))
    if isinstance(event, DeviceHealth) and event.fault is not None and not event.reason:
        return replace(event, reason=fault_words(event.fault))
    if isinstance(event, ControllerResultEvent) and not event.what:
        return replace(event, what=result_type_words(event.result_type))
    return event


def _faults(faults: tuple[tuple[str, FaultWhy], ...]) -> str:
    """The devices in fault, each with its own words: the state's reason and a refusal
    alike (``lift: no answer; pair1: no frame``)."""
    return "; ".join(f"{device}: {fault_words(why)}" for device, why in faults)


def _teaching(model: str | None, user: str | None, bolt: str | None) -> str:
    """Teach mode, as the state's reason and a refusal say it alike."""
    doing = f"measuring {bolt}" if bolt is not None else "hold the tool on a bolt"
    return f"teaching {model} ({user}): {doing}"


def _meant(r: Reason) -> str:
    """What a name typed in another case meant (`` (did you mean B04?)``), else nothing."""
    return f" (did you mean {r.other}?)" if r.other else ""


def _loosen_first(r: StateReason) -> str:
    """A bolt selected for its loosen pset: said after the bolt, by the reason and the line."""
    return f": loosen first (pset {r.pset})" if r.loosen else ""


def _late_ack(bolt: str | None) -> str:
    """An acknowledgement after its selection: the tool-off reason and the notice alike."""
    return f"late acknowledgement for {bolt} ignored"


#: a bolt whose result is not known, after why: the selection was dropped for a person
_HELD_FOR = "; held for a supervisor"


def _skipped(skip: Skip | None) -> str:
    """A skip's words, where a reason may lack it (``None``: never from the core)."""
    return "None" if skip is None else skip_words(skip)


def _per_pair(r: Reason, full: bool = False) -> str:
    """Each pair's reason; said once with how many pairs say it when they all say the same
    (the operator's large words; ``full``: every pair's, as the journal keeps it)."""
    if not r.per_pair:
        return r.note or "no localization"
    said = {why for _, _, why in r.per_pair}
    if len(said) == 1 and len(r.per_pair) > 1 and not full:
        return f"{said.pop()} (all {len(r.per_pair)} pairs)"
    return "; ".join(f"{pair}: {side}: {why}" if side else f"{pair}: {why}"
                     for pair, side, why in r.per_pair)


_WORDS: dict[Why, Callable[[Reason], str]] = {
    Why.STALE: lambda r: (f"camera frames too old ({r.age_ms or 0:.0f} ms): the cameras or "
                           "the station's computer fall behind"),
    Why.NO_BOLTS: lambda r: "this vehicle has no bolts",
    Why.NO_BOLT_NEAR: lambda r: (f"no bolt within {r.limit or 0:g} mm (nearest {r.bolt} at "
                                 f"{_mm(r.distance_mm)} mm)"),
    Why.AMBIGUOUS: lambda r: (f"ambiguous: {r.bolt} at {_mm(r.distance_mm)} mm, {r.other} at "
                              f"{_mm(r.other_mm)} mm"),
    Why.SKIPPED: lambda r: f"{r.bolt} skipped: {_skipped(r.skip)}",
    Why.DONE: lambda r: f"{r.bolt} is already done",
    Why.MUST_WAIT: lambda r: f"{r.bolt} must wait: " + "; ".join(
        [_waited(r.wait), *(f"{b} was skipped: {skip_words(s)}" for b, s in r.skips)]),
    Why.NOT_STABLE: lambda r: (f"{r.bolt}: hold the wrench still on it ({r.count} of "
                                f"{r.needed} frames)"),
    Why.ELSEWHERE: lambda r: f"nearest {r.bolt}",
    Why.LOCKED: lambda r: _locked(r.bolt, r.count),
    # (a trial: "B01 is not locked" of a bolt neither locked nor held, where holds are
    # released too)
    Why.NOT_LOCKED: lambda r: f"{r.bolt} is neither locked nor held: nothing to release",
    Why.LOOSEN_ORDERED: lambda r: (f"{r.bolt} is to be loosened first already: its loosen "
                                   f"pset {r.pset} goes next"),
    Why.NOT_HELD: lambda r: (
        f"{r.bolt} is not held but locked after {r.count} NOK in a row: its results were "
        "read; it is released (the screen's Release form, or stationd release), not entered"
        if r.count else
        f"{r.bolt} is not held: an outcome is entered only for a held bolt (its result could "
        "not be read, or is not known)"),
    Why.ENTERED_OUTSIDE: lambda r: (f"{r.bolt}: an OK with {r.note}: not this bolt's "
                                    "tightening OK as entered; check the value on the "
                                    "controller's screen (a NOK is entered as a NOK: NOK in "
                                    "the screen's form, or --nok)"),
    Why.HELD: lambda r: _unread(r.bolt, r.note),
    Why.LOOSEN_FIRST: lambda r: (f"{r.bolt}: loosen first (loosen pset {r.pset}), then "
                                 "tighten" + (f": {_command(r.user, r.note)}"
                                              if r.user is not None else "")),
    Why.NOTHING_TO_LOOSEN: lambda r: f"{r.bolt} is not tightened: nothing to loosen",
    Why.NO_LOOSEN_PSET: lambda r: (f"no loosen pset for {r.bolt}: the station's nok section "
                                   "gives it no loosen_pset"),
    Why.UNKNOWN_MODEL: lambda r: f"model {r.note} is not in the station's bolt tables",
    Why.PAIR_UNCHECKED: lambda r: (f"{r.pair} not checked against the references: "
                                   f"{_unchecked(r.unchecked)}" if r.pair else
                                   f"not checked against the references: "
                                   f"{_unchecked(r.unchecked)}"),
    Why.PAIR_MOVED: lambda r: (f"{r.pair} moved: reference {r.reference} off by "
                               f"{_mm(r.distance_mm)} mm (> {r.limit or 0:g} mm)"),
    Why.REFERENCE_SEEN: lambda r: (f"reference marker {r.reference} seen, not the wrench "
                                   f"({_mm(r.distance_mm)} mm from its place)"),
    Why.NO_REFERENCES: lambda r: ("no calibration check configured: the station file has no "
                                  "references"),
    Why.TEACHING: lambda r: f"teach mode is on ({_teaching(r.note, r.user, r.bolt)})",
    Why.NOT_TEACHING: lambda r: "teach mode is off: start it first",
    Why.NOT_STEADY: lambda r: (
        f"the wrench moved while measured ({r.distance_mm:.1f} mm > {r.limit:g} mm): hold it "
        "still on the bolt" if r.distance_mm is not None else
        _unseen(r) if r.cause is not None and not r.count else
        f"the wrench was not seen steadily ({r.count} of {r.needed} localizations): hold it "
        "on the bolt" + _missed(r)),
    Why.NO_FRAMES: lambda r: (f"no localization from the cameras in {r.limit or 0:g} s: are "
                              "the pairs grabbing? (the cameras screen, stationd status)"),
    Why.NOT_LOCALIZED: lambda r: _per_pair(r),
    Why.TILTED: lambda r: f"wrench tilted {r.angle_deg or 0:.1f} deg (> {r.limit or 0:g} deg)",
    Why.PAIRS_DISAGREE: lambda r: (f"pairs disagree by {r.distance_mm or 0:.2f} mm "
                                   f"(> {r.limit or 0:g} mm)"),
    Why.NO_RIGHT: lambda r: f"your role does not have the right to {r.right}" + (
        f" ({r.asked} needs it)" if r.asked else ""),
    Why.NO_VEHICLE: lambda r: "no vehicle at the station",
    # (a supervisor's trial: a car that left with a bolt held, its release refused, nothing
    # said of reopen)
    # (a VIN mistyped: "worked again after stationd reopen" led to a second refusal, "not in
    # the database"; the VIN at the station beside it shows the slip: a newcomer's trial)
    Why.OTHER_VEHICLE: lambda r: f"vehicle {r.vin} is not the one at the station" + (
        _meant(r) or (": reopened for rework, it is worked when it is back at the station at "
                      "height" if r.reopened else
                      f" ({r.here + ' is' if r.here else 'another is'}; if {r.vin} has left "
                      f"the station, stationd reopen {r.vin} opens it for rework)")),
    Why.UNKNOWN_BOLT: lambda r: f"{r.bolt} is not a bolt of vehicle {r.vin}{_meant(r)}",
    Why.TOOL_ON_BOLT: lambda r: f"{r.bolt} is being tightened now",
    Why.ALREADY_OPEN: lambda r: f"vehicle {r.vin} is open at the station",
    Why.NOT_CLOSED: lambda r: f"vehicle {r.vin} is not closed",
    Why.UNKNOWN_VEHICLE: lambda r: f"vehicle {r.vin} is not in the database{_meant(r)}",
    Why.DEVICE_FAULT: lambda r: f"a device is in fault: {_faults(r.faults)}",
    Why.NOT_RECORDED: lambda r: f"the database did not record it: {r.note}",
    Why.SIGN_IN: lambda r: "sign in to tighten: nobody is signed in at the station",
    Why.NOT_SIGNED_IN: lambda r: "nobody is signed in at the station",
    Why.SIGNED_IN: lambda r: f"{r.user} is signed in already",
}


def _ids(n: Notice) -> str:
    """A gap's tightening ids (:func:`id_span`)."""
    return id_span(n.tightening_id, n.last_id)


def _entered(n: Notice) -> str:
    """An outcome entered for a held bolt, and the hold it ends (which result it replaces);
    a loosening's says so first (its OK is the bolt loosened, not tightened)."""
    held = ("" if not n.note else f" (the result not taken: {n.note})"
            if is_not_taken_note(n.note) else f" (the hold: {n.note})"
            if is_unknown_note(n.note) else f" (the result that could not be read: {n.note})")
    ok = n.said in (Said.ENTERED_OK, Said.ENTERED_LOOSENING_OK)
    outcome = outcome_words(ok, n.torque_nm or 0.0, n.angle_deg or 0.0)
    if n.said in (Said.ENTERED_LOOSENING_OK, Said.ENTERED_LOOSENING_NOK):
        outcome = "loosening " + outcome
    return f"{n.bolt}: {outcome} entered by {n.user} from the controller's screen{held}"


def _unattributed(why: Unattributed | None) -> str:
    """An unattributed result's why, where a notice may lack it (``None``: never from the
    core)."""
    return "None" if why is None else unattributed_words(why)


def _controller_event(n: Notice) -> str:
    """A result that is not a rundown, the bolt still open, what to check for an unknown."""
    return (f"{result_type_words(n.result_type)} on the controller: not a tightening"
            + (f", {n.bolt} still open" if n.bolt is not None else "")
            + ("; check the controller's result there" if n.said is Said.UNKNOWN_TYPE else ""))


def _result_id(tightening_id: int | None) -> str:
    """``result 12`` (a tightening or a loosening), or "the result" where its id is not
    told."""
    return "the result" if tightening_id is None else f"result {tightening_id}"


_SAID: dict[Said, Callable[[Notice], str]] = {
    Said.NO_REFERENCES: lambda n: ("no calibration check configured (no references in the "
                                   "station file): every pair is trusted"),
    Said.PAIR_DISTRUSTED: lambda n: f"{n.pair} no longer trusted while bolt {n.bolt} is selected",
    Said.IDS_AGAIN: lambda n: (f"tightening id {n.tightening_id} again with other values: the "
                               "controller's ids started again (a new or reset controller?); "
                               "taken as a new result"),
    Said.SENT_AGAIN: lambda n: sent_again_words(n.tightening_id, n.bolt, n.vin),
    Said.UNATTRIBUTED: lambda n: _unattributed(n.unattributed) + (
        ": stored apart with its values" if n.unattributed is not None
        and n.unattributed.kind in (UnattributedKind.UNREAD_READ, UnattributedKind.OTHER_PSET)
        else ": not attributable to a bolt, stored unattributed"),
    Said.CONTROLLER_EVENT: _controller_event,
    Said.UNKNOWN_TYPE: _controller_event,
    Said.GAP: lambda n: (f"tightening {_ids(n)} missed "
                         f"{'with the link up' if n.link_up else 'while the link was down'}: "
                         f"a gap ({n.note})"),
    Said.NOT_STORED: lambda n: f"tightening {n.tightening_id} of {n.bolt} not stored: {n.note}",
    Said.UNREADABLE: lambda n: (f"a result from the controller could not be read ({n.note}): "
                                "stored whole; no bolt it could belong to"),
    Said.HELD: lambda n: _unread(n.bolt, n.note),
    Said.NOT_TAKEN: lambda n: (f"{n.bolt}: {NOT_TAKEN_NOTE}, {_mm(n.torque_nm)} Nm outside "
                               f"{_mm(n.torque_min)}-{_mm(n.torque_max)} Nm (tightening "
                               f"{n.tightening_id}): not taken as a tightening; "
                               f"{CHECK_ON_CONTROLLER}"),
    Said.UNKNOWN_TYPE_HELD: lambda n: (f"{n.bolt}: result {n.tightening_id} of type "
                                  f"{n.result_type}, a type the station does not know: not "
                                  f"taken as a tightening; {CHECK_ON_CONTROLLER}"),
    Said.CUT_RECORDED: lambda n: (f"tightening {n.tightening_id} made during the link cut, "
                                  f"fetched after it: recorded to {n.bolt} (its pset, VIN, "
                                  "tightening id and time agree)"),
    Said.LOST_RECORDED: lambda n: (
        f"tightening {n.tightening_id}, its push lost, fetched when a later one came: made "
        f"while the tool was on for {n.bolt} alone, recorded to {n.bolt}"),
    Said.LOST_CHECKED: lambda n: (
        f"tightening {n.tightening_id}, its push lost, fetched as {n.bolt}'s late-result "
        f"window ended: made while the tool was on for {n.bolt} alone, recorded to {n.bolt}"
        + (f" of {n.vin} (gone from the station since)" if n.vin else "")),
    Said.LOST_FOUND_ON: lambda n: (
        f"tightening {n.tightening_id}, its push not come (lost, or late), fetched by a check "
        f"of the controller's newest with the tool on for {n.bolt}: made while the tool was "
        f"on for {n.bolt} alone, recorded to {n.bolt}, the tool off"),
    # (a link cut, or a restart that took the enable it left as one: a technician read
    # "during the link cut" after a kill and a restart)
    Said.CUT_NOTHING: lambda n: (f"no tightening made while the link was down (cut, or the "
                                 f"station stopped; every result since fetched): {n.bolt} "
                                 "open as before"),
    Said.CUT_UNKNOWN: lambda n: (
        f"{n.bolt}: {n.note}: {CHECK_ON_CONTROLLER}"
        if n.vin is None else
        f"{n.bolt} of {n.vin} (gone from the station): {n.note}: check it on the controller; "
        "held when that vehicle is back (stationd reopen), to release or enter its outcome"),
    # recorded to its bolt: "outside a tightening: recorded, not matched" was read as a
    # result lost to the bolt it went to (a quality engineer's trial)
    Said.LATE_RESULT: lambda n: (
        f"{_result_id(n.tightening_id)} came after the tool went off for {n.bolt} (within "
        f"the late-result window): recorded to {n.bolt}"
        + (f" of {n.vin} (gone from the station since)" if n.vin else "")),
    Said.TYPED_COPY: lambda n: (
        f"tightening {n.tightening_id}, fetched without its result type and {n.bolt} held "
        f"for it, came pushed with its type, made while the tool was on for {n.bolt}: "
        f"recorded to {n.bolt}, its hold ended"),
    Said.OTHER_VIN: lambda n: (
        f"tightening {n.tightening_id} of {n.bolt} carries the controller's VIN {n.note}, not "
        f"{n.vin}: recorded to {n.bolt} (its tool was on for it); the controller files it "
        "under that VIN: its VIN download (MID 0050) did not take, or another program set it"),
    Said.LOOSEN_PSET_TIGHTENED: lambda n: (f"{n.bolt}: the loosen pset {n.pset} reported a "
                                           "tightening: the bolt counts as tightened; check "
                                           "that pset's program"),
    Said.LOOSENED: lambda n: f"{n.bolt} loosened: its tightening pset goes next",
    Said.LOOSENING_NOK: lambda n: f"{n.bolt}: loosening NOK ({n.count} NOK in a row)",
    Said.LOCKED: lambda n: _locked(n.bolt, n.count),
    Said.NOK_AFTER_LOCK: lambda n: (
        f"{n.bolt}: "
        + (f"tightening {n.tightening_id}, " if n.tightening_id is not None else "")
        + f"a NOK made after {n.bolt} had reached "
        f"{n.locked_at} NOK in a row (the push of one of them lost: the station did not know "
        f"yet), recorded: {n.count} NOK in a row; {n.bolt} stays locked for a supervisor"),
    Said.ENTERED_OK: lambda n: f"{_entered(n)}: {n.bolt} done",
    Said.ENTERED_NOK: lambda n: f"{_entered(n)}: a NOK of {n.bolt}, the NOK policy applies",
    Said.ENTERED_LOOSENING_OK: lambda n: (f"{_entered(n)}: a loosening, not a tightening: "
                                          f"{n.bolt} not done"),
    Said.ENTERED_LOOSENING_NOK: lambda n: (f"{_entered(n)}: a loosening NOK of {n.bolt}, the "
                                           "NOK policy applies"),
    Said.REWORK_REOPENED: lambda n: (f"VIN {n.vin} already closed: reopened as a rework (its "
                                     "records kept)"),
    Said.LATE_ACK: lambda n: _late_ack(n.bolt),
}


def closed_after_outage(vin: str) -> str:
    """What follows a vehicle's close when the lift PLC said the lift down in its first read
    after an outage (a restarted PLC may have forgotten the vehicle still on the lift)."""
    return (f"; the lift PLC came back from an outage saying the lift is down (a PLC that "
            f"restarted forgets the vehicle): if {vin} is still on the lift, stationd reopen "
            f"{vin} --user NAME")


def sent_again_words(tightening_id: int | None, bolt: str | None,
                     vin: str | None = None) -> str:
    """A result the database had already, sent again by the controller: ``result 7 of B11
    sent again by the controller: stored once`` (the bolt it was stored for; left out for a
    result no bolt owns; ``vin``: its vehicle, where not the one at the station)."""
    of = f" of {bolt}" if bolt is not None else ""
    of += f" of VIN {vin}" if vin is not None else ""
    what = f"result {tightening_id}" if tightening_id is not None else "a result"
    return f"{what}{of} sent again by the controller: stored once"


def notice_words(notice: Notice) -> str:
    """A notice as the journal and the operator's log say it: ``B03 locked after 3 NOK in a
    row: a supervisor releases it``."""
    return _SAID[notice.said](notice)


def _unreadable(r: StateReason) -> str:
    """A result not read; a loosening's says so (the outcome to enter is a loosening's)."""
    whose = "loosening's " if r.loosen else ""
    return f"bolt {r.bolt}: its {whose}result could not be read"


def _not_taken(r: StateReason) -> str:
    """A result not taken for a tightening: its note says which (a type the station does
    not know), else an untyped OK outside the window."""
    return f"bolt {r.bolt}: " + (
        r.note or "an OK result without a result type outside its torque window")


_BECAUSE: dict[Because, Callable[[StateReason], str]] = {
    Because.OPENING: lambda r: "opening the devices",
    Because.FAULT: lambda r: _faults(r.faults),
    Because.RECOVERED: lambda r: "recovered; waiting for the lift",
    Because.STARTED: lambda r: "station started: the tool stays off until a bolt is confirmed",
    Because.CONTROLLER_BACK: lambda r: ("controller back: the tool stays off until a bolt is "
                                        "confirmed"),
    Because.WAITING_LIFT: lambda r: "waiting for the lift",
    Because.LIFT_NOT_READY: lambda r: r.note or "",
    Because.LOADING: lambda r: f"loading vehicle {r.vin}",
    Because.TRACKING: lambda r: "tracking the wrench",
    Because.SELECTED: lambda r: f"bolt {r.bolt} selected{_loosen_first(r)}",
    Because.ACKNOWLEDGED: lambda r: (f"bolt {r.bolt} acknowledged; confirming the wrench is "
                                     "on it"),
    Because.RESULT_OWED: lambda r: (f"bolt {r.bolt}: the tool stays off until bolt {r.owed}'s "
                                    "result is in, or can no longer come"),
    Because.CUT_OWED: lambda r: (f"bolt {r.bolt}: the tool stays off until the controller's "
                                 f"results made during the link cut are fetched (bolt "
                                 f"{r.owed} was enabled)"),
    # the tool on for a loosen pset: the operator loosens, never "tighten" (as the screens)
    Because.TIGHTENING: lambda r: f"{'loosening' if r.loosen else 'tightening'} bolt {r.bolt}",
    Because.NOT_CONFIRMED: lambda r: f"wrench not confirmed on bolt {r.bolt}",
    Because.SELECTED_UNCONFIRMED: lambda r: f"bolt {r.bolt} selected; wrench not confirmed",
    Because.WRENCH_LEFT: lambda r: f"wrench left bolt {r.bolt}",
    Because.LATE_ACK: lambda r: _late_ack(r.bolt),
    # a NOK says so: "bolt B42 tightened" after a NOK, in the neutral tone, was read as done
    # (an operator trial); ``ok`` None (not told) reads as before
    Because.RUNDOWN: lambda r: f"bolt {r.bolt} " + (
        ("loosening NOK" if r.loosen else "NOK") if r.ok is False
        else "loosened" if r.loosen else "tightened"),
    Because.PUSH_AFTER_LOST: lambda r: (f"bolt {r.bolt}: a rundown's result came after "
                                        "others the controller did not push: those first"),
    Because.RESULT: lambda r: (f"bolt {r.bolt} {'loosening ' if r.loosen else ''}"
                               f"{'OK' if r.ok else 'NOK'}; tracking"),
    Because.UNREADABLE: _unreadable,
    Because.UNREADABLE_HELD: lambda r: _unreadable(r) + _HELD_FOR,
    Because.NOT_TAKEN: _not_taken,
    Because.NOT_TAKEN_HELD: lambda r: _not_taken(r) + _HELD_FOR,
    Because.UNKNOWN_HELD: lambda r: f"bolt {r.bolt}: its result not known" + _HELD_FOR,
    Because.SKIPPED: lambda r: f"bolt {r.bolt} {_skipped(r.skip)}",
    Because.LOOSEN_ORDERED: lambda r: f"bolt {r.bolt}: loosen first",
    Because.OPERATOR: lambda r: f"operator {r.how}",
    Because.TEACH_MODE: lambda r: "teach mode",
    Because.TEACHING: lambda r: _teaching(r.model, r.user, r.bolt),
    Because.TEACH_ENDED: lambda r: "teach mode ended; waiting for the lift",
    Because.TEACH_ENDED_TRACKING: lambda r: "teach mode ended; tracking the wrench",
}


def state_words(reason: StateReason) -> str:
    """Why the station is in its state, or why the tool went off, as the screens, OPC UA and
    the journal say it: ``tightening bolt B05``, ``lift: no answer from 10.0.0.7:502``."""
    return _BECAUSE[reason.kind](reason)


#: the journal's shorter words for a bolt selected: the state says "bolt selected" already
_SELECTED_LINE: dict[Because, Callable[[StateReason], str]] = {
    Because.SELECTED: lambda r: f"{r.bolt}{_loosen_first(r)}",
    Because.SELECTED_UNCONFIRMED: lambda r: f"{r.bolt}; wrench not confirmed",
}


def state_line(state: State, reason: StateReason) -> str:
    """The state and its reason in one line, as the journal and the unit's STATUS= say it:
    ``tightening: tightening bolt B05``.  A bolt selected is named once (``bolt selected:
    B11``, where the reason alone says ``bolt B11 selected``)."""
    if state is State.BOLT_SELECTED and reason.kind in _SELECTED_LINE:
        return f"{state}: {_SELECTED_LINE[reason.kind](reason)}"
    return f"{state}: {state_words(reason)}"


def records_waiting(n: int) -> str:
    """The records a line database that is down keeps waiting, with the verb agreeing:
    ``no record waits yet``, ``1 record waits``, ``13 records wait``."""
    return "no record waits yet" if n == 0 else f"{counted(n, 'record')} " + (
        "waits" if n == 1 else "wait")


def check_words(ev: PairChecked) -> str:
    """A pair's calibration check in one line: ``pair2 moved: reference R1 off by 3.4 mm``."""
    if ev.why is not None:
        return reason_words(ev.why)
    return (f"{ev.pair} checked: reference {ev.reference} within {_mm(ev.offset_mm)} mm "
            f"(<= {ev.tolerance_mm or 0:g} mm)")


def operator_words(ev: OperatorChanged) -> str:
    """The journal's line for a change of operator: ``operator: olga signed in``."""
    if ev.user is not None:
        return f"operator: {ev.user} signed in" + (
            f" (after {ev.previous})" if ev.previous and ev.previous != ev.user else "") + (
            " (still, from before this start or reload)"
            if ev.how is OperatorChange.STILL_SIGNED_IN else "")
    if ev.previous is None:
        return "operator: nobody signed in" + (
            ": sign in to tighten (access.operator_required)" if ev.required else "")
    how = "signed out: idle too long" if ev.how is OperatorChange.IDLE else ev.how
    return f"operator: {ev.previous} {how}" + (f" by {ev.by}" if ev.by else "") + (
        "; sign in to tighten" if ev.required else "")


def reason_words(reason: Reason, *, full: bool = False) -> str:
    """One line an operator reads (``full``: each pair's vision reason, for the journal)."""
    if full and reason.kind is Why.NOT_LOCALIZED:
        return _per_pair(reason, full=True)
    return _WORDS[reason.kind](reason)


def command_words(cmd: Command) -> str:
    """What the command was: ``skip B07 of VIN123 ("no access")``."""
    what = KIND[type(cmd)]
    if isinstance(cmd, SkipBolt | ReleaseBolt | LoosenBolt):
        what += f" {cmd.bolt} of {cmd.vin}"
    elif isinstance(cmd, EnterOutcome):   # a held loosening's outcome: said to be one
        what += f" {cmd.bolt} of {cmd.vin}: " + ("loosening " if cmd.loosening else "") \
            + outcome_words(cmd.ok, cmd.torque_nm, cmd.angle_deg)
    elif isinstance(cmd, ReopenVehicle):
        what += f" {cmd.vin}"
    elif isinstance(cmd, TeachStart):
        what += f" {cmd.model}"
    elif isinstance(cmd, TeachPoint):
        what += f" {cmd.bolt}"
    elif isinstance(cmd, SignOut) and cmd.user is not None:
        what += f" of {cmd.user}"
    comment = comment_words(cmd)
    if comment:
        what += f" ({comment!r})"
    return what


def _reopened(bolt: str, hold: str | None) -> str:
    """What a release of a hold leaves (a lock's alone: nothing): the bolt open to be
    tightened again, though its result is not known: the result fetched late (or not given
    by the controller, or unreadable, or made during a link cut) may be its own (a
    supervisor's trial: "accepted: its hold (...) ended", and the joint, torqued already, was
    tightened again; the operator's screen marks the bolt "check first" alike)."""
    if hold is None:
        return ""
    tid = held_result_id(hold)
    if tid is not None:
        by = f", by tightening {tid} (stored unattributed)"
    elif GAP_NOTE_MARK in hold:
        by = " (a result the controller did not give)"
    elif hold.startswith(CHECK_NOTE_HEAD):
        by = " (a push lost, the controller's newest result not read)"
    else:
        by = ""
    return (f": {bolt} is open to be tightened again, but it may be tightened already{by}: "
            "check the controller before tightening it again")


def unrecorded_words(hold: str | None, loose: Sequence[Mapping[str, Any]] = ()) -> str:
    """A bolt with no rundown recorded to it, as the vehicle's page and ``db report`` say
    it: ``not tightened``; held (``hold``: its hold's note), not so: its result is not known,
    and a lost push's names the result stored unattributed that may be its own, with its
    values where the vehicle's unattributed results (``loose``, as the repository reads
    them) have it.  A supervisor's trial: the page said "not tightened" of a bolt whose
    result may be tightening 41, stored unattributed."""
    if hold is None:
        return "not tightened"
    tid = held_result_id(hold)
    if tid is None:
        return "held: no rundown recorded to it, its result not known"
    found = [u for u in loose if u.get("tightening_id") == tid]
    values = "" if not found else (
        f"{str(found[-1]['status']).upper()} {_mm(found[-1]['torque_nm'])} Nm, "
        f"{_deg(found[-1]['angle_deg'])} deg, ")
    return (f"held: no rundown recorded to it, but tightening {tid} may be its own ({values}"
            "stored unattributed)")


def entered_as_words(entered_as: dict[str, str] | None) -> str:
    """"; the outcome entered for B09 by sam": of a result stored unattributed whose entered
    outcome a person gave a bolt held for it (:meth:`db.others.OtherResults.unattributed`:
    one tightening, the bolt's row that result as read on the controller's screen); empty
    where there is none."""
    if not entered_as:
        return ""
    return f"; the outcome entered for {entered_as['bolt']} by {entered_as['by']}"


def _deg(v: float | None) -> str:
    return "?" if v is None else f"{v:.0f}"


def outcome_words(ok: bool, torque_nm: float, angle_deg: float) -> str:
    """An outcome as a person reads it off the controller: ``OK 49.6 Nm, 31.0 deg``."""
    return f"{'OK' if ok else 'NOK'} {torque_nm:.1f} Nm, {angle_deg:.1f} deg"


def answer_words(answer: Answer) -> str:
    """The journal's line: the command, who gave it and from where, and the answer."""
    who = answer.issuer
    head = f"command {command_words(answer.command)} by {who.user} ({who.source})"
    if answer.reason is None and isinstance(answer.command, ReopenVehicle):
        # what comes of it, where "accepted" alone left the person wondering (a supervisor
        # reopened a vehicle while another was on the lift)
        return (f"{head}: accepted: it opens as a rework when it is at the station (its "
                "skips before no longer count)")
    if answer.reason is None and isinstance(answer.command, ReleaseBolt) and answer.result:
        # what it ended: a lock after NOKs, or a hold (which result), so that a release
        # meant for a lock that ends a new hold is seen (a supervisor's trial)
        ended = answer.result
        said = ([f"its lock after {ended['lock']} NOK in a row"] if "lock" in ended else []) \
            + ([f"its hold ({ended['hold']})"] if "hold" in ended else [])
        loosen = "" if ended.get("loosen_pset") is None else \
            f"; its loosen pset {ended['loosen_pset']} goes first"
        left = (f": {answer.command.bolt} stays done (its OK result recorded)"
                if ended.get("done") else _reopened(answer.command.bolt, ended.get("hold")))
        return f"{head}: accepted: {' and '.join(said)} ended" + left + loosen
    if answer.reason is None:
        return f"{head}: accepted"
    return f"{head}: refused: {reason_words(answer.reason)}"


def _unseen(r: Reason) -> str:
    """A teach point with no localization of the wrench at all: what the cameras said first
    (a camera giving no frame is no reason to hold the tool stiller)."""
    assert r.cause is not None  # noqa: S101 - the caller's condition
    return (f"the wrench was not localized ({counted(float(r.limit or 0), 'localization')} "
            f"without it, none of the {r.needed} needed): {reason_words(r.cause)}")


def _missed(r: Reason) -> str:
    """What the localizations without a fresh wrench said (a teach point refused): "0 of 10
    localizations" alone, while the cameras gave no frame for two minutes, sent the engineer
    to hold the tool stiller."""
    if r.cause is None:
        return ""
    many = counted(float(r.limit), "localization") if r.limit else "the localizations"
    return f"; {many} without the wrench, the last: {reason_words(r.cause)}"


__all__ = [
    "answer_words",
    "check_asked_words",
    "check_words",
    "closed_after_outage",
    "command_words",
    "comment_words",
    "entered_as_words",
    "fault_words",
    "gap_plan_words",
    "id_span",
    "notice_words",
    "operator_words",
    "outcome_words",
    "reason_words",
    "records_waiting",
    "result_type_words",
    "sent_again_words",
    "skip_words",
    "state_line",
    "state_words",
    "stored_what",
    "unattributed_words",
    "unchecked_words",
    "unproved_words",
    "unrecorded_words",
    "wait_words",
    "worded",
]
