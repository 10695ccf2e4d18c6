"""How an MES that was away catches up (OPC 40450-1 1.01, JoiningSystemResultManagementType):
RequestResults (a range of sequence numbers, or of time), RequestUnacknowledgedResults and
AcknowledgeResults (Machinery Result), answered from the station's records.

Why from the records and not from memory: the results feed (:mod:`db.ledger`) holds every
rundown the station stored, with the sequence number the result events carry, so an MES that
missed events asks for them by that number, and the acknowledgements are rows beside the
feed (``opcua_acknowledged``): they survive a restart of the server or of the station.

Requested results are sent as events of a concrete subtype of RequestedResultEventType (a
subtype of JoiningSystemResultReadyEventType: a client subscribed to the latter gets both and
tells them apart by type, as the standard intends), after the method has answered, one after
the other and at least :data:`MIN_INTERVAL_MS` apart; requests are served one at a time,
at most :data:`MAX_WAITING` wait, beyond that a request is refused as busy.  Anonymous clients
may ask (they only get stored results again), so no request may hold the queue for long: the
interval is revised to at most :data:`MAX_INTERVAL_MS` (an infinite one would hold it for
ever) and one request sends at most :data:`MAX_PER_REQUEST` results (the client asks again
from the last sequence number it got).

The methods' ``Status`` (Int64) is 0 when the results are being sent; the standard reserves
values above 0 and leaves those below 0 to the application: :data:`BAD_ARGUMENTS`,
:data:`BUSY`, :data:`NOT_READY`.  AcknowledgeResults answers per ResultId 0 (acknowledged, now
or before), :data:`UNKNOWN_RESULT` (not a rundown of this station's database) or
:data:`NOT_STORED` (the database refused; the call can be repeated).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from datetime import UTC, datetime, timedelta
from typing import Any

from db.ledger import Series, is_result
from db.repository import Repository
from stationd.opcua.results import parse_result_id
from stationd.opcua.uatypes import ua

log = logging.getLogger("stationd")

MIN_INTERVAL_MS = 5.0      # the shortest time between two requested results
MAX_INTERVAL_MS = 100.0    # the longest (a request must not hold the queue)
MAX_PER_REQUEST = 1000     # results one request sends; the client asks again for more
MAX_WAITING = 4            # requests waiting for the one being served
OK, BAD_ARGUMENTS, BUSY, NOT_READY = 0, -1, -2, -3
UNKNOWN_RESULT, NOT_STORED = -1, -2

Fire = Callable[[dict[str, Any]], Awaitable[None]]


def _plain(value: Any) -> Any:
    return value.Value if isinstance(value, ua.Variant) else value


def _time(value: Any) -> datetime | None:
    """A UtcTime argument; None for a null one (OPC UA's minimum date)."""
    t = _plain(value)
    if not isinstance(t, datetime) or t.year <= 1601:
        return None
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def _status(code: int, text: str) -> list[ua.Variant]:
    return [ua.Variant(code, ua.VariantType.Int64),
            ua.Variant(ua.LocalizedText(text, "en"), ua.VariantType.LocalizedText)]


def _duration(ms: float) -> ua.Variant:
    return ua.Variant(float(ms), ua.VariantType.Double)


class CatchUp:
    """The three methods, bound to a repository once the server reads the station's records
    (:meth:`attach`); ``fire`` sends one feed entry as a requested-result event."""

    def __init__(self, fire: Fire) -> None:
        self._fire = fire
        self.repo: Repository | None = None
        self.series = Series("")   # the ids of the records' series (:meth:`attach`)
        self._lock = asyncio.Lock()
        self._waiting = 0
        self._tasks: set[asyncio.Task[None]] = set()
        self.sent = 0               # requested results sent (this process)

    def attach(self, repo: Repository, series: Series) -> None:
        """Bind to ``repo``; ``series`` gives each record's id (the server updates it when
        the database's id is renewed)."""
        self.repo, self.series = repo, series

    async def close(self) -> None:
        """Stop the replays under way (the server stops)."""
        for t in list(self._tasks):
            t.cancel()
        for t in list(self._tasks):
            with contextlib.suppress(asyncio.CancelledError):
                await t

    async def idle(self) -> None:
        """Wait until every accepted request has been sent (tests, an orderly stop)."""
        while self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)

    # -- RequestResults ---------------------------------------------------------------------
    async def request_results(self, parent: ua.NodeId, from_seq: Any = 0, to_seq: Any = 0,
                              from_time: Any = None, to_time: Any = None,
                              interval_ms: Any = 0.0, *_: Any) -> list[ua.Variant]:
        revised = _revise(interval_ms)
        try:
            first, last = int(_plain(from_seq) or 0), int(_plain(to_seq) or 0)
        except (TypeError, ValueError):
            first, last = -1, -1
        t0, t1 = _time(from_time), _time(to_time)
        if first or last:
            if first <= 0 or last < first:
                return [_duration(revised), *_status(
                    BAD_ARGUMENTS, "FromSequenceNumber and ToSequenceNumber: both above 0 and "
                    "To not below From (or both 0 for a time range)")]
            what = f"with sequence numbers {first} to {last}"
        elif t0 is not None and t1 is not None and t1 < t0:
            return [_duration(revised), *_status(BAD_ARGUMENTS, "ToTime is before FromTime")]
        else:
            what = f"recorded from {t0.isoformat() if t0 else 'the first'} " \
                f"to {t1.isoformat() if t1 else 'the last'}"
        repo = self.repo
        refused = self._refusal(repo)
        if refused is not None or repo is None:
            return [_duration(revised), *(refused or [])]
        # a time range is the range of sequence numbers stored in it, fixed now, and what is
        # counted is what is sent (a review: counted by time, sent until the first stored
        # after ToTime, a clock stepped back told one more than came)
        try:
            newest = await _run(repo.ledger.last_seq)
            if first:
                after, stop_seq = first - 1, last
            else:
                after = 0 if t0 is None else await _run(repo.ledger.seq_before, t0)
                stop_seq = newest if t1 is None else await _run(
                    repo.ledger.seq_before, t1 + timedelta(microseconds=1))
            count = await _run(repo.ledger.results_in, after, stop_seq)
        except Exception as exc:   # a database busy or away: an answer, never a fault
            log.warning("OPC UA: reading the results feed: %s", exc)
            return [_duration(revised), *_status(
                NOT_READY, "the station's records cannot be read now")]
        if not count:
            # said as none (an MES integrator's trial: a range past the last read as results
            # on their way, and nothing came): the request is answered, nothing to send
            return [_duration(revised), *_status(
                OK, f"no result {what}: none is sent (the last sequence number so far: "
                f"{newest})")]
        self._spawn(self._send_feed(repo, after, stop_seq, revised))
        sending = min(count, MAX_PER_REQUEST)
        return [_duration(revised), *_status(
            OK, f"{sending} of the {count} results {what} are sent as events (at most "
            f"{MAX_PER_REQUEST} per request: ask again after the last one received)")]

    async def _send_feed(self, repo: Repository, after: int, stop_seq: int,
                         interval_ms: float) -> None:
        async def entries() -> AsyncIterator[dict[str, Any]]:
            cursor = after
            while True:
                page = await _run(repo.ledger.since, cursor)
                if not page:
                    return
                for e in page:
                    if e["seq"] > stop_seq:
                        return
                    cursor = e["seq"]
                    yield e

        await self._send(entries(), interval_ms)

    # -- RequestUnacknowledgedResults ---------------------------------------------------------
    async def request_unacknowledged(self, parent: ua.NodeId, max_results: Any = 0,
                                     interval_ms: Any = 0.0, *_: Any) -> list[ua.Variant]:
        revised = _revise(interval_ms)
        try:
            most = max(0, int(_plain(max_results) or 0))
        except (TypeError, ValueError):
            most = 0
        repo = self.repo
        count = 0
        if repo is not None:
            try:
                count = await _run(repo.ledger.unacknowledged_count)
            except Exception as exc:   # a database busy or away: an answer, never a fault
                log.warning("OPC UA: counting unacknowledged results: %s", exc)
                return [_duration(revised), ua.Variant(0, ua.VariantType.UInt32),
                        *_status(NOT_READY, "the station's records cannot be read now")]
        refused = self._refusal(repo)
        if refused is not None or repo is None:
            return [_duration(revised), ua.Variant(count, ua.VariantType.UInt32),
                    *(refused or [])]
        sending = min(count if most == 0 else min(most, count), MAX_PER_REQUEST)
        self._spawn(self._send_unacknowledged(repo, most, revised))
        return [_duration(revised), ua.Variant(count, ua.VariantType.UInt32),
                *_status(OK, f"{sending} of {count} unacknowledged results are sent as events")]

    async def _send_unacknowledged(self, repo: Repository, most: int,
                                   interval_ms: float) -> None:
        async def entries() -> AsyncIterator[dict[str, Any]]:
            cursor, n = 0, 0
            while True:
                page = await _run(repo.ledger.unacknowledged, cursor)
                if not page:
                    return
                for e in page:
                    if most and n >= most:
                        return
                    cursor, n = e["seq"], n + 1
                    yield e

        await self._send(entries(), interval_ms)

    # -- AcknowledgeResults -----------------------------------------------------------------
    async def acknowledge(self, result_ids: Any, by: str) -> list[ua.Variant]:
        ids = [str(_plain(i)) for i in (_plain(result_ids) or [])]
        seqs = {i: parse_result_id(self.series, i) for i in ids}
        errors = {i: UNKNOWN_RESULT for i, s in seqs.items() if s is None}
        wanted = [s for s in seqs.values() if s is not None]
        repo = self.repo
        if wanted:
            try:
                if repo is None:
                    raise RuntimeError("the station's records are not open yet")
                known = await _run(repo.ledger.acknowledge, wanted, by)
            except Exception as exc:   # a database busy or away: said per result, retried
                log.warning("OPC UA: storing acknowledgements: %s", exc)
                known, errors = set(), {i: errors.get(i, NOT_STORED) for i in ids}
            for i, s in seqs.items():
                if s is not None and s not in known:
                    errors.setdefault(i, UNKNOWN_RESULT)
        if errors:
            log.info("OPC UA: %s acknowledged %d of %d results", by, len(ids) - len(errors),
                     len(ids))
            per = [errors.get(i, OK) for i in ids]
            return [ua.Variant(per, ua.VariantType.Int32),
                    ua.Variant(next(e for e in per if e != OK), ua.VariantType.Int32)]
        return [ua.Variant([], ua.VariantType.Int32), ua.Variant(OK, ua.VariantType.Int32)]

    # -- sending --------------------------------------------------------------------------------
    def _refusal(self, repo: Repository | None) -> list[ua.Variant] | None:
        """Status and message when a request cannot be served now."""
        if repo is None:
            return _status(NOT_READY, "the station's records are not open yet")
        if self._waiting >= MAX_WAITING:
            return _status(BUSY, "other requests are being served: ask again later")
        return None

    def _spawn(self, job: Coroutine[Any, Any, None]) -> None:
        self._waiting += 1

        async def serve() -> None:
            try:
                async with self._lock:
                    self._waiting -= 1
                    await job
            except asyncio.CancelledError:
                job.close()   # cancelled before it ran (the server stops): never started
                raise
            except Exception as exc:   # a database busy or away: the client asks again
                log.warning("OPC UA: sending requested results: %s", exc)

        task = asyncio.get_running_loop().create_task(serve())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _send(self, entries: AsyncIterator[dict[str, Any]], interval_ms: float) -> None:
        first, sent = True, 0
        async for e in entries:
            if not is_result(e):
                continue
            if sent >= MAX_PER_REQUEST:
                return
            sent += 1
            if not first:
                await asyncio.sleep(interval_ms / 1000.0)
            first = False
            await self._fire(e)
            self.sent += 1


def _revise(requested: Any) -> float:
    try:
        ms = float(_plain(requested) or 0.0)
    except (TypeError, ValueError):
        ms = 0.0
    if ms != ms:   # NaN: the minimum
        return MIN_INTERVAL_MS
    return min(max(ms, MIN_INTERVAL_MS), MAX_INTERVAL_MS)   # infinity: the maximum


async def _run(fn: Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)`` (a database read or write) off the event loop."""
    return await asyncio.get_running_loop().run_in_executor(None, fn, *args)


__all__ = ["BAD_ARGUMENTS", "BUSY", "MAX_INTERVAL_MS", "MAX_PER_REQUEST", "MAX_WAITING",
           "MIN_INTERVAL_MS", "NOT_READY", "NOT_STORED",
           "OK", "UNKNOWN_RESULT", "CatchUp"]
