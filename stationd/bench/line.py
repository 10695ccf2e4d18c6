"""``stationd bench line [--stations 30] [--rundowns N] [--backlog N] [--station-backlog N]
[--pg URL]``: a line's stations forwarding to one PostgreSQL.

Each simulated station is what a station of the line has: its own SQLite database (its own
``db_id``), its own station id, the bolt table imported, rundowns recorded through the
repository as the daemon records them (committed, with their feed entries), and a real
:class:`stationd.forward.Forwarder` running its loop into the one line database.  Four
phases, each printed as plain lines (``--json``: one summary object):

1. **normal load**: every station records a rundown every ``--interval`` s (staggered, with
   jitter) for ``--rundowns`` rundowns; printed: forwarding throughput and the lag from a
   record's feed entry to its row in the line database (``received_at``), p50/p95/max;
2. **outage**: the line database goes down (the throw-away server is stopped; with ``--pg``
   the forwarders are held instead: another's server is not stopped) and the stations record
   a backlog of ``--backlog`` rundowns between them;
3. **drain**: the line database is back and the forwarders start from their cursors (as the
   next retry of their backoff would); printed: rundowns/s until every backlog is in the line
   database, while the first station keeps recording (its record latency
   printed beside the normal load's; it records every ``DRAIN_EVERY_S`` at most, a busy
   station, so that a drain of seconds still gives its latency more than one sample);
4. **one station's outage**: the same for the first station alone (``--station-backlog``
   rundowns, its own forwarder draining them while it records): the issue's figure is a
   station's, and on a line each station drains on its own PC.

Why one process: the line database is what is shared, and it is real; the stations' Python
runs in threads of one process on this machine's cores (harsher than a line, where each
station has its own PC).  Targets of issue 22: lag p95 <= 1 s, drain >= 500 rundowns/s.
"""

from __future__ import annotations

import argparse
import asyncio
import random
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import func, make_url, select

from db.engine import make_engine
from db.repository import Repository
from drivers.counting import counted
from stationd.bench.wait import until as _until
from stationd.boltfile import import_bolts
from stationd.demo.station import SIM_CONFIG
from stationd.errors import InputError
from stationd.forward import Forwarder, LineConfig, not_postgresql
from stationd.jsonout import strict_json
from stationd.linedb import LINE_FEED, create_line_schema
from stationd.pgserver import PgServer, PgServerError
from stationd.sim.vin import make_vin

TARGET_LAG_P95_S = 1.0
TARGET_DRAIN_PER_S = 500.0
BOLTS_PER_VEHICLE = 5
DRAIN_TIMEOUT_S = 600.0
MODEL = "SIM-1"
DRAIN_EVERY_S = 0.5      # the recording station during the drain: as fast as a wrench goes


@dataclass
class Station:
    """One simulated station: its database, its bolts, its forwarder, the vehicle at it."""

    sid: str
    repo: Repository
    bolts: list[str]
    torque: dict[str, float]  # each bolt's target, N m
    rng: random.Random
    fwd: Forwarder | None = None
    wake: asyncio.Event = field(default_factory=asyncio.Event)   # the daemon's ResultRecorded
    serial: int = 0          # the vehicle at the station (its VIN's serial)
    done: int = 0            # bolts done on it
    tid: int = 0             # the controller's tightening id
    latency_s: list[float] = field(default_factory=list)

    def record(self) -> float:
        """The next bolt of the vehicle at the station, recorded; the time it took (the
        station's own commit, what a forwarder must never slow)."""
        vin = make_vin(self.serial)
        if self.done == 0:
            self.repo.start_vehicle(vin, MODEL)
        bolt = self.bolts[self.done]
        ok = self.rng.random() > 0.03
        self.tid += 1
        t0 = time.perf_counter()
        self.repo.record_tightening(
            vin, bolt, ok=ok, position_mm=(self.rng.uniform(0, 3000), 0.0, 0.0),
            match_distance_mm=self.rng.uniform(0.5, 4.0), tilt_deg=self.rng.uniform(0, 20),
            torque_nm=self.rng.gauss(self.torque[bolt] * (1.0 if ok else 0.6), 0.6),
            angle_deg=self.rng.gauss(35.0, 5.0), tightening_id=self.tid,
            result_at=datetime.now(UTC))
        took = time.perf_counter() - t0
        self.done += 1
        if self.done == len(self.bolts):
            self.repo.close_vehicle(vin)
            self.serial, self.done = self.serial + 1, 0
        return took


