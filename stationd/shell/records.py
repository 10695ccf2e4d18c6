"""The station's persistence policy, in one place: what is written when, what is kept while
the database refuses, and what the next station is owed.

Why apart from the daemon: these are rules about records, not I/O and timing.  A result is
written before the controller is told it is stored; a result the database refuses is kept
(in memory, journaled in full) and written first when the database is back; the SQLite file
is checked before each write (a file removed or replaced under the daemon would swallow
acknowledged results); the tool enable is noted before the tool is enabled, so a reload, a
restart or a kill still records its result to that bolt.  Every method here blocks (the daemon
calls them from its executor threads) and raises what the database raises.
"""

from __future__ import annotations

import logging
import re
import shutil
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path
from typing import Any, TypeVar

import cv2

from db.cameras import Replaced, pin_cameras
from db.checks import record_check
from db.counting import counted
from db.curves import link_curves, store_curve
from db.enables import CutRundown, OwedEnable
from db.entered import record_entered
from db.errors import DatabaseError, DataError, DbError, NotFoundError, VehicleClosedError
from db.holds import ENDS_A_HOLD
from db.kinds import (
    LOCK,
    LOCK_SOURCE,
    LOCK_USER,
    LOOSENING,
    MISSING,
    NOK,
    OK,
    REFUSED,
    SKIPPED,
    TIGHTENING,
    TO_LOOSEN,
)
from db.location import sqlite_path, unwritable_file
from db.report import VehicleReport
from db.repository import Repository
from drivers.errors import DeviceError, DriverError
from drivers.keeper import one_line
from drivers.wrench.base import TighteningResult
from drivers.wrench.openprotocol.curve import Curve
from stationd.boltfile import import_bolts
from stationd.config import StationConfig
from stationd.errors import StationError
from stationd.localize import Localization
from stationd.reasons import Reason, Skip, SkipKind, Why
from stationd.station.actions import (
    LoadVehicle,
    NoteLock,
    Owed,
    Record,
    RecordCommand,
    RecordRefusal,
    Selection,
    SettleClosing,
    StoreControllerEvent,
    StoreCutUnknown,
    StoreUnattributed,
    StoreUnreadable,
)
from stationd.station.commands import (
    KIND,
    EnterOutcome,
    ReopenVehicle,
    SignIn,
    SignOut,
    TeachStart,
)
from stationd.station.inputs import (
    LoadedBolt,
    ResultCopy,
    ResultIn,
    UnreadableIn,
    VehicleEnded,
    VehicleLoaded,
    VehicleRejected,
)
from stationd.station.results import type_code
from stationd.station.trust import RecordCheck, summary
from stationd.words import (
    closed_after_outage,
    command_words,
    comment_words,
    reason_words,
    sent_again_words,
    stored_what,
    unattributed_words,
)

log = logging.getLogger("stationd")
T = TypeVar("T")


class FileChange(StrEnum):
    """How the SQLite file the daemon opened is no longer there as it opened it (its words
    after "the database file PATH was")."""

    REMOVED = "removed"
    REPLACED = "replaced by another file"
#: what a device, the database or the station's own data raise: a fault, never an exit
STATION_FAULTS: tuple[type[Exception], ...] = (StationError, DbError, DriverError)


@dataclass
class Unsaved:
    """A result the database has not taken yet, with what its record needs."""

    record: Record
    images: list[str]
    #: when the station took the result (the record's ``t``, the input's time the core
    #: decided on): the rundown's ``result_at``, also where it is stored late
    result_at: datetime
    parameters_id: int | None = None
    enable_id: int | None = None     # the tool enable this result settles
    #: written, and found stored already: a copy the controller sent again (the core says
    #: so and publishes no new result); then the stored record's vehicle and bolt
    again: bool = False
    stored_vin: str | None = None
    stored_bolt: str | None = None

    def describe(self) -> str:
        """One journal line with every value of the record (the only copy while unsaved)."""
        a, r = self.record, self.record.result
        return (f"VIN {a.vin} bolt {a.bolt} tightening {r.tightening_id} "
                f"{'OK' if r.ok else 'NOK'} torque {float(r.torque_nm):.2f} Nm angle "
                f"{float(r.angle_deg):.1f} deg pset {r.pset} at {self.result_at.isoformat()}"
                + (f" operator {a.selection.operator}" if a.selection is not None
                   and a.selection.operator else ""))


