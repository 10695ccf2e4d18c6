"""The core's inputs: what the shell saw, typed (a lift read, a localization, the controller's
acknowledgement or result, a device's fault, a command), each with its time ``t``.

Why a module of their own: they are the core's whole vocabulary from the world, read by the
shell that builds them and by every subject of the rules that handles them."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from db.bolts import Parameters
from db.kinds import BoltStatus, HeldUnder
from drivers.identity import DeviceIdentity
from drivers.keeper import FaultKind
from drivers.wrench.base import TighteningResult, UnreadableResult
from stationd.reasons import Reason, Skip
from stationd.station.actions import Record
from stationd.station.commands import Command, Issuer
from stationd.station.trust import ReferencesChecked


class Device(enum.StrEnum):
    """The station's devices besides its camera pairs (a pair is named by the station file)."""

    LIFT = "lift"
    WRENCH = "wrench"
    VEHICLE = "vehicle"     # the vehicle at height: its data can fault (an unknown model)
    DATABASE = "database"


LIFT, WRENCH, VEHICLE, DATABASE = Device.LIFT, Device.WRENCH, Device.VEHICLE, Device.DATABASE


# -- inputs -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Input:
    """Base of every input: ``t`` is when it happened (``time.time()`` scale)."""

    t: float


@dataclass(frozen=True)
class Started(Input):
    """The daemon is serving (devices may still be down)."""


@dataclass(frozen=True)
class Announce(Input):
    """A new station takes over (the daemon's start, a reload) before it opens anything: the
    core tells its state as it stands, so the screens forget the last one's reports."""


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
    #: the PLC's fault bit (the lift itself in fault, the PLC answering): a station fault
    plc_fault: bool = False


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
    #: measured at connect), pushed or fetched; None when the controller's clock is not known
    made_at: float | None = None
    #: fetched with the link up: a later result came pushed and skipped its id (a push the
    #: controller, or a device on the way, lost), not after a reconnect
    live: bool = False
    #: fetched with the link up: the id of that later result, which comes to the core after
    #: this one (the results in the order they were made: a NOK counted in its place)
    before: int | None = None


@dataclass(frozen=True)
class ResultsSkipped(Input):
    """A result pushed with the link up (``tightening_id``) skipped ids: their pushes were
    lost.  The shell fetches them and feeds them first, then the pushed one.  Why told
    before: the rundown is over (the tool goes off now, not after the fetches: the operator
    could pull again), and the enable's result stays owed until the pushed one is in,
    however long the fetches take."""

    tightening_id: int


@dataclass(frozen=True)
class NewestChecked(Input):
    """The controller's newest result was asked for (:class:`~stationd.station.actions.
    CheckNewest`) and what it had since the last one heard fed: or the check could not be
    made (a catch-up running, the link down), or was void.  Why told: the enable whose
    window ended stays owed until then (its result, its push lost, is fetched and recorded
    to it), and no tool goes on meanwhile (a trial: the next bolt's enable, 30 ms after the
    window's end, voided the check).  ``nothing_made``: the controller's newest was the last
    result heard (no tightening since: the enable got none, and no later gap is its).
    ``unknown``: why the controller could not tell (its answer failed, the link dropped
    meanwhile, its newest unreadable): the enable's bolt is held, as a lost push's may be
    its own (a reviewer: left open, the tool went on for it again, tightened twice); empty
    where it told, or keeps no results to ask (the next one pushed tells, by its id).
    ``serial``: the enable the check was asked for (:class:`~stationd.station.actions.
    CheckNewest`): a check's answer ends no later one (None: whichever runs)."""

    nothing_made: bool = False
    unknown: str = ""
    serial: int | None = None


