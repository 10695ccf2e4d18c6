"""Bolt table <-> database: the import diff (what changed) and the table read back for export.

Why a diff rather than "delete all, insert all": tightening records point at bolts and at the
parameter version they were tightened with.  The import therefore matches models by name,
psets by (scope, number) and bolts by (model, id); it updates what may be updated, versions
what must be kept (parameters of a bolt whose current version has records or tool enables:
the trail says which parameters the tool was enabled with), retires what is referenced and
deletes only what nothing refers to (a bolt whose tool was enabled and never used is
referenced: deleted, the database refused the import and the station stayed in fault).  It
runs inside the caller's transaction, so a failure anywhere leaves the database as it was;
writing nothing when the file matches the database is what makes an import idempotent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import exists, func, select
from sqlalchemy.orm import Session

from db.bolts import BoltSpec, BoltTable, ModelSpec, Parameters, Pset, Window
from db.counting import counted
from db.models import (
    Bolt,
    ProcessParameters,
    PsetProgram,
    TighteningRecord,
    ToolEnable,
    Vehicle,
    VehicleModel,
    utcnow,
)

_LABELS = {"models_added": "models added", "models_changed": "models changed",
           "models_removed": "models removed", "psets_added": "psets added",
           "psets_changed": "psets changed", "psets_removed": "psets removed",
           "added": "bolts added", "changed": "bolts changed", "removed": "bolts removed",
           "new_versions": "new parameter versions"}


@dataclass
class ImportReport:
    """What an import changed; bolts are named ``MODEL/BOLT``, model psets ``MODEL/pset N``."""

    added: list[str] = field(default_factory=list)
    changed: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)
    removed: list[str] = field(default_factory=list)
    new_versions: list[str] = field(default_factory=list)  # "MODEL/BOLT v2 (v1: 3 records)"
    models_added: list[str] = field(default_factory=list)
    models_changed: list[str] = field(default_factory=list)
    models_removed: list[str] = field(default_factory=list)
    psets_added: list[str] = field(default_factory=list)
    psets_changed: list[str] = field(default_factory=list)
    psets_removed: list[str] = field(default_factory=list)

    @property
    def has_changes(self) -> bool:
        return any(v for k, v in self.to_json().items() if k != "unchanged")

    def lines(self) -> list[str]:
        """One line per kind of change, for the command's output."""
        if not self.has_changes:
            return [f"no changes ({counted(len(self.unchanged), 'bolt')} unchanged)"]
        out = [f"{label}: {', '.join(getattr(self, key))}"
               for key, label in _LABELS.items() if getattr(self, key)]
        out.append(f"unchanged: {counted(len(self.unchanged), 'bolt')}")
        return out

    def to_json(self) -> dict[str, list[str]]:
        return {k: list(v) for k, v in vars(self).items()}


def _window(prefix: str, row: Any) -> Window | None:
    target = getattr(row, f"{prefix}_target")
    if target is None:
        return None
    return Window(target, getattr(row, f"{prefix}_min"), getattr(row, f"{prefix}_max"))


def _program_columns(torque: Window, angle: Window | None) -> dict[str, float | None]:
    return {"torque_target": torque.target, "torque_min": torque.min, "torque_max": torque.max,
            "angle_target": angle.target if angle else None,
            "angle_min": angle.min if angle else None, "angle_max": angle.max if angle else None}


def parameters_of(row: ProcessParameters) -> Parameters:
    torque = _window("torque", row)
    if torque is None:  # the column is NOT NULL; a None here is a corrupted row
        raise ValueError(f"parameter version {row.id} has no torque")
    return Parameters(row.pset, torque, _window("angle", row))


def pset_of(row: PsetProgram) -> Pset:
    torque = _window("torque", row)
    if torque is None:
        raise ValueError(f"pset row {row.id} has no torque")
    return Pset(row.number, row.name, torque, _window("angle", row))


def _has_records(session: Session, **where: int) -> bool:
    conds = [getattr(TighteningRecord, k) == v for k, v in where.items()]
    return bool(session.scalar(select(exists().where(*conds))))


def _record_count(session: Session, parameters_id: int) -> int:
    return session.scalar(select(func.count()).select_from(TighteningRecord).where(
        TighteningRecord.parameters_id == parameters_id)) or 0


def _enable_count(session: Session, *parameters_ids: int) -> int:
    """Tool enables made with these parameter versions (the trail points at them)."""
    return session.scalar(select(func.count()).select_from(ToolEnable).where(
        ToolEnable.parameters_id.in_(parameters_ids))) or 0


