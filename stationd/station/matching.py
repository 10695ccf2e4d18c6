"""Which bolt is the wrench on?  Only an answer that cannot be the wrong bolt.

A bolt is *taken* only when all of these hold, else the matcher says why it takes none:
- the bolt end is within ``tolerance_mm`` of the bolt (in the vehicle frame, X and Y: the
  depth along the wrench axis is where the socket sits, not which bolt it is);
- the second-nearest bolt is farther than the nearest by ``margin_mm`` (unambiguous);
- the bolt is not done yet (unless re-tightening is allowed);
- the same bolt has been the answer for ``stable_frames`` consecutive localizations, each no
  older than ``max_age_s`` (a stale or flickering answer is no answer).
A refused localization breaks the streak: stability must be earned again.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class MatchParams:
    tolerance_mm: float = 8.0
    margin_mm: float = 6.0
    stable_frames: int = 3
    max_age_s: float = 0.5
    allow_retighten: bool = False


@dataclass(frozen=True)
class Match:
    """The matcher's verdict for one localization: ``bolt`` is set only when it is taken."""

    bolt: str | None
    candidate: str | None
    distance_mm: float | None
    reason: str | None
    streak: int = 0


@dataclass
class BoltMatcher:
    """Matches bolt ends to a vehicle's bolt table, with the stability rule."""

    bolts: Mapping[str, np.ndarray]  # id -> position (vehicle frame, mm)
    params: MatchParams = field(default_factory=MatchParams)
    done: set[str] = field(default_factory=set)
    skipped: dict[str, str] = field(default_factory=dict)  # bolt -> why it is not tightened
    _ids: list[str] = field(init=False, repr=False)
    _xy: np.ndarray = field(init=False, repr=False)
    _streak_bolt: str | None = field(default=None, init=False, repr=False)
    _streak: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        self._ids = list(self.bolts)
        self._xy = np.array([np.asarray(self.bolts[i], dtype=np.float64)[:2]
                             for i in self._ids]).reshape(-1, 2)

    def mark_done(self, bolt: str) -> None:
        self.done.add(bolt)
        self.reset()

    def reset(self) -> None:
        """Forget the streak (after a selection, a refusal, or the wrench leaving)."""
        self._streak_bolt, self._streak = None, 0

    def refuse(self, reason: str) -> Match:
        """A localization was refused (or is missing): no bolt, and the streak restarts."""
        self.reset()
        return Match(None, None, None, reason)

    def update(self, bolt_end_mm: np.ndarray, age_s: float = 0.0) -> Match:
        p = self.params
        if age_s > p.max_age_s:
            return self.refuse(f"localization is stale ({age_s * 1e3:.0f} ms old)")
        if not self._ids:
            return self.refuse("this vehicle has no bolts")
        d = np.hypot(*(self._xy - np.asarray(bolt_end_mm, dtype=np.float64)[:2]).T)
        order = np.argsort(d)
        i = int(order[0])
        near, dist = self._ids[i], float(d[i])
        if dist > p.tolerance_mm:
            return self.refuse(f"no bolt within {p.tolerance_mm:g} mm (nearest {near} at "
                               f"{dist:.1f} mm)")
        if len(order) > 1:
            second = float(d[int(order[1])])
            if second - dist < p.margin_mm:
                return self.refuse(f"ambiguous: {near} at {dist:.1f} mm, "
                                   f"{self._ids[int(order[1])]} at {second:.1f} mm")
        if near in self.skipped:
            self.reset()
            return Match(None, near, dist, f"{near} skipped: {self.skipped[near]}")
        if near in self.done and not p.allow_retighten:
            self.reset()
            return Match(None, near, dist, f"{near} is already done")
        self._streak = self._streak + 1 if self._streak_bolt == near else 1
        self._streak_bolt = near
        if self._streak < p.stable_frames:
            return Match(None, near, dist, f"{near}: stable for {self._streak} of "
                         f"{p.stable_frames} frames", self._streak)
        return Match(near, near, dist, None, self._streak)


def check_spacing(bolts: Mapping[str, Iterable[float]], tolerance_mm: float) -> list[str]:
    """Pairs of bolts closer than twice the tolerance (their capture zones would overlap)."""
    ids = list(bolts)
    xy = np.array([list(bolts[i])[:2] for i in ids], dtype=np.float64).reshape(-1, 2)
    out = []
    for a in range(len(ids)):
        for b in range(a + 1, len(ids)):
            d = float(np.hypot(*(xy[a] - xy[b])))
            if d < 2 * tolerance_mm:
                out.append(f"{ids[a]} and {ids[b]} are {d:.1f} mm apart (< 2 x {tolerance_mm:g})")
    return out