def _pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(q * (len(s) - 1))))]


def _spread(values: list[float], scale: float = 1.0) -> dict[str, float]:
    return {"n": len(values), "p50": _pct(values, 0.5) * scale,
            "p95": _pct(values, 0.95) * scale, "max": max(values, default=float("nan")) * scale}


def _check(args: argparse.Namespace) -> None:
    if args.station_backlog < 0:
        raise InputError(f"--station-backlog {args.station_backlog}: 0 or more")
    if not 1 <= args.stations <= 90:
        raise InputError(f"--stations {args.stations}: 1-90 (one connection each)")
    if args.rundowns < 1:
        raise InputError(f"--rundowns {args.rundowns}: at least 1")
    if args.backlog < 0:
        raise InputError(f"--backlog {args.backlog}: 0 or more")
    if not 0.05 <= args.interval <= 60:
        raise InputError(f"--interval {args.interval:g}: 0.05-60 s")
    if args.pg is not None:
        try:
            backend = make_url(args.pg).get_backend_name()
        except Exception:
            raise InputError(f"--pg {args.pg!r}: not a database URL (e.g. "
                             "postgresql+psycopg://user@host/line)") from None
        if backend != "postgresql":
            raise InputError(f"--pg: {not_postgresql(args.pg, backend)}")


def _stations(folder: Path, n: int, seed: int) -> list[Station]:
    """``n`` stations, each its own database with the simulated bolt table, each doing
    ``BOLTS_PER_VEHICLE`` bolts of every vehicle (the stations of a line share the work)."""
    table = SIM_CONFIG.parent / "bolts.yaml"
    out = []
    for i in range(n):
        repo = Repository.open(f"sqlite:///{folder / f'st{i + 1:02d}.db'}")
        import_bolts(repo, table)
        torque = {b.bolt_id: b.parameters.torque.target for b in repo.bolts_for_model(MODEL)}
        codes = list(torque)
        mine = [codes[(i * BOLTS_PER_VEHICLE + j) % len(codes)]
                for j in range(BOLTS_PER_VEHICLE)]
        out.append(Station(f"BENCH-{i + 1:02d}", repo, mine, torque,
                           random.Random(seed * 1000 + i)))  # noqa: S311
    return out


class Line:
    """The forwarders of every station, run as the daemon runs one, stopped and restarted
    together."""

    def __init__(self, stations: list[Station], url: str) -> None:
        self.stations, self.url = stations, url
        self.stop = asyncio.Event()
        self.tasks: list[asyncio.Task[None]] = []
        self.went_down: set[str] = set()

    def start(self) -> None:
        self.stop = asyncio.Event()
        for st in self.stations:
            st.fwd = Forwarder(st.repo, LineConfig(self.url, st.sid, max_records=10**9))
            self.tasks.append(asyncio.create_task(st.fwd.run(self.stop, self._heard(st),
                                                             st.wake)))

    def _heard(self, st: Station) -> Callable[[dict[str, Any]], None]:
        def on_change(status: dict[str, Any]) -> None:
            if status["up"] is False:
                self.went_down.add(st.sid)
        return on_change

    async def halt(self) -> None:
        self.stop.set()
        await asyncio.gather(*self.tasks)
        self.tasks = []
        for st in self.stations:
            if st.fwd is not None:
                st.fwd.line.dispose()

    async def caught_up(self, targets: dict[str, int], timeout: float) -> float | None:
        """Seconds until every station's forwarder passed its target sequence number (None:
        not within ``timeout``)."""
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            if all(st.fwd is not None and st.fwd.cursor >= targets[st.sid]
                   for st in self.stations):
                return time.monotonic() - t0
            await asyncio.sleep(0.02)
        return None


async def _record_at_rate(loop: asyncio.AbstractEventLoop, st: Station, count: int | None,
                          interval: float, until: asyncio.Event | None = None) -> None:
    """``count`` rundowns (or until ``until``), one every ``interval`` s with +-20 % jitter,
    starting after a random part of an interval (the stations are not in step)."""
    await asyncio.sleep(st.rng.uniform(0, interval))
    n = 0
    while (count is None or n < count) and not (until is not None and until.is_set()):
        st.latency_s.append(await loop.run_in_executor(None, st.record))
        st.wake.set()      # as the daemon's bus tells its forwarder (ResultRecorded)
        n += 1
        await asyncio.sleep(interval * st.rng.uniform(0.8, 1.2))


