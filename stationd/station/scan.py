"""Which camera pairs to grab and localize in a cycle: attention on the pairs that see the
marker.

Localizing every pair every cycle costs the same CPU whether a pair sees the wrench or not
(one reduced search per 20 MP image at least), and on a station's few cores the pair that
sees it waits for the others: the latency from exposure to parameters is mostly that wait.
While some pairs see the marker, only they are localized every cycle and the others every
``every``-th cycle (so a wrench that also comes into their view is still found, at a quarter
of the rate); as soon as a watched pair no longer sees it, or none does, every pair is
localized the next cycle.  Nothing about safety changes: a decision still uses only what was
localized in its own cycle, with its own exposure time.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence


class ScanPlan:
    """The pairs of the next cycle (:meth:`choose`), from what the last cycle saw
    (:meth:`saw`)."""

    def __init__(self, every: int = 4) -> None:
        if every < 1:
            raise ValueError("every must be >= 1")
        self.every = every
        self._watch: frozenset[str] = frozenset()
        self._since_full = 0

    @property
    def watching(self) -> frozenset[str]:
        """The pairs that saw the marker in the last cycle."""
        return self._watch

    def choose(self, names: Sequence[str]) -> list[str]:
        """The pairs to localize this cycle, in ``names``' order."""
        watched = [n for n in names if n in self._watch]
        if not watched or self._since_full + 1 >= self.every:
            self._since_full = 0
            return list(names)
        self._since_full += 1
        return watched

    def saw(self, seen: Mapping[str, bool]) -> None:
        """What this cycle's pairs saw (pair -> marker seen in either image).  A watched pair
        that no longer sees it ends the watch: every pair is localized next."""
        lost = any(not seen.get(n, True) for n in self._watch)
        now = {n for n, s in seen.items() if s}
        if lost:
            self._watch = frozenset()
        else:
            self._watch = frozenset(now | {n for n in self._watch if n not in seen})
