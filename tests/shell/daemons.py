"""The scaffolding of the tests that run a whole daemon, in one place (it was written again in
each test module that needed it).

Two harnesses, for two kinds of test:

* in the test process (:func:`station`, :func:`scenario`): a :class:`Station` on config/sim,
  its lift PLC over Modbus TCP and its controller over Open Protocol on loopback, its
  ``sim://`` cameras rendered by a :class:`World`; the test drives the world and the devices
  and reads the station's bus.  Waits are :func:`until_async` on the station's loop.
* as systemd runs it (:class:`Proc`): ``station_proc.py`` (the real ``serve`` with its
  signals) on a copy of config/sim (:func:`sim_station`) whose devices are served from the
  test process (:func:`serve_devices`, :func:`at_height`, all of it :func:`tracking`); the
  test reads its journal and its notification socket, and the daemon must stop cleanly after
  it (:func:`stops_cleanly`).  Waits are :func:`until`, off any loop.
"""

from __future__ import annotations

import asyncio
import os
import random
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from contextlib import asynccontextmanager, contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim.controller import SimController
from stationd.config import load_station_config
from stationd.demo.station import SIM_CONFIG, simulators
from stationd.shell.daemon import Station
from stationd.sim.devices_cli import psets_of
from stationd.sim.world import World
from tests.shell.notify import NotifyManager

SIM = Path(__file__).resolve().parents[2] / "config" / "sim"
PROC = Path(__file__).with_name("station_proc.py")

# The simulator ray-casts 20 MP frames on the machine's shared cores, seconds after their
# exposure when the machine is busy; the in-process tests are about the wiring, so they accept
# old frames (freshness, counted from the exposure, is the core's, tested in test_core).
WIRING_MAX_AGE_S = 30.0


def free_port() -> int:
    """A loopback port nothing uses now, for a device the test starts later.  Taken below
    the kernel's ephemeral range: a port the kernel gave out (``bind(0)``) is also the one it
    may give next as the local port of an outgoing connection, and a daemon connecting
    meanwhile held the controller's port when its simulator came to listen on it (CI once:
    "Address already in use").  Random, so that two test processes rarely try the same."""
    low = _ephemeral_low()
    rng = random.Random()
    for _ in range(200):
        port = rng.randrange(20000, low)
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket() as s:      # the range full: the kernel's choice
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _ephemeral_low() -> int:
    """The first port of the kernel's ephemeral range (Linux's default 32768 elsewhere)."""
    try:
        low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768
    return low if low > 20100 else 32768