class Records:
    """The station's database and its policy: ``open()``, then the daemon's calls."""

    def __init__(self, cfg: StationConfig) -> None:
        self.cfg = cfg
        #: where its lines go: the station's journal (the demo's stations each with their
        #: name first: :meth:`stationd.shell.effects.Effects.label`)
        self.log: logging.Logger | logging.LoggerAdapter[logging.Logger] = log
        self.repo: Repository | None = None
        # the SQLite file opened and its identity (device, inode)
        self._db_file: tuple[Path, tuple[int, int]] | None = None
        # results the database refused: kept, written by its keeper before it is called back
        self._unsaved: list[Unsaved] = []
        self._saved_late: list[Unsaved] = []
        # the NOK policy's locks the database refused: written first when it is back
        self._locks_owed: list[NoteLock] = []
        self._lock = threading.Lock()
        self._images_room = True   # the images' disk had room at the last save (said once)
        # the tool enable the station owes a result to (its selection and its row on disk)
        self._enable: tuple[Selection, int] | None = None
        self._enable_off = False          # its tool-off time is on disk

    def open(self) -> Repository:
        """Open (and migrate) the database, prove it takes writes (:meth:`prove_writable`)
        and import the bolt table.  Why the proof: an SQLite file the daemon's user may not
        write (a copy of root's put in its place) opens read-only without a word; the
        station ran, every write failed, and a chown needed a second reload."""
        try:
            repo = Repository.open(self.cfg.database_url)
        except DbError as exc:   # a migration is a write: said as one the file refuses
            raise self._refused(exc) from None
        self.prove_writable(repo)   # closed again if it refuses: the next open is anew
        self.repo = repo
        self._db_file = _sqlite_file(self.cfg.database_url)
        if self.cfg.bolts_path is not None:
            r = import_bolts(self.repo, self.cfg.bolts_path,
                             tolerance_mm=self.cfg.matching.tolerance_mm)
            # the models' and psets' own changes too: a model's code swapped changes which
            # model the lift's code loads, and read "0 changed" (an engineer's trial)
            others = "".join(f"; {label}: {', '.join(names)}" for label, names in (
                ("models added", r.models_added), ("models changed", r.models_changed),
                ("models removed", r.models_removed), ("psets changed", r.psets_changed))
                if names)
            self.log.info("bolt table %s: %d added, %d changed, %d unchanged, %d removed, "
                          "%d new parameter versions%s", self.cfg.bolts_path, len(r.added),
                          len(r.changed), len(r.unchanged), len(r.removed), len(r.new_versions),
                          others)
            if r.removed:   # a table cut short that still reads removes bolts: said loudly
                # (the vehicle at the station too: a reload opens it again with the table;
                # a new user's trial read "on new vehicles" and saw it gone from the one there)
                self.log.warning("bolt table %s: %s removed (%s%s): no longer tightened, on the "
                                 "vehicle at the station too", self.cfg.bolts_path,
                                 counted(len(r.removed), "bolt"),
                                 ", ".join(r.removed[:5]), ", ..." if len(r.removed) > 5 else "")
            # the vehicle at the station read once for both words on it
            here = self._at_station(self.repo) if r.removed or r.changed or r.added else None
            if here is not None:
                self._removed_open(here, r.removed)
                self._changed_open(here, r.changed, r.added)
        return self.repo

    def pin_cameras(self, pair: str, calibration: str,
                    serials: Mapping[str, str | None]) -> list[Replaced]:
        """Each side's camera against the one ``pair``'s calibration was first used with
        (pinned now where none is): the sides whose camera was replaced (``db.cameras``).
        ``DatabaseError`` while the database is not open or fails: not checked."""
        if self.repo is None:
            raise DatabaseError("the database is not open")
        return pin_cameras(self.repo, pair, calibration, serials)

    def _changed_open(self, report: VehicleReport, changed: Sequence[str],
                      added: Sequence[str]) -> None:
        """Bolts the table changed or added that the vehicle at the station has not done:
        said, naming the vehicle.  Why: a reload mid-vehicle goes on with it under the new
        table (a changed bolt tightened to its new parameters, an added one more to do)
        while the journal said only "1 added, 1 changed" (a process engineer's trial); a
        removal names the vehicle at the station (:meth:`_removed_open`)."""
        vin, model = report.vehicle.vin, report.vehicle.model
        open_ = {b.bolt_id for b in report.bolts if b.status not in (OK, SKIPPED)}
        # "MODEL/BOLT", a model's name may hold a "/" itself (the name rule): its own prefix
        prefix = f"{model}/"
        news = [f"{n[len(prefix):]} {how}"
                for names, how in ((changed, "changed"), (added, "added"))
                for n in names if n.startswith(prefix) and n[len(prefix):] in open_]
        if news:   # at most ten named (a table of 50 bolts reordered changes each one)
            self.log.warning("vehicle %s at the station (%s) goes on under the new table: %s "
                             "(its bolts done keep the parameters they were tightened with)",
                             vin, model, ", ".join(news[:10]) + (
                                 f" and {len(news) - 10} more" if len(news) > 10 else ""))

    def _removed_open(self, report: VehicleReport, removed: Sequence[str]) -> None:
        """Bolts the table removed that the vehicle at the station ends NOK (or locked, or
        to be loosened) or holds: said, each with what stays.  Why: the station counts them
        no more (its bolts are the table's) while the vehicle's report keeps their NOKs and
        the lock with no release (an engineer's trial: a locked bolt removed, its lock gone
        from the screen without a word, the report still saying it)."""
        vin, model = report.vehicle.vin, report.vehicle.model
        held = dict(report.held)
        open_ = [b.bolt_id + (" held" if b.bolt_id in held else " ending NOK"
                              if b.status == NOK else " to be loosened")
                 for b in report.bolts if f"{model}/{b.bolt_id}" in removed
                 and (b.status in (NOK, TO_LOOSEN) or b.bolt_id in held)]
        if open_:
            self.log.warning("vehicle %s at the station: removed from the table while not "
                             "done: %s; the vehicle's report keeps each one's records and "
                             "counts it, the station no more (put a bolt back to work it, "
                             "or skip it with a reason before removing it)", vin,
                             ", ".join(open_))

    def _at_station(self, repo: Repository) -> VehicleReport | None:
        """The report of the vehicle at the station, with its holds, for a reload's words
        on it; None without one, or when it cannot be read (said: a word the more, never the
        database's opening)."""
        try:
            vin = repo.at_station()
            return None if vin is None else repo.vehicle_report(vin, held=True)
        except STATION_FAULTS as exc:
            self.log.warning("the vehicle at the station not read: %s", one_line(exc))
            return None

    def _repo(self) -> Repository:
        if self.repo is None:
            raise DeviceError("not open", device="database")
        return self.repo

    def _writer(self) -> Repository:
        """The repository for a write, the SQLite file checked first (:meth:`check_file`): a
        command, a vehicle's opening or a hold written into a file removed under the daemon
        would be accepted and gone, as a result would."""
        repo = self._repo()
        self.check_file()
        return repo

    # -- what the last station owed -------------------------------------------------------
    def owed(self, late_result_s: float, cut: bool = True) -> Owed | None:
        """The tool enable the last station (a reload, a restart, a kill) left without its
        result: within its late-result window (from its tool-off time, or now when it
        stopped with the tool on) a result of its pset pushed now is its own; and, with
        ``cut`` (a controller that keeps its results to fetch), the new station takes it as a
        link cut during it (its result, made meanwhile, fetched and proved; its tool kept off
        until then).  None where neither applies."""
        enables = self._repo().enables
        owed = enables.owed()
        if owed is None:
            return self._cut_rundown(enables.cut_rundown()) if cut else None
        now = time.time()
        off = owed.off_at.timestamp() if owed.off_at is not None else now
        in_window = now - off < late_result_s
        if not in_window and not cut:
            return None
        sel = _selection(owed)
        self._enable, self._enable_off = (sel, owed.id), owed.off_at is not None
        if in_window:
            self.log.info("the tool was enabled for bolt %s of %s (pset %s) when the last station "
                          "stopped: its result within %.0f s is recorded to it", owed.bolt,
                          owed.vin, owed.pset, late_result_s - (now - off))
        else:
            self.log.info("the tool was enabled for bolt %s of %s (pset %s), its result not "
                          "recorded: the controller's results since are fetched for it", owed.bolt,
                          owed.vin, owed.pset)
        return Owed(sel, off, owed.enabled_at.timestamp() if cut else None, in_window)

    def _cut_rundown(self, done: CutRundown | None) -> Owed | None:
        """The last enable, answered by a rundown made during a link cut (``done``): the
        catch-up that fetched it may have been cut short by the stop (a kill, a reload
        between two fetches), so the new station's catch-up holds its bolt for a rundown it
        fetches made by then (a re-check with an independent controller: a NOK then an OK
        during a cut, killed between their fetches, left the bolt ending NOK, its tool on
        again).  None where there is none."""
        if done is None:
            return None
        en = done.enable
        self.log.info("the last rundown recorded (tightening %d, bolt %s of %s) was made "
                      "during a link cut, and its catch-up may have been cut short by the "
                      "stop: the tool stays off until the controller's results are fetched; "
                      "one it made before that rundown was stored holds %s",
                      done.tightening_id, en.bolt, en.vin, en.bolt)
        return Owed(_selection(en), en.enabled_at.timestamp(), en.enabled_at.timestamp(),
                    in_window=False,
                    cut_rundown=(done.tightening_id, done.recorded_at.timestamp()))

    def settle(self, sel: Selection) -> None:
        """The enable for ``sel`` is owed nothing more (:class:`SettleEnable`)."""
        enable = self._settles(sel)
        if enable is not None:
            self._writer().enables.settle(enable)

    def note_enable(self, sel: Selection) -> None:
        """The tool is about to be enabled for ``sel``: noted on disk first."""
        row = self._writer().enables.note(sel.vin, sel.bolt, sel.pset, sel.parameters_id,
                                       _selection_json(sel), datetime.now(UTC))
        self._enable, self._enable_off = (sel, row), False

    def note_off(self) -> None:
        """The owed enable's tool-off time on disk: the next station counts the late-result
        window from it.  Best effort: without it the next station counts from its start."""
        if self._enable is None or self._enable_off or self.repo is None:
            return
        try:
            self.repo.enables.tool_off(self._enable[1], datetime.now(UTC))
            self._enable_off = True
        except STATION_FAULTS as exc:
            self.log.warning("the tool-off time of bolt %s not stored: %s", self._enable[0].bolt,
                             one_line(exc))

    @property
    def owes_off_time(self) -> bool:
        return self._enable is not None and not self._enable_off

    # -- results ---------------------------------------------------------------------------
    def unsaved_result(self, a: Record, loc: Localization | None) -> Unsaved:
        """The record to write for ``a``: the selection's crops saved beside the records,
        and the tool enable it settles (in the record's transaction).  Its ``result_at`` is
        ``a.t``, when the station took the result (the input the core decided on), not this
        call's clock: what the result caused (a lock, :meth:`note_lock`) is dated from the
        same input or a later one, and a rundown stamped here, after the core had decided,
        came out later than the lock it caused (an MES integrator's trial)."""
        r, sel = a.result, a.selection
        images = self.save_images(a.vin, a.bolt, int(r.tightening_id), loc)
        enable = self._settles(sel)
        return Unsaved(a, images, datetime.fromtimestamp(a.t, UTC),
                       sel.parameters_id if sel else None, enable)

    def _settles(self, sel: Selection | None, take: bool = True) -> int | None:
        """The noted tool enable a record answering ``sel`` settles, or None; ``take``: the
        station owes it nothing more from now (else only once the record is written)."""
        if self._enable is None or sel is None or self._enable[0] is not sel:
            return None
        enable = self._enable[1]
        if take:
            self._enable = None
        return enable

    def write(self, u: Unsaved) -> None:
        """One result into the database; raises what the database raises.  ``u.again`` set
        when the database has it already (a copy the controller sent again: nothing written;
        the core says so).  The controller's own time of the result goes with it: what tells
        such a copy from another result under the same id."""
        repo = self._writer()
        a = u.record
        r, sel = a.result, a.selection
        done = repo.record_tightening_once(
            a.vin, a.bolt, ok=bool(r.ok),
            position_mm=list(sel.point_mm) if sel else [0.0, 0.0, 0.0],
            match_distance_mm=sel.distance_mm if sel else 0.0,
            tilt_deg=sel.tilt_deg if sel else 0.0,
            torque_nm=float(r.torque_nm), angle_deg=float(r.angle_deg),
            parameters_id=u.parameters_id,
            tightening_id=int(r.tightening_id),
            sent_at=datetime.fromtimestamp(sel.decided_t, UTC) if sel else None,
            result_at=u.result_at, images=u.images, enable_id=u.enable_id, kind=a.kind,
            params_sent=_loosen_sent(sel.pset) if sel is not None and sel.loosen else None,
            operator=sel.operator if sel is not None else None,
            controller_at=controller_time(r), offline=a.offline)
        u.again = done.again
        if done.again:
            u.stored_vin, u.stored_bolt = done.vin, done.bolt
            return
        rid = done.id
        # the tightening's curves (stored as they came, usually just before) go with it; the
        # record stands whatever happens here (reading finds them by tightening id anyway)
        try:
            link_curves(repo, int(r.tightening_id), rid)
        except STATION_FAULTS as exc:
            self.log.warning("curves of tightening %d not linked: %s", r.tightening_id,
                             one_line(exc))

    def copy_input(self, ev: ResultIn, vin: str | None) -> ResultIn | ResultCopy:
        """``ev`` as the core is to have it: a :class:`ResultCopy` when the database has
        this very result stored already (:meth:`Repository.stored_result`: the same id,
        values and controller time, any vehicle's; without a controller time, of ``vin``,
        the vehicle at the station, or of the enable the station owes), else ``ev``.

        Why before the core: a copy the controller sends again after a reload (stored, its
        acknowledgement lost) met a new core that had not seen it, which attributed it to
        the enable it owes now (another bolt of the same pset): that bolt was taken as done
        or counted a NOK without being tightened.  Asked here, the core attributes no copy.
        Blocking (the executor's, as every read)."""
        r = ev.result
        if r.tightening_id is None:
            return ev
        enable = self._enable
        vins = {v for v in (vin, enable[0].vin if enable is not None else None) if v}
        stored = self._repo().stored_result(
            tightening_id=int(r.tightening_id), torque_nm=float(r.torque_nm),
            angle_deg=float(r.angle_deg), controller_at=controller_time(r), vins=vins)
        if stored is not None:
            return ResultCopy(ev.t, r, stored.vin, stored.bolt, ev)
        # a copy that reads of a message stored unreadable (garbled on the line the first
        # time): that result, held for a person, never the enable owed now
        made = None if ev.made_at is None else datetime.fromtimestamp(ev.made_at, UTC)
        held = self._repo().others.unreadable_of(tightening_id=int(r.tightening_id),
                                                 pset=int(r.pset), at=controller_time(r), made=made)
        return ev if held is None else ResultCopy(ev.t, r, held[0], held[1], ev)

    def unreadable_input(self, ev: UnreadableIn) -> UnreadableIn:
        """``ev`` as the core is to have it: saying where it was stored when the database has
        this very message already (:meth:`db.others.OtherResults.stored_unreadable`: a copy the
        controller sent again, after a reload or a restart), which the core then attributes
        to no bolt.  Blocking (the executor's, as every read)."""
        u = ev.unreadable
        if u.tightening_id is None and u.timestamp is None:
            return ev       # it says nothing of itself: the same text is no proof of a copy
        stored = self._repo().others.stored_unreadable(mid=u.mid, raw=u.raw,
                                                        header_len=u.header_len)
        return ev if stored is None else replace(ev, stored=stored)

    def keep(self, u: Unsaved) -> None:
        """The database refused ``u``: kept until it takes it."""
        with self._lock:
            self._unsaved.append(u)

    def carry(self, unsaved: list[Unsaved], locks: list[NoteLock] | None = None) -> None:
        """Results and locks the last station (a reload) could not write: written first."""
        with self._lock:
            self._unsaved[:0] = unsaved
            self._locks_owed[:0] = locks or []

    def locks_owed(self) -> list[NoteLock]:
        with self._lock:
            return list(self._locks_owed)

    def unsaved(self) -> list[Unsaved]:
        with self._lock:
            return list(self._unsaved)

    def take_saved_late(self) -> list[Unsaved]:
        """The results :meth:`probe` wrote on the database's way back (to publish and
        acknowledge)."""
        with self._lock:
            done, self._saved_late = self._saved_late, []
        return done

    def store_unattributed(self, a: StoreUnattributed) -> None:
        """The result, unless the database has it already (a copy the controller sent
        again: said in the journal, stored once)."""
        r = a.result
        row = self._writer().others.record_unattributed(
            vin=a.vin, controller_vin=str(r.vin or "").strip() or None,
            tightening_id=int(r.tightening_id), pset=int(r.pset), ok=bool(r.ok),
            torque_nm=float(r.torque_nm), angle_deg=float(r.angle_deg),
            result_at=controller_time(r), reason=unattributed_words(a.why),
            result_type=type_code(r))
        if row is None:
            self.log.info("%s", sent_again_words(int(r.tightening_id), None))

    def store_controller_event(self, a: StoreControllerEvent) -> None:
        """The result; the tool enable it answers settled with it, where it does (its bolt
        held for a person: no later result is owed to it)."""
        r = a.result
        enable = self._settles(a.selection, take=False)
        row = self._writer().others.record_controller_event(
            result_type=type_code(r) or 0, what=stored_what(a), vin=a.vin, bolt=a.bolt,
            controller_vin=str(r.vin or "").strip() or None,
            tightening_id=int(r.tightening_id), pset=int(r.pset), ok=bool(r.ok),
            torque_nm=float(r.torque_nm), angle_deg=float(r.angle_deg),
            result_at=controller_time(r), enable_id=enable)
        self._settles(a.selection)
        if row is None:
            self.log.info("%s", sent_again_words(int(r.tightening_id), a.bolt))

    def store_cut_unknown(self, a: StoreCutUnknown) -> None:
        """A bolt held after a link cut left its result unknown (or a result whose push was
        lost may be its own): a controller event of the station's own kind without a result
        (its note, why), the enable settled with it."""
        enable = self._settles(a.selection, take=False)
        self._writer().others.record_controller_event(
            result_type=0, what=a.what, vin=a.vin, bolt=a.bolt, controller_vin=None,
            tightening_id=a.tightening_id, pset=a.selection.pset, ok=None, torque_nm=None,
            angle_deg=None, result_at=None, enable_id=enable, note=a.note)
        self._settles(a.selection)

    def store_unreadable(self, a: StoreUnreadable) -> None:
        """The message whole; the tool enable it answers settled with it (the bolt is held
        for a person now: no later result is owed to it)."""
        u, sel = a.unreadable, a.selection
        enable = self._settles(sel, take=False)
        self._writer().others.record_unreadable(
            mid=u.mid, revision=u.revision, raw=u.raw, error=u.error, vin=a.vin, bolt=a.bolt,
            controller_vin=u.vin.strip() or None, tightening_id=u.tightening_id, pset=u.pset,
            result_at=_aware(u.timestamp),
            enable_id=enable, header_len=u.header_len)
        self._settles(sel)

    # -- vehicles, commands, gaps and curves ---------------------------------------------------
    def load_vehicle(self, a: LoadVehicle) -> VehicleLoaded | VehicleRejected:
        """The vehicle at height, from the database: loaded with its bolts, what is done,
        skipped and NOK so far (a rework resumed after a reload is still one), or rejected
        (unknown model, a closed VIN, another model's VIN)."""
        repo = self._writer()
        gone = repo.left_unseen(a.vin)
        if gone is not None:   # the lowering that closes it was not seen (station down then)
            # a warning where a bolt is not OK, as at any close (an IT administrator's trial:
            # "45 missing" at INFO, a journal read by priority missed it)
            missing, nok = _verdict(gone, ())
            self.log.log(logging.INFO if not missing and not nok else logging.WARNING,
                         "vehicle %s (%s) closed: it left while the station did not see it go; "
                         "%s", gone.vehicle.vin, gone.vehicle.model, gone.counts())
        model = repo.model_for_code(a.model_code)
        if model is None:   # which vehicle, and the codes there are (a line engineer's trial)
            codes = ", ".join(f"{name} {code}" for name, code in repo.model_codes().items()
                              if code is not None) or "none: import a bolt table"
            return VehicleRejected(time.time(), a.vin,
                                   f"unknown vehicle model code {a.model_code} for {a.vin} "
                                   f"(the bolt tables' codes: {codes})")
        try:
            started = repo.start_vehicle(a.vin, model, reopen=a.reopen)
        except DataError as exc:   # a closed VIN back, another model's VIN
            return VehicleRejected(time.time(), a.vin, one_line(exc),
                                   closed=isinstance(exc, VehicleClosedError))
        infos = repo.bolts_for_model(model)
        report = repo.vehicle_report(a.vin)
        since = started.reopened_at or started.started_at
        skipped = repo.ledger.skipped(a.vin, since)
        noks = repo.nok_streaks(a.vin, since)
        locked = repo.ledger.locked(a.vin, since, ENDS_A_HOLD)
        # each with what its result came under; of every pass (a rework ends no hold: its
        # result is still not known)
        holds = repo.holds(a.vin)
        # the report's "missing" is "no rundown yet": on an open vehicle the bolt is to do
        status = {b.bolt_id: b.status for b in report.bolts if b.status != MISSING}
        done = frozenset(k for k, s in status.items() if s is OK)
        specs = {b.bolt_id: LoadedBolt(xyz(b.position), b.parameters.pset, b.order, b.batch,
                                     b.parameters_id, b.parameters) for b in infos}
        self.log.info("vehicle %s (%s) opened%s: %d bolts, %d done", a.vin, model,
                      " for rework" if started.rework else "", len(infos),
                      len(done & specs.keys()))   # (of its bolts now: one removed is not counted)
        # by keyword: held and status are both bolt -> text, and given by position (status
        # in held's place) every bolt done before a reload or a restart came back held.  A
        # skip read back from the command ledger is the person's command, typed as the core
        # decided it then (who and their comment): said as it was before the restart
        return VehicleLoaded(time.time(), a.vin, model, specs, done, started.rework,
                             skipped={b: Skip(SkipKind.COMMAND, user=user, comment=comment)
                                      for b, (user, comment) in skipped.items()},
                             noks=noks, locked=locked, released=repo.released_holds(a.vin),
                             held={b: note for b, (note, _) in holds.items()},
                             status=status,
                             held_under={b: under for b, (_, under) in holds.items()},
                             loosen_nok=frozenset(b.bolt_id for b in report.bolts
                                                  if b.status is NOK and b.kind == LOOSENING))

    def close_vehicle(self, vin: str, after_lift_outage: bool = False,
                      due: tuple[str, ...] = ()) -> VehicleEnded:
        """Close ``vin`` and say its verdict; ``due``: its bolts whose result is still due
        from the controller, neither missing nor NOK (their verdict follows:
        :meth:`settle_closing`)."""
        report = self._writer().close_vehicle(vin)
        # in db report's words (counted and labelled: "missing B01, ..., B50, skipped none,
        # NOK none" gave 45 names and no count)
        # a vehicle leaving with a bolt not OK is a warning: a journal read by priority
        # (journalctl -p warning) missed "50 missing" at INFO (an engineer's trial)
        missing, nok = _verdict(report, due)
        self.log.log(logging.INFO if not missing and not nok and not due else logging.WARNING,
                     "vehicle %s (%s) closed: %s%s%s", vin, report.vehicle.model,
                     report.counts(due), "; its verdict follows the result due" if due else "",
                     closed_after_outage(vin) if after_lift_outage else "")
        # the screens' "not tightened when the vehicle left": skipped ones too
        return VehicleEnded(time.time(), vin, missing, nok, due)

    def settle_closing(self, a: SettleClosing) -> VehicleEnded:
        """The results due as ``a.vin`` closed are settled for ``a.settled`` (recorded to
        that vehicle, or no longer to come): its closing verdict again, from its records,
        each settled bolt's status named."""
        report = self._writer().vehicle_report(a.vin, held=True)
        missing, nok = _verdict(report, a.due)
        status = {b.bolt_id: b.status for b in report.bolts}
        now = ", ".join(f"{b} {str(status.get(b, MISSING)).upper()}" for b in a.settled)
        self.log.log(logging.INFO if not missing and not nok and not a.due else logging.WARNING,
                     "vehicle %s (%s) closing verdict, the result due at its close settled (%s): "
                     "%s", a.vin, report.vehicle.model, now, report.counts(a.due))
        return VehicleEnded(time.time(), a.vin, missing, nok, a.due, a.settled)

    def record_refusal(self, a: RecordRefusal) -> None:
        """A refused command that would have changed a bolt or a vehicle, kept as a
        :data:`db.kinds.REFUSED` command: who, from where, on what, and in its comment what
        it was and why it was refused (``enter-outcome B01 of VIN1: OK 5 Nm, 2 deg
        ('looked'): refused: torque 5 Nm outside 22-28 Nm``)."""
        cmd = a.command
        words = f"{command_words(cmd)}: refused: " \
                f"{reason_words(a.reason)}"
        self._writer().ledger.record_command(
            at=datetime.fromtimestamp(a.t, UTC), user=a.issuer.user, source=a.issuer.source,
            kind=REFUSED, vin=getattr(cmd, "vin", None), bolt=getattr(cmd, "bolt", None),
            comment=words[:500])

    def record_command(self, a: RecordCommand, vin_at_height: str | None) -> Reason | None:
        """An accepted command on disk with its user (a reopen reopens the vehicle in the
        same transaction); None once recorded, else why not (the database's own faults
        raise)."""
        repo, cmd, who = self._writer(), a.command, a.issuer
        at = datetime.fromtimestamp(a.t, UTC)
        vin = getattr(cmd, "vin", None) or (
            vin_at_height if not isinstance(cmd, ReopenVehicle) else None)
        comment = comment_words(cmd)      # the station's idle sign-out: in words here
        if isinstance(cmd, TeachStart):   # the model taught is part of the record
            comment = f"model {cmd.model}" + (f": {comment}" if comment else "")
        if isinstance(cmd, SignOut) and cmd.user is not None and cmd.user != who.user:
            comment = f"{cmd.user} signed out" + (f": {comment}" if comment else "")
        try:
            if isinstance(cmd, ReopenVehicle):
                repo.reopen_vehicle(cmd.vin, at=at, user=who.user, source=who.source,
                                    comment=cmd.comment)
            elif isinstance(cmd, EnterOutcome):   # the command and its rundown, together
                # of the kind the core decided: a held loosening's outcome is a loosening
                record_entered(repo, vin=cmd.vin, bolt=cmd.bolt, ok=cmd.ok,
                               torque_nm=cmd.torque_nm, angle_deg=cmd.angle_deg, at=at,
                               user=who.user, source=who.source, comment=cmd.comment,
                               kind=LOOSENING if cmd.loosening else TIGHTENING,
                               pset=cmd.loosen_pset)
            else:
                repo.ledger.record_command(at=at, user=who.user, source=who.source,
                                           kind=KIND[type(cmd)], vin=vin,
                                           bolt=getattr(cmd, "bolt", None), comment=comment)
        except NotFoundError:
            return Reason(Why.UNKNOWN_VEHICLE, vin=vin,
                          other=None if vin is None else repo.vin_in_other_case(vin))
        except DataError as exc:
            if isinstance(cmd, EnterOutcome):
                return Reason(Why.NOT_RECORDED, note=one_line(exc))
            return Reason(Why.NOT_CLOSED, vin=vin)
        return None

    def note_lock(self, a: NoteLock) -> None:
        """The NOK policy's lock in the command ledger (:class:`NoteLock`): by the station,
        after ``count`` NOKs in a row; a release or a skip ends it.  Its time is ``a.t``, when
        the core decided it: the ``result_at`` of the NOK that caused it, or later.  One the
        database refuses is kept and written when it is back (:meth:`probe`), before any
        result: lost, a reload raising ``max_nok`` would end the lock with no one's release
        (its time stays the decision's, the kept NOK's ``result_at`` its taking)."""
        try:
            self._write_lock(a)
        except STATION_FAULTS:
            with self._lock:
                self._locks_owed.append(a)
            raise

    def _write_lock(self, a: NoteLock) -> None:
        self._writer().ledger.record_command(
            at=datetime.fromtimestamp(a.t, UTC), user=LOCK_USER, source=LOCK_SOURCE, kind=LOCK,
            vin=a.vin, bolt=a.bolt, comment=f"{a.count} NOK in a row")

    def knows_vehicle(self, vin: str) -> tuple[bool | None, str | None]:
        """Whether the database has the vehicle ``vin``, and the VIN it has that is ``vin``
        typed in another case (else None); (None, None) when it cannot say (not open,
        failing): what a command naming a VIN is fed with (:class:`CommandIn`)."""
        try:
            repo = self._repo()
            if repo.knows_vehicle(vin):
                return True, None
            return False, repo.vin_in_other_case(vin)
        except (DbError, DeviceError) as exc:
            self.log.debug("vehicle %s not looked up: %s", vin, one_line(exc))
            return None, None

    def operator(self) -> tuple[str, datetime] | None:
        """Who signed in at the station and has not signed out since, with when (the last
        sign-in or sign-out command decides; None: nobody)."""
        last = self._repo().ledger.last_of((KIND[SignIn], KIND[SignOut]))
        if last is None or last.kind != KIND[SignIn]:
            return None
        return last.user, last.at

    def last_tightening_id(self) -> int | None:
        return self._repo().last_tightening_id()

    def record_gap(self, first: int, last: int, vin: str | None, reason: str) -> None:
        self._writer().others.record_gap(first, last, vin, reason)

    def record_check(self, a: RecordCheck) -> None:
        """A pair's calibration check, with its feed entry (the line gets it)."""
        c, s = a.check, summary(a.check)
        why = None if c.why is None else c.why.value + (f": {c.note}" if c.note else "")
        record_check(self._writer(), at=datetime.fromtimestamp(a.t, UTC), pair=c.pair,
                     verdict=c.verdict.value, reference=c.reference, offset_mm=c.offset_mm,
                     tolerance_mm=c.tolerance_mm, reason=why, references=s["references"])

    def store_curve(self, curve: Curve) -> None:
        """A tightening curve with its rundown, by tightening id (one stored before its
        rundown is written is found by that id)."""
        store_curve(self._writer(), tightening_id=curve.tightening_id,
                    trace_type=curve.trace_type, unit=curve.unit, values=curve.values,
                    sample_period_s=curve.time_step_s,
                    times_s=None if curve.time_step_s is not None else curve.times_s,
                    result_at=None if curve.timestamp is None
                    else curve.timestamp.astimezone(UTC))

    # -- the database's health -------------------------------------------------------------
    def check_file(self) -> None:
        """Raise DbError when the SQLite file the daemon opened is gone or was replaced (its
        open connection would go on writing into the deleted file: results acknowledged,
        then lost, and the bolts tightened again after a restart)."""
        changed = self._file_state()
        if changed is not None:
            assert self._db_file is not None  # noqa: S101 - a state says there is one
            raise DbError(f"the database file {self._db_file[0]} was {changed}")

    def _file_state(self) -> FileChange | None:
        """How the SQLite file the daemon opened is no longer there as it opened it; None
        where it is (or the database is no SQLite file)."""
        if self._db_file is None:
            return None
        path, ident = self._db_file
        try:
            st = path.stat()
        except OSError:
            return FileChange.REMOVED
        return None if (st.st_dev, st.st_ino) == ident else FileChange.REPLACED

    def file_changed(self, url: str) -> FileChange | None:
        """How the SQLite file the daemon opened changed, where ``url``, a reload's
        database, is that same file; else None.  Removed, a reload would open a new, empty
        database there: the vehicle on the lift with no bolt done, its bolts tightened again
        (an engineer's trial).  Replaced (a backup put back), the reload opens that file."""
        if self._db_file is None or sqlite_path(url) != self._db_file[0]:
            return None
        return self._file_state()

    def new_file(self, url: str) -> Path | None:
        """The SQLite file a reload's database ``url`` names where it is not there yet and
        not the file the daemon opened (a reload would create it, empty); else None."""
        path = sqlite_path(url)
        if path is None or path.exists() or (
                self._db_file is not None and path == self._db_file[0]):
            return None
        return path

    def probe(self, repo: Repository) -> None:
        """The database's "reconnect" (its keeper's thread): one cheap query (the engine's
        pool reconnects by itself), one write (:meth:`prove_writable`), then the results it
        refused, oldest first: it is back only once it has taken them all (a full disk still
        answers reads).  A failure is a
        device error, the keeper's kind of failure."""
        try:
            repo.models()
            self.check_file()   # a removed file still answers through its connection
            # it answers reads; back only once a write commits (a file its user may not
            # write answers every read: "back", then the next write failed, a flip-flop)
            self.prove_writable(repo)
        except STATION_FAULTS as exc:
            raise DeviceError(one_line(exc)) from None
        for lock in self._drain(self._locks_owed, self._write_lock, "a lock not recorded"):
            self.log.info("the lock of %s of %s recorded late", lock.bolt, lock.vin)
        for u in self._drain(self._unsaved, self.write, "results not stored"):
            with self._lock:
                self._saved_late.append(u)
            self.log.info("tightening %d of %s stored late", u.record.result.tightening_id,
                          u.record.bolt)

    def prove_writable(self, repo: Repository) -> None:
        """One write that commits (:meth:`Repository.prove_writable`), else a DatabaseError
        saying what to do (:meth:`_refused`) and the repository's connections closed: SQLite
        opens a file its user may not write read-only, and such a connection stays so once
        the file is chowned; the next attempt opens new ones (back with no reload)."""
        try:
            repo.prove_writable()
        except DbError as exc:
            repo.engine.dispose()
            raise self._refused(exc) from None

    def _refused(self, exc: DbError) -> DbError:
        """``exc``, a database that refused a write or an opening, in the words of what to
        do where its SQLite file (or its -wal, -shm) is not this daemon's user's to write
        (:func:`db.location.unwritable_file`: "... chown it to stationd"); else ``exc``, its
        own words."""
        path = sqlite_path(self.cfg.database_url)
        words = None if path is None else unwritable_file(path, "this daemon's user")
        if words is None:
            return exc
        return DatabaseError(f"the database takes no writes: {words}")

    def _drain(self, owed: list[T], write: Callable[[T], None], failed: str) -> Iterator[T]:
        """Each of ``owed`` written, oldest first, and yielded once written (taken off the
        list only then); the first the database refuses raises a device error."""
        while True:
            with self._lock:
                if not owed:
                    return
                item = owed[0]
            try:
                write(item)
            except STATION_FAULTS as exc:
                raise DeviceError(f"{failed}: {one_line(exc)}") from None
            with self._lock:
                owed.pop(0)
            yield item

    def save_images(self, vin: str, bolt: str, tightening_id: int,
                    loc: Localization | None) -> list[str]:
        """Write the selection's crops beside the records; a failure is logged and the
        tightening is recorded without them, never lost."""
        folder = self.cfg.records.images_dir
        if not self.cfg.records.save_images or folder is None or loc is None:
            return []
        if not self._room_for_images(folder):
            return []
        out = []
        for key, img in sorted(loc.crops.items()):
            path = folder / _path_part(vin) / (f"{_path_part(bolt)}-{tightening_id}-"
                                               f"{_path_part(key.replace('/', '-'))}.png")
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                if not cv2.imwrite(str(path), img):
                    raise OSError("the PNG encoder refused it")
            except (OSError, cv2.error) as exc:
                self.log.warning("image %s not saved: %s", path, exc)
                continue
            out.append(str(path))
        return out

    def _room_for_images(self, folder: Path) -> bool:
        """Whether the images' file system has more than ``images_keep_free_mb`` free: below
        it the images are not saved, said once as a warning until there is room again (said
        then too); the records go on.  A file system that cannot be looked at: saved, as
        before (the writes say what fails)."""
        keep = self.cfg.records.images_keep_free_mb
        try:
            free = shutil.disk_usage(_nearest(folder)).free / 1e6
        except OSError:
            return True
        room = free > keep
        if room != self._images_room:
            self._images_room = room
            if room:
                self.log.info("images saved again: %.0f MB free on %s", free, folder)
            else:
                self.log.warning("images not saved: %.0f MB free on %s, within the %d MB "
                                 "kept free for the database (records.images_keep_free_mb); "
                                 "the tightenings are recorded without them: move old "
                                 "images to an archive", free, folder, keep)
        return room


