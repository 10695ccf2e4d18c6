"""What the demo's stations serve beside tightening: the OPC UA endpoint for an MES and the
forwarding of their records to a line database.

Why here and not in the serve loop: the demo runs one station after another in one process,
on temporary databases, and must print where each endpoint listens before the first rundown
(a port in use moves the default endpoint to the next free port and says so) and, at its end,
wait until the line database has taken every record before it reads the line's results back.
The components are the daemon's own (:class:`stationd.opcua.server.OpcUaServer`,
:func:`stationd.shell.serve.forward`), so what the demo shows is what a station runs; only the
choices are the demo's: security none (anonymous browse, read and subscribe; no certificates)
and IsSimulated true in every result.  Also here: the names that keep a later station's
simulated cameras on its own world (:func:`own_pairs`) and the line's results read back at the
end (:func:`line_report`).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import socket
import time
from collections import Counter
from collections.abc import Callable, Collection
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from sqlalchemy import make_url
from sqlalchemy.exc import SQLAlchemyError

from db.errors import DbError
from db.kinds import LOOSENING
from db.repository import Repository
from drivers.counting import counted
from stationd.bus import EventBus
from stationd.config import StationConfig
from stationd.errors import ConfigError, InputError
from stationd.forward import CURSOR_KEY, LineConfig
from stationd.linedb import LINE_FEED, LineResult, results, write_problem
from stationd.opcua import OpcUaConfig
from stationd.shell.sdnotify import Notifier
from stationd.shell.serve import Screens, forward, opcua_devices
from stationd.station.inputs import Event
from stationd.web.config import split_listen
from stationd.yamlio import YamlNode

log = logging.getLogger("stationd")
DEFAULT_OPCUA = "127.0.0.1:4840"
#: how long one station's services wait for the line database to take its records, s
DRAIN_S = 20.0
#: the longest the demo waits at its end for the line database to take every station's
#: records, s.  It waits for each forwarder's own state, not for a time (:func:`drain_all`):
#: until it has handed over every record, or the line database is away now.  A forwarder in
#: backoff tries again within the longest backoff plus its jitter (72 s; later on a busy
#: machine): this bound only ends the wait on one that neither takes the records nor tries.
LINE_DRAIN_BOUND_S = 180.0
#: the longest the read-back waits for a line database's host to answer, s
CONNECT_TIMEOUT_S = 10
#: where records that did not reach the line database are (:func:`unforwarded`)
KEPT = "they stay in the demo's station database, kept when the demo ends"
#: the demo's security words, printed beside the endpoint
SECURITY_WORDS = "security none: anonymous clients browse, read and subscribe, no certificates"


def bindable(host: str, port: int) -> bool:
    """Whether ``host:port`` can be listened on now (as asyncio's server binds: address
    reuse on, so a port in TIME_WAIT counts as free)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def next_free_port(host: str, start: int, taken: Collection[int] = (),
                   what: str = "the screens") -> int:
    """The first port from ``start`` on that is not in ``taken`` and can be listened on at
    ``host`` now; InputError (``what`` names the service) when none is left."""
    port = start
    while port in taken or not bindable(host, port):
        port += 1
        if port > 65535:
            raise InputError(f"{what}: no free port from {start} on {host}")
    return port


def _any_port(host: str) -> int:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


@dataclass(frozen=True)
class Endpoints:
    """Where the demo's stations serve OPC UA: ``host`` and the first ``port``; ``given``:
    the port was asked for (``--opcua``), so the first station takes it or the demo refuses;
    otherwise a port in use moves on to the next free one."""

    host: str
    port: int
    given: bool

    @classmethod
    def from_arg(cls, text: str | None) -> Endpoints:
        """``--opcua HOST:PORT`` (port 0: any free port), or the default."""
        try:
            host, port = split_listen(text or DEFAULT_OPCUA)
        except ValueError as exc:
            raise InputError(f"--opcua: {exc}".replace("listen ", "", 1)) from None
        return cls(host, port, text is not None and port != 0)

    def take(self, taken: set[int]) -> tuple[str, str | None]:
        """The next endpoint (``opc.tcp://HOST:PORT``) not in ``taken`` (which it joins),
        and why it is not the one asked for (None: it is)."""
        if self.port == 0:
            port = _any_port(self.host)
            taken.add(port)
            return f"opc.tcp://{_url_host(self.host)}:{port}", None
        if self.given and not taken:
            if not bindable(self.host, self.port):
                raise InputError(f"--opcua {self.host}:{self.port}: the port is in use or the "
                                 "address is not this machine's (another port, or leave "
                                 "--opcua out for the next free one)")
            taken.add(self.port)
            return f"opc.tcp://{_url_host(self.host)}:{self.port}", None
        start = max(taken) + 1 if taken else self.port   # the station before took its own
        port = next_free_port(self.host, start, taken, "OPC UA")
        taken.add(port)
        why = None if port == start else f"{start} is in use: the next free port"
        return f"opc.tcp://{_url_host(self.host)}:{port}", why


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def demo_opcua(endpoint: str, station_id: str) -> OpcUaConfig:
    """The demo's OPC UA section: security none, no certificates, no users (anonymous clients
    browse, read, subscribe and call the reading methods; nobody writes)."""
    return OpcUaConfig(endpoint=endpoint, station_id=station_id, security=("none",))


