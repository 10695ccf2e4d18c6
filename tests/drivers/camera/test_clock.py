"""A camera's clock mapped onto host time from the frames' own stamps (``clock.ClockMap``)."""

import numpy as np
import pytest

from drivers.camera.clock import ClockMap

OFFSET = 1.7e9 - 1234.5  # host - device: the camera counts from its power-on


def _frames(cm, n, *, rate=1.0, period=0.1, delay=(0.020, 0.060), trigger=True, seed=0,
            start=0.0):
    """Feed ``n`` frames exposed every ``period`` s (host time); the trigger is sent 1-3 ms
    before the exposure, the first packet arrives ``delay`` s after it.  Returns the true
    host exposure times and device stamps."""
    rng = np.random.default_rng(seed)
    truth, stamps = [], []
    for k in range(n):
        exposure = OFFSET + 1234.5 + start + k * period
        device = 1234.5 + start + k * period * rate
        system = exposure + rng.uniform(*delay)
        cm.add(device, system, exposure - rng.uniform(0.001, 0.003) if trigger else None)
        truth.append(exposure)
        stamps.append(device)
    return truth, stamps


def test_a_verified_clock_maps_to_the_exposure_within_the_trigger_bracket():
    cm = ClockMap()
    truth, stamps = _frames(cm, 30)
    assert cm.offset() is not None  # 3 s of frames at the host's rate
    errors = [cm.host_time(d) - t for d, t in zip(stamps, truth, strict=True)]
    # bounded by the smallest trigger lead (>= 1 ms) and the smallest delay (>= 20 ms)
    assert max(abs(e) for e in errors) < 0.012 and cm.reason == ""


def test_without_triggers_the_upper_bound_is_used():
    cm = ClockMap()
    truth, stamps = _frames(cm, 30, trigger=False)
    err = cm.host_time(stamps[-1]) - truth[-1]
    assert 0.020 <= err < 0.025  # late by the least delay seen, never early


def test_not_trusted_before_two_seconds_of_frames():
    cm = ClockMap()
    _frames(cm, 10)  # 0.9 s
    assert cm.host_time(1234.5) is None and cm.checking and "being checked" in cm.reason


def test_a_clock_in_the_wrong_unit_is_not_trusted():
    cm = ClockMap()
    _frames(cm, 30, rate=10.0, trigger=False)  # ticks of 100 ns reported as ns, say
    assert cm.host_time(1234.5) is None and not cm.checking
    assert "runs at 10 x the host's" in cm.reason
    triggered = ClockMap()  # with triggers the bounds cross at once: never trusted either
    _frames(triggered, 30, rate=10.0)
    assert triggered.host_time(1234.5) is None


def test_no_device_timestamps_and_a_clock_that_jumps_reset_the_map():
    cm = ClockMap()
    cm.add(0.0, 1.7e9, 1.7e9 - 0.001)
    assert cm.host_time(1.0) is None and "no timestamps" in cm.reason and not cm.checking
    _frames(cm, 30)
    assert cm.offset() is not None
    cm.add(5.0, OFFSET + 1234.5 + 3.1, None)  # the camera rebooted: its clock restarts
    assert cm.offset() is None and cm.checking
    cm2 = ClockMap()
    _frames(cm2, 30)
    _frames(cm2, 1, start=3.0 - 0.5 / 1.0)  # stamps 0.5 s early: the bounds cross
    assert cm2.offset() is None


def test_arguments():
    with pytest.raises(ValueError):
        ClockMap(window=1)
    with pytest.raises(ValueError):
        ClockMap(rate_tolerance=0)


def test_the_interval_brackets_the_exposure():
    cm = ClockMap()
    assert cm.interval(1234.5) is None
    truth, stamps = _frames(cm, 30)
    lo, hi = cm.interval(stamps[-1])
    assert lo <= truth[-1] <= hi and hi - lo < 0.025
    free = ClockMap()
    truth, stamps = _frames(free, 30, trigger=False)
    lo, hi = free.interval(stamps[-1])
    assert lo == -np.inf and truth[-1] <= hi


class _Buffer:
    """The two stamps of an Aravis buffer, in ns."""

    def __init__(self, device_s, system_s):
        self.device_ns, self.system_ns = round(device_s * 1e9), round(system_s * 1e9)

    def get_timestamp(self):
        return self.device_ns

    def get_system_timestamp(self):
        return self.system_ns


def _link():
    from drivers.camera.aravis import _Link

    link = _Link.__new__(_Link)  # the stamping only: no camera behind it
    link.clock, link.triggered_at, link._warned_clock, link.device = ClockMap(), None, False, "x"
    return link


def test_aravis_stamps_the_trigger_until_the_clock_is_verified_then_the_mapped_exposure():
    link = _link()
    host0, dev0 = 1.7e9, 50.0  # host = device + 1.7e9 - 50
    stamps = []
    for k in range(30):
        exposure = host0 + 0.1 * k
        link.triggered_at = exposure - 0.002
        stamps.append(link._exposure_time(_Buffer(dev0 + 0.1 * k, exposure + 0.03)))
    assert stamps[0] == pytest.approx(host0 - 0.002)  # the trigger while checking the clock
    assert stamps[-1] == pytest.approx(host0 + 2.9, abs=0.016)  # the mapped exposure
    # a frame of an earlier trigger still in transit when the next trigger is sent: it keeps
    # its own, older time, and the trigger stays pending for its own frame
    link.triggered_at = host0 + 3.5
    late = link._exposure_time(_Buffer(dev0 + 3.0, host0 + 3.52))
    assert late == pytest.approx(host0 + 3.0, abs=0.016) and link.triggered_at == host0 + 3.5