def _nearest(folder: Path) -> Path:
    """``folder``, or its nearest parent that exists (not made yet: its file system)."""
    while not folder.exists() and folder.parent != folder:
        folder = folder.parent
    return folder


def _verdict(report: VehicleReport, due: tuple[str, ...]) -> tuple[tuple[str, ...],
                                                                   tuple[str, ...]]:
    """A closing vehicle's bolts not tightened (skipped ones too: the screens' "not
    tightened when the vehicle left") and ending NOK, those whose result is ``due`` aside."""
    return (tuple(b for b in report.untightened if b not in due),
            tuple(b for b in report.nok if b not in due))


def _path_part(text: str) -> str:
    """``text`` as one file or folder name: every character but letters, digits, ``-``,
    ``_`` and ``.`` as ``_``, never a leading dot.  Why: the VIN comes from the PLC, and a
    garbled or hostile one (``../../x``, ``/run/x``) made the images go outside their folder;
    a bolt's code comes from the bolt table."""
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", text) or "_"
    return "_" + safe[1:] if safe.startswith(".") else safe


def _sqlite_file(url: str) -> tuple[Path, tuple[int, int]] | None:
    """The file of an SQLite URL and its (device, inode); None for another database, one in
    memory, or a file that is not there."""
    path = sqlite_path(url)
    if path is None:
        return None
    try:
        st = path.stat()
    except OSError:
        return None
    return path, (st.st_dev, st.st_ino)


