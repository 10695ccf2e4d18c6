"""A result's values as OPC UA says them (:mod:`stationd.opcua.results`), without a server."""

from __future__ import annotations

from stationd.opcua.results import value_ok


def test_each_value_is_judged_against_its_own_limits():
    """A NOK for an angle below its minimum: the torque within its limits is OK (an MES
    counting torque failures counted it), the angle is not."""
    torque, angle = {"min": 45.0, "max": 55.0, "target": 50.0}, {"min": 15.0, "max": 90.0}
    assert value_ok(50.8, torque, ok=False) is True
    assert value_ok(0.0, angle, ok=False) is False
    assert value_ok(55.0, torque, ok=True) is True and value_ok(55.01, torque, ok=True) is False
    assert value_ok(16.0, {"min": 15.0}, ok=False) is True          # one limit known
    # neither limit, or no value: the result's own verdict
    assert value_ok(12.0, {}, ok=False) is False and value_ok(None, torque, ok=True) is True
