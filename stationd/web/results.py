"""Read-only results for the results screens and their exports: the vehicles, and every
rundown of each bolt of a vehicle (OK, NOK, rework; a tightening or a loosening), with the
saved crops, and the commands given on the vehicle (its audit trail).

Why beside the repository and not in it: ``db.repository.Repository`` is the daemon's write
path; the screens only read, and only need two queries the repository does not offer (the
vehicle list, every record rather than the last).  They go through the repository's engine
in a session that never commits; the vehicle's status comes from ``vehicle_report``.

Each rundown carries its ``operator``: the user signed in at the station when its tool was
enabled (None: nobody was, or the record is older than operators signing in).

Each rundown of the vehicle's page (and of its JSON export) carries its tightening curve when
the controller sent one (``db.curves``): ``curve`` is None, or the torque and angle traces
(N m and degrees, one value per sample, the sample period) the page draws as a torque-angle
plot within that rundown's limits.  The CSV export stays one line per rundown, without it.
"""

from __future__ import annotations

import csv
import io
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from db.curves import curves_of_records
from db.kinds import LOOSENING, MISSING, NOK, PENDING, SKIPPED, message_words
from db.ledger import COMMAND, CONTROLLER_EVENT, RUNDOWN, UNATTRIBUTED, UNREADABLE
from db.models import Bolt, ProcessParameters, TighteningRecord, Vehicle, VehicleModel
from db.repository import Repository
from db.shift import list_status
from stationd.words import entered_as_words, result_type_words, unrecorded_words

CSV_FIELDS = ("vin", "model", "bolt", "attempt", "rundown", "status", "operator", "torque_nm",
              "angle_deg", "torque_min_nm", "torque_max_nm", "angle_min_deg", "angle_max_deg",
              "pset",
              "parameter_version", "tightening_id", "x_mm", "y_mm", "z_mm",
              "match_distance_mm", "tilt_deg", "sent_at", "result_at", "recorded_at", "images",
              "skipped_by", "comment",   # a skipped bolt's row: who skipped it, and why
              # an outcome a person entered from the controller's screen (its result could
              # not be read): who (empty: measured), with their comment in ``comment``
              "entered_by",
              # a bolt locked after its NOKs, or held, released by a person: a row of its own
              # (status ``released``, the time, their comment) between its rundowns
              "released_by",
              # the controller's own time of the result, on its clock: when it was made, where
              # ``result_at`` is when the station took it (a result fetched after a link cut
              # is taken at the reconnect, minutes later: a quality trial)
              "controller_at",
              # the row's record outside the station: OPC UA's ResultId, the line's (db_id,
              # seq) as "db_id:seq" (an MES joining an export to its results had no key);
              # empty for a bolt's row without a record (missing, pending, skipped)
              "result_id",
              # a person's loosen command on a bolt (an OK opened again): a row of its own
              # (status ``loosen ordered``, the time, their comment) before its loosening
              # (new columns go last: a sheet reading the columns by place keeps working)
              "ordered_by",
              # which station made it (its ``line.station_id``, else ``opcua.station_id``):
              # an export a plant collects from several stations named none; empty where
              # the database was named without its station file
              "station",
              # the targets sent with the row's limits (a quality trial: the line had them,
              # the station's own export did not); empty for a loosening
              "torque_target_nm", "angle_target_deg")

#: how long after a lock the NOK it comes of may have been taken: none for a record stored
#: by this version (the NOK's result_at is the time the lock was decided at, or earlier);
#: records of an earlier version took the NOK's time as the shell built its record, a moment
#: after the core had decided the lock
LOCK_TAKEN_S = timedelta(seconds=2)
#: an export row of a person's release of a locked or held bolt
RELEASED_STATUS = "released"


#: an export row of a result the station could not read (kept whole in the database)
UNREADABLE_STATUS = "unreadable"
#: a row of a result no bolt owns (made at height, stored unattributed: its reason in the
#: comment): an export without it lost a rundown a quality engineer has to account for
UNATTRIBUTED_STATUS = "unattributed"
#: a row of a controller result that is no rundown (a batch increment, a bypass, a type the
#: station does not know, a link cut that left a bolt's result unknown): its kind in
#: ``rundown``, the bolt the tool was on; an export without it hid a bypass from an auditor
CONTROLLER_EVENT_STATUS = "controller event"
#: a row of the NOK policy's lock of a bolt (its NOKs in a row in the comment)
LOCKED_STATUS = "locked"
#: a row of a person's loosen command on a bolt: OK, a loosening, OK read as the NOK
#: policy's own, with no word of who opened an OK bolt again or why (a quality auditor's
#: trial)
LOOSEN_ORDERED_STATUS = "loosen ordered"
#: the rows of an export that are not rundowns of a bolt (their count apart)
NOT_RUNDOWNS = frozenset({RELEASED_STATUS, UNREADABLE_STATUS, UNATTRIBUTED_STATUS,
                          CONTROLLER_EVENT_STATUS, LOCKED_STATUS, LOOSEN_ORDERED_STATUS})


