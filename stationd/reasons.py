"""Why the station does not do something: one enumeration of kinds, with the measured details
as fields.

Why typed: a refusal is produced where it is decided (the matcher, the core, a command's
check) and read by several edges (the operator screen, the journal, the command line, later
an MES and translated screens).  Carried as text it had to be parsed back with regular
expressions; carried as a :class:`Reason` each edge reads the kind and the fields, and
:mod:`stationd.words` turns it into words at the very end.  This module is a leaf: it imports
nothing of the station.

Beside the refusals, the other reasons the core decides and edges word that a refusal carries:
why a bolt is skipped (:class:`Skip`), a fault of the station's own rules
(:class:`CoreFault`), the sequence's rule a bolt waits for (:class:`Wait`), why a pair is not
checked (:class:`Unchecked`); and why a result is stored unattributed (:class:`Unattributed`,
stored in words by the shell).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TypeAlias


class Why(enum.Enum):
    """The kinds of refusal."""

    # the matcher: a localization that selects no bolt
    STALE = "stale"                      # frames older than max_age_s (age_ms, limit_ms)
    NO_BOLTS = "no bolts"                # the vehicle's table has none
    NO_BOLT_NEAR = "no bolt near"        # outside every bolt's tolerance (bolt = nearest)
    AMBIGUOUS = "ambiguous"              # two bolts within the margin (bolt, other)
    SKIPPED = "skipped"                  # the bolt was skipped (skip: why)
    DONE = "done"                        # already tightened OK
    MUST_WAIT = "must wait"              # order or batch (wait: which rule; skips: the
                                         # bolts waited for that were skipped, and why)
    NOT_STABLE = "not stable"            # stable for `count` of `needed` frames
    ELSEWHERE = "elsewhere"              # on another bolt than the one selected (bolt)
    LOCKED = "locked"                    # too many NOKs in a row: a release unlocks (count)
    NOT_LOCALIZED = "not localized"      # each pair's vision reason (per_pair) or note
    TILTED = "tilted"                    # the wrench tilted beyond the limit (angle_deg, limit)
    PAIRS_DISAGREE = "pairs disagree"    # pairs' bolt ends apart (distance_mm, limit)
    # a command refused by the station's rules
    NO_RIGHT = "no right"                # the user's role lacks the right (right)
    NO_VEHICLE = "no vehicle"            # no vehicle at the station
    OTHER_VEHICLE = "other vehicle"      # the command names another VIN (vin)
    UNKNOWN_BOLT = "unknown bolt"        # not a bolt of the vehicle (bolt)
    TOOL_ON_BOLT = "tool on bolt"        # the bolt is being tightened now (bolt)
    ALREADY_OPEN = "already open"        # a reopen of a vehicle that is open (vin)
    NOT_CLOSED = "not closed"            # a reopen of a vehicle that is not closed (vin)
    UNKNOWN_VEHICLE = "unknown vehicle"  # a VIN the database does not know (vin)
    DEVICE_FAULT = "device fault"        # a device is in fault (faults)
    NOT_RECORDED = "not recorded"        # the database refused the command's record (note)
    NOT_LOCKED = "not locked"            # a release of a bolt that is not locked (bolt)
    NOT_HELD = "not held"                # an entered outcome for a bolt not held (bolt)
    #: an OK entered with a value outside the bolt's window (bolt, note: the value and window)
    ENTERED_OUTSIDE = "entered outside"
    HELD = "held"                        # the controller's result could not be read: a
                                         # supervisor checks it there and releases (note)
    TEACHING = "teaching"                # teach mode is on (note: the model; user; bolt:
                                         # the one being measured)
    NOT_TEACHING = "not teaching"        # a teach command while teach mode is off
    NOT_STEADY = "not steady"            # teaching: too few steady localizations (count)
    NO_FRAMES = "no frames"              # teaching: no localization at all in `limit` s
    # the NOK policy's loosen strategy and the loosen command
    LOOSEN_FIRST = "loosen first"        # the bolt gets its loosen pset next (bolt, pset;
                                         # user, note: whose command, and their comment)
    NOTHING_TO_LOOSEN = "nothing to loosen"  # a loosen of a bolt not tightened (bolt)
    LOOSEN_ORDERED = "loosen ordered"    # a loosen of a bolt to be loosened already (bolt,
                                         # pset: its loosen pset)
    NO_LOOSEN_PSET = "no loosen pset"    # a loosen of a bolt no loosen_pset applies to (bolt)
    UNKNOWN_MODEL = "unknown model"      # a model no bolt table of the station has (note)
    # the calibration check against the reference markers
    PAIR_UNCHECKED = "pair unchecked"    # a pair not checked yet, or not measurable (pair,
                                         # unchecked: why)
    PAIR_MOVED = "pair moved"            # a reference off beyond the tolerance (pair,
                                         # reference, distance_mm, limit)
    REFERENCE_SEEN = "reference seen"    # a reference marker taken for the wrench (reference,
                                         # distance_mm from its place)
    NO_REFERENCES = "no references"      # a calibration check without references configured
    # the operator signed in at the station (access.operator_required)
    SIGN_IN = "sign in"                  # nobody signed in and the station requires one
    NOT_SIGNED_IN = "not signed in"      # a sign-out with nobody signed in
    SIGNED_IN = "signed in"              # a sign-in of the operator signed in already (user)


class SkipKind(enum.StrEnum):
    """Why a bolt is skipped for the vehicle (not tightened at this station): the kind of a
    :class:`Skip`."""

    NOK_POLICY = "nok policy"            # a NOK under the NOK policy's ``skip`` strategy
    NO_LOOSEN_PSET = "no loosen pset"    # to be loosened, and no loosen_pset applies to it
    REFUSED = "refused"                  # the controller refused its parameters (reason)
    COMMAND = "command"                  # a person's skip command (user, comment)


@dataclass(frozen=True)
class Skip:
    """Why a bolt is skipped, as the station decided it: the kind and the details that apply
    (the others stay None).  Typed, not words: the matcher keeps it, refusals, the state's
    reason and :class:`~stationd.station.events.BoltSkipped` carry it, and
    :func:`stationd.words.skip_words` says it at the edges (``olga's command (no access)``)."""

    kind: SkipKind
    user: str | None = None             # who gave the command (COMMAND)
    comment: str | None = None          # their comment (COMMAND; empty: none)
    reason: str | None = None           # the controller's own words (REFUSED)


class CoreFaultKind(enum.StrEnum):
    """The station's own faults, decided by its rules (a device's own faults are its words):
    the kind of a :class:`CoreFault`."""

    VIN_CHANGED = "vin changed"          # the PLC reports another VIN at height (plc_vin, vin)
    MODEL_CHANGED = "model changed"      # ... another model code (plc_code, code, vin)
    CLOSED = "closed"                    # the vehicle at height rejected: its VIN closed
                                         # before, and no rework (vin, note: the rejection's
                                         # own words)
    PARAMS_REFUSED = "params refused"    # the controller refused a bolt's parameters (bolt,
                                         # note: the controller's words)
    LIFT_REPORTS_FAULT = "lift fault"    # the lift PLC answers with its fault bit set: a
                                         # fault of the station until it clears


@dataclass(frozen=True)
class CoreFault:
    """A fault the station's rules decided (the vehicle at height is not the one loaded, a
    closed vehicle back without a rework, parameters refused): its kind and the details that
    apply.  Typed, not words: :func:`stationd.words.fault_words` says it where a device's
    fault is said (the state's reason, a refusal, the device's health, the journal)."""

    kind: CoreFaultKind
    vin: str | None = None              # the vehicle loaded (or the closed one)
    plc_vin: str | None = None          # the VIN the PLC reports at height
    code: int | None = None             # the model code the vehicle was loaded as
    plc_code: int | None = None         # the model code the PLC reports at height
    bolt: str | None = None
    note: str | None = None             # words from elsewhere (the database, the controller)


#: why a device is in fault: its own words (a driver's or the shell's text: a device text,
#: kept as it came), or a fault of the station's own rules, typed
FaultWhy: TypeAlias = str | CoreFault


class WaitKind(enum.StrEnum):
    """Which rule of the sequence a bolt must wait for: the kind of a :class:`Wait`."""

    BATCH = "batch"                      # other batches begun and not finished (batches)
    ORDER = "order"                      # bolts before it in its order (order, batch, bolts)


@dataclass(frozen=True)
class Wait:
    """Why the sequence (order, batch) forbids a bolt now, as the matcher decided it: the
    rule and the bolts it waits for.  Typed, not words: a ``MUST_WAIT`` refusal carries it
    and :func:`stationd.words.wait_words` says it (``order 2 in batch subframe needs A1, A2
    done first``)."""

    kind: WaitKind
    #: each batch begun and not finished, with its bolts remaining (BATCH), in table order
    batches: tuple[tuple[str, tuple[str, ...]], ...] = ()
    order: int | None = None            # the bolt's order (ORDER)
    batch: str | None = None            # the bolt's batch, if any (ORDER)
    bolts: tuple[str, ...] = ()         # the bolts before it not done yet (ORDER)


class UncheckedKind(enum.StrEnum):
    """Why a camera pair is not checked against the reference markers (not trusted until it
    is): the kind of an :class:`Unchecked`."""

    SINCE_START = "since start"          # no check since the start (or a reload)
    ARRIVAL = "arrival"                  # a vehicle arrived: a check asked for it (vin)
    PAIRS_UNKNOWN = "pairs unknown"      # which pairs saw the wrench is not known
    NO_MARKER = "no marker"              # the pair sees no reference marker
    NOT_MEASURED = "not measured"        # its check measured no reference within reach
                                         # (reference, measure, note)


@dataclass(frozen=True)
class Unchecked:
    """Why a pair is not checked, as the trust rules decided it (a ``PAIR_UNCHECKED``
    refusal carries it; :func:`stationd.words.unchecked_words` says it)."""

    kind: UncheckedKind
    vin: str | None = None              # the vehicle arrived (ARRIVAL)
    reference: str | None = None        # the worst reference (NOT_MEASURED), if any
    #: why that reference was not measured, as the check said it (its ``RefWhy`` value:
    #: ``not found``; None: nothing measured) (NOT_MEASURED)
    measure: str | None = None
    note: str | None = None             # the check's own words (a grab's error, the vision)


class UnprovedKind(enum.StrEnum):
    """What did not agree when a result fetched after a link cut was checked against the
    enable the cut came during: the kind of an :class:`Unproved`."""

    PSET = "pset"                        # its pset not the one sent (pset, sent_pset, bolt)
    VIN = "vin"                          # the VIN it echoes not the one sent (vin, sent_vin)
    NOT_FIRST = "not first"              # not the first id after the last accounted for
                                         # (follows)
    FOLLOWS_UNKNOWN = "follows unknown"  # the last id accounted for unknown
    CLOCK_UNKNOWN = "clock unknown"      # the controller's clock not known
    OUTSIDE_CUT = "outside cut"          # made outside the enable and the cut (bolt)
    NO_CUT = "no cut"                    # no enable left without its result by the link cut
    #                                      (none was on, or its result is in already)
    RAN_AGAIN = "ran again"              # after the cut's rundown (follows) of bolt, made
    #                                      during the same cut: the tool ran again (held)


@dataclass(frozen=True)
class Unproved:
    """Why a result fetched after a link cut is not proved to be the cut enable's: the
    first of its data that did not agree."""

    kind: UnprovedKind
    bolt: str | None = None             # the bolt the cut enable was for
    pset: int | None = None             # the result's pset
    sent_pset: int | None = None        # the pset sent for that bolt
    vin: str | None = None              # the VIN the result echoes
    sent_vin: str | None = None         # the VIN sent
    follows: int | None = None          # the last tightening id accounted for


class UnattributedKind(enum.StrEnum):
    """Why a result is stored unattributed (no bolt owns it): the kind of an
    :class:`Unattributed`."""

    OUTSIDE = "outside"                  # pushed outside any tightening
    FETCHED_LIVE = "fetched live"        # fetched after a later one came, the link up
    FETCHED_CHECKED = "fetched checked"  # fetched when the controller's newest was asked
    #                                      for as an enable's window ended, the link up
    FETCHED = "fetched"                  # fetched after a reconnect
    # pushed while the tool was on for ``bolt`` (or within its late-result window), of
    # another pset than the one sent for it: run with another program, its bolt held
    OTHER_PSET = "other pset"
    # fetched after a later one came, the link up, and it is the result that could not be
    # read for ``bolt`` (the one id between the tightenings read before and after it)
    UNREAD_READ = "unreadable, read"


@dataclass(frozen=True)
class Unattributed:
    """Why a result no bolt owns is stored so, as the core decided it: the result, how it
    came, and what did not prove it the cut enable's.  Typed, not words: the shell writes
    :func:`stationd.words.unattributed_words` into the record's reason (the text stored is
    what the core wrote before), and the journal's notice says the same."""

    kind: UnattributedKind
    tightening_id: int
    pset: int | None
    unproved: Unproved | None = None
    #: UNREAD_READ: the held bolt whose unreadable result this is, and the ids read before and
    #: after that unreadable message
    bolt: str | None = None
    between: tuple[int, int] | None = None


@dataclass(frozen=True)
class Reason:
    """One refusal: its kind and the details that apply (the others stay None)."""

    kind: Why
    bolt: str | None = None
    other: str | None = None            # the second bolt of an ambiguity; what was meant
    #                                     (a bolt or VIN typed in another case)
    vin: str | None = None
    distance_mm: float | None = None
    other_mm: float | None = None
    limit: float | None = None          # a tolerance (mm) or an age limit (ms)
    age_ms: float | None = None
    count: int | None = None
    needed: int | None = None
    right: str | None = None
    #: NO_RIGHT: the command asked, where its right has another name (an entered outcome
    #: ends a hold: the release right; a supervisor's trial read "no right to release" of it)
    asked: str | None = None
    angle_deg: float | None = None
    blocking: tuple[str, ...] = ()
    # (pair, camera side or "", the vision's reason) for each pair
    per_pair: tuple[tuple[str, str, str], ...] = ()
    note: str | None = None             # words from elsewhere (the vision, a device)
    pset: int | None = None             # the pset that goes next (a loosen pset)
    pair: str | None = None             # a camera pair (the calibration check)
    reference: str | None = None        # a reference marker (the calibration check)
    user: str | None = None             # a user (the operator signed in, who teaches)
    #: (device, why: its own words or the station's typed fault) for each device in fault,
    #: in the order they failed
    faults: tuple[tuple[str, FaultWhy], ...] = ()
    skip: Skip | None = None            # why a bolt was skipped (SKIPPED)
    #: the bolts waited for that were skipped, each with why (MUST_WAIT: waiting for them is
    #: waiting for something that will not happen on its own)
    skips: tuple[tuple[str, Skip], ...] = ()
    wait: Wait | None = None            # which rule of the sequence forbids it (MUST_WAIT)
    unchecked: Unchecked | None = None  # why a pair is not checked (PAIR_UNCHECKED)
    #: OTHER_VEHICLE: the VIN named was reopened for rework and is not back at the station yet
    #: (True; None: not said, as every detail that does not apply)
    reopened: bool | None = None
    #: OTHER_VEHICLE: the VIN at the station (a VIN mistyped shows beside it)
    here: str | None = None
    #: the refusal behind this one (a teach point not steady: what the localizations without
    #: the wrench said, e.g. no frame from a camera)
    cause: Reason | None = None

    def key(self) -> tuple[object, ...]:
        """What makes two refusals the same for the operator: the kind and the bolts, not the
        measurements ("stale (812 ms)" and "stale (790 ms)" are one refusal; "B18 is done" and
        "B01 is done" are two)."""
        return (self.kind, self.bolt, self.other, self.vin, self.blocking, self.right,
                self.pair, self.reference)


__all__ = ["CoreFault", "CoreFaultKind", "FaultWhy", "Reason", "Skip", "SkipKind",
           "Unattributed", "UnattributedKind", "Unchecked", "UncheckedKind", "Unproved",
           "UnprovedKind", "Wait", "WaitKind", "Why"]
