"""The screens' and the command line's way into the station: log in, give a command, read the
results feed.

Why the command line comes here too: one authenticated path for every person's command (a
session from a user's password, the core's answer), whatever the client; the station token
(``http.token``) still guards every request as it guards the screens.

- ``POST /api/login`` ``{"user", "password"}``: a session (an HttpOnly, SameSite=Strict cookie);
  a wrong password or an unknown user is 401 and a journal line, nothing else.
- ``POST /api/logout``; ``GET /api/me``: who is logged in, with their rights.
- ``GET /api/nonce``: a single-use nonce for the next command (with a session).
- ``POST /api/commands`` ``{"kind": "skip"|"reopen"|"release"|"loosen"|"calibration-check",
  "vin", "bolt", "comment", "nonce"}`` (``enter-outcome`` also ``"ok"`` true or false,
  ``"torque_nm"``, ``"angle_deg"`` and a comment: the outcome of a held bolt read on the
  controller's screen; and the teach commands, and ``sign-in`` /
  ``sign-out``: the session's user signs in at the station as its operator, or whoever is
  signed in is signed out):
  with a session; a nonce this server did not issue, an old or a used one is refused (400)
  before the station sees it; the station's answer is 200 (accepted) or 409 (refused, with
  its typed reason and the words).  A session whose user was removed from the station file
  (a reload) ends; one whose role changed has the new role's rights.
- ``GET /api/feed?since=N&limit=M``: every record after sequence number N, in order (a
  subscriber that was away catches up from the database, not from the live bus).
- ``GET /api/teach``, ``GET /api/teach/table``: what teach mode measured, the table to import
  (:mod:`stationd.web.teach`).

POSTs must be JSON (``Content-Type: application/json``): a cross-site form cannot send that
without a preflight this server never grants, and the session cookie is SameSite=Strict.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
from collections.abc import Awaitable, Callable
from typing import Any

from aiohttp import web

from db.ledger import FEED_LIMIT
from stationd.access import AccessConfig, LoginThrottle, ReplayGuard, Sessions
from stationd.reasons import Reason
from stationd.station.commands import (
    KIND,
    WITH_REASON,
    Answer,
    CheckCalibration,
    Command,
    EnterOutcome,
    Issuer,
    LoosenBolt,
    ReleaseBolt,
    ReopenVehicle,
    SignIn,
    SignOut,
    SkipBolt,
    TeachPoint,
    TeachStart,
    TeachStop,
)
from stationd.station.events import jsonable
from stationd.web.teach import TeachRoutes
from stationd.words import answer_words, reason_words

log = logging.getLogger("stationd")
COOKIE = "session"
#: the POST endpoints (everything else on the server is read-only)
POSTS = ("/api/login", "/api/logout", "/api/commands")
#: the station's answer to one command (the serve loop sets it to the running station's)
Submit = Callable[[Command, Issuer], Awaitable[Answer]]


class CommandRoutes:
    """Sessions, the replay guard and the handlers; ``submit`` and ``access`` follow the
    running station (None: no station running, nobody configured)."""

    def __init__(self, feed: Callable[[], Any]) -> None:
        self.access: AccessConfig | None = None
        self.submit: Submit | None = None
        self.sessions = Sessions()
        self.replays = ReplayGuard()
        self.throttle = LoginThrottle()
        self._feed = feed   # the results source (None while the database is not open)
        #: what teach mode measured (every teach answer passes here): the Teach panel's
        self.teach = TeachRoutes(feed)

    def add_to(self, app: web.Application) -> None:
        r = app.router
        r.add_post("/api/login", self._login)
        r.add_post("/api/logout", self._logout)
        r.add_get("/api/me", self._me)
        r.add_get("/api/nonce", self._nonce)
        r.add_post("/api/commands", self._command)
        r.add_get("/api/feed", self._feed_since)
        self.teach.add_to(app)

    # -- sessions ---------------------------------------------------------------------------
    async def _login(self, request: web.Request) -> web.Response:
        body = await _json(request)
        user, password = body.get("user"), body.get("password")
        if not isinstance(user, str) or not isinstance(password, str):
            raise web.HTTPBadRequest(text="login: user and password\n")
        access = self.access
        if access is None or not access.users:
            raise web.HTTPForbidden(text="no users are configured (access.users)\n")
        client = body.get("client")
        source = f"{client if client in ('cli', 'screen') else 'screen'} " \
                 f"{request.remote or '?'}"
        wait = self.throttle.blocked(user)
        if wait > 0:
            log.warning("login refused for user %r from %s: too many wrong passwords",
                        user[:64], request.remote)
            raise web.HTTPTooManyRequests(text=f"too many wrong passwords for {user[:64]}: "
                                          f"try again in {wait:.0f} s\n")
        # scrypt takes tens of ms: in a thread, the station's loop goes on
        issuer = await asyncio.get_running_loop().run_in_executor(
            None, access.issuer, user, password, source)
        if issuer is None:
            self.throttle.failed(user)
            log.warning("login refused for user %r from %s", user[:64], request.remote)
            raise web.HTTPUnauthorized(text="wrong user or password\n")
        self.throttle.passed(user)
        token = self.sessions.open(issuer)
        log.info("user %s logged in (%s)", issuer.user, source)
        resp = web.json_response(_who(issuer))
        resp.set_cookie(COOKIE, token, httponly=True, samesite="Strict", path="/")
        return resp

    async def _logout(self, request: web.Request) -> web.Response:
        self.sessions.close(request.cookies.get(COOKIE))
        resp = web.json_response({"user": None})
        resp.del_cookie(COOKIE, path="/")
        return resp

    async def _me(self, request: web.Request) -> web.Response:
        issuer = self._session(request)
        return web.json_response(_who(issuer) if issuer else {"user": None, "rights": []})

    def _session(self, request: web.Request) -> Issuer | None:
        """The request's user as the running configuration has them (None: not logged in,
        or removed since: then the session ends)."""
        token = request.cookies.get(COOKIE)
        issuer = self.sessions.get(token)
        if issuer is None:
            return None
        now = self.access.current(issuer) if self.access is not None else None
        if now is None:
            self.sessions.close(token)
            log.warning("session of %s ended: no longer a user of the station", issuer.user)
        return now

    async def _nonce(self, request: web.Request) -> web.Response:
        if self._session(request) is None:
            raise web.HTTPUnauthorized(text="log in first\n")
        return web.json_response({"nonce": self.replays.issue()})

    # -- commands ---------------------------------------------------------------------------
    async def _command(self, request: web.Request) -> web.Response:
        issuer = self._session(request)
        if issuer is None:
            raise web.HTTPUnauthorized(text="log in first\n")
        body = await _json(request)
        nonce = body.get("nonce")
        if not isinstance(nonce, str):
            raise web.HTTPBadRequest(text="a command needs a nonce (GET /api/nonce)\n")
        problem = self.replays.check(nonce)
        if problem is not None:
            log.warning("command from %s (%s) refused: %s", issuer.user, issuer.source,
                        problem)
            raise web.HTTPBadRequest(text=problem + "\n")
        command = _command(body)
        if self.submit is None:
            raise web.HTTPServiceUnavailable(text="the station is not serving yet (starting, "
                                             "reloading, or its database does not open)\n")
        try:
            answer = await self.submit(command, issuer)
        except TimeoutError:
            raise web.HTTPServiceUnavailable(text="the station did not answer in time\n"
                                             ) from None
        self.teach.heard(answer)
        out: dict[str, Any] = {"accepted": answer.accepted, "words": answer_words(answer),
                               "kind": KIND[type(command)]}
        if answer.result is not None:
            out["result"] = dict(answer.result)
        if answer.reason is not None:
            out["reason"] = reason_json(answer.reason)
        return web.json_response(out, status=200 if answer.accepted else 409)

    # -- the feed ---------------------------------------------------------------------------
    async def _feed_since(self, request: web.Request) -> web.Response:
        results = self._feed()
        if results is None:
            raise web.HTTPServiceUnavailable(text="results database unavailable\n")
        try:
            since = int(request.query.get("since", "0"))
            limit = int(request.query.get("limit", "100"))
        except ValueError:
            raise web.HTTPBadRequest(text="since and limit: integers\n") from None
        if not 0 <= since < 2 ** 62 or not 1 <= limit <= FEED_LIMIT:
            raise web.HTTPBadRequest(text=f"since >= 0, limit 1-{FEED_LIMIT}\n")
        ledger = results.repo.ledger
        loop = asyncio.get_running_loop()
        entries = await loop.run_in_executor(None, ledger.since, since, limit)
        last = await loop.run_in_executor(None, ledger.last_seq)
        # each record under the id the line keeps it (a database put back from a copy:
        # the records before the renewal keep the earlier id), the database's own at the top
        series = await loop.run_in_executor(None, ledger.series)
        return web.json_response({"db_id": series.db_id, "last_seq": last, "entries": [
            {**e, "db_id": series.id_of(e["seq"])} for e in entries]})


def reason_json(reason: Reason) -> dict[str, Any]:
    """A refusal as the command's answer carries it: its kind, the details that apply (JSON
    values: a reason inside it, such as what a teach point missed, with its kind's value) and
    its words."""
    details = {k: v for k, v in jsonable(reason).items() if v not in (None, [])}
    return {**details, "kind": reason.kind.value, "words": reason_words(reason)}


def _who(issuer: Issuer) -> dict[str, Any]:
    return {"user": issuer.user, "rights": sorted(r.value for r in issuer.rights)}


async def _json(request: web.Request) -> dict[str, Any]:
    if request.content_type != "application/json":
        raise web.HTTPUnsupportedMediaType(text="send JSON (Content-Type: application/json)\n")
    try:
        body = await request.json(loads=json.loads)
    except (ValueError, UnicodeDecodeError, RecursionError):   # (nested past Python's depth)
        raise web.HTTPBadRequest(text="the body is not JSON\n") from None
    if not isinstance(body, dict):
        raise web.HTTPBadRequest(text="the body must be a JSON object\n")
    return body


def _text(body: dict[str, Any], key: str, *, limit: int, required: bool = True) -> str:
    """The text field ``key``, stripped; 400 saying what is wrong with it: missing or blank
    ("required": a VIN of spaces read "at most 32 characters", as if too long, in an
    operator trial), too long, or not a text."""
    v = body.get(key, None if required else "")
    if required and (v is None or (isinstance(v, str) and not v.strip())):
        why = ": say why (a skip, a release or a loosen order is kept with its reason)" \
            if key == "comment" else " (empty)"
        raise web.HTTPBadRequest(text=f"{key}: required{why}\n")
    if not isinstance(v, str) or len(v) > limit:
        need = "required" if required else "optional"
        raise web.HTTPBadRequest(text=f"{key}: a text of at most {limit} characters "
                                      f"({need})\n")
    if not v.isprintable():
        # a control character (a newline, an escape) kept in the records, the exports and
        # the line database read as something else there (a quality trial)
        raise web.HTTPBadRequest(text=f"{key}: printable characters only (no newline, tab "
                                      "or control character)\n")
    return v.strip()


#: the widest values an entered outcome may carry (a typing slip, not a joint: refused)
MAX_TORQUE_NM, MAX_ANGLE_DEG = 100_000.0, 100_000.0


def _ok(body: dict[str, Any]) -> bool:
    v = body.get("ok")
    if not isinstance(v, bool):
        raise web.HTTPBadRequest(text="ok: true (OK) or false (NOK), as the controller shows "
                                      "it\n")
    return v


def _number(body: dict[str, Any], key: str, low: float, high: float) -> float:
    """A finite number within [low, high]; 400 for anything else (text, NaN, a boolean)."""
    v = body.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
            or not low <= v <= high:
        raise web.HTTPBadRequest(text=f"{key}: a number from {low:g} to {high:g}\n")
    return float(v)


def _command(body: dict[str, Any]) -> Command:
    """The typed command of a request's body; 400 for anything else."""
    kind = body.get("kind")
    # a skip, a release and a loosen order change a bolt's verdict: each with its reason
    comment = _text(body, "comment", limit=500, required=kind in WITH_REASON)
    if kind == "skip":
        return SkipBolt(_text(body, "vin", limit=32), _text(body, "bolt", limit=32), comment)
    if kind == "reopen":
        return ReopenVehicle(_text(body, "vin", limit=32), comment)
    if kind == "release":
        return ReleaseBolt(_text(body, "vin", limit=32), _text(body, "bolt", limit=32), comment)
    if kind == KIND[EnterOutcome]:
        return EnterOutcome(_text(body, "vin", limit=32), _text(body, "bolt", limit=32),
                            _ok(body), _number(body, "torque_nm", 0.0, MAX_TORQUE_NM),
                            _number(body, "angle_deg", -MAX_ANGLE_DEG, MAX_ANGLE_DEG),
                            _text(body, "comment", limit=500))
    if kind == "loosen":
        return LoosenBolt(_text(body, "vin", limit=32), _text(body, "bolt", limit=32), comment)
    if kind == "teach-start":
        return TeachStart(_text(body, "model", limit=32), comment)
    if kind == "teach-point":
        return TeachPoint(_text(body, "bolt", limit=32), comment)
    if kind == "teach-stop":
        return TeachStop(comment)
    if kind == KIND[CheckCalibration]:
        return CheckCalibration(comment)
    if kind == KIND[SignIn]:      # the session's user signs in at the station
        return SignIn(comment)
    if kind == KIND[SignOut]:
        return SignOut(comment)
    raise web.HTTPBadRequest(text=f"kind: one of {', '.join(KIND.values())}\n")


__all__ = ["COOKIE", "POSTS", "CommandRoutes", "Submit", "reason_json"]
