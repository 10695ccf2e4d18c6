"""Fixtures for the lift tests: simulated PLCs on loopback / a pty, short timings (leak checks:
``tests/drivers/conftest.py``)."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from drivers.lift.sim import SimulatedPlc

# short timings keep every file well under 10 s
FAST = {"timeout": 0.3}
VIN = "WVWZZZ1KZAW000123"


@pytest.fixture
def plc():
    with SimulatedPlc() as p:
        yield p


def require_mbpoll() -> str:
    path = shutil.which("mbpoll")
    if path is None:
        pytest.skip("mbpoll is not installed (apt-get install mbpoll; .ci/bootstrap installs it)")
    return path


def mbpoll(*args: str) -> tuple[int, dict[int, int], str]:
    """Run Debian's mbpoll once with 0-based addresses: exit code, address -> value, stderr."""
    r = subprocess.run([require_mbpoll(), "-0", "-1", "-o", "1", *args],
                       capture_output=True, text=True, timeout=10)
    values = {int(a): int(v) for a, v in re.findall(r"^\[(\d+)\]:\s+(-?\d+)", r.stdout, re.M)}
    return r.returncode, values, r.stderr.strip()
