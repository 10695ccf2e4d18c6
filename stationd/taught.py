"""A taught bolt table: the taught positions compared with the CAD table, and the YAML written.

Why one module for both: ``stationd teach`` (the command line) and the commissioning screen's
Teach panel (``GET /api/teach/table``) hand the engineer the same file, built by the same
code, which ``stationd db import`` then turns into new parameter versions of the bolts that
moved (never an overwrite).  The comparison is the same too: per bolt the X-Y difference from
CAD, flagged beyond the matching tolerance, and the bolts closer to a neighbour than the
spacing rule allows (:mod:`db.spacing`, the bolt table's own rule).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import yaml

from db.spacing import too_close

Position = Sequence[float]


@dataclass(frozen=True)
class Compared:
    """One taught bolt against CAD: ``cad_mm`` None when the CAD table does not have it;
    ``neighbours``: the bolts (taught or CAD) closer to it than the spacing rule allows."""

    bolt: str
    position_mm: tuple[float, float, float]
    dispersion_mm: float
    cad_mm: tuple[float, float, float] | None
    difference_mm: float | None     # X-Y, as the matcher measures
    beyond: bool                    # farther from CAD than the matching tolerance
    neighbours: tuple[str, ...]

    def to_json(self) -> dict[str, Any]:
        return {"bolt": self.bolt, "position_mm": list(self.position_mm),
                "dispersion_mm": self.dispersion_mm,
                "cad_mm": None if self.cad_mm is None else list(self.cad_mm),
                "difference_mm": self.difference_mm, "beyond": self.beyond,
                "neighbours": list(self.neighbours)}


def _xyz(p: Position) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in p)
    return x, y, z


def compare(taught: Mapping[str, Mapping[str, Any]], cad: Mapping[str, Position],
            tolerance_mm: float) -> list[Compared]:
    """Each taught bolt (``{"position_mm", "dispersion_mm"}``, the teach point's answer)
    against ``cad`` (id -> position), in the order taught.  The spacing rule is checked on
    the table as it would be imported: CAD positions with the taught ones in their place."""
    everywhere = {**{b: _xyz(p) for b, p in cad.items()},
                  **{b: _xyz(r["position_mm"]) for b, r in taught.items()}}
    ids = list(everywhere)
    close: dict[str, list[str]] = {}
    for i, j, _ in too_close([list(everywhere[b]) for b in ids], tolerance_mm):
        close.setdefault(ids[i], []).append(ids[j])
        close.setdefault(ids[j], []).append(ids[i])
    out = []
    for bolt, r in taught.items():
        pos = _xyz(r["position_mm"])
        ref = _xyz(cad[bolt]) if bolt in cad else None
        diff = None if ref is None else math.dist(pos[:2], ref[:2])
        out.append(Compared(bolt, pos, float(r["dispersion_mm"]), ref, diff,
                            diff is not None and diff > tolerance_mm,
                            tuple(close.get(bolt, ()))))
    return out


def table_text(doc: Mapping[str, Any], model: str, taught: Mapping[str, Mapping[str, Any]]
               ) -> str:
    """The bolt table to import: ``doc`` (a bolt table's YAML tree: every model, so that an
    import removes none) with ``model``'s taught bolts at their taught positions, or without
    one the taught positions alone (the parameters to be added before an import)."""
    def pos(r: Mapping[str, Any]) -> list[float]:
        return [round(float(v), 1) for v in r["position_mm"]]

    body: Any
    unknown: list[str] = []   # taught, but no bolt of the table: said, never dropped
    if doc:
        body = dict(doc)
        known = set()
        for b in body["models"][model].get("bolts") or []:
            if isinstance(b, dict) and str(b.get("id")) in taught:
                b["position"] = pos(taught[str(b["id"])])
                known.add(str(b["id"]))
        # (an id typed with a line break in it is written escaped: never a line of YAML)
        unknown = [f"#   {b if b.isprintable() else repr(b)}: position {pos(r)}, "
                   f"dispersion {float(r['dispersion_mm']):.3f} mm\n"
                   for b, r in taught.items() if b not in known]
    else:
        body = {"model": model, "bolts": [{"id": b, "position": pos(r), "dispersion_mm":
                                           round(float(r["dispersion_mm"]), 3)}
                                          for b, r in taught.items()]}
    head = (f"# taught by stationd teach for {model}: positions in the vehicle frame, mm\n"
            + ("" if doc else "# positions only: add each bolt's parameters before import\n")
            + (f"# taught, but not bolts of {model} in this table (add each with its "
               "parameters, or teach it again under its id):\n" + "".join(unknown)
               if unknown else ""))
    return head + yaml.safe_dump(body, sort_keys=False)


__all__ = ["Compared", "compare", "table_text"]
