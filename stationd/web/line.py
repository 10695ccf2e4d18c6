"""The line page (``/line``): every station's rundowns from the line database, newest first,
for a VIN, a station or a bolt; its data at ``/api/line/results?vin=&station=&bolt=&limit=``,
read from the typed ``line_rundowns`` (:mod:`stationd.linedb`).

Why on a station's screens: a quality engineer or a team leader at any station asks where a
vehicle's bolts were tightened along the line, and the line database (the forwarders' copy of
every station's records) is the one place that knows.  Read only, as every screen; the line
database is connected for each request (it is asked by a person, seldom) and never from the
station's own loop: a line database that is away makes the page say so (503), nothing else.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from aiohttp import web
from sqlalchemy import Engine, create_engine, make_url
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.pool import NullPool

from stationd.linedb import LINE_FEED, LINE_RUNDOWNS, results

PAGE = Path(__file__).with_name("static") / "line.html"
LIMIT = (1, 1000)


class NotUpgraded(Exception):  # noqa: N818 - a state of the line database
    """The line database has records but no typed tables: an earlier stationd made it."""


class LineRoutes:
    """``/line`` and ``/api/line/results``; ``url`` is the running configuration's line
    database (``line.url``; None: the station has no line section, the page says so)."""

    def __init__(self) -> None:
        self.url: str | None = None
        self._engine: tuple[str, Engine] | None = None

    def add_to(self, app: web.Application) -> None:
        app.router.add_get("/line", self._page)
        app.router.add_get("/api/line/results", self._results)

    async def _page(self, request: web.Request) -> web.FileResponse:
        return web.FileResponse(PAGE)

    def _engine_for(self, url: str) -> Engine:
        if self._engine is None or self._engine[0] != url:   # a reload may change it
            self._engine = (url, create_engine(url, poolclass=NullPool))
        return self._engine[1]

    def _read(self, url: str, vin: str | None, station: str | None, bolt: str | None,
              limit: int) -> list[dict[str, Any]]:
        engine = self._engine_for(url)
        with engine.connect() as c:
            if not engine.dialect.has_table(c, LINE_RUNDOWNS.table.name):
                if engine.dialect.has_table(c, LINE_FEED.name):
                    raise NotUpgraded
                return []      # nothing forwarded to it yet
        return [r.to_json() for r in results(engine, vin=vin, station=station, bolt=bolt,
                                           limit=limit)]

    async def _results(self, request: web.Request) -> web.Response:
        url = self.url
        if url is None:
            raise web.HTTPNotFound(text="no line database: the station file has no line "
                                        "section\n")
        q = request.query
        try:
            limit = int(q.get("limit") or 200)
        except ValueError:
            raise web.HTTPBadRequest(text="limit: a number 1-1000\n") from None
        if not LIMIT[0] <= limit <= LIMIT[1]:
            raise web.HTTPBadRequest(text="limit: a number 1-1000\n")
        vin, station, bolt = ((q.get(k) or "").strip() or None
                              for k in ("vin", "station", "bolt"))
        try:
            rows = await asyncio.get_running_loop().run_in_executor(
                None, self._read, url, vin, station, bolt, limit)
        except NotUpgraded:
            raise web.HTTPServiceUnavailable(
                text=f"line database {make_url(url).render_as_string()}: no "
                     f"{LINE_RUNDOWNS.table.name} (made by an earlier stationd): `stationd "
                     "line init URL` adds it, as does a forwarder of this version\n") from None
        except SQLAlchemyError as exc:
            orig = str(getattr(exc, "orig", None) or exc).strip().splitlines()
            raise web.HTTPServiceUnavailable(
                text=f"line database {make_url(url).render_as_string()} unreachable: "
                     f"{orig[0] if orig else type(exc).__name__}\n") from None
        return web.json_response({"line_db": make_url(url).render_as_string(), "vin": vin,
                                  "station": station, "bolt": bolt, "rundowns": rows})


__all__ = ["LineRoutes"]
