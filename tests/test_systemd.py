"""The unit file: systemd-analyze verify says nothing, security rates it 2.0 or better."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

UNIT = Path(__file__).resolve().parents[1] / "systemd" / "stationd.service"
ANALYZE = shutil.which("systemd-analyze")
pytestmark = pytest.mark.skipif(ANALYZE is None, reason="systemd-analyze not installed "
                                "(apt-get install systemd; .ci/bootstrap does)")


@pytest.fixture
def unit(tmp_path):
    """The unit as installed, but with ExecStart pointing at this checkout's stationd (verify
    checks that the executable exists)."""
    exe = Path(sys.executable).with_name("stationd")
    text = UNIT.read_text().replace("/opt/stationd/.venv/bin/stationd", str(exe))
    p = tmp_path / "stationd.service"
    p.write_text(text)
    return p


def test_verify_prints_nothing(unit):
    r = subprocess.run([ANALYZE, "verify", str(unit)], capture_output=True, text=True,
                       timeout=60)
    # verify exits 0 on some parse errors: any output is a failure
    assert r.returncode == 0 and r.stdout == "" and r.stderr == "", r.stdout + r.stderr


def test_security_exposure_is_2_or_better(unit):
    r = subprocess.run([ANALYZE, "security", "--offline=true", str(unit)], capture_output=True,
                       text=True, timeout=60)
    m = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", r.stdout)
    assert m, r.stdout + r.stderr
    assert float(m.group(1)) <= 2.0


def test_unit_keeps_device_access_and_notify():
    text = UNIT.read_text()
    for line in ("Type=notify", "WatchdogSec=", "Restart=on-failure",
                 "RestartPreventExitStatus=2", "User=stationd",
                 "DeviceAllow=char-ttyUSB rw", "DeviceAllow=char-ttyACM rw",
                 "DeviceAllow=char-usb_device rw", "SupplementaryGroups=dialout plugdev",
                 "StateDirectory=stationd", "ConfigurationDirectory=stationd"):
        assert line in text
    assert "PrivateDevices=yes" not in text and "PrivateUsers=yes" not in text
