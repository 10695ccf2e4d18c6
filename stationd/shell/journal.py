"""Which refusals the journal writes: each once, then how many times it came again.

Why: the core publishes a refusal whenever its kind or bolts change (the screens must follow
the wrench), so a wrench held still between two bolts, or flickering between "tilted" and
"not stable", alternates two refusals and the journal wrote a line a second for as long as
it stayed there.  Here a refusal said in the last ``quiet_s`` is counted instead of written;
its count is written when the episode ends (a bolt selected, a change of state, a vehicle
opened or closed) or with its next line after ``quiet_s``.  Event times only (no clock),
so it is tested event by event.
"""

from __future__ import annotations

from dataclasses import dataclass

from stationd.reasons import Reason
from stationd.words import reason_words

QUIET_S = 60.0   # a refusal said this recently is counted, not written again
KEPT = 64        # refusals remembered at once (an episode of more is cut short)


@dataclass
class _Said:
    words: str
    at: float           # when its last line was written
    again: int = 0      # how many times it came since, not written


class RefusalJournal:
    """``refused(reason, t)``: the line to write now, or None (counted); ``ended(t)``: the
    counts of the episode that ended, one line each."""

    def __init__(self, quiet_s: float = QUIET_S) -> None:
        self.quiet_s = quiet_s
        self._said: dict[tuple[object, ...], _Said] = {}

    def refused(self, reason: Reason, t: float) -> str | None:
        key = reason.key()
        said = self._said.get(key)
        if said is not None and t - said.at < self.quiet_s:
            said.again += 1
            return None
        words = reason_words(reason, full=True)
        line = f"no bolt: {words}"
        if said is not None and said.again:
            line += f" (again {_times(said.again)} in the {t - said.at:.0f} s before)"
        if said is None and len(self._said) >= KEPT:
            self._said.pop(next(iter(self._said)))
        self._said[key] = _Said(words, t)
        return line

    def ended(self, t: float) -> list[str]:
        """The episode of refusals ended: each one that came again since its line, with how
        many times and over how long; then it starts afresh."""
        lines = [f"no bolt: {s.words}: again {_times(s.again)} in {t - s.at:.0f} s"
                 for s in self._said.values() if s.again]
        self._said.clear()
        return lines


def _times(n: int) -> str:
    return "once" if n == 1 else f"{n} times"
