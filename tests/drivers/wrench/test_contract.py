"""One contract, every controller backend (as tests/drivers/camera/test_contract.py is for the
cameras): what the station relies on whatever the controller is -- Open Protocol over TCP and
over a serial line, a register-driven controller over Modbus TCP and RTU, and the simulated
controller behind ``sim://wrench`` -- each against its simulated controller on loopback or a
pty."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from drivers.errors import DeviceError, RefusedError, UrlError
from drivers.wrench import Wrench, open_wrench
from drivers.wrench.base import TighteningResult
from drivers.wrench.modbus_sim import SimRegisterController
from drivers.wrench.sim.controller import SimController

KINDS = ["openprotocol", "openprotocol+serial", "modbus-tcp", "modbus-rtu", "sim", "sim+modbus"]


class Backend:
    """A backend under test: its URL, the trigger of its controller, the options it takes."""

    def __init__(self, url: str, trigger: Any, pset: int, **kw: Any) -> None:
        self.url, self.trigger, self.pset, self.kw = url, trigger, pset, kw


@pytest.fixture(params=KINDS)
def backend(request: pytest.FixtureRequest, tmp_path: Any) -> Iterator[Backend]:
    kind = request.param
    if kind.startswith("openprotocol"):
        with SimController(seed=1, nok_rate=0.0) as c:
            url = f"openprotocol://127.0.0.1:{c.listen_tcp()}" if kind == "openprotocol" \
                else f"openprotocol+serial://{c.open_pty(str(tmp_path / 'tty'))}?baud=9600"
            yield Backend(url, c.pull_trigger, 1, timeout=1.0)
    elif kind.startswith("modbus"):
        with SimRegisterController(seed=1, nok_rate=0.0) as c:
            url = f"modbus-tcp://127.0.0.1:{c.start_tcp()}?unit=1" if kind == "modbus-tcp" \
                else f"modbus-rtu://{c.start_rtu()}?baud=19200&parity=N&unit=1"
            yield Backend(url, c.pull_trigger, 1, timeout=1.0, poll=0.02)
    elif kind == "sim+modbus":   # as sim: the simulated controller starts with the wrench
        yield Backend("sim+modbus://wrench", None, 1, timeout=1.0, poll=0.02)
    else:   # the simulated controller starts with the wrench: its trigger is set by _open
        yield Backend("sim://wrench", None, 1, timeout=1.0)


def _open(b: Backend) -> Wrench:
    w = open_wrench(b.url, **b.kw)
    if b.url.startswith("sim"):
        b.trigger = w.controller.pull_trigger   # type: ignore[attr-defined]
    return w


def test_parameters_then_the_tool_then_a_result_acknowledged(backend: Backend) -> None:
    with _open(backend) as w:
        assert w.status().connected
        w.send_parameters(backend.pset, 0.0, None)     # the pset's own targets
        w.enable_tool()
        assert backend.trigger() is not None
        r = w.wait_result(5.0, acknowledge=False)
        assert isinstance(r, TighteningResult) and r.pset == backend.pset and r.ok
        w.acknowledge_result(r)
        with pytest.raises(ValueError):          # once, never twice
            w.acknowledge_result(r)
        w.disable_tool()
        assert w.wait_result(0.2, acknowledge=False) is None
        assert isinstance(w.can_fetch, bool)
        if not w.can_fetch:
            with pytest.raises(DeviceError):
                w.fetch_result(0)


def test_open_and_close_are_idempotent_and_a_closed_wrench_says_so(backend: Backend) -> None:
    w = _open(backend)
    w.open()                                      # a second open does nothing
    w.close()
    w.close()
    with pytest.raises(DeviceError):
        w.enable_tool()
    with pytest.raises(DeviceError):
        w.open()                                  # a closed wrench is not reopened


def test_a_pset_the_controller_does_not_have_is_refused_with_its_reason(
        backend: Backend) -> None:
    with _open(backend) as w:
        with pytest.raises(RefusedError) as err:
            w.send_parameters(998, 0.0, None)
        assert str(err.value)
        w.send_parameters(backend.pset, 0.0, None)    # the link is still usable after it


def test_bad_options_are_a_url_error_naming_them(backend: Backend) -> None:
    with pytest.raises(UrlError, match="timeout must be > 0"):
        open_wrench(backend.url, **{**backend.kw, "timeout": 0})


def test_a_serial_speed_out_of_range_is_refused_for_the_register_driven_controller() -> None:
    with pytest.raises(UrlError, match="serial speed"):
        open_wrench("modbus-rtu:///dev/ttyUSB0?baud=0&unit=1", connect=False)


@pytest.mark.parametrize("url, targets", [
    ("openprotocol://127.0.0.1:4545", False), ("openprotocol+serial:///dev/ttyUSB1", False),
    ("sim://wrench", False), ("modbus-tcp://127.0.0.1:502", True),
    ("modbus-rtu:///dev/ttyUSB2", True), ("sim+modbus://wrench", True),
    ("nonsense://x", False), ("not a url", False)])
def test_whether_a_controller_takes_targets_is_its_drivers_to_say(url, targets):
    """Psets only, or a bolt's own targets: asked of the backend's class, nothing opened
    (the configuration check warns of bolts without a pset from it).  So is whether it is
    driven through a register map (the station file's ``wrench.registers``), not read from
    "modbus" in its scheme: here the controllers that take targets are those."""
    from drivers.wrench import BACKENDS, takes_register_map, takes_targets

    assert takes_targets(url) is targets
    assert takes_register_map(url) is targets
    assert set(BACKENDS) >= {"openprotocol", "sim", "modbus-tcp", "sim+modbus"}


@pytest.mark.parametrize("url, keeps", [
    ("openprotocol://127.0.0.1:4545", True), ("openprotocol+serial:///dev/ttyUSB1", True),
    ("sim://wrench", True), ("modbus-tcp://127.0.0.1:502", False),
    ("sim+modbus://wrench", False), ("nonsense://x", False), ("not a url", False)])
def test_whether_a_controller_keeps_its_results_to_fetch_is_its_drivers_to_say(url, keeps):
    """An Open Protocol controller keeps its results by id (MID 0064): after a link cut the
    station fetches what was made, a register map has only the newest; nothing opened."""
    from drivers.wrench import fetches

    assert fetches(url) is keeps


def test_every_registered_backend_keeps_the_contract():
    """A backend registered for a scheme is in this suite (a new one must be added here)."""
    from drivers.wrench import BACKENDS

    assert set(BACKENDS) == set(KINDS)
