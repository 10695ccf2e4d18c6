"""The web server on the daemon's loop: live view by server-sent events, the commissioning
frames on demand, the results from the database, read-only but for the logged-in users'
commands (:mod:`stationd.web.commands`).

Why SSE rather than WebSocket: the screens only listen; SSE is plain HTTP (one long GET),
reconnects by itself in every browser and needs no protocol code on either side.

Cost on the daemon: one bus queue for the whole server; a pump task folds the events into one
:class:`View`, serialises its snapshot once per flush (at most ``FLUSH_HZ`` a second, several
events coalesced) and hands the same bytes to each client's bounded queue (a slow client
loses intermediate snapshots, never slows the station).  Frames are encoded and the database
is read in the default thread pool, only when a screen asks.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import hmac
import json
import logging
import platform
import socket
import time
from collections import Counter
from collections.abc import Callable
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from aiohttp import web
from aiohttp.http_exceptions import HttpProcessingError

from db.errors import NotFoundError
from db.quality import LAST_N
from db.repository import Repository
from stationd.bus import EventBus
from stationd.configread import is_local
from stationd.errors import InputError
from stationd.station.commands import Right
from stationd.station.events import PairFrames
from stationd.station.inputs import LIFT, WRENCH
from stationd.station.state import CoreStatus
from stationd.web.commands import POSTS, CommandRoutes
from stationd.web.config import HttpConfig, open_bind_problem
from stationd.web.connections import Connections, WrongTokens
from stationd.web.frames import LatestFrames, sharpness
from stationd.web.line import LineRoutes
from stationd.web.results import Results, attempt_words, rundowns_csv
from stationd.web.view import View, fold

log = logging.getLogger(__name__)
STATIC = Path(__file__).with_name("static")
FLUSH_HZ = 10.0
#: with nothing to tell, the latest snapshot is sent again this often, s: a screen that hears
#: nothing for three of these knows its stream stalled (a dead link need not break it)
HEARTBEAT_S = 5.0
#: the files the image route serves (the station saves PNGs; a record may name others)
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"})
KEEPALIVE_S = 75.0   # an idle kept-alive connection is closed after this
#: on every answer: no page of the station inside another site's frame, no content-type
#: guessing, no address (with a ``?token=``) sent on as a referrer, no script or style
#: from elsewhere (the screens load only their own)
SECURITY_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data: blob:; "
                               "frame-ancestors 'none'",
}
STOP_RETRY_S = 1.0   # a pump not ended by its cancellation is cancelled again
_MAX_LAST = 500   # results per group the quality screen may ask to plot
CLIENT_QUEUE = 16
PAGES = {"/": "operator.html", "/cameras": "cameras.html", "/vehicles": "vehicles.html",
         "/quality": "quality.html"}


def _versions() -> dict[str, str]:
    def v(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "unknown"
    from stationd.release import release

    return {"stationd": release(), "aiohttp": v("aiohttp"),
            "python": platform.python_version()}


#: what a request without the token is answered (a browser shows it as the page)
UNAUTHORIZED_PAGE = ("token required: open the screens once as /?token=TOKEN (the station "
                  "file's http.token); this browser then keeps it\n")


class WebServer:
    """``WebServer(bus, results, frames, listen="127.0.0.1:8080", token=None)``; then
    ``await start()`` on the daemon's loop and ``await stop()`` at shutdown.  ``results``: a
    :class:`Results` or a ``Repository`` (read only); None hides the results screens' data.
    ``listen`` with port 0 picks a free port (``url`` tells which).  ``devices``: the
    configured devices (lift, wrench, each pair), listed on the screens even before one
    reports its health.  ``results_error``: why a configured results database is not open
    (the screens say it is down, not that none is configured)."""

    def __init__(self, bus: EventBus, results: Results | Repository | None = None,
                 frames: LatestFrames | None = None, listen: str = "127.0.0.1:8080",
                 token: str | None = None, images_dir: Path | None = None,
                 devices: tuple[str, ...] = (), results_error: str | None = None) -> None:
        problem = open_bind_problem(HttpConfig(listen, token))
        if problem is not None:
            raise InputError(problem)
        self.bus = bus
        self.results = Results(results) if isinstance(results, Repository) else results
        self.results_error = results_error
        self.frames = frames if frames is not None else LatestFrames()
        self.config = HttpConfig(listen, token)
        #: why the last reload was refused, until a station runs on a file that reads
        self.reload_refused: str | None = None
        #: the running station's pairs not registered into the vehicle frame (set by the
        #: serve loop): up, but localizing nothing
        self.unregistered: tuple[str, ...] = ()
        self.images_dir = None if images_dir is None else images_dir.resolve()
        self.devices = tuple(devices)
        self.view = View(configured=self.devices)
        self.started = time.time()
        #: which station this is (``stationd.config.station_identity``: its id and station
        #: file), set by the serve loop; in ``/api/status`` so that a command given a station
        #: file acts only on that station's daemon
        self.station: dict[str, Any] | None = None
        self.snapshots = 0           # flushes serialised (the bench reads it)
        self.errors = 0              # events the view could not fold (logged)
        # requests served per route ("/api/events", "/api/cameras/{pair}/{side}/frame.jpg",
        # ...): what the screens' clients really asked for (the bench reads it)
        self.requests: Counter[str] = Counter()
        self.pairs: dict[str, PairFrames] = {}   # each pair's latest detection summary
        self._sharpness: dict[tuple[str, str], tuple[tuple[Any, ...], float]] = {}
        self._snapshot = b""
        self._clients: set[asyncio.Queue[bytes]] = set()
        self._runner: web.AppRunner | None = None
        self._listening: asyncio.Server | None = None
        #: requests with a wrong token, told in the journal (at most once a minute)
        self._wrong_tokens = WrongTokens()
        #: the connections kept (counted, each given a time to send its first request)
        self.connections: Connections | None = None
        self._pump: asyncio.Task[None] | None = None
        self._port = 0
        #: logins, commands and the results feed; the serve loop sets ``commands.submit`` and
        #: ``commands.access`` from the running station
        self.commands = CommandRoutes(lambda: self.results)
        #: the line forwarder's latest status (backlog, lag, last error), set by the serve loop
        self.line: Callable[[], dict[str, Any] | None] = lambda: None
        #: the line page (every station's rundowns); the serve loop sets ``line_results.url``
        self.line_results = LineRoutes()

    # -- lifecycle ---------------------------------------------------------------------
    async def start(self) -> None:
        queue = self.bus.queue(maxsize=10_000)
        history = tuple(self.bus.history)
        self.view = fold(history, self.devices)
        self.pairs = {e.pair: e for e in history if isinstance(e, PairFrames)}
        self._snapshot = self._encode()
        self._pump = asyncio.get_running_loop().create_task(self._run_pump(queue))
        app = web.Application(middlewares=[self._guard])
        app.on_response_prepare.append(_secure)
        self._routes(app)
        # (keep-alive: an idle connection closed after KEEPALIVE_S, not aiohttp's hour)
        self._runner = web.AppRunner(app, access_log=None, shutdown_timeout=1.0,
                                     keepalive_timeout=KEEPALIVE_S)
        await self._runner.setup()
        server = self._runner.server
        assert server is not None  # noqa: S101 - made by setup()
        self.connections = Connections(server)
        self._listening = await asyncio.get_running_loop().create_server(
            self.connections, self.config.host, self.config.port, reuse_address=True)
        self._port = int(self._listening.sockets[0].getsockname()[1])

    async def stop(self) -> None:
        for q in list(self._clients):
            _offer(q, b"")           # wakes each stream, which then ends
        if self._pump is not None:
            pump, self._pump = self._pump, None
            # cancelled again until it ends: Python 3.11's wait_for loses a cancellation that
            # meets its inner get completing (the pump then ran on, and a daemon's SIGTERM or
            # a reload that moved the screens waited for it for good, seen under load)
            while not pump.done():
                pump.cancel()
                await asyncio.wait({pump}, timeout=STOP_RETRY_S)
            with contextlib.suppress(asyncio.CancelledError):
                await pump
        self._wrong_tokens.close()
        if self._listening is not None:
            self._listening.close()     # no new connection; the runner closes the open ones
            self._listening = None
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    @property
    def port(self) -> int:
        """The port it listens on (the one picked when configured 0)."""
        return self._port

    @property
    def url(self) -> str:
        host = self.config.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self._port}/"

    def seed(self, now: CoreStatus) -> None:
        """The running station's snapshot (``core.status()``) taken over the history folded
        at :meth:`start` (:meth:`View.seed`: what a bounded history lost), then sent."""
        self.view.seed(now)
        with contextlib.suppress(TypeError, ValueError):
            self._snapshot = self._encode()
        for q in list(self._clients):
            _offer(q, self._snapshot)

    def set_devices(self, devices: tuple[str, ...]) -> None:
        """The configured devices changed (a reload): the next snapshot lists the new set."""
        self.devices = tuple(devices)
        self.view.configured = self.devices

    @property
    def clients(self) -> int:
        return len(self._clients)

    # -- the live view ---------------------------------------------------------------------
    async def _run_pump(self, queue: asyncio.Queue[Any]) -> None:
        try:
            while True:
                try:
                    event = await asyncio.wait_for(queue.get(), HEARTBEAT_S)
                except TimeoutError:
                    # the line forwarder's state changes without station events
                    with contextlib.suppress(TypeError, ValueError):
                        self._snapshot = self._encode()
                    for q in list(self._clients):
                        _offer(q, self._snapshot)
                    continue
                self._apply(event)
                while not queue.empty():
                    self._apply(queue.get_nowait())
                try:
                    self._snapshot = self._encode()
                except (TypeError, ValueError) as exc:
                    log.warning("screens: snapshot not serialisable: %s", exc)
                    continue
                self.snapshots += 1
                for q in list(self._clients):
                    _offer(q, self._snapshot)
                await asyncio.sleep(1.0 / FLUSH_HZ)
        finally:
            self.bus.unqueue(queue)

    def _apply(self, event: Any) -> None:
        """Fold one event; an event the view cannot take is logged and skipped (the screens
        must not stop following the station over one odd event)."""
        if isinstance(event, PairFrames):
            self.pairs[event.pair] = event
            return
        try:
            self.view.apply(event)
        except Exception:
            self.errors += 1
            log.exception("screens: event not shown: %r", event)

    def _encode(self) -> bytes:
        doc = {**self.view.to_json(), "heartbeat_s": HEARTBEAT_S, "line": self.line(),
               "release_by": self.release_by(), "reload_refused": self.reload_refused}
        return b"data: " + json.dumps(doc, separators=(",", ":"),
                                      default=_plain).encode() + b"\n\n"

    def release_by(self) -> list[str]:
        """The roles whose users may release a locked bolt (the running station's
        ``access``), of those some user has: what the operator screen says beside a lock,
        so the operator knows whom to call (a role nobody holds, after a reload that removed
        its users, sent them to nobody)."""
        access = self.commands.access
        if access is None:
            return []
        held = {u.role for u in access.users.values()}
        return [r for r in access.roles_with(Right.RELEASE) if r in held]

    # -- HTTP -----------------------------------------------------------------------------
    def _routes(self, app: web.Application) -> None:
        r = app.router
        for path, page in PAGES.items():
            r.add_get(path, self._page(page))
        r.add_get("/vehicles/{vin}", self._page("vehicle.html"))
        r.add_static("/static", STATIC, append_version=False)
        # the pages link /static/favicon.svg; a browser asks /favicon.ico anyway on its own
        r.add_get("/favicon.ico", self._favicon)
        r.add_get("/healthz", self._healthz)
        r.add_get("/api/status", self._status)
        r.add_get("/api/view", self._view)
        r.add_get("/api/events", self._events)
        r.add_get("/api/cameras", self._cameras)
        r.add_get("/api/pairs", self._pairs)
        r.add_get("/api/cameras/{pair}/{side}/frame.jpg", self._frame)
        r.add_get("/api/cameras/{pair}/{side}/crop.jpg", self._crop)
        r.add_get("/api/vehicles", self._vehicles)
        r.add_get("/api/vehicles/{vin}/export.csv", self._export_csv)
        r.add_get("/api/vehicles/{vin}/export.json", self._export_json)
        r.add_get("/api/vehicles/{vin}", self._vehicle)
        r.add_get("/api/spc", self._spc)
        r.add_get("/images/{path:.+}", self._image)
        self.commands.add_to(app)
        self.line_results.add_to(app)

    @web.middleware
    async def _guard(self, request: web.Request, handler: Any) -> web.StreamResponse:
        """Read-only (GET/HEAD only: nothing here can send parameters or enable the tool) but
        for the logins and commands (JSON POSTs, a session's), and, with a token configured,
        only for who presents it."""
        if request.method not in ("GET", "HEAD") and not (request.method == "POST"
                                                          and request.path in POSTS):
            return _refused(405, "read-only: GET only (POST: " + ", ".join(POSTS) + ")")
        route = request.match_info.route.resource
        self.requests[route.canonical if route is not None else "?"] += 1
        token = self.config.token
        set_cookie = False
        # /healthz is for a monitoring probe that holds no token: it says "ok" or "fault"
        # and nothing else, so it stays open; every other endpoint needs the token
        if not token and request.path != "/healthz" \
                and not _local_host(request.host, self.config.host):
            # no token: a loopback bind; a page of another site whose name was made to
            # point at 127.0.0.1 (DNS rebinding) must not read the station through the
            # browser of someone on this machine
            return _refused(421, "this server answers only its own address (localhost, "
                                 "this machine's name); set http.token to be reached by "
                                 "another name (a proxy)")
        if token and request.path != "/healthz":
            given = request.headers.get("Authorization", "").removeprefix("Bearer ").strip() \
                or request.cookies.get("token", "") or request.query.get("token", "")
            if not hmac.compare_digest(given.encode(), token.encode()):
                self._wrong_tokens.tell(request.remote or "?", bool(given))
                # a browser shows this text: how to get in (the token itself never said)
                return _refused(401, UNAUTHORIZED_PAGE.rstrip("\n"))
            set_cookie = request.query.get("token") == token
            if set_cookie and request.method == "GET" \
                    and "text/html" in request.headers.get("Accept", ""):
                # a browser opening /?token=...: the cookie set, and the address without
                # the token (it stayed in the address bar, the history and bookmarks); the
                # path made relative to this server whatever it was (//other.example/x)
                url = request.rel_url
                moved = web.HTTPSeeOther(url.with_path("/" + url.path.lstrip("/")).with_query(
                    [(k, v) for k, v in url.query.items() if k != "token"]))
                _token_cookie(moved, token)
                raise moved
        if self.connections is not None:   # let in: no longer on probation
            self.connections.served(request.transport)
        resp: web.StreamResponse = await handler(request)
        if set_cookie and token and not resp.prepared:
            _token_cookie(resp, token)
        return resp

    def _page(self, name: str) -> Any:
        async def handler(request: web.Request) -> web.StreamResponse:
            return web.FileResponse(STATIC / name, headers={"Cache-Control": "no-cache"})
        return handler

    async def _favicon(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "favicon.svg",
                                headers={"Content-Type": "image/svg+xml"})

    async def _healthz(self, request: web.Request) -> web.Response:
        """``ok`` (200), or ``fault`` (503) while the station is in fault or a device reports
        one: a probe can alarm on the status code alone; no detail is given (the probe is
        not authenticated)."""
        if self.view.in_fault() and not self.view.alarm:
            return web.Response(status=503, text="fault\n")
        return web.Response(text="ok\n")

    def status(self) -> dict[str, Any]:
        """What ``GET /api/status`` and ``stationd status`` show."""
        v = self.view.to_json()
        return {"station": self.station, "state": v["state"], "reason": v["reason"],
                # what /healthz answers 503 for, and stationd status exits 1 for
                "in_fault": self.view.in_fault(),
                "reason_kind": v["reason_kind"], "headline": v["headline"],
                # the headline in full (the screen's hover title): ``headline`` cuts a
                # fault's reason for large type, which a command's line need not
                "headline_title": v["headline_title"],
                "vehicle": v["vehicle"], "counters": v["counters"], "devices": v["devices"],
                "versions": _versions(), "uptime_s": round(time.time() - self.started, 1),
                "clients": self.clients, "line": self.line(), "operator": v["operator"],
                "locks": v["locks"], "release_by": self.release_by(),
                # of the locks, the holds (``stationd status`` says them apart: a held bolt
                # is no lock of its NOKs, and its outcome may be entered)
                "holds": self.view.holds(),
                # the bolts those locks are on (the release command names one)
                "locked_bolts": [b["bolt"] for b in v["bolts"] if b["state"] == "locked"],
                # of those, the ones held for a result not known (an outcome may be entered)
                "held_bolts": [b["bolt"] for b in v["bolts"]
                               if b["state"] == "locked" and b["held"]],
                # the bolts to be loosened first (a NOK's loosening, a person's loosen
                # command), each with its loosen pset: the state line says only the last
                # rundown (a newcomer's trial: "bolt B21 OK; tracking" after loosen B21)
                "to_loosen": [{"bolt": b["bolt"], "loosen_pset": b["loosen_pset"]}
                              for b in v["bolts"] if b["loosen"]],
                # the last reload's refusal (the file on disk does not read): the station
                # runs on the configuration it loaded before (None: it runs on the file)
                "reload_refused": self.reload_refused,
                "unregistered": list(self.unregistered)}

    async def _status(self, request: web.Request) -> web.Response:
        return web.json_response(self.status(), dumps=lambda o: json.dumps(o, default=_plain))

    async def _view(self, request: web.Request) -> web.Response:
        return web.Response(body=self._snapshot[len(b"data: "):].strip(),
                            content_type="application/json")

    async def _events(self, request: web.Request) -> web.StreamResponse:
        resp = web.StreamResponse(headers={"Content-Type": "text/event-stream",
                                           "Cache-Control": "no-cache"})
        await resp.prepare(request)
        q: asyncio.Queue[bytes] = asyncio.Queue(CLIENT_QUEUE)
        self._clients.add(q)
        try:
            await resp.write(b"retry: 1000\n\n" + self._snapshot)
            while True:
                data = await q.get()
                if not data:
                    break
                await resp.write(data)
        except (ConnectionError, asyncio.CancelledError):
            pass      # the client went (aiohttp says so as ConnectionError "Connection lost")
        finally:
            self._clients.discard(q)
        return resp

    # -- cameras ---------------------------------------------------------------------------
    async def _cameras(self, request: web.Request) -> web.Response:
        loop = asyncio.get_running_loop()
        out = []
        for f in self.frames.cameras():
            pe = self.pairs.get(f.pair)
            # the pair's published summary, overridden by what was handed over with the frame
            s = {**(pe.sides.get(f.side, {}) if pe is not None else {}), **f.summary}
            if pe is not None:
                s.setdefault("exposure_t", pe.exposure_t)
            if s.get("sharpness") is None and s.get("roi"):
                x, y, w, h = (int(c) for c in s["roi"])
                # once per frame and ROI: every cameras page asks for the list each second
                key = (f.pair, f.side, f.seq, x, y, w, h)
                hit = self._sharpness.get((f.pair, f.side))
                if hit is None or hit[0] != key:
                    value = await loop.run_in_executor(None, sharpness, f.image, (x, y, w, h))
                    hit = self._sharpness[(f.pair, f.side)] = (key, value)
                s["sharpness"] = hit[1]
            out.append({"pair": f.pair, "side": f.side, "grabbed_at": f.grabbed_at,
                        "age_s": round(time.time() - f.grabbed_at, 3), "fps": f.fps,
                        "width": int(f.image.shape[1]), "height": int(f.image.shape[0]),
                        "seq": f.seq, "summary": _json_safe(s)})
        return web.json_response(out)

    async def _pairs(self, request: web.Request) -> web.Response:
        """Each configured camera pair with its health (the operator screen's devices, the
        pairs only): the cameras screen shows a pair that is down, or not opened yet, with
        its reason even when it never handed over a frame."""
        health = self.view.device_health()
        return web.json_response([{"pair": n, **health[n]} for n in self._pair_names()
                                  if n in health])

    def _pair_names(self) -> list[str]:
        """The camera pairs among the configured devices (in their order)."""
        return [n for n in self.devices if n not in (LIFT, WRENCH)]

    def _known_camera(self, pair: str, side: str) -> None:
        """Where no frame is kept: a pair the station was configured with, and a side it has,
        or a typo in a URL said as such, not as "no frame yet" of a camera that never will
        have one.  (A frame kept is served whatever its pair: one of before a reload; a
        server told no devices, as in a bench, knows of no pairs and checks none.)"""
        pairs = self._pair_names()
        if side not in ("left", "right"):
            raise web.HTTPNotFound(text=f"no side {side!r}: left or right\n")
        if pairs and pair not in pairs:
            raise web.HTTPNotFound(text=f"no pair {pair!r} at this station (its pairs: "
                                        f"{', '.join(pairs)})\n")

    async def _frame(self, request: web.Request) -> web.Response:
        pair, side = request.match_info["pair"], request.match_info["side"]
        width = _int_arg(request, "w", 640)
        data = await asyncio.get_running_loop().run_in_executor(
            None, self.frames.jpeg, pair, side, width)
        if data is None:
            self._known_camera(pair, side)
            raise web.HTTPNotFound(text=f"no frame from {pair}/{side} yet\n")
        return web.Response(body=data, content_type="image/jpeg",
                            headers={"Cache-Control": "no-store"})

    async def _crop(self, request: web.Request) -> web.Response:
        pair, side = request.match_info["pair"], request.match_info["side"]
        x, y = _int_arg(request, "x", 0), _int_arg(request, "y", 0)
        size = _int_arg(request, "size", 512)
        data = await asyncio.get_running_loop().run_in_executor(
            None, self.frames.crop, pair, side, x, y, size)
        if data is None:
            self._known_camera(pair, side)
            raise web.HTTPNotFound(text=f"no frame from {pair}/{side} yet\n")
        return web.Response(body=data, content_type="image/jpeg",
                            headers={"Cache-Control": "no-store"})

    # -- results ---------------------------------------------------------------------------
    def _need_results(self) -> Results:
        if self.results is None:
            # configured but not open (the daemon retries it) is a fault to say, not a setting
            text = ("no results database configured" if self.results_error is None
                    else f"results database unavailable: {self.results_error}")
            raise web.HTTPServiceUnavailable(text=text + "\n")
        return self.results

    async def _db(self, fn: Any, *args: Any) -> Any:
        try:
            return await asyncio.get_running_loop().run_in_executor(None, fn, *args)
        except NotFoundError as exc:    # an unknown VIN
            raise web.HTTPNotFound(text=f"{exc}\n") from None
        except Exception as exc:        # the database is down: the screen says so
            raise web.HTTPServiceUnavailable(
                text=f"results database unavailable: {exc}\n") from None

    async def _vehicles(self, request: web.Request) -> web.Response:
        """The newest vehicles (``Results.list_limit``), the database's count of them in
        ``X-Vehicles-Total``: the list says when it shows only the newest."""
        res = self._need_results()
        listed = await self._db(res.vehicles)
        total = await self._db(res.vehicle_count)
        return web.json_response(listed, headers={"X-Vehicles-Total": str(total)})

    async def _vehicle(self, request: web.Request) -> web.Response:
        res = self._need_results()
        doc = await self._db(res.vehicle, request.match_info["vin"])
        for b in doc["bolts"]:
            for r in b["rundowns"]:
                r["image_urls"] = [u for u in map(self._image_url, r["images"]) if u]
                r["attempt_words"] = attempt_words(r, doc.get("reopened_at"))
        return web.json_response(doc)

    def _image_url(self, path: str) -> str | None:
        """The URL of a record's saved crop, when it lies in the image directory."""
        if self.images_dir is None:
            return None
        p = Path(path)
        p = (p if p.is_absolute() else self.images_dir / p).resolve()
        if not p.is_relative_to(self.images_dir):
            return None
        return "/images/" + p.relative_to(self.images_dir).as_posix()

    async def _spc(self, request: web.Request) -> web.Response:
        """Cp/Cpk per bolt and pset on every measured tightening with the last results and
        limits for the plot, NOK per day (``?model=``, ``?since=``, ``?last=`` results per
        group)."""
        res = self._need_results()
        last = request.query.get("last", "")
        if last and not (last.isdigit() and 1 <= int(last) <= _MAX_LAST):
            raise web.HTTPBadRequest(text=f"last: a count of results from 1 to {_MAX_LAST}\n")
        since = None
        if request.query.get("since"):
            try:
                since = datetime.fromisoformat(request.query["since"])
            except ValueError:
                raise web.HTTPBadRequest(text="since: an ISO date (2026-11-23)\n") from None
            since = since if since.tzinfo is not None else since.replace(tzinfo=UTC)
        model = request.query.get("model") or None
        if model is not None:   # as `db spc --model`: an unknown model is said, not empty
            models = await self._db(res.repo.models)
            if model not in models:
                raise web.HTTPNotFound(text=f"model {model}: no such model (models: "
                                       f"{', '.join(models) or 'none'})\n")
        doc = await self._db(res.repo.spc, model, since, int(last) if last else LAST_N)
        return web.json_response(doc)

    async def _export_json(self, request: web.Request) -> web.Response:
        res = self._need_results()
        vin = request.match_info["vin"]
        doc = await self._db(res.vehicle, vin)
        return web.Response(text=json.dumps(doc, indent=1), content_type="application/json",
                            headers=_attachment(f"{vin}.json"))

    async def _export_csv(self, request: web.Request) -> web.Response:
        res = self._need_results()
        vin = request.match_info["vin"]
        station = (self.station or {}).get("id")
        runs = await self._db(res.export, vin, station)   # 404 for an unknown VIN
        return web.Response(text=rundowns_csv(runs), content_type="text/csv",
                            headers=_attachment(f"{vin}.csv"))

    async def _image(self, request: web.Request) -> web.StreamResponse:
        """A saved crop of a record: an image file (:data:`IMAGE_SUFFIXES`) inside the
        records' image directory, nothing else (a folder named as the images' that also held
        the database or the OPC UA server's key served them to any holder of the token)."""
        if self.images_dir is None:
            raise web.HTTPNotFound(text="no image directory configured\n")
        p = (self.images_dir / request.match_info["path"]).resolve()
        if not p.is_relative_to(self.images_dir) or not p.is_file() \
                or p.suffix.lower() not in IMAGE_SUFFIXES:
            raise web.HTTPNotFound(text="no such image\n")
        return web.FileResponse(p)


def _refused(status: int, text: str) -> web.Response:
    """A refusal that also ends its connection (a client refused keeps no slot of
    :class:`Connections` for the keep-alive time: 128 of them shut the screens out)."""
    resp = web.Response(status=status, text=text + "\n")
    resp.force_close()
    return resp


def _token_cookie(resp: web.StreamResponse, token: str) -> None:
    """The token kept by the browser.  SameSite=Lax, not Strict: a link to the screens with
    ``?token=`` followed from another site (the MES, the plant's portal) is redirected to the
    address without it, and a Strict cookie is not sent on that redirect (the page then
    asked for the token it was just given).  Lax sends it on top-level GETs only: every
    command is a POST with its own session cookie (Strict) and nonce."""
    resp.set_cookie("token", token, httponly=True, samesite="Lax")


@functools.cache
def _own_names() -> frozenset[str]:
    """This machine's name (``hostname``, lower case): a kiosk browser on the station PC may
    open the screens by it (not its DNS name: a lookup would hold the loop)."""
    name = socket.gethostname().lower()
    return frozenset({name} if name else set())


def _local_host(host: str, listen: str) -> bool:
    """Whether a request's ``Host`` (with or without its port, any case) names this machine:
    its loopback, its own names, or the address listened on."""
    host = host.lower()
    if host.startswith("["):            # [::1]:8080
        name = host[1:].partition("]")[0]
    elif host.count(":") == 1:          # 127.0.0.1:8080, localhost:8080
        name = host.partition(":")[0]
    else:                               # no port, or a bare IPv6 address
        name = host
    return name in ("localhost", listen.lower()) or name in _own_names() or is_local(name)


class _QuietBadRequests(logging.Filter):
    """aiohttp logs a request it could not parse (a header over 8 KiB, a broken request
    line) as an ERROR with its traceback, after answering it 400: anyone reaching the port
    could fill the journal with them.  Left out (the client has its 400)."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return not isinstance(exc, HttpProcessingError)


logging.getLogger("aiohttp.server").addFilter(_QuietBadRequests())


async def _secure(request: web.Request, response: web.StreamResponse) -> None:
    """Every answer carries :data:`SECURITY_HEADERS` and names no server software."""
    response.headers.update(SECURITY_HEADERS)
    response.headers["Server"] = "stationd"


def _offer(q: asyncio.Queue[bytes], data: bytes) -> None:
    """Put without waiting; a full queue loses its oldest snapshot (the newest wins)."""
    if q.full():
        q.get_nowait()
    q.put_nowait(data)


def _int_arg(request: web.Request, name: str, default: int) -> int:
    try:
        return int(request.query.get(name, default))
    except ValueError:
        raise web.HTTPBadRequest(text=f"{name}: an integer\n") from None


def _attachment(name: str) -> dict[str, str]:
    safe = "".join(c for c in name if c.isalnum() or c in "._-")
    return {"Content-Disposition": f'attachment; filename="{safe}"'}


def _plain(o: Any) -> Any:
    """NumPy scalars and arrays (a daemon may hand them over) as plain JSON values."""
    if hasattr(o, "tolist"):
        return o.tolist()
    raise TypeError(f"{type(o).__name__} is not JSON")


def _json_safe(v: Any) -> Any:
    return json.loads(json.dumps(v, default=lambda o: o.tolist() if hasattr(o, "tolist")
                                 else str(o)))
