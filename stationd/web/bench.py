"""What the screens cost the daemon: the live fan-out with browsers connected.

``fanout_bench(seconds, rate_hz, clients)`` runs the station's loop in a thread publishing
localizations at ``rate_hz`` (the rate the daemon publishes them for the screens; a result
now and then), first without a server, then with the server and ``clients`` SSE clients
reading in another thread (as browsers would, out of the loop), and reports the loop
thread's CPU in both runs (``time.thread_time`` inside the loop thread: the clients' own
reading is not counted), the loop's scheduling lag (a 5 ms timer's overshoot, p95: what the
station's own coroutines would wait for the screens' work) and what each client received.

``ScreenClients`` connects the screens' real clients to a running server for ``stationd bench
station --browsers N``: headless Chromium windows (Debian's ``chromium``, no driver needed:
the page runs by itself), alternately on ``/`` and ``/cameras``; where Chromium cannot start,
SSE readers for ``/`` and page-plus-frames loaders for ``/cameras`` stand in, and ``kind``
says which.
"""

from __future__ import annotations

import asyncio
import contextlib
import http.client
import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
import urllib.request
from typing import Any

from stationd.bus import EventBus
from stationd.station.events import BoltView, Localized, ResultRecorded, VehicleOpened
from stationd.web.server import WebServer


