"""A command typed to the simulated PLC (``stationd sim plc``, the daemon's idle operator):
a bad one is answered in stationd's words, never Python's, and changes nothing."""

from __future__ import annotations

from drivers.lift.sim import SimulatedPlc
from stationd.sim.devices_cli import first_serial, plc_command
from stationd.sim.vin import make_vin


def test_a_model_code_that_is_not_a_number_is_refused_in_words():
    said: list[str] = []
    with SimulatedPlc() as plc:
        before = plc.state()
        assert plc_command(plc, "vehicle abc", 1, [0], said.append) is True
        assert (plc.state().model_code, plc.state().vin) == (before.model_code, before.vin)
        assert plc_command(plc, "vehicle 2 VINX", 1, [0], said.append) is True
        assert plc.state().model_code == 2
    assert said[0] == "refused: the model code is a whole number, not 'abc' (vehicle CODE [VIN])"
    assert "invalid literal" not in " ".join(said)


def test_next_vehicles_go_on_from_the_clock_not_from_one():
    """A restarted simulator met its last run's VINs again (from 000001 at each start), and
    the station reopened them as reworks."""
    serial = [first_serial(1_700_000_123.9)]
    assert serial == [1_700_000_123 % 900_000]
    with SimulatedPlc() as plc:
        plc_command(plc, "next", 1, serial, lambda _: None)
        assert plc.state().vin == make_vin(serial[0]) and serial[0] == 800_124
        later = [first_serial(1_700_000_130.0)]
        assert later[0] > serial[0]     # a restart seconds later starts beyond it