def until(pred: Callable[[], Any], timeout: float, what: str) -> None:
    """Poll ``pred`` off any event loop until it is truthy; fail naming ``what``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return
        time.sleep(0.05)
    raise AssertionError(f"not reached in {timeout} s: {what}")


def taken(path: Path, text: str) -> bool:
    """Whether the world of ``station_proc.py`` has what ``path`` (its POSE file or
    ``knock``) says, ``text``: it acknowledged it in ``PATH.taken``."""
    done = path.with_name(path.name + ".taken")
    return done.exists() and done.read_text() == text.strip()


async def until_async(pred: Callable[[], Any], timeout: float,
                      what: str | Callable[[], str] = "condition") -> bool:
    """Poll ``pred`` on the station's loop (the station runs between two polls) until it is
    truthy; fail naming ``what`` (called then, when it says the station's state)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        await asyncio.sleep(0.05)
    raise AssertionError(f"not reached in {timeout} s: {what() if callable(what) else what}")


# -- in the test process ---------------------------------------------------------------------
def station(tmp_path: Path, config: Path | None = None, **wrench_kw: Any
            ) -> tuple[Station, World]:
    """An opened station on ``config`` (default: this module's ``SIM_CONFIG``, which a test
    may point at a copy) with its database in ``tmp_path``, and the world its cameras see;
    ``wrench_kw`` go to the simulated controller."""
    cfg = load_station_config(config or SIM_CONFIG)
    cfg = replace(cfg, database_url=f"sqlite:///{tmp_path}/s.db",
                  matching=replace(cfg.matching, max_age_s=WIRING_MAX_AGE_S))
    assert cfg.bolts_path is not None
    st = Station(cfg, device_kw={"wrench": {"psets": psets_of(cfg.bolts_path), **wrench_kw}})
    st.open()
    return st, World(cfg, seed=1)


def vehicle_bolts(st: Station) -> dict[str, Any]:
    """The loaded vehicle's bolts as the database has them (the test's truth)."""
    assert st.repo is not None and st.core.model is not None
    return {b.bolt_id: b for b in st.repo.bolts_for_model(st.core.model)}


@asynccontextmanager
async def running(st: Station) -> AsyncIterator[None]:
    """The station's loop running for the block (on the block's loop), stopped after it
    whatever happened."""
    stop = asyncio.Event()
    task = asyncio.create_task(st.run(stop))
    try:
        yield
    finally:
        stop.set()
        await task


def run_station(st: Station, world: World,
                body: Callable[[Station, World], Awaitable[None]]) -> None:
    """``body`` with the station's loop running, then the loop stopped and both closed."""
    async def main() -> None:
        async with running(st):
            await body(st, world)

    try:
        asyncio.run(main())
    finally:
        world.close()
        st.close()


def scenario(tmp_path: Path, body: Callable[[Station, World], Awaitable[None]],
             vin: str = "FAULTVIN000000001",
             prepare: Callable[[Station], None] | None = None, loaded: bool = True,
             **wrench_kw: Any) -> Station:
    """The daemon running, a vehicle on the lift raised (loaded, unless ``loaded`` is False:
    a test of a failing load waits for it itself), then ``body``; ``prepare(st)`` runs on
    the opened station before its loop."""
    st, world = station(tmp_path, **wrench_kw)
    if prepare is not None:
        prepare(st)

    async def arrived(st: Station, world: World) -> None:
        plc = simulators(st)[0]
        plc.set_vehicle(1, vin)
        plc.raise_lift()
        if loaded:
            await until_async(lambda: st.vin is not None, 30, f"{vin} loaded")
        await body(st, world)

    run_station(st, world, arrived)
    return st


# -- as systemd runs it ----------------------------------------------------------------------
def sim_station(tmp: Path, lift_url: str, ctl_port: int,
                edit: Callable[[str], str] | None = None) -> Path:
    """config/sim copied into ``tmp``, its station file (returned) on the lift PLC at
    ``lift_url`` and the controller on loopback ``ctl_port``, its database in ``tmp``, no
    screens, frames up to 5 s old accepted (the simulator renders 20 MP on shared cores,
    seconds after the exposure when the machine is busy: freshness is test_core's); ``edit``
    makes the final text."""
    for f in SIM.iterdir():
        shutil.copy(f, tmp)
    station = tmp / "station.yaml"
    text = station.read_text()
    for old, new in (("sim://lift", lift_url),
                     ("sim://wrench", f"openprotocol://127.0.0.1:{ctl_port}"),
                     ("sqlite:///stationd-sim.db", f"sqlite:///{tmp}/station.db"),
                     ("max_age_s: 0.5", "max_age_s: 5.0"),
                     ("http: {listen: '127.0.0.1:8080'}", "")):
        assert old in text
        text = text.replace(old, new)
    station.write_text(edit(text) if edit else text)
    return station


class Proc:
    """``station_proc.py`` on a copy of config/sim whose lift and controller are on loopback
    ports (nothing listening until the test says so); the journal goes to a file."""

    def __init__(self, tmp: Path, lift_port: int, ctl_port: int,
                 edit: Callable[[str], str] | None = None) -> None:
        sim_station(tmp, f"modbus-tcp://127.0.0.1:{lift_port}?timeout=0.5", ctl_port, edit)
        (tmp / "pose").write_text("")
        self.tmp = tmp
        self.sock = NotifyManager(tmp / "notify")
        self.log_path = tmp / "daemon.log"
        self._err = self.log_path.open("w")
        env = {**os.environ, "NOTIFY_SOCKET": str(tmp / "notify"), "PYTHONUNBUFFERED": "1"}
        self.p = subprocess.Popen([sys.executable, str(PROC), str(tmp / "station.yaml"),
                                   str(tmp / "pose")], cwd=tmp, stderr=self._err, env=env)

    def status(self, needle: str, timeout: float = 90) -> list[str]:
        return list(self.sock.until(needle, timeout))

    def log(self) -> str:
        return self.log_path.read_text()

    def wait_log(self, needle: str, timeout: float = 90, count: int = 1) -> None:
        end = time.monotonic() + timeout
        while (time.monotonic() < end and self.log().count(needle) < count
               and self.p.poll() is None):
            time.sleep(0.1)
        assert self.log().count(needle) >= count, \
            f"{needle!r} not {count} time(s) in the journal: {self.log()[-3000:]}"

    def stop(self) -> int:
        self.p.send_signal(signal.SIGTERM)
        code = self.p.wait(timeout=60)
        self._err.close()
        self.sock.close()
        return code

    def kill(self) -> None:
        if self.p.poll() is None:
            self.p.kill()
            self.p.wait()


def serve_devices(plc: SimulatedPlc, ctl: SimController, lift_port: int, ctl_port: int
                  ) -> None:
    """The PLC (Modbus TCP) and the controller (Open Protocol) serving on their ports, as a
    plant's would on their own machines."""
    plc.start_tcp(lift_port)
    ctl.start()
    ctl.listen_tcp(port=ctl_port)


def at_height(d: Proc, plc: SimulatedPlc, ctl: SimController, lift_port: int, ctl_port: int,
              vin: str) -> None:
    """The PLC and the controller serving on their ports, ``vin`` raised to height, the
    station tracking the wrench."""
    plc.set_vehicle(1, vin)
    serve_devices(plc, ctl, lift_port, ctl_port)
    plc.raise_lift()
    d.wait_log("tracking: tracking the wrench")


def controller(seed: int, nok_rate: float = 0.0) -> SimController:
    """The simulated controller with config/sim's psets, seeded ``seed`` (always OK unless
    ``nok_rate`` says otherwise)."""
    return SimController(psets_of(SIM / "bolts.yaml"), seed=seed, nok_rate=nok_rate)


@contextmanager
def stops_cleanly(d: Proc, *close: Callable[[], object]) -> Iterator[Proc]:
    """The block with the daemon ``d`` running; after the block, the daemon stopped as systemd
    stops it (SIGTERM) must exit 0 and leave no Traceback in its journal (every daemon test
    checks both).  Killed, then ``close`` called in order (the devices the test served),
    whatever happened."""
    try:
        yield d
        assert d.stop() == 0, d.log()[-3000:]
    finally:
        d.kill()
        for c in close:
            c()
    assert "Traceback" not in d.log(), d.log()[-3000:]


@contextmanager
def tracking(tmp: Path, vin: str, seed: int = 9, edit: Callable[[str], str] | None = None,
             ctl: SimController | None = None
             ) -> Iterator[tuple[Proc, SimulatedPlc, SimController]]:
    """A :class:`Proc` on the station file ``edit`` makes (see :class:`Proc`), its devices
    served (``ctl``, default an always-OK controller seeded ``seed``) and ``vin`` at height:
    the station tracking the wrench.  After the block it stops cleanly (see
    :func:`stops_cleanly`); killed and closed on the way out whatever happened."""
    lift_port, ctl_port = free_port(), free_port()
    plc = SimulatedPlc()
    wrench = controller(seed) if ctl is None else ctl
    d = Proc(tmp, lift_port, ctl_port, edit=edit)
    with stops_cleanly(d, wrench.close, plc.close):
        at_height(d, plc, wrench, lift_port, ctl_port, vin)
        yield d, plc, wrench


def tool_on(d: Proc, ctl: SimController, pose: Path, bolt: str) -> None:
    """The simulated operator's wrench on ``bolt`` (``pose``: the file the station's
    simulated cameras read it from) until the controller has the tool enabled for it."""
    pose.write_text(bolt)
    d.wait_log(f"tightening bolt {bolt}")
    until(lambda: ctl.tool_enabled, 30, f"tool enabled on {bolt}")


def stored_on(d: Proc, ctl: SimController, pose: Path, bolt: str) -> Any:
    """A tightening of ``bolt`` the station has stored (the controller had its
    acknowledgement): the last result it accounts for, before what a test does next."""
    tool_on(d, ctl, pose, bolt)
    made = ctl.pull_trigger()
    assert made is not None
    until(lambda: made.tightening_id in ctl.acked_ids, 30, f"{bolt}'s result stored")
    return made


def db_rows(db: Path | str, sql: str) -> list[tuple[Any, ...]]:
    """The rows ``sql`` reads from the station's SQLite database (read after the daemon)."""
    con = sqlite3.connect(db)
    try:
        return list(con.execute(sql))
    finally:
        con.close()
