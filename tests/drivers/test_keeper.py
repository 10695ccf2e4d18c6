"""The one reconnect-with-backoff mechanism (``drivers.keeper``), on a fake clock and a fake
device: what it reports, when it retries, that a fault never ends it.  The real protocols'
side (a PLC or controller that vanishes and comes back) is in tests/shell."""

from __future__ import annotations

import asyncio
import random
from typing import Any

import pytest

from drivers.errors import ConnectError, ConnectionLostError, DeviceTimeoutError, ProtocolError
from drivers.keeper import Backoff, DeviceKeeper, fault_kind, one_line


class FakeDevice:
    """A device whose link fails on the uses and attempts the test says."""

    def __init__(self, script: Any) -> None:
        self.script = script
        self.closed = False
        self.reconnects = 0


class World:
    """Scripted outcomes for opens, reconnects and uses, a fake clock, and the reports."""

    def __init__(self, opens: list[Exception | None], reconnects: list[Exception | None],
                 uses: list[Exception | None]) -> None:
        self.opens, self.reconnect_results, self.uses = opens, reconnects, uses
        self.now = 0.0
        self.sleeps: list[float] = []
        self.reports: list[tuple[Any, ...]] = []
        self.devices: list[FakeDevice] = []
        self.done = asyncio.Event()

    def open(self) -> FakeDevice:
        exc = self.opens.pop(0)
        if exc is not None:
            raise exc
        dev = FakeDevice(self)
        self.devices.append(dev)
        return dev

    def reconnect(self, dev: FakeDevice) -> None:
        exc = self.reconnect_results.pop(0)
        dev.reconnects += 1
        if exc is not None:
            raise exc

    async def use(self, dev: FakeDevice) -> None:
        if not self.uses:
            self.done.set()
            await asyncio.Event().wait()      # idle until cancelled
        exc = self.uses.pop(0)
        await asyncio.sleep(0)
        if exc is not None:
            raise exc

    async def sleep(self, dt: float) -> None:
        self.sleeps.append(dt)
        self.now += dt
        await asyncio.sleep(0)

    async def blocking(self, fn: Any) -> Any:
        return fn()

    def keeper(self, **kw: Any) -> DeviceKeeper[FakeDevice]:
        async def on_fault(kind: str, reason: str) -> None:
            self.reports.append(("fault", self.now, kind, reason))

        async def on_back(reconnects: int) -> None:
            self.reports.append(("back", self.now, reconnects))

        return DeviceKeeper("lift", open=self.open, reconnect=self.reconnect,
                            close=lambda d: setattr(d, "closed", True), on_fault=on_fault,
                            on_back=on_back, blocking=self.blocking, sleep=self.sleep, **kw)


def run(world: World, keeper: DeviceKeeper[FakeDevice], use: bool = True) -> None:
    async def main() -> None:
        task = asyncio.create_task(keeper.run(world.use if use else None))
        await asyncio.wait_for(world.done.wait(), 10)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    asyncio.run(main())


def down(reason: str = "connection refused by 127.0.0.1:502") -> ConnectError:
    return ConnectError(reason, device="modbus-tcp://127.0.0.1:502")


def test_down_at_boot_then_back_reports_once_per_reason_and_backs_off():
    w = World(opens=[down(), down(), down(), None], reconnects=[], uses=[None, None])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    assert k.open_now() == ("down", "modbus-tcp://127.0.0.1:502: connection refused by "
                                    "127.0.0.1:502")
    assert k.device is None and not k.up
    run(w, k)
    # the boot fault is the caller's to report; the same reason is not reported again
    assert w.reports == [("back", 3.5, 0)]
    assert w.sleeps == [0.5, 1.0, 2.0]
    assert k.up and k.device is w.devices[0] and k.reconnects == 0


def test_a_lost_link_is_reported_then_reconnected_on_the_same_device():
    w = World(opens=[None], reconnects=[down(), None],
              uses=[None, ConnectionLostError("peer closed", device="d"), None])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    assert k.open_now() is None
    run(w, k)
    assert w.reports == [("fault", 0.0, "down", "d: peer closed"),
                         ("fault", 0.5, "down", "modbus-tcp://127.0.0.1:502: connection "
                                                "refused by 127.0.0.1:502"),
                         ("back", 1.5, 1)]
    dev = w.devices[0]
    assert len(w.devices) == 1 and dev.reconnects == 2 and not dev.closed
    assert k.reconnects == 1


def test_a_device_that_connects_then_fails_at_once_is_retried_ever_more_slowly():
    """Accepts the connection, answers garbage: the backoff is reset only by a use that
    worked, so the reconnects slow down to the cap instead of hammering the device."""
    garbage = ProtocolError("bad frame", device="d")
    w = World(opens=[None], reconnects=[None] * 6, uses=[garbage] * 6 + [None])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    k.open_now()
    run(w, k)
    assert w.sleeps == [0.5, 1.0, 2.0, 4.0, 4.0, 4.0]
    assert [r[0] for r in w.reports] == ["fault", "back"] * 6
    assert all(r[2] == "garbage" for r in w.reports if r[0] == "fault")