def _lags(url: str, stations: list[Station], after: dict[str, int]) -> list[float]:
    """Seconds from each rundown's feed entry to its line row, for the entries after
    ``after`` (per station)."""
    engine = make_engine(url)
    f = LINE_FEED.c
    lags: list[float] = []
    try:
        with engine.connect() as c:
            for st in stations:
                q = select(func.extract("epoch", f.received_at - f.at)).where(
                    f.station_id == st.sid, f.db_id == st.repo.ledger.db_id(),
                    f.seq > after[st.sid],
                    f.kind == "rundown")
                lags.extend(float(v) for v in c.scalars(q))
    finally:
        engine.dispose()
    return lags


def _last(stations: list[Station]) -> dict[str, int]:
    return {st.sid: st.repo.ledger.last_seq() for st in stations}


async def _bench(args: argparse.Namespace, url: str, server: PgServer | None
                 ) -> dict[str, Any]:
    loop = asyncio.get_running_loop()
    loop.set_default_executor(ThreadPoolExecutor(max_workers=2 * args.stations + 4))
    engine = make_engine(url)
    create_line_schema(engine)
    engine.dispose()
    with tempfile.TemporaryDirectory(prefix="stationd-line-") as tmp:
        stations = _stations(Path(tmp), args.stations, args.seed)
        line = Line(stations, url)
        try:
            return await _phases(args, loop, stations, line, url, server)
        finally:
            await line.halt()
            for st in stations:
                st.repo.close()


async def _phases(args: argparse.Namespace, loop: asyncio.AbstractEventLoop,
                  stations: list[Station], line: Line, url: str, server: PgServer | None
                  ) -> dict[str, Any]:
    res: dict[str, Any] = {"stations": args.stations, "interval_s": args.interval,
                           "line_rate_per_s": args.stations / args.interval}
    # 1. normal load
    line.start()
    # a forwarder connects at its first record (once per start): one rundown each first,
    # not counted
    await asyncio.gather(*(_record_at_rate(loop, st, 1, 0.05) for st in stations))
    warm = _last(stations)
    if await line.caught_up(warm, 60.0) is None:
        raise InputError(f"the line database {make_url(url).render_as_string()} did not "
                         "take the stations' first records within 60 s")
    for st in stations:
        st.latency_s = []
    t0 = time.monotonic()
    await asyncio.gather(*(_record_at_rate(loop, st, args.rundowns, args.interval)
                           for st in stations))
    made = _last(stations)
    wait = await line.caught_up(made, 60.0)
    took = time.monotonic() - t0
    lags = _lags(url, stations, warm)
    normal_latency = [v for st in stations for v in st.latency_s]
    res["normal"] = {"rundowns": len(lags), "seconds": took,
                     "per_s": len(lags) / took if took > 0 else float("nan"),
                     "caught_up": wait is not None, "lag_s": _spread(lags),
                     "record_ms": _spread(normal_latency, 1000.0)}
    line.went_down = set()
    if args.backlog:
        res["outage"], res["drain"] = await _outage(loop, line, args.backlog, server,
                                                    args.interval)
    if args.station_backlog:
        await line.halt()
        one = Line(stations[:1], url)     # one station's backlog, its own forwarder alone
        one.start()
        try:
            res["station_outage"], res["station_drain"] = await _outage(
                loop, one, args.station_backlog, server, args.interval)
        finally:
            await one.halt()
    return res