@dataclass(frozen=True)
class ResultCopy(Input):
    """A result from the controller that the database has stored already (the shell asked it
    before the core saw the result): a copy the controller sent again, its acknowledgement
    lost (a reload, a link cut).  ``vin`` and ``bolt``: the vehicle and bolt it was stored
    for (None: stored as a result no bolt owns, or with no vehicle at height).  Why apart
    from :class:`ResultIn`: the core must not attribute it: taken for the result of the
    bolt the tool is enabled for now (a new station's owed enable, same pset), it closed,
    counted or settled a bolt that was never tightened."""

    result: TighteningResult
    vin: str | None
    bolt: str | None
    #: the result as it came (how, its time), where the shell had it as a ResultIn
    of: ResultIn | None = None


@dataclass(frozen=True)
class UnreadableIn(Input):
    """A result message the driver could not read (kept whole), not yet acknowledged;
    ``stored``: the vehicle and bolt the database has the same message stored for already
    (a copy the controller sent again; None: not stored)."""

    unreadable: UnreadableResult
    stored: tuple[str | None, str | None] | None = None


@dataclass(frozen=True)
class CaughtUp(Input):
    """The results the controller made while its link was down were fetched after the
    reconnect (``complete``: every one since the link was lost went through the core), or
    could not all be (``reason``: why not, in the shell's words).  Ends what a link cut during
    an enable left open: its result proved and recorded, or, not found among a complete
    catch-up, none made; else unknown, and its bolt held for a person."""

    complete: bool
    reason: str = ""
    #: the controller's connection it caught up on (its reconnect count, as DeviceBack's;
    #: None: not known): one of the connection that was cut, or earlier, is stale
    reconnects: int | None = None
    #: the controller refused (or did not answer) the catch-up's ask for its newest: what
    #: it made during the cut was not counted, and it may still send it, pushed late
    unasked: bool = False
    #: the controller's ids started again (its results cleared, or its count restarted):
    #: the ids told before are another count's
    restarted: bool = False


@dataclass(frozen=True)
class ResultsMissed(Input):
    """Tightenings ``first``..``last`` were made while the link was down (``live``: with it
    up, never pushed) and cannot be fetched (``reason``): a gap in the controller's
    numbering, to be stored and said."""

    first: int
    last: int
    reason: str
    live: bool = False


@dataclass(frozen=True)
class NotStored(Input):
    """The database refused the record of tightening ``tightening_id`` on ``bolt``
    (``reason``); the shell keeps it until the database takes it."""

    tightening_id: int
    bolt: str
    reason: str


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
class DeviceSaid(Input):
    """What a device said it is when it (re)connected (the controller's MID 0002: name, cell
    and channel, software versions).  The core keeps it and tells it (``DeviceIdentified``):
    the devices panel and OPC UA show what the core was told, as for every other report.

    ``identity``: its words (the journal, the devices panel, the status);
    ``identification``: the same reading typed, its nameplate fields for OPC UA (its
    ``words`` are ``identity``); None from a device that gives words only."""

    device: str
    identity: str
    identification: DeviceIdentity | None = None

    def __post_init__(self) -> None:
        # one reading, two views: words that disagree would tell two devices at once
        if self.identification is not None and self.identification.words != self.identity:
            raise ValueError(f"{self.device}: identity {self.identity!r} is not its "
                             f"identification's words {self.identification.words!r}")

    @classmethod
    def of(cls, t: float, device: str, identification: DeviceIdentity) -> DeviceSaid:
        """What a driver's typed identity says, words and fields."""
        return cls(t, device, identification.words, identification)

    @property
    def nameplate(self) -> DeviceIdentity:
        """The typed identity, words alone where the device gave no fields."""
        return self.identification or DeviceIdentity(self.identity)


@dataclass(frozen=True)
class LineLinkIn(Input):
    """The line forwarder's link to the line database went up or down (``reason``: its last
    error), or its backlog alarm changed.  Never a fault of the station (a lost line database
    stops no tightening): the core keeps it for its status and tells it (``LineLinkChanged``)
    for the line asset's health in OPC UA."""

    up: bool
    reason: str = ""
    alarm: str | None = None


