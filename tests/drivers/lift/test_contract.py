"""One contract, every lift backend (as tests/drivers/camera/test_contract.py is for the
cameras): what the station relies on whatever the PLC link is -- Modbus TCP, Modbus RTU over
a pty, and the simulated PLC behind ``sim://lift`` (over TCP and RTU) -- each against a
simulated PLC."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from drivers.errors import DeviceError, UrlError
from drivers.lift import Lift, LiftState, open_lift
from drivers.lift.sim import SimLift, SimulatedPlc

VIN = "WVWZZZ1KZAW000123"


class Backend:
    def __init__(self, url: str, plc: SimulatedPlc | None) -> None:
        self.url, self.plc = url, plc


KINDS = ["modbus-tcp", "modbus-rtu", "sim-tcp", "sim-rtu"]   # sim: over either transport


@pytest.fixture(params=KINDS)
def backend(request: pytest.FixtureRequest) -> Iterator[Backend]:
    kind = request.param
    if kind.startswith("sim"):
        yield Backend(f"sim://lift?transport={kind[4:]}", None)
        return
    with SimulatedPlc() as plc:
        url = f"modbus-tcp://127.0.0.1:{plc.start_tcp()}?unit=1" if kind == "modbus-tcp" \
            else f"modbus-rtu://{plc.start_rtu()}?baud=19200&parity=N&unit=1"
        yield Backend(url, plc)


def _open(b: Backend) -> Lift:
    lift = open_lift(b.url, timeout=1.0)
    if isinstance(lift, SimLift):
        b.plc = lift.plc
    return lift


def test_the_state_follows_the_plc(backend: Backend) -> None:
    with _open(backend) as lift:
        assert backend.plc is not None
        st = lift.read_state()
        assert isinstance(st, LiftState) and not st.ready
        backend.plc.set_vehicle(7, VIN)
        backend.plc.raise_lift()
        st = lift.read_state(1.0)
        assert st.ready and st.at_working_height and (st.model_code, st.vin) == (7, VIN)
        assert lift.identity()


def test_open_and_close_are_idempotent_and_a_closed_lift_says_so(backend: Backend) -> None:
    lift = _open(backend)
    lift.open()
    lift.close()
    lift.close()
    with pytest.raises(DeviceError):
        lift.read_state()


def test_a_plc_that_goes_away_is_a_typed_device_error(backend: Backend) -> None:
    with _open(backend) as lift:
        assert backend.plc is not None
        lift.read_state()
        backend.plc.close()
        with pytest.raises(DeviceError):
            for _ in range(3):      # a buffered answer may still arrive once
                lift.read_state(0.5)


def test_bad_arguments_are_refused(backend: Backend) -> None:
    with _open(backend) as lift, pytest.raises(ValueError):
        lift.read_state(0)
    with pytest.raises((UrlError, ValueError)):
        open_lift(backend.url + ("&" if "?" in backend.url else "?") + "unit=999")




def test_every_registered_backend_keeps_the_contract():
    """A backend registered for a scheme is in this suite (a new one must be added here)."""
    from drivers.lift import BACKENDS

    assert set(BACKENDS) == {k.removesuffix("-tcp").removesuffix("-rtu")
                             if k.startswith("sim") else k for k in KINDS}
