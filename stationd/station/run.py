"""``stationd run --config station.yaml``: the daemon as systemd runs it.

READY=1 once the devices are open; STATUS= on every state change; WATCHDOG=1 as the unit asks.
SIGTERM (and SIGINT) stop the loop, disable the tool and close every device in order, then
exit 0.  SIGHUP re-reads the configuration: a valid one replaces the running station (devices
reopened), an invalid one is logged with its reason and the running one stays.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys

from stationd.config import StationConfig, load_station_config
from stationd.errors import StationError
from stationd.station.daemon import Station
from stationd.station.sdnotify import Notifier

log = logging.getLogger("stationd")


async def serve(cfg_path: str, cfg: StationConfig, notifier: Notifier) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    reload = asyncio.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    loop.add_signal_handler(signal.SIGHUP, reload.set)
    while True:
        station = Station(cfg, notifier=notifier)
        await loop.run_in_executor(None, station.open)
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
                try:  # validate first: an invalid file never stops the running station
                    new = load_station_config(cfg_path)
                except StationError as exc:
                    log.error("reload refused, keeping the running configuration: %s", exc)
                    notifier.status(f"reload refused: {exc}")
        inner.set()
        await task
        if new is not None and not stop.is_set():
            log.info("configuration reloaded; reopening the devices")
            await loop.run_in_executor(None, station.close)
            cfg = new
            continue
        notifier.stopping("closing devices")
        await loop.run_in_executor(None, station.close)
        log.info("stationd stopped")
        return


def run_daemon(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(levelname)s %(message)s")  # one line per event (journal)
    logging.getLogger("alembic").setLevel(logging.WARNING)
    cfg = load_station_config(args.config)  # an invalid config at start: exit 2
    asyncio.run(serve(args.config, cfg, Notifier()))
    return 0