def _isos(row: dict[str, Any]) -> dict[str, Any]:
    """A row with its times as ISO text."""
    return {k: _iso(v) if isinstance(v, datetime) else v for k, v in row.items()}


def _iso(t: datetime | None) -> str | None:
    return None if t is None else t.isoformat()


class Results:
    """The read-only results source the web server is given."""

    #: the vehicles the results list shows, newest first (the older ones: ``db shift``)
    list_limit = 200

    def __init__(self, repo: Repository) -> None:
        self.repo = repo

    def vehicle_count(self) -> int:
        """How many vehicles the database has: the list says when it shows only the newest
        (a supervisor's trial: it stopped at 200, less than a shift at some lines, without a
        word)."""
        with Session(self.repo.engine) as s:
            return int(s.scalar(select(func.count()).select_from(Vehicle)) or 0)

    def vehicles(self, limit: int | None = None) -> list[dict[str, Any]]:
        """The latest vehicles first, each with its status (open, complete, NOK, missing;
        ``reopened``: reopened for rework and not back at the station yet, which read "open,
        reworked" as the vehicle on the lift did, before any rework: an operator trial);
        ``held``: its bolts held for a person (bolt -> which result), as its page has them
        (a supervisor's trial: the list had no word of them)."""
        with Session(self.repo.engine) as s:
            rows = s.execute(select(Vehicle.vin).order_by(Vehicle.started_at.desc(),
                                                         Vehicle.id.desc())
                             .limit(self.list_limit if limit is None else limit)).all()
        may_hold = self.repo.may_hold([vin for (vin,) in rows])
        out = []
        for (vin,) in rows:
            r = self.repo.vehicle_report(vin, held=vin in may_hold)
            j = r.to_json()
            j["status"] = list_status(r)
            j.pop("bolts")
            out.append(j)
        return out

    def vehicle(self, vin: str) -> dict[str, Any]:
        """The report (last result per bolt) plus every rundown per bolt, oldest first.
        Raises ``NotFoundError`` for an unknown VIN."""
        report = self.repo.vehicle_report(vin, held=True).to_json()
        rows = self._rows(vin, curves=True)
        runs = [r for _, r in rows]
        loose = self.repo.others.unattributed(vin)
        for b in report["bolts"]:
            b["rundowns"] = [r for r in runs if r["bolt"] == b["bolt"]]
            if not b["rundowns"]:   # "not tightened", or why held (as db report says it)
                b["unrecorded"] = unrecorded_words(report["held"].get(b["bolt"]), loose)
        report["commands"] = self.commands(vin)
        # what the controller said that was no rundown, and what could not be read (whole)
        report["controller_events"] = [_isos(e) for e in self.repo.others.controller_events(vin)]
        report["unreadable_results"] = [_isos(x) for x in self.repo.others.unreadable(vin)]
        # results made at height that no bolt owns, each with its type in words
        report["unattributed"] = [{**_isos(u), "what": result_type_words(u["result_type"])}
                                  for u in loose]
        return report

    def commands(self, vin: str) -> list[dict[str, Any]]:
        """The vehicle's audit trail: every command given on it (skip, reopen, release,
        loosen) with its user, where from and when, oldest first."""
        return [{"at": _iso(c.at), "user": c.user, "source": c.source, "kind": c.kind,
                 "bolt": c.bolt, "comment": c.comment} for c in self.repo.ledger.commands(vin)]

    def rundowns(self, vin: str) -> list[dict[str, Any]]:
        return [r for _, r in self._rows(vin)]

    def _rows(self, vin: str, curves: bool = False) -> list[tuple[int, dict[str, Any]]]:
        """(record id, rundown) of ``vin``, oldest first; with ``curves`` each rundown has
        its ``curve`` (None when none was stored)."""
        with Session(self.repo.engine) as s:
            rows = s.execute(
                select(TighteningRecord, Bolt.code, ProcessParameters, VehicleModel.name)
                .join(Vehicle, TighteningRecord.vehicle_id == Vehicle.id)
                .join(VehicleModel, Vehicle.model_id == VehicleModel.id)
                .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
                .join(ProcessParameters, TighteningRecord.parameters_id == ProcessParameters.id)
                .where(Vehicle.vin == vin)
                .order_by(TighteningRecord.recorded_at, TighteningRecord.id)).all()
            traces = curves_of_records(
                s, [(rec.id, rec.tightening_id, rec.recorded_at) for rec, *_ in rows]) \
                if curves else {}
        out: list[tuple[int, dict[str, Any]]] = []
        attempts: dict[str, int] = {}
        for rec, code, params, model in rows:
            attempts[code] = attempts.get(code, 0) + 1
            run = {
                "vin": vin, "model": model, "bolt": code, "attempt": attempts[code],
                "rundown": rec.kind, "status": rec.status,
                # who was signed in at the station (None: nobody, or an older record)
                "operator": rec.operator, "torque_nm": rec.torque_nm,
                "angle_deg": rec.angle_deg,
                # the limits in force for this rundown (its parameter version), as quality
                # judges it; none for a loosening: its loosen pset is the controller's own
                # program, not the bolt's tightening window
                **_limits(params, rec.kind),
                "pset": (rec.params_sent or {}).get("pset"), "parameter_version": params.version,
                "tightening_id": rec.tightening_id, "x_mm": rec.x_mm, "y_mm": rec.y_mm,
                "z_mm": rec.z_mm, "match_distance_mm": rec.match_distance_mm,
                "tilt_deg": rec.tilt_deg, "sent_at": _iso(rec.sent_at),
                "result_at": _iso(rec.result_at), "recorded_at": _iso(rec.recorded_at),
                "controller_at": _iso(rec.controller_at),
                "images": list(rec.images or []),
                # entered by a person from the controller's screen, not measured (None:
                # measured): who, why, and the unreadable result it resolves
                "entered_by": rec.entered_by, "entered_comment": rec.entered_comment,
                "unreadable_id": rec.unreadable_id}
            if curves:
                run["curve"] = plot_curve(traces.get(rec.id, []))
            out.append((rec.id, run))
        return out

    def export(self, vin: str, station: str | None = None) -> list[dict[str, Any]]:
        """The vehicle's rundowns, then one row per bolt with none, no values: status
        ``missing`` (``pending`` while the vehicle is open: at the station, or reopened, its
        bolt is still to do, not forgotten), or ``skipped`` with who skipped it and their
        comment (an export that lists only rundowns reads as a complete vehicle, and one that
        calls a bolt skipped on purpose missing reads as a bolt forgotten).  Each release of
        a locked or held bolt is a row (status ``released``, who, when, why): three NOKs then
        an OK read as a bolt that simply took four tries, where a person decided it may be
        tightened again.  Every row names ``station`` (the station's id; None: not known).
        Raises ``NotFoundError`` for an unknown VIN."""
        report = self.repo.vehicle_report(vin)
        still_open = report.vehicle.ended_at is None
        others = self.repo.others
        rows, unreadable = self._rows(vin), others.unreadable(vin)
        unattributed, events = others.unattributed(vin), others.controller_events(vin)
        given = self.repo.ledger.commands(vin)
        commands = [c for c in given if c.kind in ("release", "lock", "loosen") and c.bolt]
        # a skipped bolt's row is its skip's record: (bolt, when) -> the skip command's id
        skips: dict[tuple[str | None, datetime | None], int] = {
            (c.bolt, c.at): c.id for c in given if c.kind == "skip"}
        ids = self.repo.ledger.result_ids(
            [(RUNDOWN, rid) for rid, _ in rows] + [(UNREADABLE, x["id"]) for x in unreadable]
            + [(UNATTRIBUTED, u["id"]) for u in unattributed]
            + [(CONTROLLER_EVENT, e["id"]) for e in events]
            + [(COMMAND, c.id) for c in commands] + [(COMMAND, i) for i in skips.values()])
        # every row with every field (a JSON row of a release had keys the others had not:
        # a quality engineer's trial)
        runs = [{**dict.fromkeys(CSV_FIELDS), **{k: v for k, v in r.items() if k in CSV_FIELDS},
                 "skipped_by": None, "comment": r["entered_comment"],
                 "result_id": ids.get((RUNDOWN, rid))} for rid, r in rows]
        none: list[dict[str, Any]] = [
            {**dict.fromkeys(CSV_FIELDS), "vin": vin, "model": report.vehicle.model,
             "bolt": b.bolt_id, "attempt": 0,
             "status": PENDING if still_open and b.status == MISSING else
             SKIPPED if b.skipped_by else b.status,
             "images": [], "recorded_at": _iso(b.skipped_at),   # a skip's: when it was
             "skipped_by": b.skipped_by, "comment": b.comment,
             "result_id": ids.get((COMMAND, skips.get((b.bolt_id, b.skipped_at), 0)))}
            for b in report.bolts if b.status in (MISSING, SKIPPED) or b.skipped_by]
        model = report.vehicle.model
        # a result that could not be read: its bolt's row says so, with the parse error
        unread = [_stored_row(vin, model, UNREADABLE_STATUS, x, bolt=x["bolt"],
                              comment=_unreadable_comment(x),
                              result_id=ids.get((UNREADABLE, x["id"])))
                  for x in unreadable]
        loose = [_stored_row(vin, model, UNATTRIBUTED_STATUS, u, bolt=None,
                             # its type as the controller sent it (an unattributed loosening
                             # read as a tightening OK: an MES integrator's trial); none: empty
                             rundown=None if u["result_type"] is None
                             else result_type_words(u["result_type"]),
                             torque_nm=u["torque_nm"], angle_deg=u["angle_deg"],
                             comment=f"{str(u['status']).upper()}; {u['reason']}"
                             + entered_as_words(u["entered_as"]),
                             result_id=ids.get((UNATTRIBUTED, u["id"])))
                 for u in unattributed]
        events = [_stored_row(vin, model, CONTROLLER_EVENT_STATUS, e, bolt=e["bolt"],
                              rundown=e["what"], torque_nm=e["torque_nm"],
                              angle_deg=e["angle_deg"],
                              comment=e["note"] or ("not a rundown" + (
                                  f"; the tool was on {e['bolt']}" if e["bolt"] else "")),
                              result_id=ids.get((CONTROLLER_EVENT, e["id"])))
                  for e in events]
        for c in commands:
            # a release, and the NOK policy's lock, among the rundowns where they came
            at = c.at.isoformat()
            runs.insert(_after_nok(runs, at, c.bolt or "") if c.kind == "lock"
                        else _after(runs, at), {
                **dict.fromkeys(CSV_FIELDS), "vin": vin, "model": report.vehicle.model,
                "bolt": c.bolt, "attempt": 0, "images": [], "recorded_at": at,
                "comment": c.comment, "result_id": ids.get((COMMAND, c.id)), **(
                    {"status": RELEASED_STATUS, "released_by": c.user}
                    if c.kind == "release" else
                    {"status": LOOSEN_ORDERED_STATUS, "ordered_by": c.user}
                    if c.kind == "loosen" else {"status": LOCKED_STATUS})})
        out = runs + none + unread + loose + events
        for row in out:
            row["station"] = station
        return out