@dataclass(frozen=True)
class LoadedBolt:
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
    skipped since it was (re)opened (bolt -> why: the person's command, typed)."""

    vin: str
    model: str
    bolts: Mapping[str, LoadedBolt]
    done: frozenset[str] = frozenset()
    rework: bool = False
    skipped: Mapping[str, Skip] = field(default_factory=dict)
    noks: Mapping[str, int] = field(default_factory=dict)   # NOKs in a row, since a release
    held: Mapping[str, str] = field(default_factory=dict)   # held by an unreadable result
    status: Mapping[str, BoltStatus] = field(default_factory=dict)  # bolt -> ok, nok, ...
    #: the bolts whose last rundown is a NOK loosening (the report says nok: the joint did
    #: not come loose, its loosen pset goes again whatever the strategy)
    loosen_nok: frozenset[str] = frozenset()
    #: held bolt -> what its result came under, as the records tell it (a held bolt without
    #: one: not known, the core decides as for an enable not found)
    held_under: Mapping[str, HeldUnder] = field(default_factory=dict)
    #: the bolts the NOK policy locked (recorded by :class:`NoteLock`) and no person
    #: released or skipped since: locked again whatever ``max_nok`` says now
    locked: frozenset[str] = frozenset()
    #: the bolts whose last hold a person released, not run down since: open again, but they
    #: may be tightened already (the screens say "check first" after a restart too)
    released: frozenset[str] = frozenset()

@dataclass(frozen=True)
class ToolOn(Input):
    """The controller enabled the tool for ``bolt`` (the outcome of :class:`EnableTool`)."""

    bolt: str


@dataclass(frozen=True)
class Written(Input):
    """The database took ``record`` (with the crops ``images``): it may be acknowledged.
    ``again``: it had it already (a copy the controller sent again, stored once); then
    ``stored_vin`` and ``stored_bolt`` are the stored record's, which may not be
    ``record``'s (the copy was attributed to another bolt: the core undoes that)."""

    record: Record
    images: tuple[str, ...] = ()
    again: bool = False
    stored_vin: str | None = None
    stored_bolt: str | None = None


@dataclass(frozen=True)
class VehicleEnded(Input):
    """The database closed ``vin``: the bolts missing and NOK when it left, those whose result
    was still due (``due``: neither).  ``settled``: not the close but its verdict again, the
    results due of these bolts settled (:class:`~stationd.station.actions.SettleClosing`)."""

    vin: str
    missing: tuple[str, ...] = ()
    nok: tuple[str, ...] = ()
    due: tuple[str, ...] = ()
    settled: tuple[str, ...] = ()


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
    #: whether the database has the VIN the command names (the shell looked it up: a VIN
    #: mistyped is refused as unknown, not told to reopen it: a supervisor's trial); None:
    #: not asked (no VIN, the one at the station, a reopen), or the database could not say
    known: bool | None = None
    #: the VIN the database has that the one named is in another case (what was meant)
    meant: str | None = None


@dataclass(frozen=True)
class ModelsKnown(Input):
    """The vehicle models of the station's bolt tables (what ``teach start`` may name)."""

    models: frozenset[str]


@dataclass(frozen=True)
class OperatorBack(Input):
    """At a start or a reload: ``user`` signed in at ``since`` and did not sign out (the
    commands' records say so), and is still a user of the station file (or the simulated
    operator, whom the simulation keeps signed in across a reload)."""

    user: str
    since: float


@dataclass(frozen=True)
class CommandDone(Input):
    """The shell carried out a command's :class:`RecordCommand`: recorded (``reason`` None)
    or refused by the database (an unknown VIN, a vehicle not closed, a failed write)."""

    request: int
    reason: Reason | None = None


Event = (Started | Announce | LiftRead | LocalizedIn | ParamsAcked | ParamsRefused | ResultIn
         | ResultsSkipped | NewestChecked | ResultCopy | UnreadableIn
         | ResultsMissed | CaughtUp | NotStored
         | DeviceFault | DeviceBack | DeviceSaid | LineLinkIn
         | VehicleLoaded | VehicleRejected | VinSent | Tick
         | CommandIn | CommandDone | ToolOn | Written | VehicleEnded | ModelsKnown
         | ReferencesChecked | OperatorBack)
