"""``stationd bench station --opcua --line``: the station with its OPC UA server (an MES
subscribed in a process of its own) and its forwarder to a line PostgreSQL, against the same
plan without them.

Two figures: each OPC UA result event's delay from the moment its result was stored (the
station's ResultRecorded, published after the commit) to its arrival at the subscribed client
(target <= 100 ms), and the daemon's latency from exposure to acknowledgement with these
services on against off (it should not move beyond the machine's noise: they read the
station's database on their own connections, after the commit, never on the way to the
controller).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import numpy as np

from stationd.config import StationConfig
from stationd.demo.services import StationServices
from stationd.shell.daemon import Station
from stationd.station.events import ResultRecorded, StationEvent

#: the client's requested publishing interval, ms (an MES that wants its events at once)
PUBLISHING_MS = 10.0
#: after the last bolt, this long for the last event to arrive, s
SETTLE_S = 1.0


class Listener:
    """The MES: :mod:`stationd.bench.ua_listener` in its own process."""

    def __init__(self, url: str) -> None:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
        self.proc = subprocess.Popen(   # noqa: S603 - this interpreter, this package
            [sys.executable, "-m", "stationd.bench.ua_listener", url, str(PUBLISHING_MS)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            text=True, env=env)
        self.events: list[dict[str, Any]] = []
        self.ready = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None  # noqa: S101 - piped above
        for line in self.proc.stdout:
            doc = json.loads(line)
            if doc.get("ready"):
                self.ready.set()
            else:
                self.events.append(doc)

    def close(self) -> None:
        if self.proc.stdin is not None:
            with contextlib.suppress(OSError):
                self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def delays_ms(stored: list[tuple[str, float]], received: list[dict[str, Any]]) -> list[float]:
    """Each event's delay after its result was stored: the k-th result stored for a bolt
    with the k-th event naming that bolt (results are published in the order stored)."""
    at: dict[str, list[float]] = {}
    for bolt, t in stored:
        at.setdefault(bolt, []).append(t)
    seen: dict[str, int] = {}
    out = []
    for e in received:
        bolt = str(e["bolt"])
        k = seen.get(bolt, 0)
        seen[bolt] = k + 1
        if k < len(at.get(bolt, [])):
            out.append(1e3 * (float(e["t"]) - at[bolt][k]))
    return out


@asynccontextmanager
async def services_on(cfg: StationConfig, station: Station, info: dict[str, Any]
                      ) -> AsyncIterator[None]:
    """The station's OPC UA server (with the MES subscribed) and forwarder while the plan
    runs; ``info`` gets the events' delays and what the line database took."""
    stored: list[tuple[str, float]] = []

    def heard(event: StationEvent) -> None:     # the publisher's thread, after the commit
        if isinstance(event, ResultRecorded):
            stored.append((event.bolt, time.monotonic()))

    unsubscribe = station.bus.subscribe(heard)
    svc = StationServices(cfg, station.bus, tell=station.tell)
    await svc.start()
    listener = None
    loop = asyncio.get_running_loop()
    try:
        if cfg.opcua is not None:
            if svc.opcua is None:
                raise RuntimeError(f"OPC UA: {svc.problem}")
            listener = Listener(cfg.opcua.endpoint)
            if not await loop.run_in_executor(None, listener.ready.wait, 60):
                raise RuntimeError("the OPC UA client did not subscribe in 60 s")
        yield
        await asyncio.sleep(SETTLE_S)
        info["line_drained"] = await svc.drain()
    finally:
        if listener is not None:
            await loop.run_in_executor(None, listener.close)
        await svc.stop()
        unsubscribe()
    info["stored"] = len(stored)
    if listener is not None:
        info["events"] = len(listener.events)
        info["event_delay_ms"] = delays_ms(stored, listener.events)


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def services_summary(on: list[dict[str, Any]], off: list[dict[str, Any]], opcua: bool,
                     line: bool, interval: list[float]) -> dict[str, Any]:
    """The passes with the services against those without (latencies pooled)."""
    lat_on = [x for r in on for x in r["latency"]]
    lat_off = [x for r in off for x in r["latency"]]
    delays = [x for r in on for x in r.get("event_delay_ms", [])]
    return {
        "opcua": opcua, "line": line, "passes": len(on),
        "opcua_event_delay_ms": {"n": len(delays), "p50": _pct(delays, 50),
                                 "p95": _pct(delays, 95),
                                 "max": max(delays, default=float("nan")),
                                 "target_p95": 100.0} if opcua else None,
        "events": sum(r.get("events", 0) for r in on) if opcua else None,
        "stored": sum(r.get("stored", 0) for r in on),
        "line_drained": all(r.get("line_drained", True) for r in on) if line else None,
        "with": {"p50": _pct(lat_on, 50), "p95": _pct(lat_on, 95), "n": len(lat_on)},
        "without": {"p50": _pct(lat_off, 50), "p95": _pct(lat_off, 95), "n": len(lat_off)},
        "delta": {"p50_ms": _pct(lat_on, 50) - _pct(lat_off, 50),
                  "p95_ms": _pct(lat_on, 95) - _pct(lat_off, 95)},
        "delta_p95_interval_ms": interval,
    }


def print_services(s: dict[str, Any]) -> None:
    what = " and ".join(x for x in (("OPC UA (an MES subscribed in its own process)"
                                     if s["opcua"] else ""),
                                    "forwarding to a line PostgreSQL" if s["line"] else "")
                        if x)
    print(f"services: {what}, {s['passes']} pass(es) with them, framed by passes without")
    d = s["opcua_event_delay_ms"]
    if d is not None:
        print(f"  OPC UA result event after the result was stored: p50 {d['p50']:.1f} ms, "
              f"p95 {d['p95']:.1f} ms, max {d['max']:.1f} ms ({s['events']} events of "
              f"{s['stored']} results; publishing interval {PUBLISHING_MS:g} ms; target p95 "
              "<= 100 ms)")
    if s["line_drained"] is not None:
        every = "every record" if s["line_drained"] else "NOT every record"
        print(f"  line database: {every} forwarded by the end of each pass")
    w, wo, dl = s["with"], s["without"], s["delta"]
    lo, hi = s["delta_p95_interval_ms"]
    print(f"  latency exposure -> acknowledged: with p50 {w['p50']:.1f} ms, p95 {w['p95']:.1f} "
          f"ms ({w['n']}); without p50 {wo['p50']:.1f} ms, p95 {wo['p95']:.1f} ms "
          f"({wo['n']}): p95 {dl['p95_ms']:+.1f} ms (90 % interval {lo:+.1f} to {hi:+.1f} ms)")


__all__ = ["Listener", "delays_ms", "print_services", "services_on", "services_summary"]