def _stored_row(vin: str, model: str, status: str, x: dict[str, Any], **fields: Any
                ) -> dict[str, Any]:
    """An export row of a stored result that is no rundown of a bolt (unreadable,
    unattributed, a controller event: ``x`` as the repository reads it), with ``fields``.
    One clock per column on every row: the station's in ``result_at`` (when it stored it),
    the controller's own (as it sent it) in ``controller_at``."""
    return {**dict.fromkeys(CSV_FIELDS), "vin": vin, "model": model, "attempt": 0,
            "status": status, "images": [], "pset": x["pset"],
            "tightening_id": x["tightening_id"], "result_at": _iso(x["recorded_at"]),
            "controller_at": _iso(x["result_at"]), "recorded_at": _iso(x["recorded_at"]),
            **fields}


def _unreadable_comment(x: dict[str, Any]) -> str:
    """``MID 0061 revision 7: what could not be read``, the MID said once (the driver's error
    may begin with it: "MID 0061 revision 7: MID 0061 revision 7 torque ...")."""
    head = message_words(x["mid"], x["revision"])
    error = str(x["error"])
    return error if error.startswith(head) else f"{head}: {error}"


def _after(rows: list[dict[str, Any]], at: str) -> int:
    """The place of a row made at ``at`` (ISO) among ``rows`` in the order they were made:
    after the last one recorded at or before it."""
    when = datetime.fromisoformat(at)
    place = 0
    for k, r in enumerate(rows):
        t = r.get("recorded_at")
        if t is not None and datetime.fromisoformat(t) <= when:
            place = k + 1
    return place


