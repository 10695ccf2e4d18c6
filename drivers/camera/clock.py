"""A camera's own clock mapped onto the host's ``time.time()`` scale.

A GenICam camera stamps each buffer with its clock at the start of the frame (the exposure):
the instant the station needs, since the wrench may move while 20 MP are read out, sent and
queued.  But that clock has its own origin, and some cameras report it in a wrong unit
(Hikrobot: Aravis's ``src/arv-test.cfg``).  Aravis also stamps each buffer on the host when its
first packet arrives (the *system* timestamp), which is later than the exposure by the
readout and transfer.  Each frame therefore bounds the offset ``host - device``:

- from above: ``system - device`` (the frame cannot reach the host before it was exposed);
- from below, for a software-triggered frame: ``trigger - device`` (the camera cannot expose
  before the host asked it to).

The offset kept is the middle of the tightest bounds over the last frames (NTP's reasoning:
the best observations are the ones with the least delay), or the upper bound while no trigger
bounds it from below.  The map is trusted only once its frames span ``verify_span_s`` of host
time and the device clock ran at the host's rate over that span (within ``rate_tolerance``,
measured between the least-delayed of the first and of the last few frames):
until then, or when the device clock is absent (0), runs at another rate or jumps (bounds that
cross), ``host_time`` answers None and the caller uses its fallback (the software trigger
time).  Pure arithmetic: tested without a camera.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

ENVELOPE = 8  # frames at each end of the rate check


@dataclass(frozen=True)
class Sample:
    """One frame's stamps, in seconds: the camera's clock, the host's at first packet, and the
    host's when the software trigger was sent (None for line/free-running triggers)."""

    device_s: float
    system_s: float
    trigger_s: float | None


class ClockMap:
    """Maps device timestamps to host time from the frames' own stamps."""

    def __init__(self, window: int = 64, verify_span_s: float = 2.0,
                 rate_tolerance: float = 0.02) -> None:
        if window < 2 or not verify_span_s > 0 or not 0 < rate_tolerance < 1:
            raise ValueError("window >= 2, verify_span_s > 0 and 0 < rate_tolerance < 1")
        self.window = window
        self.verify_span_s = verify_span_s
        self.rate_tolerance = rate_tolerance
        self._samples: deque[Sample] = deque(maxlen=window)
        self._early: list[Sample] = []  # the first ENVELOPE samples since the last reset
        self.reason = "no frames yet"
        self.checking = True  # not trusted yet only because too few frames were seen

    def reset(self, reason: str) -> None:
        """Forget everything (a reconnect, a clock that jumped); ``reason`` says why."""
        self._samples.clear()
        self._early = []
        self.reason = reason
        self.checking = False

    def add(self, device_s: float, system_s: float, trigger_s: float | None = None) -> None:
        """Record one frame's stamps; a zero or non-finite device stamp resets the map."""
        if not (device_s > 0 and math.isfinite(device_s) and math.isfinite(system_s)):
            self.reset("the camera gives no timestamps")
            return
        sample = Sample(device_s, system_s, trigger_s)
        if self._samples and device_s <= self._samples[-1].device_s:
            self.reset("the camera's clock went backwards")
        self._samples.append(sample)
        if len(self._early) < ENVELOPE:
            self._early.append(sample)
        lo, hi = self._bounds()
        if lo is not None and lo > hi:
            self.reset("the camera's clock jumped (its stamps contradict the host's)")
            self._samples.append(sample)
            self._early = [sample]

    def _bounds(self) -> tuple[float | None, float]:
        hi = min(s.system_s - s.device_s for s in self._samples)
        lows = [s.trigger_s - s.device_s for s in self._samples if s.trigger_s is not None]
        return (max(lows) if lows else None), hi

    def offset(self) -> float | None:
        """``host - device`` in seconds, or None while the map is not trusted (``reason``)."""
        if not self._samples or not self._early:
            return None
        # the rate from the least-delayed frame among the first few and among the last few:
        # a frame delayed by load or transfer does not pass for a clock running slow
        a = min(self._early, key=lambda s: s.system_s - s.device_s)
        b = min(list(self._samples)[-ENVELOPE:], key=lambda s: s.system_s - s.device_s)
        span_host = b.system_s - a.system_s
        self.checking = span_host < self.verify_span_s
        if self.checking:
            self.reason = (f"the camera's clock is being checked ({max(span_host, 0.0):.2f} "
                           f"of {self.verify_span_s:g} s of frames)")
            return None
        rate = (b.device_s - a.device_s) / span_host
        if abs(rate - 1.0) > self.rate_tolerance:
            self.reason = (f"the camera's clock runs at {rate:.3g} x the host's (a wrong "
                           "timestamp unit?)")
            return None
        lo, hi = self._bounds()
        self.reason = ""
        return hi if lo is None else 0.5 * (lo + hi)

    def interval(self, device_s: float) -> tuple[float, float] | None:
        """The host times device instant ``device_s`` may be (earliest, latest), or None
        while the map is not trusted.  Without triggers the earliest is unbounded."""
        if self.offset() is None:
            return None
        lo, hi = self._bounds()
        return device_s + (-math.inf if lo is None else lo), device_s + hi

    def host_time(self, device_s: float) -> float | None:
        """The host time of device instant ``device_s``, or None while not trusted."""
        off = self.offset()
        return None if off is None else device_s + off