def _vehicle() -> VehicleOpened:
    bolts = tuple(BoltView(f"B{i}", 100.0 * (i % 6), 150.0 * (i // 6), 0.0, 1, order=i)
                  for i in range(24))
    return VehicleOpened(vin="BENCH0000000001", model="BENCH", bolts=bolts)


async def _publish(bus: EventBus, seconds: float, rate_hz: float) -> int:
    n = 0
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        bus.publish(Localized(point_mm=(float(n % 500), 100.0, 0.0), tilt_deg=2.0, reason=None,
                              candidate="B1", distance_mm=3.0, age_ms=40.0,
                              allowed=("B1", "B2")))
        if n % 25 == 24:
            bus.publish(ResultRecorded(vin="BENCH0000000001", bolt=f"B{n % 24}", ok=True,
                                       torque_nm=50.0, angle_deg=30.0, tightening_id=n))
        n += 1
        await asyncio.sleep(1.0 / rate_hz)
    return n


async def _lag_probe(stop: asyncio.Event, lags: list[float]) -> None:
    while not stop.is_set():
        t0 = time.perf_counter()
        await asyncio.sleep(0.005)
        lags.append((time.perf_counter() - t0 - 0.005) * 1000.0)


def _p95(xs: list[float]) -> float:
    ys = sorted(xs)
    return ys[min(len(ys) - 1, int(0.95 * len(ys)))] if ys else 0.0


def _client(port: int, stop: threading.Event, got: dict[str, int]) -> None:
    # a blocking read: an idle station sends nothing for minutes, and a socket that timed
    # out once cannot be read again; the stream ends when the server stops (it closes it)
    conn = http.client.HTTPConnection("127.0.0.1", port)
    conn.request("GET", "/api/events")
    resp = conn.getresponse()
    while not stop.is_set():
        try:
            line = resp.fp.readline()
        except OSError:
            break
        if not line:
            break
        got["bytes"] += len(line)
        if line.startswith(b"data: "):
            got["snapshots"] += 1
    conn.close()


def _cameras_client(url: str, stop: threading.Event, width: int = 960, shown: int = 4
                    ) -> None:
    """What the cameras screen does in a 1920x1080 window, without a browser: the page,
    every frame once, then each second the cameras' list and the frames in view (the first
    ``shown``: one pair and the top of the next) at the width it shows them."""
    def get(path: str) -> bytes:
        with urllib.request.urlopen(url + path, timeout=10) as r:  # noqa: S310 - loopback
            return bytes(r.read())
    get("cameras")
    first = True
    while not stop.is_set():
        try:
            cams = json.loads(get("api/cameras"))
            for c in cams if first else cams[:shown]:
                get(f"api/cameras/{c['pair']}/{c['side']}/frame.jpg?w={width}")
            first = not cams
        except OSError:
            pass
        stop.wait(1.0)


class ScreenClients:
    """``n`` clients of the screens at ``url``: ``start()`` returns their kind
    ("chromium" or "sse"), ``close()`` ends them.  Browser ``i`` shows ``/`` when ``i`` is
    even, ``/cameras`` when odd (two browsers: the operator's and the commissioning one)."""

    def __init__(self, url: str, n: int, force_sse: bool = False,
                 nice: int | str = 0) -> None:
        self.url, self.n = url, n
        self.nice = nice
        self.pages = ["" if i % 2 == 0 else "cameras" for i in range(n)]
        self.kind = "none"
        self.why_not_chromium = ""
        self._procs: list[subprocess.Popen[bytes]] = []
        self._dirs: list[tempfile.TemporaryDirectory[str]] = []
        self._stop_mp: Any = None
        self._stand_ins: Any = None   # a multiprocessing Process
        self._force_sse = force_sse

    def start(self) -> str:
        exe = shutil.which("chromium") or shutil.which("chromium-browser")
        if exe is not None and not self._force_sse:
            try:
                for page in self.pages:
                    d = tempfile.TemporaryDirectory(prefix="stationd-bench-browser-")
                    self._dirs.append(d)
                    niced = (["chrt", "--idle", "0"] if self.nice == "idle" else
                             ["nice", "-n", str(self.nice)] if self.nice else [])
                    self._procs.append(subprocess.Popen(  # noqa: S603 - a fixed argv
                        [*niced, exe, "--headless", "--no-sandbox", "--disable-gpu",
                         "--disable-dev-shm-usage", "--no-first-run", "--disable-sync",
                         "--disable-background-networking", "--disable-component-update",
                         f"--user-data-dir={d.name}", "--window-size=1920,1080",
                         self.url + page],
                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
                self.kind = "chromium"
                return self.kind
            except OSError as exc:
                self.why_not_chromium = str(exc)
                self._end_browsers()
        else:
            self.why_not_chromium = "forced" if self._force_sse else "chromium not installed"
        return self.fallback()

    def fallback(self) -> str:
        """SSE readers and frame loaders instead of browsers, in a process of their own (as
        browsers on the panel PCs: the daemon serves the same requests, and their reading
        neither holds its GIL nor counts as its CPU)."""
        self._end_browsers()
        self.kind = "sse"
        ctx = multiprocessing.get_context("spawn")   # not a fork of the daemon's threads
        self._stop_mp = ctx.Event()
        proc = ctx.Process(target=stand_ins, args=(self.url, self.pages, self._stop_mp),
                           name="stationd-bench-screens", daemon=True)
        proc.start()
        self._stand_ins = proc
        return self.kind

    def alive(self) -> bool:
        return all(p.poll() is None for p in self._procs)

    def hold(self, held: bool) -> None:
        """Stop (SIGSTOP) or continue (SIGCONT) every client process: ``bench station
        --paired`` alternates bolts with the clients running and held within one pass, so
        the machine's drift between passes does not enter the difference.  A held client
        stays connected (its streams fill their buffers; the server drops old snapshots)."""
        sig = signal.SIGSTOP if held else signal.SIGCONT
        for pid in tree_pids(self._roots()):
            with contextlib.suppress(OSError):
                os.kill(pid, sig)

    def _roots(self) -> list[int]:
        pids = [p.pid for p in self._procs]
        if self._stand_ins is not None and self._stand_ins.pid is not None:
            pids.append(self._stand_ins.pid)
        return pids

    def cpu_s(self) -> float:
        """CPU seconds the browsers (or their stand-ins) have used so far."""
        return tree_cpu_s(self._roots())

    def _end_browsers(self) -> None:
        for p in self._procs:
            if p.poll() is None:
                p.terminate()
        for p in self._procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self._procs = []
        for d in self._dirs:
            with contextlib.suppress(OSError):
                d.cleanup()
        self._dirs = []

    def close(self) -> None:
        self.hold(False)     # a stopped process does not act on SIGTERM
        self._end_browsers()
        if self._stand_ins is not None:
            self._stop_mp.set()
            self._stand_ins.join(10)
            if self._stand_ins.is_alive():
                self._stand_ins.kill()
                self._stand_ins.join()
            self._stand_ins = None


def stand_ins(url: str, pages: list[str], stop: Any) -> None:
    """The stand-in clients' process: one thread per page (``""``: the operator's event
    stream, ``"cameras"``: the cameras screen), until ``stop`` (a multiprocessing Event)."""
    port = int(url.rstrip("/").rsplit(":", 1)[1])
    done = threading.Event()
    threads = []
    for page in pages:
        if page == "":
            t = threading.Thread(target=_client, args=(port, done, {"bytes": 0, "snapshots": 0}),
                                 daemon=True)
        else:
            t = threading.Thread(target=_cameras_client, args=(url, done), daemon=True)
        t.start()
        threads.append(t)
    stop.wait()
    done.set()


def _proc_table() -> tuple[dict[int, int], dict[int, float]]:
    """Every process's parent and CPU seconds (its own and its reaped children's), from
    ``/proc``; empty where it cannot be read."""
    parent: dict[int, int] = {}
    times: dict[int, float] = {}
    tick = float(os.sysconf("SC_CLK_TCK")) if hasattr(os, "sysconf") else 100.0
    try:
        pids = [int(d) for d in os.listdir("/proc") if d.isdigit()]
    except OSError:
        return parent, times
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat", "rb") as f:
                fields = f.read().rsplit(b")", 1)[1].split()
        except (OSError, IndexError):
            continue   # ended meanwhile
        parent[pid] = int(fields[1])
        times[pid] = sum(int(x) for x in fields[11:15]) / tick
    return parent, times


def tree_pids(roots: list[int], parent: dict[int, int] | None = None) -> set[int]:
    """``roots`` and all their descendants (a browser is a tree of processes)."""
    if parent is None:
        parent = _proc_table()[0]
    wanted = set(roots)
    grew = True
    while grew:
        more = {p for p, pp in parent.items() if pp in wanted and p not in wanted}
        wanted |= more
        grew = bool(more)
    return wanted


def tree_cpu_s(roots: list[int]) -> float:
    """User and system CPU seconds of the processes ``roots`` and all their descendants,
    from ``/proc`` (those that ended count through their parent's reaped-children times).
    0 where ``/proc`` cannot be read."""
    parent, times = _proc_table()
    return sum(times.get(p, 0.0) for p in tree_pids(roots, parent))


def _run(seconds: float, rate_hz: float, clients: int, serve: bool) -> dict[str, Any]:
    loop = asyncio.new_event_loop()
    th = threading.Thread(target=loop.run_forever, daemon=True)
    th.start()

    def call(coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, loop).result(timeout=seconds + 30)

    bus = EventBus(history=10_000)
    bus.publish(_vehicle())
    srv = WebServer(bus, listen="127.0.0.1:0") if serve else None
    got = [{"bytes": 0, "snapshots": 0} for _ in range(clients if serve else 0)]
    stop = threading.Event()
    readers = []
    if srv is not None:
        call(srv.start())
        port = int(srv.url.rsplit(":", 1)[1].strip("/"))
        readers = [threading.Thread(target=_client, args=(port, stop, g), daemon=True)
                   for g in got]
        for r in readers:
            r.start()
        deadline = time.monotonic() + 5
        while srv.clients < clients and time.monotonic() < deadline:
            time.sleep(0.01)
    lags: list[float] = []

    async def measured() -> tuple[int, float, float]:
        probe_stop = asyncio.Event()
        probe = asyncio.get_running_loop().create_task(_lag_probe(probe_stop, lags))
        c0, w0 = time.thread_time(), time.monotonic()
        n = await _publish(bus, seconds, rate_hz)
        c1, w1 = time.thread_time(), time.monotonic()
        probe_stop.set()
        await probe
        return n, c1 - c0, w1 - w0

    published, cpu_s, wall_s = call(measured())
    stop.set()
    if srv is not None:
        call(srv.stop())
    for r in readers:
        r.join(5)
    loop.call_soon_threadsafe(loop.stop)
    th.join(5)
    loop.close()
    return {"published": published, "cpu_pct": 100.0 * cpu_s / wall_s, "lag_p95_ms": _p95(lags),
            "snapshots_per_client": [g["snapshots"] for g in got],
            "kbytes_per_client": [round(g["bytes"] / 1024, 1) for g in got]}


def fanout_bench(seconds: float = 3.0, rate_hz: float = 30.0, clients: int = 2
                 ) -> dict[str, Any]:
    """The loop thread's CPU (% of a core) publishing without a server and with the server
    and ``clients`` connected; ``extra_cpu_pct`` is the screens' cost."""
    base = _run(seconds, rate_hz, 0, serve=False)
    served = _run(seconds, rate_hz, clients, serve=True)
    return {"seconds": seconds, "rate_hz": rate_hz, "clients": clients,
            "published": served["published"], "cpu_pct_without": round(base["cpu_pct"], 2),
            "cpu_pct_with": round(served["cpu_pct"], 2),
            "extra_cpu_pct": round(served["cpu_pct"] - base["cpu_pct"], 2),
            "loop_lag_p95_ms_without": round(base["lag_p95_ms"], 2),
            "loop_lag_p95_ms_with": round(served["lag_p95_ms"], 2),
            "snapshots_per_client": served["snapshots_per_client"],
            "kbytes_per_client": served["kbytes_per_client"]}


def main(argv: list[str] | None = None) -> int:
    """``python -m stationd.web.bench [SECONDS] [RATE_HZ]``: the fan-out figures as JSON."""
    import argparse
    import json

    ap = argparse.ArgumentParser(prog="python -m stationd.web.bench",
                                 description="what the screens' live fan-out costs the "
                                 "daemon's loop, with and without two SSE clients")
    ap.add_argument("seconds", nargs="?", type=float, default=3.0,
                    help="each run's length (default: %(default)s)")
    ap.add_argument("rate_hz", nargs="?", type=float, default=30.0,
                    help="localizations published per second (default: %(default)s)")
    args = ap.parse_args(argv)
    if not (0 < args.seconds <= 3600 and 0 < args.rate_hz <= 1000):
        ap.error("SECONDS must be in (0, 3600] and RATE_HZ in (0, 1000]")
    print(json.dumps(fanout_bench(args.seconds, args.rate_hz), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
