"""A count in words, as English says it: ``counted(1, "bolt")`` is "1 bolt", ``counted(3,
"bolt")`` "3 bolts" (never "3 bolt(s)").  db imports nothing of drivers or stationd: this is
its copy of :mod:`drivers.counting` (kept alike: tests/test_counting.py runs the same checks on
both)."""

from __future__ import annotations


def noun(n: float, word: str, plural: str | None = None) -> str:
    """The noun for ``n`` of it: ``word`` for exactly one, else ``plural`` (default: ``word``
    + "s"): ``noun(2, "key")`` is "keys", ``noun(2, "entry", "entries")`` "entries"."""
    return word if n == 1 else plural if plural is not None else word + "s"


def counted(n: float, word: str, plural: str | None = None) -> str:
    """``n`` and its noun: "1 bolt", "0 bolts", "3 bolts" (a float as ``:g`` prints it)."""
    number = f"{n:g}" if isinstance(n, float) else str(n)
    return f"{number} {noun(n, word, plural)}"


__all__ = ["counted", "noun"]
