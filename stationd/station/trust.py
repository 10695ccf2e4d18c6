"""Which camera pairs the station trusts: the rules of the calibration check, pure.

Why: a pair knocked out of place localizes the wrench confidently and wrongly, and a wrong
position is a wrong bolt.  With reference markers configured (``references:``), no pair is
trusted after a start or a reload until a check has measured its references within the
tolerance; a check is asked for when a vehicle arrives (its pairs are not trusted again until
it answers), every ``period_s`` while the station is idle, again every :data:`RETRY_S` while a
pair is unchecked with a vehicle loaded, and on a person's command.  A pair whose reference is
off beyond the tolerance is *moved*: a fault of that pair alone (the others go on), until a
check finds it in place again.  A bolt end that only untrusted pairs see is refused with the
pair's reason.

Without references nothing changes: every pair is trusted, and the station says that no
calibration check is configured.  The core (:mod:`stationd.station.core`) owns one
:class:`PairTrust` and calls it; nothing here does I/O.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from stationd.localize.check import PairCheck, RefWhy, Verdict
from stationd.reasons import Reason, Unchecked, UncheckedKind, Why

#: with a vehicle loaded, an unchecked pair is checked again this often, s
RETRY_S = 10.0
#: a check not answered in this long is asked again (the shell lost it), s
WAIT_S = 30.0


def reason_of(check: PairCheck) -> Reason | None:
    """What a check's verdict makes of its pair: None (trusted), moved, or unchecked."""
    if check.verdict is Verdict.OK:
        return None
    if check.verdict is Verdict.MOVED:
        return Reason(Why.PAIR_MOVED, pair=check.pair, reference=check.reference,
                      distance_mm=check.offset_mm, limit=check.tolerance_mm)
    return Reason(Why.PAIR_UNCHECKED, pair=check.pair, reference=check.reference,
                  unchecked=Unchecked(UncheckedKind.NOT_MEASURED, reference=check.reference,
                                      measure=check.why.value if check.why is not None
                                      else None, note=check.note or None))


def summary(check: PairCheck) -> dict[str, Any]:
    """A check as plain values (a command's answer, the records)."""
    return {"verdict": check.verdict.value, "reference": check.reference,
            "offset_mm": check.offset_mm, "tolerance_mm": check.tolerance_mm,
            "why": check.why.value if check.why is not None else None, "note": check.note,
            "references": {m.name: {"offset_mm": m.offset_mm, "measured_mm": m.measured_mm,
                                    "why": m.why.value if m.why is not None else None,
                                    "note": m.note} for m in check.measures}}


def from_summary(pair: str, s: Mapping[str, Any]) -> PairCheck:
    """A check back from :func:`summary`'s plain values (a daemon's answer read by a client):
    its verdict, worst reference, offset and why (each reference's own measurement is left
    out)."""
    return PairCheck(pair, Verdict(s["verdict"]), (), s.get("reference"), s.get("offset_mm"),
                     float(s.get("tolerance_mm") or 0.0),
                     RefWhy(s["why"]) if s.get("why") is not None else None, s.get("note"))


