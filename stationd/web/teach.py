"""Teach-in on the commissioning screen: what was taught, against CAD, and the table to import.

Why here and not in the station's core: the core answers each teach point (the mean of steady
localizations and their dispersion) and forgets it, as it forgets any answer; the engineer's
work is the set of those answers, kept where they pass by (every teach command, from a screen
or ``stationd teach``, goes through :class:`~stationd.web.commands.CommandRoutes`), so that a
reloaded page shows it and the table can be downloaded after teach mode ended.  A daemon
restart loses it, as it ends teach mode.

- ``GET /api/teach[?model=CODE]``: the models of the station's database, teach mode's latest
  session per model, and for ``model`` its CAD bolts (ids, positions) and each taught bolt
  with its position, dispersion, X-Y difference from CAD and flags (beyond the matching
  tolerance; closer to a neighbour than the spacing rule allows).
- ``GET /api/teach/table?model=CODE``: the bolt table to import (``stationd db import``: a new
  parameter version of each bolt that moved, never an overwrite), the same text
  ``stationd teach`` writes (:mod:`stationd.taught`): the database's whole table with the taught
  positions, or the taught positions alone when the database has no table for the model.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import yaml
from aiohttp import web

from db.repository import Repository
from stationd.station.commands import Answer, TeachPoint, TeachStart, TeachStop
from stationd.station.matching import MatchParams
from stationd.taught import compare, table_text

#: without a measured answer (which carries the station's), the matcher's default tolerance
DEFAULT_TOLERANCE_MM = MatchParams().tolerance_mm


@dataclass
class TeachSession:
    """One teach mode of one model: who, since when, whether it ended, the taught bolts."""

    model: str
    user: str
    started: float
    ended: bool = False
    taught: dict[str, dict[str, Any]] = field(default_factory=dict)
    tolerance_mm: float = DEFAULT_TOLERANCE_MM

    def to_json(self) -> dict[str, Any]:
        return {"model": self.model, "user": self.user, "started": self.started,
                "ended": self.ended, "taught": len(self.taught)}


class TeachRoutes:
    """The taught points, heard from the station's answers; ``results`` gives the database
    (its ``.repo``), or None while none is open."""

    def __init__(self, results: Callable[[], Any]) -> None:
        self._results = results
        self.sessions: dict[str, TeachSession] = {}   # model -> its latest teach mode
        self._current: str | None = None              # the model being taught now

    def heard(self, answer: Answer) -> None:
        """An accepted teach command's answer: a new session, a taught bolt, or the end."""
        if not answer.accepted:
            return
        cmd = answer.command
        if isinstance(cmd, TeachStart):
            self.sessions[cmd.model] = TeachSession(cmd.model, answer.issuer.user, time.time())
            self._current = cmd.model
        elif self._current is not None and self._current in self.sessions:
            s = self.sessions[self._current]
            if isinstance(cmd, TeachPoint) and answer.result is not None:
                r = dict(answer.result)
                s.taught[cmd.bolt] = r
                s.tolerance_mm = float(r.get("tolerance_mm", s.tolerance_mm))
            elif isinstance(cmd, TeachStop):
                s.ended, self._current = True, None

    def add_to(self, app: web.Application) -> None:
        app.router.add_get("/api/teach", self._teach)
        app.router.add_get("/api/teach/table", self._table)

    async def _db(self, fn: Callable[[Repository], Any]) -> Any:
        """``fn(repo)``'s answer in a thread, or None without a database (or when it fails:
        the panel then compares with nothing rather than failing)."""
        results = self._results()
        if results is None:
            return None
        try:
            return await asyncio.get_running_loop().run_in_executor(None, fn, results.repo)
        except Exception:   # the database down: no CAD table, said as none
            return None

    async def _teach(self, request: web.Request) -> web.Response:
        model = request.query.get("model", "").strip()
        models = await self._db(Repository.models) or []
        out: dict[str, Any] = {"models": models, "current": self._current,
                               "sessions": [s.to_json() for s in self.sessions.values()]}
        if model:
            cad = await self._cad(model)
            s = self.sessions.get(model)
            tol = s.tolerance_mm if s is not None else DEFAULT_TOLERANCE_MM
            out.update(model=model, tolerance_mm=tol,
                       cad=[{"bolt": b, "position_mm": list(p)} for b, p in cad.items()],
                       taught=[c.to_json() for c in compare(s.taught if s else {}, cad, tol)])
        return web.json_response(out)

    async def _cad(self, model: str) -> dict[str, tuple[float, float, float]]:
        """The model's bolts as the database holds them (id -> position), or none."""
        table = await self._db(Repository.table)
        for m in table.models if table is not None else ():
            if m.name == model:
                return {b.bolt_id: b.position for b in m.bolts}
        return {}

    async def _table(self, request: web.Request) -> web.Response:
        model = request.query.get("model", "").strip()
        s = self.sessions.get(model)
        if not model or s is None or not s.taught:
            raise web.HTTPNotFound(text=f"nothing taught for {model or '?'} since the daemon "
                                   "started\n")
        text = await self._db(Repository.export_bolts)
        doc = yaml.safe_load(text) if text else None
        if not isinstance(doc, dict) or model not in (doc.get("models") or {}):
            doc = {}
        safe = "".join(c for c in model if c.isalnum() or c in "._-") or "model"
        return web.Response(text=table_text(doc, model, s.taught),
                            content_type="application/yaml",
                            headers={"Content-Disposition":
                                     f'attachment; filename="bolts.taught.{safe}.yaml"',
                                     "Cache-Control": "no-store"})


__all__ = ["TeachRoutes", "TeachSession"]