def test_a_use_that_worked_resets_the_backoff():
    lost = ConnectionLostError("gone", device="d")
    w = World(opens=[None], reconnects=[down(), None, None],
              uses=[lost, None, lost, None])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    k.open_now()
    run(w, k)
    assert w.sleeps == [0.5, 1.0, 0.5]


def test_jitter_shortens_waits_within_bounds_reproducibly():
    waits = []
    for _ in range(2):
        b = Backoff(0.5, 5.0, jitter=0.25, rng=random.Random("pair1"))
        waits.append([b.next() for _ in range(12)])
    assert waits[0] == waits[1]                         # seeded: reproducible
    nominal = [min(5.0, 0.5 * 2 ** i) for i in range(12)]
    for got, nom in zip(waits[0], nominal, strict=True):
        assert 0.75 * nom <= got <= nom                 # never above the cap
    assert len(set(waits[0][6:])) > 1                   # at the cap, still spread out
    other = Backoff(0.5, 5.0, jitter=0.25, rng=random.Random("pair2"))
    assert [other.next() for _ in range(12)] != waits[0]


@pytest.mark.parametrize(("first", "cap", "jitter"), [(0, 1, 0), (2, 1, 0), (1, 2, 1.0)])
def test_bad_backoff_settings_are_refused(first, cap, jitter):
    with pytest.raises(ValueError, match=r"backoff|jitter"):
        Backoff(first, cap, jitter=jitter)


def test_someone_else_using_the_device_reports_it_lost():
    """A camera pair has no ``use`` of its own: the vision loop tells the keeper."""
    w = World(opens=[None], reconnects=[None], uses=[])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    k.open_now()

    async def main() -> None:
        task = asyncio.create_task(k.run())
        await asyncio.sleep(0)
        k.lost(DeviceTimeoutError("3 grabs failed", device="pair1"))
        k.lost(ConnectError("ignored: already lost", device="pair1"))
        for _ in range(20):
            await asyncio.sleep(0)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)

    asyncio.run(main())
    assert w.reports == [("fault", 0.0, "timeout", "pair1: 3 grabs failed"), ("back", 0.5, 1)]


def test_a_bug_in_the_device_is_a_fault_not_an_exit(caplog):
    w = World(opens=[None], reconnects=[None], uses=[KeyError("registers"), None])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    k.open_now()
    run(w, k)
    assert w.reports[0][:3] == ("fault", 0.0, "garbage") and w.reports[1][0] == "back"
    assert "using it crashed" in caplog.text


class LibraryError(Exception):
    """What a library under a driver raises (OpenCV's ``cv2.error``): not a driver error."""


def test_a_library_error_on_open_is_one_journal_line_once_without_traceback(caplog):
    """OpenCV refusing a camera is a device fault: one line, not a traceback per retry."""
    crash = LibraryError("(-5:Bad argument) in function 'VideoCapture'\n> more detail")
    w = World(opens=[crash, crash, crash, None], reconnects=[], uses=[None])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    caplog.set_level("INFO")
    assert k.open_now() == ("garbage", "(-5:Bad argument) in function 'VideoCapture'")
    run(w, k)
    errors = [r for r in caplog.records if r.levelname == "ERROR"]
    assert [r.getMessage() for r in errors] == [
        "lift: an attempt to connect crashed: LibraryError: (-5:Bad argument) in function "
        "'VideoCapture'"]
    assert errors[0].exc_info is None and "Traceback" not in caplog.text
    assert k.up


def test_a_bug_on_open_keeps_its_traceback_once(caplog):
    w = World(opens=[KeyError("unit"), KeyError("unit"), None], reconnects=[], uses=[None])
    k = w.keeper(backoff=Backoff(0.5, 4.0, jitter=0.0))
    k.open_now()
    run(w, k)
    errors = [r for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1 and errors[0].exc_info is not None
    assert "an attempt to connect crashed" in errors[0].getMessage()


def test_close_closes_the_device_and_an_attempt_after_close_closes_what_it_opens():
    w = World(opens=[None, None], reconnects=[], uses=[])
    k = w.keeper()
    k.open_now()
    first = w.devices[0]
    k.close()
    assert first.closed and k.device is None
    assert k.open_now() is not None          # refused: the keeper is closed
    assert len(w.devices) == 1


def test_fault_kinds_and_one_line_reasons():
    assert fault_kind(DeviceTimeoutError("t")) == "timeout"
    assert fault_kind(ProtocolError("p")) == "garbage"
    assert fault_kind(ConnectError("c")) == "down"
    assert fault_kind(ValueError("v")) == "garbage"
    assert one_line(ValueError("first\nsecond")) == "first"
    assert one_line(ValueError()) == "ValueError"
