"""Which camera pairs to grab and localize in a cycle: attention on the pairs that see the
marker.

Localizing every pair every cycle costs the same CPU whether a pair sees the wrench or not
(one reduced search per 20 MP image at least), and on a station's few cores the pair that
sees it waits for the others: the latency from exposure to parameters is mostly that wait.
While some pairs see the marker, only they are localized for the decision every cycle; every
``every``-th cycle the others are localized too, *after* the watched pairs' localization has
gone to the core (a scout: what it finds joins the watch, so a wrench that also comes into
their view is still found, at a quarter of the rate, without delaying a decision).  As soon
as a watched pair no longer sees the marker, or none does, every pair is localized for the
next decision.  Nothing about safety changes: a decision still uses only what was localized
in its own cycle, with its own exposure time.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Cycle:
    """The pairs whose localization goes to the core (``decide``), then the pairs localized
    only to see whether the marker came into their view (``scout``)."""

    decide: list[str]
    scout: list[str]


class ScanPlan:
    """The pairs of the next cycle (:meth:`choose`), from what the last ones saw
    (:meth:`saw`)."""

    def __init__(self, every: int = 4) -> None:
        if every < 1:
            raise ValueError("every must be >= 1")
        self.every = every
        self._watch: frozenset[str] = frozenset()
        self._since_full = 0

    @property
    def watching(self) -> frozenset[str]:
        """The pairs that saw the marker when last localized."""
        return self._watch

    def choose(self, names: Sequence[str]) -> Cycle:
        """This cycle's pairs, in ``names``' order."""
        watched = [n for n in names if n in self._watch]
        if not watched:
            self._since_full = 0
            return Cycle(list(names), [])
        self._since_full += 1
        if self._since_full >= self.every:
            self._since_full = 0
            return Cycle(watched, [n for n in names if n not in self._watch])
        return Cycle(watched, [])

    def saw(self, seen: Mapping[str, bool]) -> None:
        """What some pairs saw (pair -> marker seen in either image).  A watched pair that no
        longer sees it ends the watch (every pair is localized for the next decision); a pair
        that sees it joins."""
        if any(not seen.get(n, True) for n in self._watch):
            self._watch = frozenset()
        else:
            self._watch = frozenset({n for n, s in seen.items() if s} | self._watch)