def xyz(p: Any) -> tuple[float, float, float]:
    """Three plain floats from any sequence (NumPy values included)."""
    return float(p[0]), float(p[1]), float(p[2])


def _selection_json(sel: Selection) -> dict[str, Any]:
    """Where the wrench was when its bolt was selected, for the record of a result that comes
    after a reload or restart (the evidence, the marker crops, stays in memory)."""
    return {"point_mm": [float(v) for v in sel.point_mm], "tilt_deg": float(sel.tilt_deg),
            "distance_mm": float(sel.distance_mm), "exposure_t": float(sel.exposure_t),
            "decided_t": float(sel.decided_t), "loosen": sel.loosen, "operator": sel.operator,
            "torque_window": None if sel.torque_window is None else list(sel.torque_window)}


def _window(stored: Any) -> tuple[float, float] | None:
    """A selection's torque window as stored with its enable (None: not stored, an enable
    of an older release)."""
    if not isinstance(stored, list | tuple) or len(stored) != 2:
        return None
    return float(stored[0]), float(stored[1])


def _loosen_sent(pset: int | None) -> dict[str, Any]:
    """What went to the controller for a loosening: its loosen pset, no targets of the
    station's (the record's parameter version stays the bolt's, the one it is tightened
    with)."""
    return {"pset": pset, "torque": None, "angle": None, "loosen": True}


def controller_time(r: TighteningResult) -> datetime | None:
    """The controller's own time of the result (aware, UTC); None where it has no clock (a
    register-driven controller: the station stamped it as it read it, and a copy read again
    after a reload gets another stamp) or none was given."""
    if not r.controller_clock:
        return None
    return _aware(r.timestamp)


def _aware(t: datetime | None) -> datetime | None:
    """The controller's naive local timestamp as an aware one (the database keeps UTC)."""
    return None if t is None else t.astimezone(UTC)


def _selection(owed: OwedEnable) -> Selection:
    """The selection a noted tool enable was made for, as the core took it."""
    j = owed.selection
    return Selection(owed.bolt, owed.pset, xyz(j["point_mm"]), float(j["tilt_deg"]),
                     float(j["distance_mm"]), float(j["exposure_t"]), float(j["decided_t"]),
                     None, owed.vin, owed.parameters_id, bool(j.get("loosen", False)),
                     j.get("operator"), _window(j.get("torque_window")))


__all__ = ["STATION_FAULTS", "Records", "Unsaved", "controller_time", "xyz"]

