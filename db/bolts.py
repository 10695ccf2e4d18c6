"""The bolt table as typed values, and its YAML form (what ``stationd db export`` writes).

The same types come out of the file checker (``stationd.boltfile``) and out of the database
(``Repository.table()``), so "import, export, import again changes nothing" is a comparison of
two equal values.  Units are fixed and never written next to a number: positions mm in the
vehicle frame, torque N m, angle degrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import yaml

from db.counting import counted


@dataclass(frozen=True)
class Window:
    """A target with its acceptance limits (the controller judges a result against them)."""

    target: float
    min: float
    max: float


@dataclass(frozen=True)
class Pset:
    """A controller program: its number and the torque (and angle) it tightens to."""

    number: int
    name: str | None
    torque: Window
    angle: Window | None = None


@dataclass(frozen=True)
class Parameters:
    """The process parameters of a bolt, resolved: what one parameter version stores.

    ``pset`` is what a pset-driven controller (Open Protocol) is sent; ``torque`` and ``angle``
    are what a register-driven controller is sent, and what the result is recorded against.
    """

    pset: int | None
    torque: Window
    angle: Window | None = None


@dataclass(frozen=True)
class BoltSpec:
    bolt_id: str
    name: str
    position: tuple[float, float, float]
    parameters: Parameters
    order: int | None = None
    batch: str | None = None


@dataclass(frozen=True)
class ModelSpec:
    name: str
    bolts: tuple[BoltSpec, ...]
    psets: tuple[Pset, ...] = ()
    description: str | None = None
    code: int | None = None


@dataclass(frozen=True)
class BoltTable:
    """A whole bolt table: global psets and every vehicle model with its psets and bolts."""

    models: tuple[ModelSpec, ...]
    psets: tuple[Pset, ...] = ()

    @property
    def bolt_count(self) -> int:
        return sum(len(m.bolts) for m in self.models)

    def summary(self) -> str:
        psets = len(self.psets) + sum(len(m.psets) for m in self.models)
        return (f"{counted(len(self.models), 'model')}, {counted(self.bolt_count, 'bolt')}, "
                f"{counted(psets, 'pset')}")


# -- YAML output ------------------------------------------------------------------------------
class _Flow(list[Any]):
    """A list written on one line: ``[x, y, z]``."""


class _FlowMap(dict[str, Any]):
    """A mapping written on one line: ``{target: 25.0, min: 23.0, max: 27.0}``."""


class _Dumper(yaml.SafeDumper):
    pass


_Dumper.add_representer(_Flow, lambda d, v: d.represent_sequence(
    "tag:yaml.org,2002:seq", v, flow_style=True))
_Dumper.add_representer(_FlowMap, lambda d, v: d.represent_mapping(
    "tag:yaml.org,2002:map", v.items(), flow_style=True))


def _window(w: Window) -> _FlowMap:
    return _FlowMap(target=w.target, min=w.min, max=w.max)


def _pset(p: Pset) -> dict[str, Any]:
    out: dict[str, Any] = {"id": p.number}
    if p.name is not None:
        out["name"] = p.name
    out["torque"] = _window(p.torque)
    if p.angle is not None:
        out["angle"] = _window(p.angle)
    return out


def _bolt(b: BoltSpec, programs: dict[int, Pset]) -> dict[str, Any]:
    """A bolt as written by hand: the pset alone when its program gives the targets."""
    out: dict[str, Any] = {"id": b.bolt_id, "name": b.name, "position": _Flow(b.position)}
    p = b.parameters
    program = programs.get(p.pset) if p.pset is not None else None
    if p.pset is not None:
        out["pset"] = p.pset
    if program is None or program.torque != p.torque:
        out["torque"] = _window(p.torque)
    if p.angle is not None and (program is None or program.angle != p.angle):
        out["angle"] = _window(p.angle)
    if b.order is not None:
        out["order"] = b.order
    if b.batch is not None:
        out["batch"] = b.batch
    return out


def dump_bolts(table: BoltTable, header: str = "") -> str:
    """The table as bolts.yaml text, which ``stationd.boltfile`` reads back to an equal table."""
    globals_ = {p.number: p for p in table.psets}
    doc: dict[str, Any] = {}
    if table.psets:
        doc["psets"] = [_pset(p) for p in table.psets]
    models: dict[str, Any] = {}
    for m in table.models:
        entry: dict[str, Any] = {}
        if m.description is not None:
            entry["description"] = m.description
        if m.code is not None:
            entry["code"] = m.code
        if m.psets:
            entry["psets"] = [_pset(p) for p in m.psets]
        programs = {**globals_, **{p.number: p for p in m.psets}}
        entry["bolts"] = [_bolt(b, programs) for b in m.bolts]
        models[m.name] = entry
    doc["models"] = models
    body = yaml.dump(doc, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    return "\n".join([*lines, body]) if lines else body
