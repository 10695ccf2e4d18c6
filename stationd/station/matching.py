"""Which bolt is the wrench on?  Only an answer that cannot be the wrong bolt.

A bolt is *taken* only when all of these hold, else the matcher says why it takes none:
- the bolt end is within ``tolerance_mm`` of the bolt (in the vehicle frame, X and Y: the
  depth along the wrench axis is where the socket sits, not which bolt it is);
- the second-nearest bolt is farther than the nearest by ``margin_mm`` (unambiguous);
- the bolt is not done yet (unless re-tightening is allowed) and not skipped;
- the bolt table's sequence allows it now (``order`` and ``batch``, below);
- the same bolt has been the answer for ``stable_frames`` consecutive localizations, each no
  older than ``max_age_s`` (a stale or flickering answer is no answer).
A refused localization breaks the streak: stability must be earned again.

The checks run in that order (tolerance and ambiguity, then done and skipped, then the sequence,
then stability), so the reason given is the first one that applies.  A bolt refused for
tolerance or ambiguity has no ``candidate``; a bolt refused for any later reason keeps its
``candidate`` and distance, so the cycle still sees where the wrench is (leave detection).

Sequence (``rules``: bolt id -> :class:`BoltRule`, from the bolt table's optional ``order`` and
``batch``; a bolt without a rule has neither):

- *Order*: "lower orders are tightened first".  A bolt with order k may be taken only when every
  bolt *of the same batch* with an order below k is done; bolts without a batch are ordered
  among themselves, as one more group.  Bolts without an order are not constrained by order
  and do not block anybody's order.  Orders do not reach across batches: with the batch rule
  below, an order from one batch to another could never be met (batch A started, then A's
  order 2 waits for B's order 1, which waits for A to be finished), so that a table valid on
  paper would stop the line.
- *Batch*: "bolts tightened together as one batch".  Once any bolt of a batch is done, the
  batch is *open* until all its bolts are done, and only bolts of an open batch may be taken.
  (Two batches are open at once only if a vehicle resumed like that: then bolts of either may
  be taken, else neither could ever be finished.)
- *Done* is what :meth:`BoltMatcher.mark_done` records, plus ``done`` given at construction (a
  vehicle resumed after a restart).  A skipped bolt is not done: it still blocks (its order's
  followers, the rest of the world while its batch is open) and the reason says it was skipped
  and why, so that the operator knows what to do: the vehicle then goes out with the blocked
  bolts missing rather than tightened out of sequence.
- *Counted* (``counted``): bolts not done whose NOK counts in their batch (the NOK policy's
  ``count_in_batch``): the sequence treats them as done (their batch may close, their order's
  followers go on), the selection does not (a NOK bolt may still be tightened again).
- The sequence applies to re-tightening a done bolt too (when allowed): it is a tightening.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from db.spacing import min_spacing_mm, too_close
from stationd.reasons import Reason, Skip, Wait, WaitKind, Why
from stationd.yamlio import YamlNode


@dataclass(frozen=True)
class MatchParams:
    tolerance_mm: float = 8.0
    margin_mm: float = 6.0
    stable_frames: int = 3
    max_age_s: float = 0.5
    allow_retighten: bool = False


@dataclass(frozen=True)
class BoltRule:
    """A bolt's place in the sequence: the bolt table's ``order`` (1..9999, lower first) and
    ``batch`` (a name); either may be None (not ordered, in no batch)."""

    order: int | None = None
    batch: str | None = None


NO_RULE = BoltRule()


@dataclass(frozen=True)
class Match:
    """The matcher's verdict for one localization: ``bolt`` is set only when it is taken,
    else ``reason`` says why not (typed: the edges put it into words)."""

    bolt: str | None
    candidate: str | None
    distance_mm: float | None
    reason: Reason | None
    streak: int = 0


@dataclass
class BoltMatcher:
    """Matches bolt ends to a vehicle's bolt table, with the sequence and stability rules.

    Pure: no I/O, no clock.  Build ``rules`` from the repository's bolts with
    ``{b.bolt_id: BoltRule(b.order, b.batch) for b in infos}``; without it nothing is ordered.
    """

    bolts: Mapping[str, np.ndarray]  # id -> position (vehicle frame, mm)
    params: MatchParams = field(default_factory=MatchParams)
    done: set[str] = field(default_factory=set)
    skipped: dict[str, Skip] = field(default_factory=dict)  # bolt -> why it is not tightened
    locked: dict[str, int] = field(default_factory=dict)   # bolt -> NOKs in a row (released
    #                                                        only by a supervisor's command)
    #: bolt -> why its result is not known (an unreadable result): refused, like a lock,
    #: until a supervisor has checked it on the controller and released it
    held: dict[str, str] = field(default_factory=dict)
    counted: set[str] = field(default_factory=set)  # NOK last, counted done by the sequence
    # id -> order and batch; read once, at construction.  Rules of ids that are not in
    # ``bolts`` are ignored: a bolt the station cannot tighten must not block the others.
    rules: Mapping[str, BoltRule] = field(default_factory=dict)
    _ids: list[str] = field(init=False, repr=False)
    _xy: np.ndarray = field(init=False, repr=False)
    _rule: dict[str, BoltRule] = field(init=False, repr=False)
    _before: dict[str, list[str]] = field(init=False, repr=False)  # lower orders, same group
    _batches: dict[str, list[str]] = field(init=False, repr=False)  # batch -> its bolts
    _streak_bolt: str | None = field(default=None, init=False, repr=False)
    _streak: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        self._ids = list(self.bolts)
        self._xy = np.array([np.asarray(self.bolts[i], dtype=np.float64)[:2]
                             for i in self._ids]).reshape(-1, 2)
        # precomputed in table order (the order the operator reads the bolt list in)
        self._rule = {i: self.rules.get(i, NO_RULE) for i in self._ids}
        self._before, self._batches = {}, {}
        for i, r in self._rule.items():
            if r.batch is not None:
                self._batches.setdefault(r.batch, []).append(i)
            if r.order is not None:
                k = r.order
                self._before[i] = [j for j, q in self._rule.items() if q.batch == r.batch
                                   and q.order is not None and q.order < k]

    def mark_done(self, bolt: str) -> None:
        """``bolt`` is tightened OK: it is not taken again, and what follows it in the sequence
        may now be taken."""
        self.done.add(bolt)
        self.reset()

    def why_blocked(self, bolt: str) -> Wait | None:
        """Why the sequence (order, batch) forbids taking ``bolt`` now, or None if it allows it.

        Only the sequence: tolerance, done, skipped and stability are :meth:`update`'s.  Done
        and skipped are read live, so :meth:`mark_done` (or a new skip) counts at once.
        """
        blocked = self._blocked(bolt)
        return None if blocked is None else blocked[0]

    def _blocked(self, bolt: str) -> tuple[Wait, tuple[str, ...], tuple[tuple[str, Skip], ...]] \
            | None:
        """Why the sequence forbids ``bolt`` (the rule, typed: words are the edges'), the
        bolts it waits for, and those of them that were skipped with why (waiting for them is
        waiting for something that will not happen on its own: the refusal names them); None
        if it allows it."""
        rule = self._rule.get(bolt, NO_RULE)
        open_batches: dict[str, list[str]] = {}
        for name, members in self._batches.items():
            rest = [b for b in members if b not in self.done and b not in self.counted]
            if rest and len(rest) < len(members):
                open_batches[name] = rest
        if open_batches and rule.batch not in open_batches:
            why = Wait(WaitKind.BATCH, batches=tuple((name, tuple(rest))
                                                     for name, rest in open_batches.items()))
            waits = [b for r in open_batches.values() for b in r]
        else:
            waits = [b for b in self._before.get(bolt, ())
                     if b not in self.done and b not in self.counted]
            if not waits:
                return None
            why = Wait(WaitKind.ORDER, order=rule.order, batch=rule.batch, bolts=tuple(waits))
        skips = tuple((b, self.skipped[b]) for b in waits if b in self.skipped)
        return why, tuple(waits), skips

    def reset(self) -> None:
        """Forget the streak (after a selection, a refusal, or the wrench leaving)."""
        self._streak_bolt, self._streak = None, 0

    def refuse(self, reason: Reason) -> Match:
        """A localization was refused (or is missing): no bolt, and the streak restarts."""
        self.reset()
        return Match(None, None, None, reason)

    def update(self, bolt_end_mm: np.ndarray, age_s: float = 0.0) -> Match:
        p = self.params
        if age_s > p.max_age_s:
            return self.refuse(Reason(Why.STALE, age_ms=age_s * 1e3, limit=p.max_age_s * 1e3))
        if not self._ids:
            return self.refuse(Reason(Why.NO_BOLTS))
        d = np.hypot(*(self._xy - np.asarray(bolt_end_mm, dtype=np.float64)[:2]).T)
        order = np.argsort(d)
        i = int(order[0])
        near, dist = self._ids[i], float(d[i])
        if dist > p.tolerance_mm:
            return self.refuse(Reason(Why.NO_BOLT_NEAR, bolt=near, distance_mm=dist,
                                      limit=p.tolerance_mm))
        if len(order) > 1:
            second = float(d[int(order[1])])
            if second - dist < p.margin_mm:
                return self.refuse(Reason(Why.AMBIGUOUS, bolt=near, distance_mm=dist,
                                          other=self._ids[int(order[1])], other_mm=second))
        if near in self.held:
            self.reset()
            return Match(None, near, dist, Reason(Why.HELD, bolt=near, note=self.held[near]))
        if near in self.locked:
            self.reset()
            return Match(None, near, dist, Reason(Why.LOCKED, bolt=near,
                                                  count=self.locked[near]))
        if near in self.skipped:
            self.reset()
            return Match(None, near, dist, Reason(Why.SKIPPED, bolt=near,
                                                  skip=self.skipped[near]))
        if near in self.done and not p.allow_retighten:
            self.reset()
            return Match(None, near, dist, Reason(Why.DONE, bolt=near))
        blocked = self._blocked(near)
        if blocked is not None:
            self.reset()
            return Match(None, near, dist, Reason(Why.MUST_WAIT, bolt=near, wait=blocked[0],
                                                  blocking=blocked[1], skips=blocked[2]))
        self._streak = self._streak + 1 if self._streak_bolt == near else 1
        self._streak_bolt = near
        if self._streak < p.stable_frames:
            return Match(None, near, dist, Reason(Why.NOT_STABLE, bolt=near,
                                                  count=self._streak, needed=p.stable_frames),
                         self._streak)
        return Match(near, near, dist, None, self._streak)


def check_spacing(bolts: Mapping[str, Iterable[float]], tolerance_mm: float) -> list[str]:
    """Pairs of bolts closer in X-Y than twice the tolerance (their capture zones would
    overlap): the bolt table's own rule (:mod:`db.spacing`), in this matcher's metric."""
    ids = list(bolts)
    pos = [list(bolts[i]) for i in ids]
    return [f"{ids[j]} and {ids[i]} are {d:.1f} mm apart in X-Y "
            f"(< {min_spacing_mm(tolerance_mm):g} = 2 x {tolerance_mm:g})"
            for i, j, d in too_close(pos, tolerance_mm)]

# what a person types, bounded to what can work (outside: a typo or another unit):
# the bolt end is localized to about a millimetre, so a tolerance under 1 mm never matches
# (0.008 is 8 mm written in metres); above 50 mm the wrench is "on" a bolt 5 cm away, and
# the bolt table's bolts would have to be 10 cm apart to be told apart
TOLERANCE_MM = (1.0, 50.0)
MAX_AGE_S = (0.05, 5.0)         # plausible staleness limits, seconds
# the second-nearest bolt must be this much farther than the nearest: under 1 mm (the
# localization's own scatter) it tells nothing apart (0.006 is 6 mm in metres); above 100 mm
# every bolt with a neighbour closer than that is ambiguous for ever (600 is no margin, it
# is a typo or another unit)
MARGIN_MM = (1.0, 100.0)


@dataclass(frozen=True)
class MatchingConfig(MatchParams):
    """Which bolt the wrench is on (the matcher's parameters, see stationd.station.matching)
    and after how many frames off it the wrench has left it."""

    leave_frames: int = 3

    @classmethod
    def from_node(cls, node: YamlNode) -> MatchingConfig:
        m = node.mapping(cls.__dataclass_fields__)
        kw: dict[str, Any] = {}
        for k, v in m.items():
            if k in ("stable_frames", "leave_frames"):
                kw[k] = v.integer(lo=1, hi=100)
            elif k == "allow_retighten":
                kw[k] = v.flag()
            elif k == "tolerance_mm":
                tol = v.number()
                if not TOLERANCE_MM[0] <= tol <= TOLERANCE_MM[1]:
                    raise v.error(f"{tol:g} mm is not plausible: the bolt end must be within "
                                  f"{TOLERANCE_MM[0]:g}-{TOLERANCE_MM[1]:g} mm of its bolt "
                                  "(millimetres: 8 for 8 mm, not 0.008)")
                kw[k] = tol
            elif k == "margin_mm":
                kw[k] = _margin(v)
            elif k == "max_age_s":
                age = v.number()
                if not MAX_AGE_S[0] <= age <= MAX_AGE_S[1]:
                    raise v.error(f"{age:g} s is not plausible: a localization older than "
                                  f"{MAX_AGE_S[0]:g}-{MAX_AGE_S[1]:g} s is stale (seconds, "
                                  "counted from the frames' exposure)")
                kw[k] = age
            else:
                kw[k] = v.number(lo=0.0, hi=1000.0)
        return replace(cls(), **kw)


def _margin(node: YamlNode) -> float:
    """``margin_mm`` within :data:`MARGIN_MM`, its likely unit mistake named."""
    margin = node.number()
    if MARGIN_MM[0] <= margin <= MARGIN_MM[1]:
        return margin
    if margin < MARGIN_MM[0]:
        hint = f"in metres? write {margin * 1e3:g} for {margin * 1e3:g} mm" \
            if MARGIN_MM[0] <= margin * 1e3 <= MARGIN_MM[1] else "6 by default"
        why = "the nearest bolt must be that much nearer than the next to be told apart"
    else:
        hint = "6 by default"
        why = (f"every bolt with another within {margin:g} mm would be ambiguous for "
               "ever")
    raise node.error(f"a margin of {margin:g} mm is not plausible ({MARGIN_MM[0]:g}-"
                     f"{MARGIN_MM[1]:g} mm): {why} (millimetres: {hint})")