class _Importer:
    def __init__(self, session: Session, source: str | None) -> None:
        self.s = session
        self.source = source
        self.report = ImportReport()

    def run(self, table: BoltTable) -> ImportReport:
        models = {m.name: m for m in self.s.scalars(select(VehicleModel))}
        wanted = {m.name for m in table.models}
        # free the lift codes first: a code may move from one model to another in one import
        codes = {m.name: m.code for m in table.models}
        for row in models.values():
            if row.code is not None and codes.get(row.name) != row.code:
                row.code = None
        self.s.flush()
        for name, row in models.items():
            if name not in wanted and row.removed_at is None:
                self.remove_model(row)
        self.sync_psets(None, table.psets, "")
        for seq, spec in enumerate(table.models):
            self.sync_model(models.get(spec.name), spec, seq)
        return self.report

    # -- models -------------------------------------------------------------------------------
    def sync_model(self, row: VehicleModel | None, spec: ModelSpec, seq: int) -> None:
        if row is None or row.removed_at is not None:
            self.report.models_added.append(spec.name)
            if row is None:
                row = VehicleModel(name=spec.name)
                self.s.add(row)
            row.removed_at = None
        elif (row.code, row.description) != (spec.code, spec.description):
            self.report.models_changed.append(spec.name)
        row.code, row.description, row.seq = spec.code, spec.description, seq
        self.s.flush()
        self.sync_psets(row.id, spec.psets, f"{spec.name}/")
        self.sync_bolts(row, spec)

    def remove_model(self, row: VehicleModel) -> None:
        self.report.models_removed.append(row.name)
        for bolt in list(row.bolts):
            if bolt.removed_at is None:
                self.remove_bolt(row.name, bolt)
        self.s.flush()
        self.s.expire(row, ["bolts"])  # drop the deleted bolts from the loaded collection
        self.sync_psets(row.id, (), f"{row.name}/")
        referenced = self.s.scalar(select(exists().where(Vehicle.model_id == row.id))) or \
            any(b.removed_at is not None for b in row.bolts)
        if referenced:
            row.removed_at, row.code = utcnow(), None
        else:
            self.s.delete(row)
        self.s.flush()

    # -- psets --------------------------------------------------------------------------------
    def sync_psets(self, model_id: int | None, psets: tuple[Pset, ...], label: str) -> None:
        rows = {r.number: r for r in self.s.scalars(
            select(PsetProgram).where(PsetProgram.model_id.is_(model_id) if model_id is None
                                      else PsetProgram.model_id == model_id))}
        for seq, p in enumerate(psets):
            row = rows.pop(p.number, None)
            name = f"{label}pset {p.number}"
            if row is None:
                row = PsetProgram(model_id=model_id, number=p.number)
                self.s.add(row)
                self.report.psets_added.append(name)
            elif pset_of(row) != p:
                self.report.psets_changed.append(name)
            row.name, row.seq = p.name, seq
            for k, v in _program_columns(p.torque, p.angle).items():
                setattr(row, k, v)
        for number, row in rows.items():
            self.report.psets_removed.append(f"{label}pset {number}")
            self.s.delete(row)
        self.s.flush()

    # -- bolts --------------------------------------------------------------------------------
    def sync_bolts(self, model: VehicleModel, spec: ModelSpec) -> None:
        rows = {b.code: b for b in self.s.scalars(select(Bolt).where(Bolt.model_id == model.id))}
        wanted = {b.bolt_id for b in spec.bolts}
        for code, row in rows.items():
            if code not in wanted and row.removed_at is None:
                self.remove_bolt(model.name, row)
        for seq, b in enumerate(spec.bolts):
            self.sync_bolt(model, rows.get(b.bolt_id), b, seq)
        self.s.flush()

    def sync_bolt(self, model: VehicleModel, row: Bolt | None, spec: BoltSpec, seq: int) -> None:
        label = f"{model.name}/{spec.bolt_id}"
        attrs = {"name": spec.name, "x_mm": spec.position[0], "y_mm": spec.position[1],
                 "z_mm": spec.position[2], "tighten_order": spec.order, "batch": spec.batch}
        if row is None:
            row = Bolt(model_id=model.id, code=spec.bolt_id, seq=seq, **attrs)
            self.s.add(row)
            self.s.flush()
            self.add_version(row, spec.parameters, 1)
            self.report.added.append(label)
            return
        revived = row.removed_at is not None
        moved = any(getattr(row, k) != v for k, v in attrs.items())
        for k, v in attrs.items():
            setattr(row, k, v)
        row.seq, row.removed_at = seq, None
        current = current_version(row)
        retuned = parameters_of(current) != spec.parameters
        if retuned:
            count = _record_count(self.s, current.id)
            enables = _enable_count(self.s, current.id)
            # never overwrite what points at it, nor what a running station may send: a new
            # version (a table imported by hand under the daemon wrote the new window over
            # the version it still tightened with, its record then read the new limits)
            if count or enables or self._model_used(model.id):
                self.add_version(row, spec.parameters, current.version + 1)
                uses = [counted(count, "record")] if count else []
                uses += [counted(enables, "tool enable")] if enables else []
                self.report.new_versions.append(
                    f"{label} v{current.version + 1} (v{current.version}: "
                    f"{', '.join(uses) or 'its model in use'})")
            else:
                self.set_parameters(current, spec.parameters)
        if revived:
            self.report.added.append(label)
        elif moved or retuned:
            self.report.changed.append(label)
        else:
            self.report.unchanged.append(label)

    def add_version(self, bolt: Bolt, p: Parameters, version: int) -> None:
        row = ProcessParameters(bolt_id=bolt.id, version=version, source=self.source)
        self.set_parameters(row, p)
        self.s.add(row)
        bolt.versions.append(row)

    def set_parameters(self, row: ProcessParameters, p: Parameters) -> None:
        row.pset = p.pset
        for k, v in _program_columns(p.torque, p.angle).items():
            setattr(row, k, v)
        row.created_at, row.source = utcnow(), self.source

    def remove_bolt(self, model_name: str, row: Bolt) -> None:
        self.report.removed.append(f"{model_name}/{row.code}")
        if _has_records(self.s, bolt_id=row.id) or \
                _enable_count(self.s, *(v.id for v in row.versions)) or \
                self._model_used(row.model_id):
            row.removed_at = utcnow()
            return
        self.s.delete(row)  # with its parameter versions (cascade): nothing refers to them

    def _model_used(self, model_id: int) -> bool:
        """Whether a vehicle of this model was ever started: its bolts are retired, never
        deleted.  Why: a vehicle's report lists its model's bolts, and a closed one keeps
        the bolts it left without a rundown (:func:`db.report.build_report`); a bolt deleted
        made a vehicle that left it missing read complete (a process engineer's trial).  And
        the vehicle at the station works from the table the daemon loaded: a table imported
        by hand under it deleted a bolt it still offered, and that bolt's tool enable and
        result were refused by the database (a lasting fault)."""
        return bool(self.s.scalar(select(exists().where(Vehicle.model_id == model_id))))


