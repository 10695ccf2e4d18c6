"""Which tightening ids to ask the controller for after a reconnect: the ids between the last
one the station recorded and the controller's newest.

Why a rule of its own: Open Protocol's tightening id grows by one with every tightening, so a
jump after the link was down is a result the station never heard.  It is fetched (MID
0064/0065) and recorded late, or, if the controller no longer has it, recorded as a gap:
visibly, never silently.  A station that never recorded anything takes the controller's
newest as its starting point (the controller's history before it is not this station's; what
it made since the link was lost is found back by time instead, in the shell's catch-up), and
so does a controller whose ids went backwards (replaced, reset): its new count is not the one
the last recorded id belongs to.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

MAX_FETCH = 100   # ids fetched one by one after a reconnect; older ones are one gap


class NoFetch(enum.StrEnum):
    """Why nothing is fetched though the controller's newest is not the last recorded: the
    kind of a :class:`GapPlan`'s ``why`` (its words: :func:`stationd.words.gap_plan_words`,
    for the journal)."""

    NOTHING_RECORDED = "nothing recorded"  # no tightening recorded yet: counting from the
    #                                        controller's newest (newest)
    IDS_RESTARTED = "ids restarted"        # the newest older than the last recorded (newest,
    #                                        last_recorded)


@dataclass(frozen=True)
class GapPlan:
    """``fetch``: the ids to ask for, oldest first; ``gap``: an id range given up on
    (too many missing), or None; ``why``: why nothing is fetched, typed (the shell's journal
    says it), with the ids it was decided from."""

    fetch: tuple[int, ...] = ()
    gap: tuple[int, int] | None = None
    why: NoFetch | None = None
    newest: int | None = None           # the controller's newest (with ``why``)
    last_recorded: int | None = None    # the last id recorded (with ``why``)


def plan(last_recorded: int | None, newest: int, most: int = MAX_FETCH) -> GapPlan:
    """What to fetch when the station last recorded ``last_recorded`` and the controller's
    newest tightening is ``newest``."""
    if last_recorded is None:
        return GapPlan(why=NoFetch.NOTHING_RECORDED, newest=newest)
    if newest < last_recorded:
        return GapPlan(why=NoFetch.IDS_RESTARTED, newest=newest, last_recorded=last_recorded)
    missing = newest - last_recorded
    if missing == 0:
        return GapPlan()
    if missing <= most:
        return GapPlan(tuple(range(last_recorded + 1, newest + 1)))
    return GapPlan(tuple(range(newest - most + 1, newest + 1)),
                   (last_recorded + 1, newest - most))


__all__ = ["MAX_FETCH", "GapPlan", "NoFetch", "plan"]