async def _outage(loop: asyncio.AbstractEventLoop, line: Line, backlog: int,
                  server: PgServer | None, interval: float
                  ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The line database away while ``line``'s stations record ``backlog`` rundowns between
    them, then back: how fast the forwarders drain it while the first station goes on
    recording."""
    stations = line.stations
    if server is not None:
        await loop.run_in_executor(None, server.pause)
    else:
        await line.halt()
    before = _last(stations)
    t0 = time.monotonic()
    per = [backlog // len(stations) + (i < backlog % len(stations))
           for i in range(len(stations))]

    def build(st: Station, n: int) -> None:
        for _ in range(n):
            st.record()

    await asyncio.gather(*(loop.run_in_executor(None, build, st, n)
                           for st, n in zip(stations, per, strict=True)))
    built = time.monotonic() - t0
    targets = _last(stations)
    if server is not None:    # each forwarder tries (at once: woken) and finds it down
        for st in stations:
            st.wake.set()
        await _until(lambda: len(line.went_down) == len(stations), 10.0)
    outage = {"stations": len(stations), "rundowns": sum(per), "seconds": built,
              "line_db": "stopped" if server is not None else "forwarders held",
              "forwarders_down": len(line.went_down)}
    # back: their backoff may wait a minute, so they start again at once (its next retry)
    if server is not None:
        await line.halt()
        await loop.run_in_executor(None, server.resume)
    first = stations[0]
    first.latency_s = []
    recording = asyncio.Event()
    every = min(interval, DRAIN_EVERY_S)
    keeps = asyncio.create_task(_record_at_rate(loop, first, None, every, recording))
    line.start()
    drained = await line.caught_up(targets, DRAIN_TIMEOUT_S)
    recording.set()
    await keeps
    total = sum(targets[s] - before[s] for s in targets)
    drain = {"rundowns": total, "seconds": drained,
             "per_s": None if not drained else total / drained,
             "recording_station": first.sid, "recording_every_s": every,
             "record_ms": _spread(first.latency_s, 1000.0)}
    await line.caught_up(_last(stations), 60.0)
    return outage, drain


def _ok(met: bool) -> str:
    return "met" if met else "MISSED"


def print_line_report(res: dict[str, Any], where: str) -> None:
    """The figures as plain lines."""
    print(f"line: {res['stations']} stations, one rundown every {res['interval_s']:g} s each "
          f"({res['line_rate_per_s']:.1f} rundowns/s on the line), line database {where}")
    n = res["normal"]
    lag, rec = n["lag_s"], n["record_ms"]
    print(f"normal load: {n['rundowns']} rundowns forwarded in {n['seconds']:.1f} s "
          f"({n['per_s']:.1f} rundowns/s){'' if n['caught_up'] else ', NOT caught up'}")
    print(f"  lag from record to line row: p50 {lag['p50']:.3f} s, p95 {lag['p95']:.3f} s, "
          f"max {lag['max']:.3f} s (target p95 <= {TARGET_LAG_P95_S:g} s: "
          f"{_ok(lag['p95'] <= TARGET_LAG_P95_S)})")
    print(f"  a station's record (commit) latency: p50 {rec['p50']:.1f} ms, p95 "
          f"{rec['p95']:.1f} ms, max {rec['max']:.1f} ms")
    for outage, drain in (("outage", "drain"), ("station_outage", "station_drain")):
        if outage in res:
            _print_drain(res[outage], res[drain], rec)


def _print_drain(o: dict[str, Any], d: dict[str, Any], normal: dict[str, float]) -> None:
    who = f"{o['stations']} stations" if o["stations"] > 1 else "one station"
    print(f"outage ({who}): {o['rundowns']} rundowns recorded in {o['seconds']:.1f} s while "
          f"the line database was away ({o['line_db']}; "
          f"{counted(o['forwarders_down'], 'forwarder')} saw it down)")
    if d["per_s"] is None:
        print(f"  drain: NOT drained within {DRAIN_TIMEOUT_S:g} s")
    else:
        print(f"  drain: {d['rundowns']} rundowns in {d['seconds']:.1f} s: {d['per_s']:.0f} "
              f"rundowns/s (target >= {TARGET_DRAIN_PER_S:g}: "
              f"{_ok(d['per_s'] >= TARGET_DRAIN_PER_S)})")
    r = d["record_ms"]
    print(f"  {d['recording_station']} kept recording meanwhile (one every "
          f"{d['recording_every_s']:g} s): {r['n']} rundowns, record latency p50 "
          f"{r['p50']:.1f} ms, p95 {r['p95']:.1f} ms, max {r['max']:.1f} ms (normal load: "
          f"p50 {normal['p50']:.1f} ms, p95 {normal['p95']:.1f} ms)")


def run_line_bench(args: argparse.Namespace) -> int:
    """The benchmark (``stationd bench line``): exit 0, or 2 for bad input or no server."""
    _check(args)
    server: PgServer | None = None
    if args.pg is None:
        server = PgServer(max_connections=2 * args.stations + 20, durable=True)
        try:
            server.start()
        except PgServerError as exc:
            raise InputError(f"{exc}; or give a line database with --pg URL") from None
        url = server.create("line")
        where = f"PostgreSQL on 127.0.0.1:{server.port} (throw-away, started for the run, fsync on)"
    else:
        url = args.pg
        where = make_url(url).render_as_string()
    try:
        res = asyncio.run(_bench(args, url, server))
    finally:
        if server is not None:
            server.stop()
    res["line_db"] = where
    if args.json:
        print(strict_json(res))
    else:
        print_line_report(res, where)
    return 0


__all__ = ["print_line_report", "run_line_bench"]