def _after_nok(rows: list[dict[str, Any]], at: str, bolt: str) -> int:
    """The place of ``bolt``'s lock made at ``at`` (ISO) among ``rows``: after that bolt's
    last NOK taken by then (the NOK it comes of is taken as the lock is decided and stored a
    moment after it, so it is not placed by the time it was stored).  A NOK whose tool was
    enabled after the lock (``sent_at``: tightened again after a release, within
    :data:`LOCK_TAKEN_S`) is none it comes of: the lock went after it, as if the bolt had
    four NOKs in a row before a lock at three (a quality auditor's trial)."""
    when = datetime.fromisoformat(at)
    latest = when + LOCK_TAKEN_S
    place = 0
    for k, r in enumerate(rows):
        t, sent = r.get("result_at"), r.get("sent_at")
        if r.get("bolt") == bolt and r.get("status") == NOK and t is not None \
                and datetime.fromisoformat(t) <= latest \
                and (sent is None or datetime.fromisoformat(sent) <= when):
            place = k + 1
    return place


def attempt_words(run: dict[str, Any], reopened_at: str | None) -> str:
    """A rundown's Attempt cell on the vehicle's page: its number among its bolt's rundowns
    (``attempt``), and what it was: ``2 (loosen pset 92)`` a loosening (the NOK policy's
    loosen step, a loosen command), in the operator screen's words for the loosen pset;
    ``1 (rework)`` a tightening after the vehicle was reopened (``reopened_at``, ISO);
    ``3 (repeat)`` a tightening again after an earlier rundown of the bolt.

    Why here and not in the page's script: a loosening was labelled a repeat tightening
    ("2 (repeat)", its number alone deciding), and words worked out in the script could only
    be checked in a browser; the page shows these as they are."""
    n = str(run["attempt"])
    if run.get("rundown") == LOOSENING:
        pset = run.get("pset")
        return f"{n} (loosen pset {pset})" if pset is not None else f"{n} (loosening)"
    at = run.get("recorded_at")
    if reopened_at and at and datetime.fromisoformat(at) >= datetime.fromisoformat(reopened_at):
        return f"{n} (rework)"    # a reopened vehicle's word: a try after a NOK is a repeat
    return f"{n} (repeat)" if run["attempt"] > 1 else n


