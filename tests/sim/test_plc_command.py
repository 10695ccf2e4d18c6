"""A command typed to the simulated PLC (``stationd sim plc``, the daemon's idle operator):
a bad one is answered in stationd's words, never Python's, and changes nothing."""

from __future__ import annotations

from drivers.lift.sim import SimulatedPlc
from stationd.sim.devices_cli import plc_command


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