def import_table(session: Session, table: BoltTable, source: str | None = None) -> ImportReport:
    """Bring the database to ``table`` inside the session's transaction; report the changes."""
    report = _Importer(session, source).run(table)
    session.flush()
    return report


def read_table(session: Session) -> BoltTable:
    """The bolt table as held by the database (active models and bolts, current versions)."""
    globals_ = tuple(pset_of(r) for r in session.scalars(
        select(PsetProgram).where(PsetProgram.model_id.is_(None)).order_by(PsetProgram.seq)))
    models: list[ModelSpec] = []
    for m in session.scalars(select(VehicleModel).where(VehicleModel.removed_at.is_(None))
                             .order_by(VehicleModel.seq, VehicleModel.name)):
        psets = tuple(pset_of(r) for r in session.scalars(
            select(PsetProgram).where(PsetProgram.model_id == m.id).order_by(PsetProgram.seq)))
        bolts = tuple(bolt_spec(b) for b in m.bolts if b.removed_at is None)
        models.append(ModelSpec(m.name, bolts, psets, m.description, m.code))
    return BoltTable(tuple(models), globals_)


def current_version(bolt: Bolt) -> ProcessParameters:
    return max(bolt.versions, key=lambda v: v.version)


def sent_bolt(s: Session, parameters_id: int | None, model_id: int, code: str) -> Bolt | None:
    """The bolt ``code`` of model ``model_id`` whose parameter version ``parameters_id`` is,
    retired or not (None: no such version, or another bolt's).  Why: a table imported by
    hand under the running station retires a bolt it still works from the table it loaded;
    the result, or the outcome entered, of the parameters sent for it is still its own."""
    sent_for = None if parameters_id is None else s.get(ProcessParameters, parameters_id)
    return None if sent_for is None else s.scalar(select(Bolt).where(
        Bolt.id == sent_for.bolt_id, Bolt.model_id == model_id, Bolt.code == code))


def bolt_spec(row: Bolt) -> BoltSpec:
    return BoltSpec(row.code, row.name, (row.x_mm, row.y_mm, row.z_mm),
                    parameters_of(current_version(row)), row.tighten_order, row.batch)
