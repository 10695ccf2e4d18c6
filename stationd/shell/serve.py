"""``stationd run --config station.yaml``: the daemon as systemd runs it.

READY=1 once the station serves, whatever its devices do (a device that is down is a fault with
its reason in STATUS=, retried with backoff); STATUS= on every state change; WATCHDOG=1 as the
unit asks.  SIGTERM (and SIGINT) stop the loop, disable the tool and close every device in
order, then exit 0.  SIGHUP validates the whole new station (the file, every file it names, the
bolt table) before switching: an invalid one is logged with its reason and the running station
stays; a valid one whose devices are down runs in fault.  Only a configuration that is invalid
at the very first start exits (2).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import enum
import logging
import random
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Coroutine
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any

from drivers.devices import Kind, simulated
from drivers.keeper import Backoff, FaultKind, one_line
from drivers.link import bind_words
from stationd.bus import EventBus
from stationd.config import StationConfig, station_identity
from stationd.errors import StationError
from stationd.lock import StationLocks
from stationd.logsetup import setup_logging
from stationd.shell.daemon import OPEN_ERRORS, Station
from stationd.shell.records import STATION_FAULTS, FileChange, Unsaved
from stationd.shell.sdnotify import Notifier
from stationd.station.actions import NoteLock
from stationd.station.events import ResultRecorded, StationEvent
from stationd.station.inputs import (
    DATABASE,
    LIFT,
    WRENCH,
    DeviceBack,
    DeviceFault,
    Event,
    LineLinkIn,
)
from stationd.stationcheck import more_errors, validate_station
from stationd.stopping import reload_asked
from stationd.words import records_waiting

if TYPE_CHECKING:
    from stationd.opcua import OpcUaConfig
    from stationd.web import Results

log = logging.getLogger("stationd")
OPEN_RETRY_S = (1.0, 30.0)   # a database that does not open: first and longest wait
#: while the database opens (a schema upgrade of a large database runs then: 38 s for 15 M
#: rows in an IT administrator's trial, against the unit's TimeoutStartSec=60s), systemd is
#: asked every this many seconds for twice as long again, the time it has taken said
OPEN_EXTEND_S = 10.0
#: what runs beside each station the loop starts, until that station stops (its configuration,
#: the station, its stop): ``stationd run``'s simulated world and operator on a ``sim://``
#: station, handed in by ``stationd.cli`` (the runtime never imports the simulator)
Beside = Callable[[StationConfig, Station, asyncio.Event], Coroutine[Any, Any, None]]


class Opened(enum.Enum):
    """How :func:`_open` ended."""

    OPEN = "open"          # the database opened: the station runs
    STOPPED = "stopped"    # stopped meanwhile
    RELOAD = "reload"      # a reload asked meanwhile: its files read before a retry


async def _open(station: Station, notifier: Notifier, stop: asyncio.Event,
                reload: asyncio.Event | None = None) -> Opened:
    """Open the station's database (its devices are the station's to retry); a database that
    does not open is retried with backoff, never an exit.  A reload asked while it waits
    ends the wait (an engineer who fixed the database's path waited up to 30 s for the next
    retry, and that retry was of the old path)."""
    loop = asyncio.get_running_loop()
    backoff = Backoff(*OPEN_RETRY_S, rng=random.Random("database"))  # noqa: S311 - jitter
    told = False
    said = ""   # the reason last said: a retry that fails the same way is said at debug only
    while not stop.is_set():
        try:
            await _extending(loop.run_in_executor(None, station.open), notifier)
            if told:
                station.heard_before_run(DeviceBack(time.time(), DATABASE))
            return Opened.OPEN
        except STATION_FAULTS as exc:
            wait = backoff.next()
            # once per reason, as a device's fault is (each retry, up to every 30 s, wrote
            # the same error line to the journal for as long as the database stayed down)
            reason = one_line(exc)
            (log.debug if reason == said else log.error)(
                "fault: database: %s (retrying in %.0f s)", reason, wait)
            said = reason
            if not told:
                notifier.ready(f"fault: database: {reason}")
                told = True
            # the core decides; the screens and /healthz say it too (before the loop runs)
            station.heard_before_run(DeviceFault(time.time(), DATABASE, FaultKind.DOWN,
                                                 one_line(exc)))
        waits = {asyncio.create_task(stop.wait())}
        if reload is not None:
            waits.add(asyncio.create_task(reload.wait()))
        await asyncio.wait(waits, timeout=wait, return_when=asyncio.FIRST_COMPLETED)
        for w in waits:
            w.cancel()
        if reload is not None and reload.is_set() and not stop.is_set():
            return Opened.RELOAD
    return Opened.STOPPED


async def _extending(opening: asyncio.Future[None], notifier: Notifier,
                     every: float = OPEN_EXTEND_S) -> None:
    """Wait for the database's ``opening``, asking systemd for more time (and saying how
    long it has taken) every ``every`` seconds it goes on: a migration before READY=1 must
    not be killed by TimeoutStartSec and restarted mid-way, in a loop."""
    began = time.monotonic()
    while True:
        done, _ = await asyncio.wait({opening}, timeout=every)
        if done:
            return opening.result()
        taken = time.monotonic() - began
        notifier.extend_timeout(2 * every, f"opening the database: {taken:.0f} s so far (a "
                                           "schema upgrade runs before the station starts)")


async def _reloaded(cfg_path: str, station: Station, screens: Screens,
                    locks: StationLocks | None, notifier: Notifier) -> StationConfig | None:
    """The station file read again for a reload and checked (every file it names, the
    screens' port, the devices' locks, the database still there): the new configuration, or
    None with the refusal said (journal, systemd's status, the screens); the running station
    is never stopped for an invalid one."""
    loop = asyncio.get_running_loop()
    try:  # validate first: an invalid station never stops the running one
        # (its warnings said once it is taken: a review found them said of a reload that was
        # then refused, read as the new table running)
        warnings: list[str] = []
        new = await loop.run_in_executor(None, validate_station, cfg_path, warnings.append)
        changed = station.records.file_changed(new.database_url)
        if changed is FileChange.REMOVED:
            raise StationError(
                f"the database file {new.database_url} was removed while the daemon ran: a "
                "reload would start a new, empty database there (the vehicle's bolts done "
                "forgotten); put a copy back (a backup) and reload, or restart the daemon to "
                "start anew")
        created = station.records.new_file(new.database_url)
        vin = station.vin
        if created is not None and vin is not None:
            # a typo in database.url (a maintenance trial): the vehicle on the lift went on
            # in a new, empty database, its bolts done offered again
            raise StationError(
                f"database.url names {created}, which does not exist: a reload would start a "
                f"new, empty database while vehicle {vin} is at the station (its bolts done "
                "forgotten, offered again); check the URL (a typo?), or restart the daemon "
                "to start a new database there")
        if changed is FileChange.REPLACED:
            log.warning("reload: the database file %s was replaced while the daemon ran (a "
                        "backup put back?): the station opens that file; results stored "
                        "after it was copied are not in it", new.database_url)
        await loop.run_in_executor(None, screens.check_move, new)
        if locks is not None:   # a device another daemon drives: refused
            hold_locks(locks, new)
        for warning in warnings:
            log.warning("reload: %s", warning)
        return new
    except StationError as exc:
        more = await loop.run_in_executor(None, more_errors, cfg_path)
        log.error("reload refused, keeping the running configuration: %s%s",
                  one_line(exc), more)
        notifier.status(f"reload refused: {one_line(exc)}")
        screens.refused(one_line(exc))
    except Exception as exc:   # a bug in a reader: still never the running station
        log.exception("reload refused (an error in reading the configuration), "
                      "keeping the running configuration: %s", one_line(exc))
        notifier.status(f"reload refused: {one_line(exc)}")
        screens.refused(one_line(exc))
    return None


async def serve(cfg_path: str, cfg: StationConfig, notifier: Notifier,
                locks: StationLocks | None = None, beside: Beside | None = None) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    reload = asyncio.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    loop.add_signal_handler(signal.SIGHUP, reload.set)
    if reload_asked():   # a SIGHUP while the daemon started: its files are read again
        log.info("reload asked while starting: the station's files are read again once it "
                 "runs")
        reload.set()
    bus = EventBus()    # one for the daemon's life: the screens follow it across reloads
    screens = Screens(bus)
    watchdog = asyncio.create_task(keep_watchdog(notifier))
    try:
        await serve_station(cfg_path, cfg, notifier, bus, screens, stop, reload, locks,
                            beside)
    finally:
        watchdog.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await watchdog
        await screens.stop()


async def keep_watchdog(notifier: Notifier) -> None:
    """WATCHDOG=1 every ``watchdog_s`` for the daemon's life, from its event loop: a loop
    that stops turning (a blocked call, a deadlock) stops the pings and systemd restarts the
    daemon; a station in fault, a database that does not open at start or one locked for
    seconds (its calls run in threads) keeps them going (it was killed for those)."""
    if not notifier.watchdog_s:
        return
    while True:
        notifier.watchdog()
        await asyncio.sleep(notifier.watchdog_s)


#: a screens' port that was in use is tried again after this long, s
SCREENS_RETRY_S = 5.0


class Screens:
    """The web screens (``stationd.web``) of the running configuration: started when its
    ``http`` section asks, moved when a reload changes it.  A port in use is a logged fault of
    the screens, never of the station (the tool keeps working without them)."""

    def __init__(self, bus: EventBus, name: str | None = None) -> None:
        self.bus = bus
        #: the station's id the screens give (``/api/status``), whatever its file says: the
        #: demo's DEMO-1, named so with or without its OPC UA and line sections; None: the
        #: configuration's (``station_identity``)
        self.name = name
        self.server: Any = None
        self.frames: Any = None
        self.station: Station | None = None   # whose commands the screens take
        self.line: Any = None                  # the forwarder to the line database, if any
        self._for: tuple[Any, str] | None = None
        self._retry: asyncio.Task[None] | None = None
        self._failed: str | None = None   # why the screens are not served (logged once)

    async def follow(self, cfg: StationConfig) -> None:
        """Serve the screens ``cfg`` asks for.  A database that does not open yet serves them
        without the results pages (the operator and monitoring see the fault); called again
        once it opens, they get their results."""
        key = (cfg.http, cfg.database_url)
        if key == self._for and (cfg.http is None or (self.server is not None
                                                      and self.server.results is not None)):
            if self.server is not None:     # a reload may add or remove a pair
                self.server.set_devices(configured_devices(cfg))
            return
        if key == self._for and self.server is not None:
            # the database opened only now: the screens get their results where they are
            # served (restarted, they were away for a moment: every screen reconnected, and
            # a client asking then was refused)
            results, self.server.results_error = self._results(cfg)
            if results is not None:
                self.server.results = results
                log.info("screens: results served from %s", cfg.database_url)
            self.server.set_devices(configured_devices(cfg))
            return
        frames = self.frames if key == self._for else None   # the station holds them
        await self.stop()
        self._for = key
        if cfg.http is None:
            return
        from stationd.web import LatestFrames, WebServer

        self.frames = frames if frames is not None else LatestFrames()
        results, results_error = self._results(cfg)
        try:
            server = WebServer(self.bus, results, self.frames,
                               listen=cfg.http.listen, token=cfg.http.token,
                               images_dir=cfg.records.images_dir,
                               devices=configured_devices(cfg),
                               results_error=results_error)
            await server.start()
            self.server = server   # only once it serves (a retry's start is awaited)
            if self.station is not None:   # started late (its port freed): what is now
                server.seed(self.station.core.status())
            self.attach(self.station, cfg)
        except OPEN_ERRORS as exc:
            # a port another program holds may be freed: tried again, journaled once
            said = bind_words(exc)
            if self._failed != said:
                self._failed = said
                log.error("screens not served on %s: %s (tried again every %.0f s)",
                          cfg.http.listen, self._failed, SCREENS_RETRY_S)
            self.server = None
            self._retry = asyncio.get_running_loop().create_task(self._again(cfg, key))
            return
        self._failed = None
        log.info("screens: %s", self.server.url)

    def check_move(self, cfg: StationConfig) -> None:
        """Refuse (StationError) a reload that moves the screens to a port nothing may listen
        on now (another program holds it): the reload would close the screens the operators
        use and serve none.  Their own port passes whatever the host (127.0.0.1 to 0.0.0.0:
        their own socket holds it, and they are stopped before they listen again), and so
        does no screens.  Blocking (a host name is resolved): run off the station's loop."""
        if cfg.http is None or self.server is None:
            return
        served = self.server.config.listen
        if cfg.http.port in (self.server.config.port, self.server.port):
            return
        try:
            # every address the name gives: the screens listen on each
            for family, kind, proto, _, address in socket.getaddrinfo(
                    cfg.http.host or None, cfg.http.port, type=socket.SOCK_STREAM,
                    flags=socket.AI_PASSIVE):
                with socket.socket(family, kind, proto) as probe:
                    probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                    probe.bind(address)
        except OSError as exc:
            raise StationError(f"http.listen {cfg.http.listen}: {bind_words(exc)}; the "
                               f"screens stay on {served}") from None

    @staticmethod
    def _results(cfg: StationConfig) -> tuple[Results | None, str | None]:
        """The results pages' database, or why it is not open (journaled)."""
        from db.repository import Repository
        from stationd.web import Results

        try:
            return Results(Repository.open(cfg.database_url)), None
        except OPEN_ERRORS as exc:
            log.error("screens served without results until the database opens: %s",
                      one_line(exc))
            return None, one_line(exc)

    def attach(self, station: Station | None, cfg: StationConfig) -> None:
        """People's commands go to ``station`` (None: refused, none is running), with the
        users of ``cfg``; the status API reads the line forwarder's state."""
        self.station = station
        if self.server is not None:
            if station is not None:     # a station on this configuration runs: the file read
                self.server.reload_refused = None
            identity = station_identity(cfg)
            self.server.station = identity if self.name is None else {**identity,
                                                                      "id": self.name}
            self.server.line = lambda: None if self.line is None else self.line.last_status
            self.server.line_results.url = None if cfg.line is None else cfg.line.url
            self.server.commands.access = cfg.access
            self.server.unregistered = unregistered(cfg)
            self.server.commands.submit = None if station is None else station.submit

    def refused(self, why: str) -> None:
        """A reload was refused (``why``): the status says so until a station runs on a
        file that reads (``stationd status`` and /api/status said nothing of it, and a
        person saw only the file's error from the command that read it)."""
        if self.server is not None:
            self.server.reload_refused = why

    async def _again(self, cfg: StationConfig, key: tuple[Any, str]) -> None:
        await asyncio.sleep(SCREENS_RETRY_S)
        if self._for == key and self.server is None:
            await self.follow(cfg)

    async def stop(self) -> None:
        retry, self._retry = self._retry, None
        if retry is not None and retry is not asyncio.current_task():
            retry.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await retry
        if self.server is not None:
            try:
                await self.server.stop()
            except Exception as exc:  # stopping the screens never stops the daemon's exit
                log.warning("stopping the screens: %s", one_line(exc))
        self.server, self.frames, self._for = None, None, None


async def _reader(cfg: StationConfig, what: str) -> Any:
    """A connection of its own to the station's database for a reader of its records (the
    forwarder, the OPC UA server); None, journaled, when it does not open."""
    from db.repository import Repository

    try:
        return await asyncio.get_running_loop().run_in_executor(None, Repository.open,
                                                                 cfg.database_url)
    except OPEN_ERRORS as exc:
        log.error("%s: the station's database does not open: %s", what, one_line(exc))
        return None


async def forward(cfg: StationConfig, notifier: Notifier, screens: Screens,
                  stop: asyncio.Event, bus: EventBus | None = None,
                  tell: Callable[[Event], None] | None = None) -> None:
    """The records to the line's database while this station runs (``cfg.line``; nothing
    without it).  A line database that is down or refuses is never a fault of the station: a
    journal line (and STATUS=) at each change, the backlog in ``/api/status``; the link's
    state is told to the station's core (``tell``: :meth:`Station.tell`), which tells OPC UA.  Each
    result the ``bus`` says was recorded wakes the forwarder (the lag is then the
    forwarding, not its poll)."""
    if cfg.line is None:
        return
    from stationd.forward import Forwarder

    loop = asyncio.get_running_loop()
    repo = await _reader(cfg, "line database: not forwarding")
    if repo is None:
        return
    fwd = Forwarder(repo, cfg.line)
    screens.line = fwd

    def told(st: dict[str, Any]) -> None:
        if st["alarm"]:
            line = f"line database: ALARM: {st['alarm']}"
        elif st.get("caught_up") is not None:
            line = f"line database: caught up after the outage: every record forwarded " \
                f"({st['caught_up']} waited at most)"
        elif st["up"] is False:
            n = st["backlog"]
            line = f"line database: down ({st['last_error']}); {records_waiting(n)} (the " \
                "station goes on; its records are forwarded when it answers)"
        else:
            line = f"line database: forwarding to {st['url']} ({st['backlog']} behind)"
        (log.warning if st["alarm"] or st["up"] is False else log.info)("%s", line)
        notifier.status(line)
        if tell is not None:   # the line asset's health in OPC UA (never a station fault)
            tell(LineLinkIn(time.time(), st["up"] is not False, st["last_error"] or "",
                            st["alarm"]))

    wake = asyncio.Event()

    def heard(event: StationEvent) -> None:   # the publisher's thread: the loop sets it
        if isinstance(event, ResultRecorded):
            loop.call_soon_threadsafe(wake.set)

    unsubscribe = bus.subscribe(heard) if bus is not None else None
    try:
        await fwd.run(stop, told, wake)
    finally:
        if unsubscribe is not None:
            unsubscribe()
        screens.line = None
        await loop.run_in_executor(None, fwd.line.dispose)
        await loop.run_in_executor(None, repo.close)


async def opcua(cfg: StationConfig, bus: EventBus, stop: asyncio.Event) -> None:
    """The station's OPC UA server while it runs (``cfg.opcua``; nothing without it).  A port
    in use or a database that does not open is logged, never a fault of the station.

    The server runs on an event loop of its own, in a thread of its own: loading the
    companion models takes seconds (tens on a busy machine), and the daemon's loop, which
    runs the station and pings systemd's watchdog, must keep turning meanwhile (it stood
    still for up to 24 s, longer than the unit's WatchdogSec).  The server already writes
    its nodes from the bus's events through its own loop."""
    if cfg.opcua is None:
        return
    loop = asyncio.get_running_loop()
    repo = await _reader(cfg, "OPC UA: not served")
    if repo is None:
        return
    there: Future[tuple[asyncio.AbstractEventLoop, asyncio.Event]] = Future()   # its loop, stop
    ua_cfg, devices = cfg.opcua, opcua_devices(cfg)
    sim = results_simulated(cfg)

    def serve_there() -> None:
        asyncio.run(_opcua_on_own_loop(ua_cfg, devices, bus, repo, there, sim))

    thread = threading.Thread(target=serve_there, name="opcua", daemon=True)
    thread.start()
    try:
        await stop.wait()
    finally:
        own, own_stop = await asyncio.wrap_future(there)
        with contextlib.suppress(RuntimeError):   # its loop closed: it ended on its own
            own.call_soon_threadsafe(own_stop.set)
        await loop.run_in_executor(None, thread.join)


async def _opcua_on_own_loop(ua_cfg: OpcUaConfig, devices: tuple[str, ...], bus: EventBus,
                             repo: Any,
                             there: Future[tuple[asyncio.AbstractEventLoop, asyncio.Event]],
                             sim: bool = False) -> None:
    """:func:`opcua`'s server, on the loop of the thread it runs in, until its stop (``there``
    gets the loop and the stop, for the daemon's loop to set it); ``sim``: its results are a
    simulated controller's."""
    from stationd.opcua.server import OpcUaServer

    loop, stop = asyncio.get_running_loop(), asyncio.Event()
    there.set_result((loop, stop))
    server = OpcUaServer(ua_cfg, bus=bus, devices=devices, simulated=sim)
    try:
        if not await _started(server, stop):
            log.info("OPC UA: its start given up: the station closes (a stop or a reload)")
            with contextlib.suppress(Exception):
                await server.stop()
            await loop.run_in_executor(None, repo.close)
            return
    except Exception as exc:   # a port in use, certificates: never the station's fault
        log.error("OPC UA: not served on %s: %s", ua_cfg.endpoint, one_line(exc))
        with contextlib.suppress(Exception):
            await server.stop()
        await loop.run_in_executor(None, repo.close)
        return
    log.info("OPC UA: serving %s", ua_cfg.endpoint)
    try:
        await server.run(stop, repo)
    finally:
        await server.stop()
        await loop.run_in_executor(None, repo.close)


async def _started(server: Any, stop: asyncio.Event) -> bool:
    """Whether ``server`` started before ``stop`` was set (its start then cancelled): loading
    the companion models takes tens of seconds on a busy machine, and a daemon stopped
    meanwhile waited for it to end (an IT administrator's trial: stops of 25 to 53 s, beyond
    the unit's TimeoutStopSec, systemd's SIGKILL before the devices closed)."""
    start = asyncio.ensure_future(server.start())
    halt = asyncio.ensure_future(stop.wait())
    try:
        await asyncio.wait({start, halt}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        halt.cancel()
    if start.done():
        start.result()            # its failure raised as it was
        return True
    start.cancel()
    with contextlib.suppress(asyncio.CancelledError, Exception):
        await start
    return False


def configured_devices(cfg: StationConfig) -> tuple[str, ...]:
    """The devices the daemon opens (lift, wrench, each pair with both cameras), by the names
    its DeviceHealth events use: the screens list them before any reports."""
    return (LIFT, WRENCH, *(n for n, pc in cfg.pairs.items() if pc.left and pc.right))


def results_simulated(cfg: StationConfig) -> bool:
    """Whether the station's results are a simulated controller's: no tightening of a real
    joint, which an MES keeps apart by the results' IsSimulated (as the demo's are)."""
    return simulated(Kind.WRENCH, cfg.wrench.url)


def opcua_devices(cfg: StationConfig) -> tuple[str, ...]:
    """The devices whose health the OPC UA server shows as the JoiningSystem's assets: the
    configured ones, the station's database and, with a line section, the line database's
    link (``stationd.opcua.health``)."""
    from stationd.opcua.health import LINE_LINK

    return (*configured_devices(cfg), DATABASE, *((LINE_LINK,) if cfg.line else ()))


def locked_devices(cfg: StationConfig) -> list[tuple[str, str]]:
    """The devices the daemon drives, as ``(what, url)`` for their locks: the lift, the
    controller and both cameras of every pair wired to two (the ones it opens)."""
    cams = [(f"camera {cam}", cfg.cameras[cam]) for pc in cfg.pairs.values()
            if pc.left and pc.right for cam in (pc.left, pc.right) if cam in cfg.cameras]
    return [("lift", cfg.lift.url), ("wrench", cfg.wrench.url), *cams]


def unregistered(cfg: StationConfig) -> tuple[str, ...]:
    """The pairs of ``cfg`` not registered into the vehicle frame yet (no ``to_vehicle``):
    up and grabbing, but localizing nothing."""
    return tuple(n for n, p in cfg.pairs.items() if p.to_vehicle is None)


def hold_locks(locks: StationLocks, cfg: StationConfig) -> None:
    """Hold the locks of ``cfg``'s database and devices (one daemon per database and per
    device); raises LockHeldError, keeping what ``locks`` held, when another daemon has one."""
    locks.hold(cfg.database_url, cfg.records.images_dir, locked_devices(cfg))


async def serve_station(cfg_path: str, cfg: StationConfig, notifier: Notifier, bus: EventBus,
                        screens: Screens, stop: asyncio.Event, reload: asyncio.Event,
                        locks: StationLocks | None = None,
                        beside: Beside | None = None) -> None:
    """Run the station of ``cfg`` until ``stop``; on ``reload`` validate ``cfg_path`` anew and
    switch to it (closing and reopening every device) or keep the running one.  Separate from
    :func:`serve` (which owns the signals) so that ``bench soak`` drives the same loop.
    ``locks`` holds the one-daemon-per-database and per-device locks: a reload onto another
    database or device moves them, or is refused when another daemon holds one.  ``beside``
    runs beside each station, started before it (a simulated world is there for its first
    grab) and awaited once it stops."""
    loop = asyncio.get_running_loop()
    carried: list[Unsaved] = []   # results the last station received and could not write
    owed: list[NoteLock] = []     # ... and the NOK policy's locks it could not record
    while True:
        await screens.follow(cfg)
        station = Station(cfg, notifier=notifier, bus=bus)
        station.announce()   # the screens forget the last configuration's device reports
        station.frames = screens.frames
        station.carry(carried, owed)
        opened = await _open(station, notifier, stop, reload)
        if opened is not Opened.OPEN:
            await loop.run_in_executor(None, station.close, opened is Opened.STOPPED)
            if opened is Opened.STOPPED:
                # said as a stop with the database open is (a maintenance trial: a stop while
                # it was in fault ended the journal without a word)
                notifier.stopping("stopping")
                log.info("stopping: the database never opened; closing the devices")
                log.info("stationd stopped")
                return
            carried, owed = station.unsaved(), station.locks_owed()
            reload.clear()   # the database did not open: read the files again, retry
            again = await _reloaded(cfg_path, station, screens, locks, notifier)
            if again is not None:
                log.info("configuration reloaded; opening the database again")
                cfg = again
            continue
        await screens.follow(cfg)   # their results, if the database opened only now
        inner = asyncio.Event()
        extra = None if beside is None else asyncio.create_task(beside(cfg, station, inner))
        task = asyncio.create_task(station.run(inner))
        screens.attach(station, cfg)
        line = asyncio.create_task(forward(cfg, notifier, screens, inner, bus, station.tell))
        served = asyncio.create_task(opcua(cfg, bus, inner))
        log.info("stationd running: %s", cfg_path)
        for name in unregistered(cfg):   # config check warns; the journal says it too
            log.warning("pair %s: not registered into the vehicle frame (no to_vehicle): its "
                        "frames localize nothing until it is (stationd calibrate vehicle "
                        "--pair %s)", name, name)
        new: StationConfig | None = None
        while new is None and not stop.is_set() and not task.done():
            waiters = {asyncio.create_task(stop.wait()), asyncio.create_task(reload.wait())}
            await asyncio.wait({task, *waiters}, return_when=asyncio.FIRST_COMPLETED)
            for w in waiters:
                w.cancel()
            if reload.is_set() and not stop.is_set():
                reload.clear()
                new = await _reloaded(cfg_path, station, screens, locks, notifier)
        if new is not None and not stop.is_set():
            # systemd: reloading until the new station's READY=1 (never STOPPING=1 here)
            notifier.reloading("reloading: closing the devices")
        elif stop.is_set():
            # said at once: under load the station's last cycle, the forwarder and the
            # devices take seconds to end, and a silent journal read as a hang
            notifier.stopping("stopping: ending the station's work, then closing devices")
            log.info("stopping: the station's last cycle ends, then the devices close as "
                     "the line forwarder and OPC UA end")
        screens.attach(None, cfg)
        inner.set()
        if extra is not None:
            await _beside_ended(extra)
        try:
            await task
        except Exception as exc:  # a bug, not a device: logged, the station restarts
            log.error("station loop failed: %s: %s", type(exc).__name__, one_line(exc))
            await asyncio.sleep(1.0)
        vin = station.vin      # the vehicle on the lift as the station closes
        # the devices close as the line forwarder and OPC UA end, not after them: the tool
        # off first, within the unit's TimeoutStopSec whatever they take (an IT
        # administrator's trial: systemd's SIGKILL came while OPC UA still started)
        final = stop.is_set()
        closing = loop.run_in_executor(None, station.close, final)
        await line
        await served
        await closing
        carried, owed = station.unsaved(), station.locks_owed()
        if stop.is_set() and not final:
            # a stop came as a reload closed the station: what it would have carried on is
            # journaled now, the only copy left (a reviewer: neither journaled nor carried)
            station.journal_unsaved()
        if stop.is_set():
            notifier.stopping("closing devices")
            log.info("stationd stopped")
            return
        if new is not None:
            log.info("configuration reloaded; reopening the devices")
            lost = vehicle_lost(vin, cfg, new)
            if lost is not None:
                log.warning("%s", lost)
            cfg = new


def vehicle_lost(vin: str | None, old: StationConfig, new: StationConfig) -> str | None:
    """Why a reload cannot keep the vehicle ``vin`` (open as the last station closed) as it
    was, in one line for the journal; None when it can: the new station reads the lift (a
    real PLC goes on through a reload; the simulated one is carried over) and the same
    database, so it reopens the vehicle with what was done.  A lift that reports another
    vehicle, or a bolt table without its model, is said by the station as it opens.  Why: a
    reload is taken for one that keeps the vehicle; one that cannot must say so, not leave a
    vehicle open for good with its bolts "missing"."""
    if vin is None:
        return None
    if new.database_url != old.database_url:
        return (f"reload: vehicle {vin} cannot go on as it was: its record is in the last "
                f"database ({old.database_url}); the new one ({new.database_url}) opens it "
                "anew, without its bolts done so far")
    return None


async def _beside_ended(task: asyncio.Task[None]) -> None:
    """What ran beside a station has ended with it; its failure is journaled, never the
    daemon's."""
    try:
        await task
    except Exception as exc:
        log.error("beside the station: %s: %s", type(exc).__name__, one_line(exc))


def run_daemon(args: argparse.Namespace, beside: Beside | None = None) -> int:
    """``stationd run``; ``beside``: see :func:`serve_station`."""
    # one line per event; stamped unless systemd's journal takes them (it stamps them)
    setup_logging(logging.INFO, sys.stderr)
    logging.getLogger("alembic").setLevel(logging.WARNING)
    logging.getLogger("asyncua").setLevel(logging.WARNING)   # ~1000 lines per start otherwise
    # an invalid station at the first start: exit 2
    cfg = validate_station(args.config, log.warning)
    locks = StationLocks()
    # a second daemon on this database or on one of its devices: one line naming the holder
    # and the device, exit 2 (taken before any device is opened)
    hold_locks(locks, cfg)
    try:
        asyncio.run(serve(args.config, cfg, Notifier(), locks, beside))
    finally:
        locks.release()
    return 0
