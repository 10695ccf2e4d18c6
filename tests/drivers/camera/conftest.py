"""Fixtures for the camera tests: Aravis's own fake GigE camera on loopback, no worlds left.

Aravis is exercised through the real library path (GigE Vision on 127.0.0.1, UDP 3956), so
only one fake camera may exist at a time: the fixture makes one per test and destroys it
after the test's cameras are closed (stream, then camera, then fake).  ``Aravis.shutdown()``
is left to the driver's atexit hook, which runs once at the end of the pytest process.
"""

from __future__ import annotations

import gc
import weakref

import pytest

from drivers.camera import sim

SERIAL = "STATIOND1"
HEARTBEAT_REGISTER = 0x0938  # GigE Vision bootstrap: heartbeat timeout in ms
FAKE_NAME = "Aravis-Fake-" + SERIAL
#: how long a grab waits for a frame the test asked for: generous on a busy machine (it ends
#: with the frame; a test that expects none gives its own short wait)
FAST = "timeout=30"
#: the fake camera's heartbeat timeout: its GigE standard 3 s is shorter than a loaded test
#: machine may stall (the fake then drops the test's camera for good, as a real one would);
#: the camera and the test share this host, so a long timeout locks nothing.  Losing control
#: is tested on its own (``test_aravis_reconnect.py``).
PATIENT = "heartbeat_ms=60000"


@pytest.fixture(scope="session", autouse=True)
def aravis_discovery_started():
    """Run Aravis's device discovery once, before any test's leak check starts counting: its
    first run opens GLib's file descriptors for the life of the process (eventfds, a timerfd,
    a netlink socket), which are no leak.  The driver still runs its own discovery."""
    from drivers.camera import aravis

    if aravis.available() is None:
        aravis.load()[0].update_device_list()


@pytest.fixture(autouse=True)
def no_registered_worlds():
    """Fail a test that leaves a registered simulated world behind (threads, sockets and
    files: the ``no_leaks`` fixture of ``tests/drivers/conftest.py``)."""
    yield
    worlds = sim.registered_worlds()
    for pair in worlds:
        sim.unregister_world(pair)
    assert not worlds, f"simulated worlds left registered: {worlds}"


def aravis_or_skip():
    """The Aravis module, or skip: the only reason to skip is that gi/Aravis cannot load."""
    from drivers.camera import aravis

    reason = aravis.available()
    if reason is not None:
        pytest.skip(f"Aravis is not importable: {reason}")
    return aravis.load()[0]


def _assert_gvcp_port_free():
    """A fake camera whose GVCP port is taken still says it runs (Aravis logs the failed
    bind and goes on), and the test's camera then talks to the other program's fake."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", 3956))
        except OSError as exc:
            pytest.fail(f"UDP 127.0.0.1:3956 is taken ({exc}): another program runs a GigE "
                        "camera or fake camera here")


class FakeGigE:
    """Aravis's fake GigE Vision camera on 127.0.0.1; ``stop()`` is the cable being pulled,
    ``start()`` plugging it back (a fresh camera with the same serial, default settings)."""

    def __init__(self, arv):
        self.arv = arv
        self.fake = None
        self.start()

    def start(self):
        assert self.fake is None, "one fake camera at a time"
        _assert_gvcp_port_free()
        self.fake = self.arv.GvFakeCamera.new("127.0.0.1", SERIAL)
        assert self.fake.is_running(), "the fake GigE camera did not start"

    def stop(self):
        fake, self.fake = self.fake, None
        alive = weakref.ref(fake)
        del fake
        if alive() is not None:
            # held in a reference cycle: collected now (a whole collection walks every
            # object of the test process, a tenth of a second each time: only when needed)
            gc.collect()

    def url(self, options=""):
        extra = "" if "heartbeat_ms=" in options else f"&{PATIENT}"
        return f"aravis://{FAKE_NAME}?{FAST}{extra}" + (f"&{options}" if options else "")

    def heartbeat_ms(self):
        """The fake camera's heartbeat timeout, as the station's camera set it."""
        ok, value = self.fake.get_fake_camera().read_register(HEARTBEAT_REGISTER)
        assert ok
        return value

    def drop_controllers_after(self, ms):
        """The camera's heartbeat timeout set behind the station's back (from the camera's
        side): below Aravis's 1 s heartbeat period, the camera drops its controller at the
        next heartbeat, as after a host stall of that length."""
        assert self.fake.get_fake_camera().write_register(HEARTBEAT_REGISTER, ms)

    def set_trigger_frequency(self, hz):
        self.fake.get_fake_camera().set_trigger_frequency(hz)


@pytest.fixture
def aravis_port():
    """The fake camera listens on the fixed GigE Vision port (UDP 3956): two test processes at
    once (two engineers, or CI beside a developer) would answer each other's discovery.  A
    machine-wide lock makes them take turns instead of failing."""
    import fcntl
    import tempfile
    from pathlib import Path

    with (Path(tempfile.gettempdir()) / "stationd-aravis-fake.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


@pytest.fixture
def fake(aravis_port):
    f = FakeGigE(aravis_or_skip())
    yield f
    f.stop()