@dataclass
class PairTrust:
    """The pairs the check measures and what is known of each: ``None`` trusted, else the
    reason it is not (unchecked, moved)."""

    pairs: tuple[str, ...]
    period_s: float
    retry_s: float = RETRY_S
    wait_s: float = WAIT_S
    why: dict[str, Reason | None] = field(default_factory=dict)
    last_t: float | None = None       # when the last check's answer came
    asked_t: float | None = None      # a check asked and not answered yet, since
    #: the last time every pair was distrusted (a vehicle's arrival): a check asked before
    #: it measured frames that may predate the new vehicle and trusts no pair again
    distrusted_t: float = float("-inf")
    requests: list[int] = field(default_factory=list)   # commands waiting for the answer

    def __post_init__(self) -> None:
        self.distrust(Unchecked(UncheckedKind.SINCE_START))

    def distrust(self, why: Unchecked, t: float | None = None) -> None:
        """Every pair unchecked, with ``why`` (a start, a vehicle's arrival at ``t``): trusted
        again by a check asked since.  A moved pair stays moved: only a check that finds it in
        place clears that."""
        if t is not None:
            self.distrusted_t = t
        for p in self.pairs:
            if not _moved(self.why.get(p)):
                self.why[p] = Reason(Why.PAIR_UNCHECKED, pair=p, unchecked=why)

    def untrusted(self) -> dict[str, Reason]:
        """The pairs not trusted now, with why (what the localization leaves out)."""
        return {p: r for p, r in self.why.items() if r is not None}

    def refusal(self, pairs: Sequence[str]) -> Reason | None:
        """Why a bolt end made by ``pairs`` may not be used, or None: every one of them must
        be trusted (and which pairs made it must be known)."""
        if not pairs:
            return Reason(Why.PAIR_UNCHECKED,
                          unchecked=Unchecked(UncheckedKind.PAIRS_UNKNOWN))
        for p in pairs:
            if p not in self.why:
                return Reason(Why.PAIR_UNCHECKED, pair=p,
                              unchecked=Unchecked(UncheckedKind.NO_MARKER))
            if self.why[p] is not None:
                return self.why[p]
        return None

    def due(self, t: float, *, idle: bool, vehicle: bool) -> bool:
        """Whether a check is to be asked now (none is pending): the idle period has passed,
        or, with a vehicle loaded, a pair is unchecked and the retry time has passed."""
        if self.asked_t is not None and t - self.asked_t < self.wait_s:
            return False
        since = t - self.last_t if self.last_t is not None else float("inf")
        unchecked = any(r is not None and r.kind is Why.PAIR_UNCHECKED
                        for r in self.why.values())
        if vehicle and unchecked and since >= self.retry_s:
            return True
        return idle and since >= self.period_s

    def asked(self, t: float) -> None:
        self.asked_t = t

    def answered(self, t: float, checks: Iterable[PairCheck], asked_t: float | None = None
                 ) -> list[tuple[PairCheck, Reason | None, Reason | None]]:
        """The checks' verdicts applied: each check with its pair's reason before and after.
        A pair not checked for want of its references (on the lift, away) keeps what it
        was: nothing was learnt about it.  A check asked (``asked_t``) before the last
        distrust (a vehicle arrived while it was grabbing) trusts no pair: its frames may be
        older than the vehicle; a pair it found moved is moved all the same."""
        stale = asked_t is not None and asked_t < self.distrusted_t
        if not stale:   # a stale answer leaves the newer check asked at the arrival pending
            self.last_t, self.asked_t = t, None
        out = []
        for c in checks:
            if c.pair not in self.why:
                continue
            before = self.why[c.pair]
            after = reason_of(c)
            if c.verdict is Verdict.NOT_CHECKED and c.why is RefWhy.LIFT_AWAY:
                after = before
            if stale and (after is None or not _moved(after)):
                after = before
            self.why[c.pair] = after
            out.append((c, before, after))
        return out


# -- the core's input and actions for the check ----------------------------------------------
@dataclass(frozen=True)
class ReferencesChecked:
    """Input: the shell measured the references (``checks``: one per pair asked, a pair it
    could not grab included as not checked); ``request``: the command that asked, if any."""

    t: float
    checks: tuple[PairCheck, ...]
    request: int | None = None
    asked_t: float | None = None   # the asking's time (MeasureReferences.t), when known


class Asked(enum.StrEnum):
    """Why a calibration check is asked for: the kind of a :class:`CheckAsked`."""

    STARTED = "started"                  # the station started (or reloaded)
    ARRIVED = "arrived"                  # a vehicle arrived (vin)
    PERIODIC = "periodic"                # the idle period passed, or a retry is due
    COMMAND = "command"                  # a person's command (user)


@dataclass(frozen=True)
class CheckAsked:
    """Why a check is measured, typed (:func:`stationd.words.check_asked_words` says it:
    ``vehicle VIN1 arrived``, ``asked by eve``)."""

    kind: Asked
    vin: str | None = None
    user: str | None = None


@dataclass(frozen=True)
class MeasureReferences:
    """Action: grab each of ``pairs`` once and check it against its references
    (:func:`stationd.localize.check.check_pair`, references on the lift only with
    ``lift_at_height``), then feed :class:`ReferencesChecked`; ``why`` it is asked, typed."""

    pairs: tuple[str, ...]
    lift_at_height: bool
    why: CheckAsked
    request: int | None = None
    t: float | None = None      # when it was asked (its answer says so back)


@dataclass(frozen=True)
class RecordCheck:
    """Action: store one pair's check (``Repository.record_check``; it joins the results
    feed)."""

    check: PairCheck
    t: float


def _moved(r: Reason | None) -> bool:
    return r is not None and r.kind is Why.PAIR_MOVED


def answer(checks: Iterable[PairCheck]) -> Mapping[str, Any]:
    """A command's answer: each pair's check as plain values."""
    return {c.pair: summary(c) for c in checks}


__all__ = ["RETRY_S", "WAIT_S", "Asked", "CheckAsked", "MeasureReferences", "PairTrust",
           "RecordCheck", "ReferencesChecked", "answer", "from_summary", "reason_of", "summary"]
