"""The core's state and the transitions every subject of its rules shares: the station's
state and reason, the vehicle, the selection and the tool, the faults, and the constants the
rules agree on.

Why apart from the rules: each subject (:mod:`~stationd.station.lift`,
:mod:`~stationd.station.tool`, :mod:`~stationd.station.results`, ...) reads and changes this one
state; the transitions here (to a state, the tool off, a selection dropped, a bolt held) are
each written once and used by all."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from db.bolts import Window
from db.kinds import LOOSENED, NOK, OK, PENDING, SKIPPED, TO_LOOSEN, loosening_note
from drivers.identity import DeviceIdentity
from stationd.reasons import CoreFault, CoreFaultKind, FaultWhy, Reason, Skip, SkipKind, Why
from stationd.station.actions import Action, DisableTool, NoteLock, Owed, Publish, Selection
from stationd.station.commands import TeachPoint
from stationd.station.events import (
    Because,
    BoltLocked,
    BoltsChanged,
    BoltView,
    LineLinkChanged,
    Notice,
    Said,
    State,
    StateReason,
    ToolDisabled,
)
from stationd.station.inputs import CommandIn, LiftRead, LoadedBolt
from stationd.station.matching import BoltMatcher, MatchParams
from stationd.station.policy import NokPolicy, NokRule, Strategy
from stationd.station.trust import PairTrust

#: a result this long after the tool went off is not the last bolt's late one: the tool cannot
#: tighten while disabled, and a controller reports within milliseconds
LATE_RESULT_S = 5.0
#: the states on a bolt (parameters sent, or the tool on), and those that read the cameras
ON_A_BOLT = (State.BOLT_SELECTED, State.TIGHTENING)
LOCALIZING = (State.TRACKING, *ON_A_BOLT)
#: the states in which the cameras are read (teaching measures the wrench, sends nothing)
CAMERAS_ON = (*LOCALIZING, State.TEACHING)
#: why a bolt is not tightened again after a NOK under the ``skip`` strategy
NOK_SKIPPED = Skip(SkipKind.NOK_POLICY)
#: the station's reason until it started: its devices being opened
OPENING = StateReason(Because.OPENING)
#: the targets sent with a loosen pset: none of the station's own (a loosen pset is a program
#: on the controller; a register-driven controller takes 0 as "the pset's own")
LOOSEN_TARGETS = Window(0.0, 0.0, 0.0)
#: why a bolt to loosen is not tightened when no loosen pset applies to it (a reload removed it)
NO_LOOSEN_PSET = Skip(SkipKind.NO_LOOSEN_PSET)
#: unanswered enables kept, of every vehicle (the oldest forgotten first)
UNANSWERED = 20
#: the longest a pushed result that skipped ids is waited for after the core was told
#: (:class:`ResultsSkipped`): the shell feeds it after the fetches, each bounded in time; a
#: result that never comes (a fault of the shell) keeps no tool off for good
PENDING_PUSH_S = 60.0
#: the longest the controller's answer to a check of its newest result is waited for (one
#: MID 0064 and the fetches of what it had since, each bounded in time by the driver)
CHECK_WAIT_S = 15.0

#: while the tool is on and its enable has no result yet, the controller is asked for its
#: newest result every this many seconds of tool-on (:class:`CheckNewest` with
#: ``tool_on``): a rundown whose push was lost is found within it, recorded to its bolt and
#: the tool goes off, as for a pushed result.  Why: a new-user trial (``lose_push_every``)
#: found the tool left on after a lost NOK, and the operator ran the bolt down again without
#: its loosening.  2.5 s: longer than a rundown takes to end and its push to come (a check
#: that comes first takes the result fetched, its push then a copy), one MID 0064 and its
#: answer per period (nothing the link feels), and shorter than an operator takes to see a
#: result, let go and pull again.  None: never
CHECK_ON_S = 2.5


@dataclass(frozen=True)
class _Cut:
    """The link to the controller went down while the tool was enabled for ``selection``
    (enabled at ``enabled_at``, the cut seen at ``cut_at``): a result fetched after the
    reconnect that the controller's own data places there is that bolt's."""

    selection: Selection
    enabled_at: float
    cut_at: float
    #: the controller's connection that was cut (its reconnect count; None: not known): a
    #: catch-up of that connection or an earlier one says nothing of this cut
    reconnects: int | None = None

    def spans(self, made_at: float, slack: float) -> bool:
        """Whether a result made at ``made_at`` (the station's clock) may have been made
        under this enable, from it to ``cut_at``, each end within ``slack``."""
        return self.enabled_at - slack <= made_at <= self.cut_at + slack


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

    def _bolt(self) -> str | None:
        """The bolt being measured (None: waiting for a teach point)."""
        c = self.measuring
        return c.command.bolt if c is not None and isinstance(c.command, TeachPoint) else None

    def reason(self) -> StateReason:
        """The station's reason while teaching: the model, who, the bolt being measured."""
        return StateReason(Because.TEACHING, model=self.model, user=self.user,
                           bolt=self._bolt())

    def refusal(self) -> Reason:
        """Why another command waits: teach mode is on (said with the same details)."""
        return Reason(Why.TEACHING, note=self.model, user=self.user, bolt=self._bolt())


def _disable(reason: StateReason, bolt: str | None = None, why: Reason | None = None, *,
             t: float) -> list[Action]:
    """The tool off: said on the bus (the screens, the journal), then done."""
    return [Publish(ToolDisabled(reason, bolt, why, t=t)), DisableTool(reason, bolt, why)]


#: the lift's own fault, its PLC's fault bit: a fault of the station while it is set (the
#: lift's rules raise and end it as a read says)
LIFT_FAULT_BIT = CoreFault(CoreFaultKind.LIFT_REPORTS_FAULT)


@dataclass(frozen=True)
class CoreStatus:
    """The station as the core decided it, a copy: what the shell and the screens ask for
    (they never read the core's fields, which only the core writes)."""

    state: State
    #: why, typed (its words: :func:`stationd.words.state_words`)
    reason: StateReason
    #: device -> why it is in fault: its own words, or the station's own fault, typed (either
    #: in words: :func:`stationd.words.fault_words`)
    faults: Mapping[str, FaultWhy]
    vin: str | None
    bolt: str | None
    tool_on: bool
    operator: str | None
    #: the pairs the calibration check does not trust now, with why (None: no check)
    untrusted: Mapping[str, Reason] | None
    #: the loaded vehicle's model (None: no vehicle loaded)
    model: str | None = None
    #: the loaded vehicle's bolts waiting for a supervisor: locked after NOKs in a row, held
    #: (their result could not be read)
    locked: frozenset[str] = frozenset()
    held: frozenset[str] = frozenset()
    #: whether the bolt selected now is to be loosened first (the NOK policy)
    loosen: bool = False
    #: device -> what it said it is when it (re)connected, in words
    identities: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    #: the line database's link as last told (None: no line forwarder, or not told yet)
    line: LineLinkChanged | None = None
    #: device -> the same, typed (its words and nameplate fields: manufacturer, serial ...)
    identifications: Mapping[str, DeviceIdentity] = field(
        default_factory=lambda: MappingProxyType({}))
    #: the loaded vehicle's bolts tightened OK, and those skipped by a person's command (who
    #: comes back to a vehicle, a simulated operator after a reload, goes on with the rest)
    done: frozenset[str] = frozenset()
    skipped: frozenset[str] = frozenset()
    #: device -> its fault's kind (``down``, ``timeout``, ...), as :class:`DeviceHealth` says it
    fault_kinds: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    #: no parameters are sent while nobody is signed in (``access.operator_required``)
    operator_required: bool = False
    #: the tool enables so far (a check of the controller's newest result is void where
    #: one came meanwhile: its own rundown would be fetched before its push)
    enables: int = 0
    #: the enable whose check of the controller's newest runs (None: none): a check the
    #: core gave up on asks nothing (a reviewer: its fetch, late, took the next bolt's
    #: result as no bolt's, and that bolt's own check then found nothing made)
    checking: int | None = None
    #: the loaded vehicle's bolts as the core holds them (their changes since:
    #: :class:`BoltsChanged`); none loaded: empty
    bolts: tuple[BoltView, ...] = ()

    @property
    def cameras_on(self) -> bool:
        """Whether the cameras are to be read (tracking, on a bolt, teaching)."""
        return self.state in CAMERAS_ON


@dataclass
class CoreState:
    """One station's state and its shared transitions.  ``rework``: a vehicle whose VIN was
    closed comes back -> reopen it (its history kept) rather than a named fault that clears
    when the lift lowers."""

    params: MatchParams = field(default_factory=MatchParams)
    leave_frames: int = 3
    rework: bool = True
    late_result_s: float = LATE_RESULT_S
    check_on_s: float | None = CHECK_ON_S
    nok: NokPolicy = field(default_factory=NokPolicy)
    state: State = State.STARTING
    reason: StateReason = OPENING
    _started: bool = field(default=False, repr=False)   # Started heard (once)
    bolt: str | None = None
    matcher: BoltMatcher | None = None
    vin: str | None = None
    model: str | None = None
    #: device -> the fault's kind, and why (its own words, or the station's own fault, typed)
    faults: dict[str, tuple[str, FaultWhy]] = field(default_factory=dict)
    #: device -> what it said it is (its words: ``identities`` in the status)
    identifications: dict[str, DeviceIdentity] = field(default_factory=dict)
    line: LineLinkChanged | None = None   # the line database's link as last told
    tool_on: bool = False
    _specs: dict[str, LoadedBolt] = field(default_factory=dict, repr=False)
    _lift: LiftRead | None = field(default=None, repr=False)
    #: when the lift PLC last went silent: a read older than that is not the lift as it is
    _lift_lost_at: float = field(default=float("-inf"), repr=False)
    #: the lift PLC's fault bit as last read (False while the PLC does not answer: unknown, the
    #: first read after the outage says it again)
    _plc_fault: bool = field(default=False, repr=False)
    _loading: bool = field(default=False, repr=False)
    _load_code: int | None = field(default=None, repr=False)   # the model code loaded
    _selection: Selection | None = field(default=None, repr=False)
    _acked_at: float | None = field(default=None, repr=False)
    _away: int = field(default=0, repr=False)
    _enabled: Selection | None = field(default=None, repr=False)  # tool last enabled for
    _off_at: float | None = field(default=None, repr=False)
    _enabled_at: float | None = field(default=None, repr=False)
    _cut: _Cut | None = field(default=None, repr=False)   # a link cut during an enable
    #: the vehicle's enables whose late-result window ended without their result, the link
    #: up (``cut_at``: when that window ended), the latest last: a result fetched late (its
    #: push lost) of one's pset, made within it, may be its bolt's, which is then held
    _unanswered: list[_Cut] = field(default_factory=list, repr=False)
    #: the vehicle's enables whose window's check found nothing made (the controller's newest
    #: the last result heard: taken as not tightened), the latest last: a result made within
    #: one that comes later all the same (the controller stored and pushed it late: an
    #: integrator's trial) may be its bolt's, which is then held, placed by its time alone
    _cleared: list[_Cut] = field(default_factory=list, repr=False)
    #: those of a bolt whose tool went on again since (:meth:`_unanswered_before`), and an
    #: enable of it still owed then (its window running): what is made now is its own, but
    #: ids a gap tells before it got a result may be the earlier rundown's (only a gap's:
    #: :meth:`LostRules._gap_in_doubt`)
    _again: list[_Cut] = field(default_factory=list, repr=False)
    #: such enables a gap may own, held once the pushed result that revealed the gap is
    #: judged (after its record to that bolt: a hold stored before a rundown ends with it),
    #: each with its hold's note (:meth:`LostRules._held_after_push`)
    _hold_after_push: list[tuple[_Cut, str]] = field(default_factory=list, repr=False)
    #: a pushed result (its id, since when) that skipped ids, fed after them
    #: (:class:`ResultsSkipped`): the enable's result stays owed until it is in
    _pending_push: int | None = field(default=None, repr=False)
    _pending_at: float = field(default=0.0, repr=False)
    #: the controller asked for its newest result (:class:`CheckNewest`) as the owed
    #: enable's window ended: since when, and that enable's count; it stays owed until the
    #: answer (:class:`NewestChecked`) or CHECK_WAIT_S
    _checking: tuple[float, int] | None = field(default=None, repr=False)
    #: the check running was asked with the tool on (:data:`CHECK_ON_S`): it ends no enable
    #: and holds nothing, and when the last such check was asked
    _checking_on: bool = field(default=False, repr=False)
    #: the gaps (first, last id) such a check told: whether they hold the enable on now is
    #: decided at the check's end (:meth:`LostRules._gaps_on_check_decided`)
    _gaps_on_check: list[tuple[int, int]] = field(default_factory=list, repr=False)
    _checked_on_at: float = field(default=float("-inf"), repr=False)
    #: bolts whose NOK came fetched while a pushed result was pending: counted, the NOK
    #: policy waits for the pushed one (bolt -> its pset)
    _nok_owed: dict[str, int | None] = field(default_factory=dict, repr=False)
    #: of those, the bolts whose NOKs so counted reached their max_nok -> the count then:
    #: locked at that count when the pushed one is a NOK too (a NOK made after it, the tool
    #: still on, the station not knowing, is said as such: :meth:`NokRules._after_nok`)
    _lock_due: dict[str, int] = field(default_factory=dict, repr=False)
    #: the tool enables so far (each EnableTool), and the last result judged: its id, the
    #: enable count then, the tool left on (the order of results proves under which enable
    #: a result fetched late was made: :meth:`ResultRules._made_under`)
    _enable_serial: int = field(default=0, repr=False)
    #: when the tool last went off (never forgotten), and that time as the latest enable
    #: came: a rundown begun before a disable took effect ends after it was sent
    _last_off_at: float | None = field(default=None, repr=False)
    _off_before_enable: float | None = field(default=None, repr=False)
    #: the bolt (vin, bolt) of the latest enable, and whether the one before it was that bolt
    _last_enabled_bolt: tuple[str | None, str] | None = field(default=None, repr=False)
    _same_bolt_before: bool = field(default=False, repr=False)
    _judged: tuple[int, int, bool] | None = field(default=None, repr=False)
    #: the enable whose window's check found nothing made since the last result judged (a
    #: result after it is the next enable's by the order of ids)
    _checked_clear: int | None = field(default=None, repr=False)
    #: the gaps told (first id, last id, the enables so far then), the latest last: their
    #: ids were made before what revealed them, so before any enable since (a review: one
    #: the controller gave after all was recorded to the bolt of its pset enabled since)
    _gaps_told: list[tuple[int, int, int]] = field(default_factory=list, repr=False)
    #: a link cut whose catch-up did not end complete, the controller's newest not said (its
    #: bolt held): its enable, and the
    #: newest id judged then; until a later id is judged, a result pushed without its own
    #: time may be the cut's rundown sent late (:meth:`LostRules._sent_late_from_cut`)
    _cut_unsettled: tuple[Selection, int | None] | None = field(default=None, repr=False)
    #: a link cut whose rundown a fetched result proved (that cut, and the result's id), until
    #: its catch-up ends: the tool, still enabled on the controller during the cut, may have
    #: run again; a rundown of its pset fetched after it may be its bolt's
    #: (:meth:`ResultRules._ran_again_after_cut`)
    #: (and, restored at a start, the time its rundown was stored: one made later is not the
    #: cut's; None: this station's own catch-up)
    _cut_closed: tuple[_Cut, int, float | None] | None = field(default=None, repr=False)
    #: that watch held its bolt already (once: its later rundowns are said, not held again)
    _cut_watch_held: bool = field(default=False, repr=False)
    #: holds decided for a vehicle not loaded at the station (stored, and said), until the
    #: next vehicle loads: that load's read of the database may have come before the hold
    #: was stored (a reviewer: a restart's catch-up held a bolt as its vehicle was loading)
    _held_away: dict[tuple[str, str], tuple[str, Selection]] = field(default_factory=dict,
                                                                      repr=False)
    _judged_at: float = field(default=float("-inf"), repr=False)   # when it came
    # the station's start or the controller's last fault: a result fetched afterwards was
    # made before it, so never under an enable that came later
    _link_lost_at: float = field(default=float("-inf"), repr=False)
    #: when the controller's link came back last (-inf: not since the station started)
    _link_back_at: float = field(default=float("-inf"), repr=False)
    # tightening id -> what the result said (a resent copy says the same; a controller whose
    # ids started again says something else under the same id, and is not a copy)
    _recorded: dict[int, object] = field(default_factory=dict, repr=False)
    # unreadable messages taken (MID, the text after the header): one sent again is a copy
    # -> the bolt it was held against (None: none)
    _unreadable_seen: dict[tuple[int, str], str | None] = field(default_factory=dict,
                                                                 repr=False)
    # the newest tightening id pushed (read), and the unreadable messages without an id that
    # held a bolt, each with the ids read before and after it (unread.py ``_UnreadGap``): a
    # result fetched for the one id between is that message, read
    _last_pushed: int | None = field(default=None, repr=False)
    _unread_gaps: list[Any] = field(default_factory=list, repr=False)
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
    #: VINs reopened for rework since this core started, not at the station since
    _reopened: set[str] = field(default_factory=set, repr=False)
    #: the results recorded (a Record) whose Written has not come yet, per (vin, bolt): on
    #: their way to the database, or kept by the shell while it refuses writes
    _flying: dict[tuple[str, str], int] = field(default_factory=dict, repr=False)
    #: vehicles closed with results still due (:meth:`_results_due`) -> those bolts
    _closing: dict[str, set[str]] = field(default_factory=dict, repr=False)
    #: the models of the station's bolt tables (None: not told, teach start not checked)
    models: frozenset[str] | None = None
    # bolts that get their loosen pset next (a NOK under ``loosen``, a loosen command), and
    # those whose last rundown is a NOK tightening (a loosen command may undo them)
    _loosen: set[str] = field(default_factory=set, repr=False)
    _nok_last: set[str] = field(default_factory=set, repr=False)
    # held bolts whose result came under their loosen pset -> that pset (None: not known):
    # an outcome entered for one is a loosening's, never a tightening's
    _held_loosening: dict[str, int | None] = field(default_factory=dict, repr=False)
    #: the loaded vehicle's bolts with a rundown (a tightening or a loosening recorded), those
    #: loosened last (OK: the tightening pset goes next), and those released from a hold, not
    #: run down since (their result not known: the operator checks the controller first)
    _ran: set[str] = field(default_factory=set, repr=False)
    _loosened: set[str] = field(default_factory=set, repr=False)
    _check_first: set[str] = field(default_factory=set, repr=False)
    #: bolts a person's loosen command ordered loosened since their last rundown: the report
    #: says "loosen first", not "ending NOK", though their NOK row stands
    _ordered_loosen: set[str] = field(default_factory=set, repr=False)
    #: each bolt as last published (:class:`BoltsChanged`, or the vehicle's opening)
    _shown: dict[str, BoltView] = field(default_factory=dict, repr=False)
    _shown_key: tuple[object, ...] = field(default=(), repr=False)
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

    def status(self) -> CoreStatus:
        """A copy of the station's state as decided (see :class:`CoreStatus`)."""
        return CoreStatus(self.state, self.reason,
                          MappingProxyType({d: r for d, (_, r) in self.faults.items()}),
                          self.vin, self.bolt, self.tool_on, self.operator,
                          None if self.trust is None
                          else MappingProxyType(self.trust.untrusted()),
                          self.model,
                          frozenset(() if self.matcher is None else self.matcher.locked),
                          frozenset(() if self.matcher is None else self.matcher.held),
                          self._selection is not None and self._selection.loosen,
                          MappingProxyType({d: i.words
                                            for d, i in self.identifications.items()}),
                          self.line,
                          MappingProxyType(dict(self.identifications)),
                          frozenset(() if self.matcher is None else self.matcher.done),
                          frozenset(() if self.matcher is None else self.matcher.skipped),
                          MappingProxyType({d: str(k) for d, (k, _) in self.faults.items()}),
                          self.operator_required, self._enable_serial,
                          None if self._checking is None else self._checking[1],
                          # as last published: every input ends with their change
                          tuple(self._shown.values()))

    def bolt_views(self) -> tuple[BoltView, ...]:
        """The loaded vehicle's bolts as the core holds them now, in the bolt table's order
        (none loaded: empty)."""
        if self.matcher is None:
            return ()
        return tuple(self._bolt_view(k) for k in self._specs)

    def _bolt_view(self, k: str) -> BoltView:
        """Bolt ``k`` of the loaded vehicle as the core holds it: skipped (refused as such),
        to be loosened first, else its last rundown's status (OK, NOK, loosened) or to do;
        with its lock, its hold, what the report counts (its last rundown a NOK, a rundown at
        all) and whether it is to be checked on the controller first."""
        m, b = self.matcher, self._specs[k]
        assert m is not None  # noqa: S101 - a vehicle is loaded
        loosen = k in self._loosen
        status = SKIPPED if k in m.skipped else TO_LOOSEN if loosen else OK if k in m.done \
            else NOK if k in self._nok_last else LOOSENED if k in self._loosened else PENDING
        return BoltView(k, *b.position, pset=b.pset, order=b.order, batch=b.batch,
                        status=status, ran=k in self._ran,
                        last_nok=k in self._nok_last and k not in self._ordered_loosen,
                        check_first=k in self._check_first and k not in m.skipped,
                        loosen_pset=self._nok_rule(k).loosen_pset if loosen else None,
                        locked=m.locked.get(k), held=m.held.get(k))

    def _bolts_changed(self, t: float) -> list[Action]:
        """The bolts whose state changed since last published, published (none: nothing)."""
        if self.matcher is None or self.vin is None:
            return []
        key = self._bolts_key()
        if key == self._shown_key:   # (most inputs, every localization: nothing of them)
            return []
        self._shown_key = key
        now = self.bolt_views()
        changed = tuple(v for v in now if self._shown.get(v.bolt) != v)
        self._shown = {v.bolt: v for v in now}
        return [Publish(BoltsChanged(self.vin, changed, t=t))] if changed else []

    def _bolts_key(self) -> tuple[object, ...]:
        """What the bolts' states are made of (:meth:`_bolt_view`), cheap to compare: the
        same, no bolt changed."""
        m = self.matcher
        assert m is not None  # noqa: S101 - a vehicle is loaded
        return (self.vin, frozenset(m.done), tuple(m.skipped), tuple(m.locked.items()),
                tuple(m.held.items()), frozenset(self._loosen), frozenset(self._nok_last),
                frozenset(self._ran), frozenset(self._loosened), frozenset(self._check_first),
                frozenset(self._ordered_loosen))

    def _judge(self, tid: int, mine: bool, t: float) -> None:
        """Result ``tid`` (read, or its id picked out of an unreadable one) judged at ``t``:
        where it is the newest, the order of ids goes by it: during which enable (``mine``:
        the enable owed now; else none known), the tool left on or off.  An older id judged
        later, a catch-up's or a copy's, says nothing of the order (a reviewer)."""
        if self._judged is not None and tid <= self._judged[0]:
            return
        self._judged = (tid, self._enable_serial if mine else -1, self.tool_on)
        # (the tool left on after it, its enable's later rundowns are in a gap after it: from
        # that enable on; a reviewer)
        self._judged_at = self._enabled_at if self.tool_on and self._enabled_at is not None \
            else t

    def _ran_once(self, bolt: str, loosening: bool, ok: bool) -> None:
        """A rundown of ``bolt`` recorded (a tightening or a loosening, measured or entered):
        its result is known (no check first), and it is loosened last or not."""
        self._ran.add(bolt)
        self._check_first.discard(bolt)
        self._ordered_loosen.discard(bolt)
        if loosening and ok:
            self._loosened.add(bolt)
        else:
            self._loosened.discard(bolt)

    @property
    def selection(self) -> Selection | None:
        return self._selection

    def resume(self, owed: Owed) -> None:
        """Take over what the last station owed (before :class:`Started`): its result, within
        the late-result window, is recorded to the bolt the tool was enabled for; and, as
        after a link cut during that enable (the controller's link was closed and opened
        again), one fetched after it is placed by the controller's data, the tool kept off
        until the catch-up has ended it."""
        if owed.cut_rundown is not None:
            # its result in already, made during a link cut: the catch-up that fetched it
            # may have been cut short by the stop (:meth:`ResultRules._ran_again_after_cut`)
            tid, stored = owed.cut_rundown
            at = owed.enabled_at if owed.enabled_at is not None else owed.off_at
            self._cut_closed = (_Cut(owed.selection, at, stored), tid, stored)
            self._cut_watch_held = False
            return
        if owed.in_window:
            self._enabled, self._off_at = owed.selection, owed.off_at
        if owed.enabled_at is not None:
            self._cut = _Cut(owed.selection, owed.enabled_at, owed.off_at)

    def allowed(self) -> tuple[str, ...]:
        """The bolts the sequence allows now (not done, skipped, locked, held or blocked)."""
        m = self.matcher
        if m is None:
            return ()
        return tuple(b for b in m.bolts if b not in m.done and b not in m.skipped
                     and b not in m.locked and b not in m.held and m.why_blocked(b) is None)

    def _checking_owed(self) -> bool:
        """A check of the controller's newest result runs for the enable owed now (none came
        since it was asked: :class:`CheckNewest`)."""
        return self._checking is not None and self._checking[1] == self._enable_serial

    def _checked_enable(self) -> Selection | None:
        """The enable owed now whose check of the controller's newest runs (no tool went on
        since: its bolt, selected again, is still open), else None."""
        return self._enabled if self._checking_owed() else None

    def _result_owed(self, t: float) -> bool:
        """The tool is on, or went off less than the late-result window before ``t``: its
        enable's result may still come."""
        return self.tool_on or self._pending_push is not None or (
            self._off_at is not None and t - self._off_at < self.late_result_s)

    def _results_due(self) -> set[tuple[str, str]]:
        """The bolts (vin, bolt) whose result is still due to their records: one may still
        come from the controller (the enable still owed: the tool on, its late-result
        window, or its check of the controller's newest, not over yet, its end decided at the
        next tick; a link cut's enable, the catch-up settles it), or one taken is not in the
        database yet (a database outage keeps it in memory until it is back)."""
        due = {k for k, n in self._flying.items() if n}
        if self._enabled is not None and self._enabled.vin:
            due.add((self._enabled.vin, self._enabled.bolt))
        if self._cut is not None and self._cut.selection.vin:
            due.add((self._cut.selection.vin, self._cut.selection.bolt))
        return due

    def _hold(self, t: float, bolt: str, note: str, said: Notice | None = None,
              under: Selection | None = None) -> list[Action]:
        """``bolt`` is refused until a supervisor releases it: its result is not known
        (``said``: the notice, where it is not a result that could not be read).  ``under``:
        the selection the result came under; where it was the bolt's loosen pset, the hold
        is a loosening's (its note says so, and an outcome entered for it is one)."""
        loosening = under is not None and under.loosen
        note = self._held(bolt, note, loosening, under.pset if under is not None else None)
        self._check_first.discard(bolt)   # held again: its own words say so
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self.matcher.reset()
        return [Publish(BoltLocked(bolt, 0, held=note, t=t)),
                Publish(said or Notice(Said.HELD, bolt=bolt, note=note, t=t))]

    def _held(self, bolt: str, note: str, loosening: bool, pset: int | None) -> str:
        """``bolt`` held with ``note`` (which result); ``loosening``: that result came under
        its loosen pset ``pset`` (None: not known), the note says so and an outcome entered
        for it is a loosening's.  The note as held."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        if loosening:
            self._held_loosening[bolt] = pset
            note = loosening_note(note, pset)
        else:
            self._held_loosening.pop(bolt, None)
        self.matcher.held[bolt] = note
        return note

    def _unanswered_before(self, sel: Selection) -> bool:
        """The tool goes on for ``sel``: the enable before it, where its result never came
        (its late-result window ended, the link up), is remembered as unanswered, so that a
        result fetched later because its push was lost is checked against it (a quality
        trial: stored unattributed, its bolt open and tightened twice); the tool on for that
        bolt again forgets it (what is made now is its own) for results fetched, but keeps
        it, and that bolt's enable still owed, for a gap told before this enable's result
        (``_again``: an independent tester's trial, the bolt run down twice, the first
        rundown's push lost and not given, closed as one OK)."""
        prev = self._enabled
        if prev is not None and (prev.vin, prev.bolt) == (sel.vin, sel.bolt) \
                and self._cut is None and self._off_at is not None \
                and self._enabled_at is not None and self._enabled_at > self._link_lost_at:
            # (its window still running, its tool off: its rundown's push may be lost too)
            self._again = [*self._again, _Cut(prev, self._enabled_at,
                                              self._off_at + self.late_result_s)]
        self._answered_bolt(sel.vin, sel.bolt, again=True)
        return prev is not None and (prev.vin, prev.bolt) != (sel.vin, sel.bolt) \
            and self._unanswered_after()

    def _unanswered_after(self) -> bool:
        """The enable owed a result (``_enabled``, its tool off) gets none in its window:
        remembered as unanswered (:meth:`_unanswered_before`) where the link stayed up from
        its enable on (a link cut's enable is the catch-up's to settle).  The bolt's earlier
        unanswered enables, kept in ``_again`` since its tool went on again, stay unanswered
        beside it: a result fetched later may be the rundown of either, and only each one's
        own span places it (a review: the earlier one dropped, a result made under it held
        nothing, the bolt left open)."""
        if self._enabled is not None and self._cut is None and self._off_at is not None \
                and self._enabled_at is not None and self._enabled_at > self._link_lost_at:
            key = (self._enabled.vin, self._enabled.bolt)
            earlier = [u for u in self._again if (u.selection.vin, u.selection.bolt) == key]
            self._answered_bolt(*key)
            self._unanswered = [*self._unanswered, *earlier, _Cut(
                self._enabled, self._enabled_at, self._off_at + self.late_result_s)][-UNANSWERED:]
            return True
        return False

    def _answered_bolt(self, vin: str, bolt: str, again: bool = False) -> None:
        """``bolt``'s (of vehicle ``vin``) unanswered enables no longer count: its own result
        came, it is held, or (``again``) the tool is on for it again: what it makes now is
        its own, and they count only for a gap told before its result (moved to
        ``_again``).  By vehicle too: the next car's bolt of the same name answers nothing
        of the last's."""
        key = (vin, bolt)
        if again:
            self._again = [*self._again, *(u for u in self._unanswered
                                           if (u.selection.vin, u.selection.bolt) == key)]
            self._again = self._again[-UNANSWERED:]
        else:
            self._again = [u for u in self._again
                           if (u.selection.vin, u.selection.bolt) != key]
        self._unanswered = [u for u in self._unanswered
                            if (u.selection.vin, u.selection.bolt) != key]
        self._cleared = [u for u in self._cleared if (u.selection.vin, u.selection.bolt) != key]

    def _unhold(self, bolt: str) -> str | None:
        """``bolt``'s hold ends (released, skipped, its outcome entered): its note, None
        where it was not held."""
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self._held_loosening.pop(bolt, None)
        note = self.matcher.held.pop(bolt, None)
        if note is not None and self.state is State.TRACKING and self.reason.bolt == bolt \
                and self.reason.kind in (Because.UNREADABLE_HELD, Because.NOT_TAKEN_HELD,
                                         Because.UNKNOWN_HELD):
            # the state's reason said it was held: no longer (`stationd status` kept saying
            # so until the next change: a supervisor's trial)
            self._to(State.TRACKING, StateReason(Because.TRACKING))
        return note

    def _loosen_unknown(self, bolt: str) -> None:
        """A released hold's bolt (its result not known: it may be a NOK) gets its loosen
        pset first where its NOK rule loosens: a NOK joint is never tightened again without
        its loosening, and an OK one loosened and tightened again is a rework, not a fault
        (a supervisor's trial: three held NOK joints, released, tightened again at once).
        Not one done: held after its OK was recorded (a gap's ids may be an earlier rundown
        of it: :meth:`LostRules._gap_again`), it is released as that OK says (its loosen
        pset would never be selected; a loosen command reworks it)."""
        if self.matcher is not None and bolt in self.matcher.done:
            return
        rule = self._nok_rule(bolt)
        if rule.strategy is Strategy.LOOSEN and rule.loosen_pset is not None:
            self._loosen.add(bolt)

    def _nok_rule(self, bolt: str, pset: int | None = None) -> NokRule:
        """``bolt``'s NOK rule, by its pset in the vehicle's bolt table (``pset``: the one
        sent, where the bolt is not in it)."""
        return self.nok.rule(bolt, self._specs[bolt].pset if bolt in self._specs else pset)

    def _lock(self, t: float, bolt: str, n: int) -> list[Action]:
        assert self.matcher is not None  # noqa: S101 - a vehicle is loaded
        self.matcher.locked[bolt] = n
        self._check_first.discard(bolt)
        noted: list[Action] = [] if self.vin is None else [NoteLock(self.vin, bolt, n, t)]
        return [*noted, Publish(BoltLocked(bolt, n, t=t)),
                Publish(Notice(Said.LOCKED, bolt=bolt, count=n, t=t))]

    def _fault_notes(self) -> tuple[tuple[str, FaultWhy], ...]:
        """Each device in fault with why (its own words, or the station's own fault), in the
        order they failed."""
        return tuple((d, r) for d, (_, r) in self.faults.items())

    def _fault_reason(self) -> StateReason:
        return StateReason(Because.FAULT, faults=self._fault_notes())

    def _fault_refusal(self) -> Reason:
        """Why a command or a teach point waits: the devices in fault."""
        return Reason(Why.DEVICE_FAULT, faults=self._fault_notes())

    def _tool_off(self, t: float, reason: StateReason,
                  why: Reason | None = None) -> list[Action]:
        was = self.tool_on
        self.tool_on = False
        if was:
            self._off_at = self._last_off_at = t
        return _disable(reason, self.bolt, why, t=t)

    def _drop(self, t: float, state: State, reason: StateReason,
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
        """The vehicle left.  What its controller still owes is kept: the enable whose
        result may still come (recorded to its bolt of that vehicle within its window), a
        link cut's enable (the catch-up settles it), the enables left unanswered (a result
        fetched later, its push lost, is held against them): a supervisor's trial found the
        last bolt's result, its push lost, stored under the next vehicle and that bolt
        neither recorded nor held."""
        self.vin, self.model, self.matcher, self._specs = None, None, None, {}
        self._loosen, self._nok_last, self._nok_owed = set(), set(), {}
        self._lock_due = {}
        self._ran, self._loosened, self._check_first, self._shown = set(), set(), set(), {}
        self._ordered_loosen = set()
        self._shown_key = ()
        self._loading = False
        self._vin_for, self._vin_pending, self._last_refusal = None, False, None

    def _to(self, state: State, reason: StateReason) -> None:
        """The one place the state changes: with any device in fault the state is FAULT, and
        in teach mode TEACHING, so no rule elsewhere can leave them by accident."""
        if self.faults:
            state, reason = State.FAULT, self._fault_reason()
        elif self._teach is not None:
            state, reason = State.TEACHING, self._teach.reason()
        self.state, self.reason = state, reason