def plot_curve(traces: list[dict[str, Any]]) -> dict[str, Any] | None:
    """A rundown's stored traces as the page draws them: torque (N m) and angle (degrees),
    sample by sample (the shorter trace's length), and ``traces``, every trace as stored
    (without the values of the two plotted: they are above); None when none was stored.
    ``torque_nm`` and ``angle_deg`` are None without both traces in those units."""
    if not traces:
        return None
    by = {t["name"]: t for t in traces}
    torque, angle = by.get("torque"), by.get("angle")
    if torque is None or angle is None or torque["unit"] != "Nm" or angle["unit"] != "deg":
        return {"torque_nm": None, "angle_deg": None, "sample_period_s": None,
                "traces": traces}
    n = min(len(torque["values"]), len(angle["values"]))
    plotted = (torque["id"], angle["id"])
    return {"torque_nm": torque["values"][:n], "angle_deg": angle["values"][:n],
            "sample_period_s": torque["sample_period_s"],
            "traces": [{k: v for k, v in t.items() if k not in ("values", "times_s")}
                       if t["id"] in plotted else t for t in traces]}


def _limits(params: Any, kind: str) -> dict[str, float | None]:
    """A rundown's limits and targets columns: its version's window and target for a
    tightening, empty for a loosening."""
    mine = kind != LOOSENING
    return {"torque_min_nm": params.torque_min if mine else None,
            "torque_max_nm": params.torque_max if mine else None,
            "angle_min_deg": params.angle_min if mine else None,
            "angle_max_deg": params.angle_max if mine else None,
            "torque_target_nm": params.torque_target if mine else None,
            "angle_target_deg": params.angle_target if mine else None}


#: the first characters that make a spreadsheet read a cell as a formula
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def _cell(value: Any) -> Any:
    """A text that a spreadsheet would run as a formula (a comment typed as
    ``=HYPERLINK(...)`` by anyone allowed a skip) with a leading ``'``, which shows it as
    text; numbers as they are (a negative angle stays a number)."""
    return "'" + value if isinstance(value, str) and value.startswith(FORMULA_STARTS) \
        else value


def rundowns_csv(runs: list[dict[str, Any]]) -> str:
    """One line per rundown; images joined by ``;``; texts kept from running as formulas
    (:func:`_cell`)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in runs:   # an entered outcome's comment in ``comment``, as a skip's
        row = {**r, "images": ";".join(r["images"])}
        if row.get("comment") is None:
            row["comment"] = r.get("entered_comment")
        w.writerow({k: _cell(row.get(k)) for k in CSV_FIELDS})
    return buf.getvalue()
