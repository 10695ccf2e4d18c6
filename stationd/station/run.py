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
import logging
import signal
import sys
from pathlib import Path

from db.boltfile import load_bolts
from stationd.config import StationConfig, load_station_config
from stationd.errors import StationError
from stationd.station.daemon import Station, one_line
from stationd.station.sdnotify import Notifier

log = logging.getLogger("stationd")
OPEN_RETRY_S = (1.0, 30.0)   # a database that does not open: first and longest wait


def validate_station(path: str | Path) -> StationConfig:
    """The whole station, checked before it is used: the file and every file it names (the
    loader reads calibrations and transforms) and the bolt table, with the station's own
    matching tolerance.  Raises the first error (one line, file and key)."""
    cfg = load_station_config(path)
    if cfg.bolts_path is not None:
        load_bolts(cfg.bolts_path, tolerance_mm=cfg.matching.tolerance_mm)
    return cfg


async def _open(station: Station, notifier: Notifier, stop: asyncio.Event) -> bool:
    """Open the station's database (its devices are the station's to retry); a database that
    does not open is retried with backoff, never an exit.  False if stopped meanwhile."""
    loop = asyncio.get_running_loop()
    wait = OPEN_RETRY_S[0]
    told = False
    while not stop.is_set():
        try:
            await loop.run_in_executor(None, station.open)
            return True
        except StationError as exc:
            log.error("fault: database: %s (retrying in %.0f s)", one_line(exc), wait)
            if not told:
                notifier.ready(f"fault: database: {one_line(exc)}")
                told = True
            notifier.status(f"fault: database: {one_line(exc)}")
        try:
            await asyncio.wait_for(stop.wait(), wait)
        except TimeoutError:
            pass
        wait = min(OPEN_RETRY_S[1], wait * 2)
    return False


async def serve(cfg_path: str, cfg: StationConfig, notifier: Notifier) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    reload = asyncio.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    loop.add_signal_handler(signal.SIGHUP, reload.set)
    while True:
        station = Station(cfg, notifier=notifier)
        if not await _open(station, notifier, stop):
            await loop.run_in_executor(None, station.close)
            notifier.stopping("stopping")
            return
        inner = asyncio.Event()
        task = asyncio.create_task(station.run(inner))
        log.info("stationd running: %s", cfg_path)
        new: StationConfig | None = None
        while new is None and not stop.is_set() and not task.done():
            waiters = {asyncio.create_task(stop.wait()), asyncio.create_task(reload.wait())}
            await asyncio.wait({task, *waiters}, return_when=asyncio.FIRST_COMPLETED)
            for w in waiters:
                w.cancel()
            if reload.is_set() and not stop.is_set():
                reload.clear()
                try:  # validate first: an invalid station never stops the running one
                    new = await loop.run_in_executor(None, validate_station, cfg_path)
                except StationError as exc:
                    log.error("reload refused, keeping the running configuration: %s",
                              one_line(exc))
                    notifier.status(f"reload refused: {one_line(exc)}")
        inner.set()
        try:
            await task
        except Exception as exc:  # a bug, not a device: logged, the station restarts
            log.error("station loop failed: %s: %s", type(exc).__name__, one_line(exc))
            await asyncio.sleep(1.0)
        await loop.run_in_executor(None, station.close)
        if stop.is_set():
            notifier.stopping("closing devices")
            log.info("stationd stopped")
            return
        if new is not None:
            log.info("configuration reloaded; reopening the devices")
            cfg = new


def run_daemon(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(levelname)s %(message)s")  # one line per event (journal)
    logging.getLogger("alembic").setLevel(logging.WARNING)
    cfg = validate_station(args.config)  # an invalid station at the first start: exit 2
    asyncio.run(serve(args.config, cfg, Notifier()))
    return 0