def line_config(url: str, station_id: str) -> LineConfig:
    """``--line-db URL`` as the station file's ``line:`` section would take it (the same
    checks: PostgreSQL, psycopg 3), refused in one line naming the option."""
    text = f"url: {_yaml_string(url)}\nstation_id: {_yaml_string(station_id)}\n"
    try:
        return LineConfig.from_node(YamlNode.parse(text, "--line-db"))
    except ConfigError as exc:
        raise InputError(f"--line-db: {_reason(exc)}") from None


def _yaml_string(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _reason(exc: ConfigError) -> str:
    """The message without the location (the option is the location here)."""
    words = str(exc)
    for head in ("--line-db:1: url: ", "--line-db:1: ", "--line-db: "):
        if words.startswith(head):
            return words[len(head):]
    return words


class StationServices:
    """One demo station's OPC UA server and forwarder: :meth:`start` beside the station (the
    endpoint listens before it returns), :meth:`drain` once its run is over (until the line
    database has taken every record), :meth:`stop` at the demo's end (both serve the
    station's records until then, also during ``--hold``: a command taken then is forwarded
    too).  ``tell`` is the station's (:meth:`Station.tell`): the line database's link goes
    to its core, which tells OPC UA (None: a forwarder without a station, as the line
    report's tests run it)."""

    def __init__(self, cfg: StationConfig, bus: EventBus, screens: Screens | None = None,
                 tell: Callable[[Event], None] | None = None, *,
                 movable: bool = True) -> None:
        self.cfg, self.bus, self._tell = cfg, bus, tell
        #: an OPC UA port taken meanwhile moves to the next free one (not a port asked for)
        self.movable = movable
        self.endpoint: str | None = None   # where OPC UA is served (once it is)
        self.screens = screens if screens is not None else Screens(bus)
        self.opcua: Any = None          # the OpcUaServer, once it serves
        self.problem: str | None = None   # why OPC UA is not served (printed by the demo)
        self.moved: str | None = None     # why it is served on another port than configured
        self.db_id = ""                   # the station database's id (its line records')
        self._repo: Repository | None = None
        self._stop_ua = asyncio.Event()
        self._stop_line = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._line: asyncio.Task[None] | None = None

    async def start(self) -> None:
        if self.cfg.opcua is None and self.cfg.line is None:
            return
        loop = asyncio.get_running_loop()
        self._repo = await loop.run_in_executor(None, Repository.open, self.cfg.database_url)
        self.db_id = await loop.run_in_executor(None, self._repo.ledger.db_id)
        if self.cfg.opcua is not None:
            await self._start_opcua(self.cfg.opcua)
        if self.cfg.line is not None:
            self._line = asyncio.create_task(forward(self.cfg, Notifier({}), self.screens,
                                                     self._stop_line, self.bus, self._tell))

    async def _start_opcua(self, ua_cfg: OpcUaConfig) -> None:
        from stationd.opcua.server import OpcUaServer

        first = ua_cfg.endpoint
        for _ in range(5):
            server = OpcUaServer(ua_cfg, bus=self.bus, simulated=True,
                                 devices=opcua_devices(self.cfg))
            try:
                await server.start()
                break
            except OSError as exc:   # taken between the check and the start
                with contextlib.suppress(Exception):
                    await server.stop()
                if exc.errno != errno.EADDRINUSE or not self.movable:
                    self.problem = f"not served on {ua_cfg.endpoint}: " \
                        f"{errno.errorcode.get(exc.errno or 0, '')} " \
                        f"{exc.strerror or exc}".strip()
                    return
                # another program took the port after it was found free (the demo's
                # station then ran with no endpoint and a PASS that did not say so): the
                # next free one, said
                url = urlsplit(ua_cfg.endpoint)
                host, port = url.hostname or "127.0.0.1", url.port or 4840
                free = next_free_port(host, port + 1, what="OPC UA")
                ua_cfg = replace(ua_cfg, endpoint=f"opc.tcp://{_url_host(host)}:{free}")
                self.moved = f"{first} was taken after it was found free: the next free port"
        else:
            self.problem = f"not served on {first}: every port tried was taken meanwhile"
            return
        assert self._repo is not None  # noqa: S101 - opened by start()
        self.opcua, self.endpoint = server, ua_cfg.endpoint
        self._tasks.append(asyncio.create_task(server.run(self._stop_ua, self._repo)))

    async def drain(self, timeout: float = DRAIN_S) -> bool:
        """Wait until the line database has every record stored so far; False when it had
        not within ``timeout`` (the rest waits in the station's database: the demo says
        so)."""
        if self._line is None:
            return True
        end = time.monotonic() + timeout
        while time.monotonic() < end and not self._line.done():
            if await self.caught_up():
                return True
            await asyncio.sleep(0.1)
        return False

    async def caught_up(self) -> bool:
        """Whether the forwarder has handed the line database every record stored so far
        (True without a line)."""
        if self._line is None:
            return True
        fwd = self.screens.line
        if fwd is None:
            return False
        last = await asyncio.get_running_loop().run_in_executor(None, fwd.repo.ledger.last_seq)
        return bool(fwd.cursor >= last)

    def tries(self) -> int:
        """How many pushes to the line database the forwarder has finished (taken or not)."""
        fwd = self.screens.line
        return 0 if fwd is None else int(fwd.tries)

    def down(self) -> bool:
        """Whether the forwarder's last push failed (the line database away then)."""
        fwd = self.screens.line
        return fwd is not None and fwd.up is False

    def given_up(self, tries_before: int, away: bool) -> bool:
        """Whether waiting longer for this station's records is waiting for nothing: its
        forwarder is not running, or the line database is away now: the forwarder tried
        again since it had made ``tries_before`` tries and failed, or it is down and
        ``away`` (the demo found the line database not answering).  A forwarder that
        failed only before the line database came back is waited for: its backoff ends
        with a try that takes the records."""
        if self._line is None:
            return False
        return self._line.done() or (self.down() and (away or self.tries() > tries_before))

    def line_error(self) -> str | None:
        """The forwarder's last error (None: none, or no forwarder)."""
        fwd = self.screens.line
        return None if fwd is None else fwd.last_error

    def forwarded_to(self) -> int:
        """The last sequence number the forwarder handed the line database (0: none)."""
        fwd = self.screens.line
        return 0 if fwd is None else int(fwd.cursor)

    async def quarantined(self) -> Counter[str]:
        """The station's records the line database refused for good, by kind (behind the
        forwarder's cursor, yet not in the line database)."""
        repo = self._repo
        if repo is None:
            return Counter()

        def count() -> Counter[str]:
            return Counter(str(q["kind"]) for q in repo.ledger.quarantined())

        return await asyncio.get_running_loop().run_in_executor(None, count)

    async def records(self, after: int = 0) -> Counter[str]:
        """The station's records (its feed: rundowns, curves, commands, checks) after
        sequence number ``after``, by kind."""
        repo = self._repo
        if repo is None:
            return Counter()

        def count() -> Counter[str]:
            kinds: Counter[str] = Counter()
            seq = after
            while batch := repo.ledger.since(seq):
                kinds.update(str(e["kind"]) for e in batch)
                seq = int(batch[-1]["seq"])
            return kinds

        return await asyncio.get_running_loop().run_in_executor(None, count)

    async def stop(self) -> None:
        if self._line is not None:
            self._stop_line.set()
            await self._line
            self._line = None
        self._stop_ua.set()
        for t in self._tasks:
            with contextlib.suppress(Exception):
                await t
        self._tasks = []
        if self.opcua is not None:
            with contextlib.suppress(Exception):
                await self.opcua.stop()
            self.opcua = None
        if self._repo is not None:
            await asyncio.get_running_loop().run_in_executor(None, self._repo.close)
            self._repo = None


def line_results(url: str, stations: list[str], db_ids: set[str], limit: int = 1000
                 ) -> list[LineResult]:
    """The rundowns this demo run forwarded to the line database (its stations' databases:
    a line database given with ``--line-db`` may hold earlier runs' too, the newest first),
    oldest first."""
    from sqlalchemy import inspect

    from db.engine import make_engine

    engine = make_engine(url)
    try:
        if not inspect(engine).has_table(LINE_FEED.name):
            return []
        rows = [r for sid in stations for r in results(engine, station=sid, limit=limit)]
    finally:
        engine.dispose()
    return sorted((r for r in rows if r.db_id in db_ids), key=lambda r: (r.at, r.station_id))


def line_summary(rows: list[LineResult], stations: list[str]) -> dict[str, Any]:
    """The line's results per station, as the demo prints them and ``--json`` has them."""
    def empty() -> dict[str, Any]:
        return {"rundowns": 0, "ok": 0, "nok": 0, "loosenings": 0, "bolts": []}

    per: dict[str, dict[str, Any]] = {s: empty() for s in stations}
    for r in rows:
        p = per.setdefault(r.station_id, empty())
        p["rundowns"] += 1
        if r.kind == LOOSENING:
            p["loosenings"] += 1
            continue
        p["ok" if r.ok else "nok"] += 1
        if r.ok and r.bolt not in p["bolts"]:
            p["bolts"].append(r.bolt)
    return {"rundowns": len(rows), "vins": sorted({r.vin for r in rows}), "stations": per}


def own_pairs(cfg: StationConfig, prefix: str) -> StationConfig:
    """``cfg`` (simulated) with its pairs and cameras named ``PREFIX.PAIR``: the first
    station's world stays registered under the plain names (its station keeps running, for
    ``--hold``), so each later station's ``sim://`` cameras render its own world.  Without
    the reference checks (they are the pairs' by name): a light station."""
    cams: dict[str, str] = {}
    pairs = {}
    for name, pc in cfg.pairs.items():
        own = f"{prefix}.{name}"
        left, right = f"{own}_left", f"{own}_right"
        cams[left], cams[right] = f"sim://{own}/left", f"sim://{own}/right"
        pairs[own] = replace(pc, left=left, right=right)
    return replace(cfg, cameras=cams, pairs=pairs, references=None)


async def drain_all(services: list[StationServices],
                    timeout: float = LINE_DRAIN_BOUND_S) -> None:
    """Wait until the line database has every station's records, as each station's forwarder
    says (not for a fixed time: a forwarder backs off longer on a busy machine): for each
    station behind, until its forwarder has handed over every record or the line database is
    away now (:meth:`StationServices.given_up`: a try since this wait began failed, or a
    station that is down finds the line database not answering the demo either, so a line
    database down for the whole run is not waited for); at most ``timeout`` in all."""
    end = time.monotonic() + timeout
    before = [s.tries() for s in services]
    away: dict[str, bool] = {}      # per line URL: not answering when the wait began
    loop = asyncio.get_running_loop()
    for s in services:
        if s.cfg.line is not None and s.down() and s.cfg.line.url not in away:
            away[s.cfg.line.url] = await loop.run_in_executor(None, not_answering,
                                                              s.cfg.line.url)
    while True:
        behind = [(s, n) for s, n in zip(services, before, strict=True)
                  if not await s.caught_up()]
        if not behind or time.monotonic() >= end or all(
                s.given_up(n, s.cfg.line is not None and away.get(s.cfg.line.url, False))
                for s, n in behind):
            return
        await asyncio.sleep(0.1)


def not_answering(url: str) -> bool:
    """Whether the database at ``url`` does not answer a query now (within seconds)."""
    return line_problem(url) is not None


def line_problem(url: str) -> str | None:
    """Why the line database at ``url`` does not answer a query now (within seconds), in the
    user's words (:func:`line_words`); None when it answers."""
    from db.engine import make_engine

    try:
        engine = make_engine(_read_url(url))
    except (SQLAlchemyError, DbError) as exc:
        return line_words(url, _error_text(exc))
    try:
        with engine.connect() as conn:
            conn.exec_driver_sql("SELECT 1")
            # it answers; a role that may not write its tables is as good as away for the
            # demo's forwarders (said at the start, and the end's wait is not in vain)
            cannot = write_problem(conn)
    except (SQLAlchemyError, DbError, OSError) as exc:
        return line_words(url, _error_text(exc))
    finally:
        engine.dispose()
    return None if cannot is None else line_words(url, cannot)


def line_counts(url: str, db_ids: set[str]) -> dict[tuple[str, str], Counter[str]]:
    """The records the line database holds from this run's station databases, by kind, per
    (station id, database id)."""
    from sqlalchemy import func, inspect, select

    from db.engine import make_engine

    engine = make_engine(url)
    try:
        if not inspect(engine).has_table(LINE_FEED.name):
            return {}
        f = LINE_FEED.c
        q = select(f.station_id, f.db_id, f.kind, func.count()).where(
            f.db_id.in_(sorted(db_ids))).group_by(f.station_id, f.db_id, f.kind)
        out: dict[tuple[str, str], Counter[str]] = {}
        with engine.connect() as c:
            for sid, db_id, kind, n in c.execute(q):
                out.setdefault((sid, db_id), Counter())[kind] = int(n)
        return out
    finally:
        engine.dispose()


def line_words(url: str, error: str) -> str:
    """Why the line database was not reached, in the user's words: where it is and what
    happened, without the driver's class names."""
    u = make_url(url)
    where = f"{u.host or 'localhost'}:{u.port or 5432}"
    low = error.lower()
    if "connection refused" in low:
        return f"the line database at {where} does not answer (connection refused)"
    if "closed the connection" in low:
        return f"the line database at {where} does not answer (the connection was closed)"
    if "timeout" in low or "timed out" in low:
        return f"the line database at {where} does not answer (no answer in time)"
    if "translate host name" in low or "name or service not known" in low \
            or "name resolution" in low:
        return f"the line database at {where}: the host name is not known"
    if "password authentication failed" in low or "no password supplied" in low:
        return f"the line database at {where} refused user {u.username} (password)"
    if "does not exist" in low and "database" in low:
        return f"the line database at {where} has no database {u.database}"
    text = error.strip().splitlines()[0] if error.strip() else "no answer"
    for head in ("connection failed: ", "the line tables: "):
        text = text.removeprefix(head)
    return f"the line database at {where}: {text}"


def _error_text(exc: BaseException) -> str:
    orig = getattr(exc, "orig", None)
    text = str(orig if orig is not None else exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _read_url(url: str) -> str:
    """``url`` for the read-back: a host that does not answer fails in seconds, not never."""
    u = make_url(url)
    if "connect_timeout" not in u.query:
        u = u.update_query_dict({"connect_timeout": str(CONNECT_TIMEOUT_S)})
    return u.render_as_string(hide_password=False)


async def line_report(url: str | None, services: list[StationServices], out: Any,
                      page: str | None, json_out: bool,
                      throwaway: bool = False) -> dict[str, Any]:
    """The line's results, read back from the line database once it has every station's
    records (or is away now: :func:`drain_all`): per station, what arrived against what the
    station recorded (``arrival``), and the rundowns (``stations``; the /line page shows them
    row by row); the summary's ``line``, whose ``missing`` counts the records that did not
    reach the line database (their station databases are kept: :func:`unforwarded`)."""
    assert url is not None  # noqa: S101 - only called with a line section
    loop = asyncio.get_running_loop()
    await drain_all(services)
    lined = [s for s in services if s.cfg.line is not None]
    ids = [s.cfg.line.station_id for s in lined if s.cfg.line is not None]
    db_ids = {s.db_id for s in lined if s.db_id}
    recorded = {sid: await s.records() for sid, s in zip(ids, lined, strict=True)}
    try:
        read = _read_url(url)
        rows = await loop.run_in_executor(None, line_results, read, ids, db_ids)
        counts = await loop.run_in_executor(None, line_counts, read, db_ids)
    except (SQLAlchemyError, DbError) as exc:   # the line database away: said, counted
        words = line_words(url, _error_text(exc))
        doc: dict[str, Any] = {"url": shown(url), "error": words, "arrival": {}}
        for sid, s in zip(ids, lined, strict=True):
            # after the cursor, and behind it those refused for good: neither reached it
            pending = await s.records(after=s.forwarded_to()) + await s.quarantined()
            doc["arrival"][sid] = {"records": sum(recorded[sid].values()), "arrived": None,
                                   "missing": sum(pending.values()),
                                   "missing_rundowns": pending["rundown"]}
        _totals(doc)
        print(f"line database: not read back: {words}" + (
            f"; {_missing_words(doc)} did not reach it: {KEPT}" if doc["missing"] else ""),
            file=out, flush=True)
        return doc
    doc = line_summary(rows, ids)
    doc["url"] = shown(url)
    doc["arrival"] = {}
    for sid, s in zip(ids, lined, strict=True):
        arrived = counts.get((sid, s.db_id), Counter())
        n, got = sum(recorded[sid].values()), sum(arrived.values())
        doc["arrival"][sid] = {
            "records": n, "arrived": got, "missing": max(0, n - got),
            "missing_rundowns": max(0, recorded[sid]["rundown"] - arrived["rundown"])}
    _totals(doc)
    errors = sorted({line_words(s.cfg.line.url, e) for s in lined
                     if s.cfg.line is not None and (e := s.line_error())})
    per = ", ".join(f"{sid} {p['arrived']} of {p['records']}"
                    for sid, p in doc["arrival"].items())
    if doc["missing"]:
        arrival = (f"NOT every record arrived ({per} records): {_missing_words(doc)} did "
                   "not reach it (" + (f"{errors[0]}; " if errors else "")
                   + f"{KEPT})")
    else:
        arrival = f"every record arrived ({per} records)"
    print(f"line database: {counted(doc['rundowns'], 'rundown')} of "
          f"{', '.join(doc['vins']) or 'no vehicle'} from {counted(len(ids), 'station')}; "
          f"{arrival}",
          file=out, flush=True)
    if not json_out:
        for text in read_back_words(doc, page, throwaway):
            print(text)
    return doc


def read_back_words(doc: dict[str, Any], page: str | None, throwaway: bool) -> list[str]:
    """The line's results per station as the demo prints them, and where every row is: the
    /line ``page`` while it is served (``--hold``); else ``stationd line results`` on a line
    database that outlives the demo (``--line-db``); a ``throwaway`` one is gone with the
    demo: said so, with how to keep one.  Why: the end suggested ``stationd line results``
    for a throw-away database already removed, a command that could not work; and "9 OK,
    3 NOK" did not say these are results (rundowns), not bolts."""
    lines = [f"  {sid}: {counted(p['rundowns'], 'rundown')}: {counted(p['ok'], 'OK result')}, "
             f"{counted(p['nok'], 'NOK result')}, {counted(p['loosenings'], 'loosening')}; "
             "bolts OK: "
             f"{', '.join(p['bolts']) or '-'}" for sid, p in doc["stations"].items()]
    if page is not None:
        lines.append(f"  every row: {page}" + (
            " (until Ctrl-C: the line database is a throw-away one, gone with the demo)"
            if throwaway else " (stationd line results with a station file naming this "
            "line database prints them too)"))
    elif throwaway:
        lines.append("  every row: not kept: the line database was a throw-away one, gone "
                     "when the demo ends (to keep one: --line-db URL, then stationd line "
                     "results; or --hold, the screens' /line page while the demo holds)")
    else:   # the screens end with the demo: the /line page is served only with --hold
        lines.append("  every row: stationd line results with a station file naming this "
                     "line database (the screens' /line page: with --hold, while the demo "
                     "holds)")
    return lines


def _totals(doc: dict[str, Any]) -> None:
    per = doc["arrival"].values()
    doc["missing"] = sum(p["missing"] for p in per)
    doc["missing_rundowns"] = sum(p["missing_rundowns"] for p in per)
    doc["all_forwarded"] = doc["missing"] == 0


def _missing_words(doc: dict[str, Any]) -> str:
    """"12 records (4 rundowns) of DEMO-1": the records that did not reach the line."""
    whose = [sid for sid, p in doc["arrival"].items() if p["missing"]]
    return (f"{counted(doc['missing'], 'record')} "
            f"({counted(doc['missing_rundowns'], 'rundown')}) of {', '.join(whose)}")


def unforwarded(database: Path) -> int:
    """How many records of a demo station's ``database`` the line database did not take:
    after its forwarder's cursor, or quarantined (refused for good).  Why asked of the file
    at the end, not of the run's report: the demo removes its folder then, and must not
    remove the only copy of a record, whatever ended the run."""
    repo = Repository.open(f"sqlite:///{database}", read_only=True)
    try:
        cursor = int(repo.ledger.get_meta(CURSOR_KEY) or 0)
        return max(0, repo.ledger.last_seq() - cursor) + len(repo.ledger.quarantined())
    finally:
        repo.close()


def shown(url: str) -> str:
    """A database URL as printed (a password hidden)."""
    return make_url(url).render_as_string()


__all__ = ["DEFAULT_OPCUA", "SECURITY_WORDS", "Endpoints", "StationServices", "bindable",
           "demo_opcua", "drain_all", "line_config", "line_counts", "line_report",
           "line_results", "line_summary", "line_words", "next_free_port", "own_pairs",
           "read_back_words", "shown", "unforwarded"]
