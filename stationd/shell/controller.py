"""What comes from the tightening controller on its own clock: the results it pushes, the
results it made while the link was down, its identity and its curves.

Why apart from the daemon: each of these waits in a thread of its own (a blocking wait on the
driver's queue, never a poll) and has its own rule against loss.  A pushed result is held in
:attr:`ControllerFeed.received` until the core has it, so a stop (a reload) feeds it rather
than dropping it; after every (re)connect the tightening ids between the last one recorded
and the controller's newest are fetched (Open Protocol MID 0064), each through the core as
any result, and so are those a pushed result skips with the link up (a live gap); an id the
controller no longer has is recorded as a gap, visibly; a curve is
read and stored apart from results, so it never delays a result or the next bolt's
parameters.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from concurrent.futures import Future, ThreadPoolExecutor

from drivers.errors import DeviceError, RefusedError
from drivers.keeper import DeviceKeeper, one_line
from drivers.wrench import Received, TighteningResult, UnreadableResult, Wrench
from drivers.wrench.openprotocol.message import UNSUPPORTED
from stationd.shell.blocking import Blocking
from stationd.shell.records import STATION_FAULTS, Records
from stationd.station.core import StationCore
from stationd.station.gaps import MAX_FETCH, GapPlan, NoFetch
from stationd.station.gaps import plan as plan_gaps
from stationd.station.inputs import (
    WRENCH,
    CaughtUp,
    DeviceBack,
    DeviceSaid,
    Event,
    NewestChecked,
    ResultCopy,
    ResultIn,
    ResultsMissed,
    ResultsSkipped,
    UnreadableIn,
)
from stationd.station.lost import CLOCK_SLACK_S
from stationd.words import gap_plan_words, id_span

log = logging.getLogger("stationd")
RESULT_WAIT_S = 0.5         # one blocking wait for pushed results (a condition, not a poll)
#: how long a check of the controller's newest waits for a push on its way to reach the core
PUSH_FED_S = 5.0
CURVE_WAIT_S = 0.5          # one blocking wait for curves, in their own thread
CURVE_IDLE_S = 1.0          # the curve loop's wait while the controller sends none
#: how often the controller's clock is measured again on a link that stays up (a clock
#: drifting 20 ppm moves 1 s in 14 hours; the slack for results placed by their time is 2 s)
CLOCK_CHECK_S = 600.0
#: how long no bolt is selected and the tool off before the clock is measured (a reviewer:
#: the core's tool off, its disable still being sent, the disable waited behind MID 0080)
CLOCK_IDLE_S = 5.0
REFUSED = "the controller refused to give them (MID 0064)"


class ControllerFeed:
    """The controller's results, missed results and curves, fed to the core through
    ``feed`` (one event at a time, with its actions)."""

    def __init__(self, core: StationCore, records: Records, keeper: DeviceKeeper[Wrench],
                 feed: Callable[[Event], Awaitable[None]], tell: Callable[[Event], None],
                 call: Blocking) -> None:
        self.core, self.records = core, records
        self._keeper, self._feed, self._tell, self._call = keeper, feed, tell, call
        self._results_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="results")
        self._curves_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="curves")
        #: results taken from the controller and not yet through the core
        self.received: list[Received] = []
        self._waiting: Future[Received | None] | None = None
        self.catching_up: asyncio.Task[None] | None = None
        #: asking the controller for its newest result (:meth:`check_newest`): the last one
        #: asked, and every one running
        self.checking: asyncio.Task[None] | None = None
        self._checks: set[asyncio.Task[None]] = set()
        #: one gap handled at a time (a push that skips ids, a check of the newest)
        self._gaps = asyncio.Lock()
        self._link = 0          # the connections seen (:meth:`came_back`)
        #: the newest tightening id accounted for on this link (a result pushed, or the
        #: controller's newest when the catch-up asked for it; None: not known yet since the
        #: last (re)connect): a pushed result further on than the next is a live gap
        self._accounted: int | None = None
        #: the first tightening id pushed since the last (re)connect, and the last one
        #: recorded before it where the controller refused to say its newest (MID 0064): the
        #: ids between the two were made during the cut and are a gap (:meth:`_refused`)
        self._first_pushed: int | None = None
        self._refused_after: int | None = None
        #: the controller refused to give its newest result at this link's catch-up as a
        #: request it does not support (``UNSUPPORTED``): it keeps none to give (a check of
        #: the newest asks nothing then).  Not for a refusal of the moment: no answer in
        #: time (the driver's "taken as refused"), error 98 and the like (the checks ask)
        self._no_history = False
        #: the catch-up found the controller with no result at all (its memory cleared, or
        #: a new controller): where its count begins is known only from the first pushed
        #: result, whose ids before it are then asked for (:meth:`_began_empty`)
        self._empty = False
        #: the pushed result whose id skipped those fetched now (fed after them)
        self._revealed_by: int | None = None
        #: the check asking now was the core's with the tool on (its fetches said so)
        self._asked_on = False
        self._again = False     # a reconnect came while a catch-up ran: one more after it
        #: the catch-up running was refused the controller's newest (:class:`CaughtUp`)
        self._unasked = False
        #: the catch-up running found the controller's ids started again (:class:`CaughtUp`)
        self._restarted = False
        #: ids whose asking the link's loss cut short (first, last, and the pushed result
        #: that skipped them with the link up, :meth:`_live_gap_alone`; None: a link cut's,
        #: :meth:`_cut_ids`): the next catch-up asks for them first, each fed as it would
        #: have been (it counts from the last recorded, beyond them: a review found them
        #: never asked for again, not even a gap, their bolt left open)
        self._owed: list[tuple[int, int, int | None]] = []
        self._reads = 0         # the results' loop's reads of the controller so far
        #: when the last of those reads that found nothing began (monotonic): the controller
        #: had no result left to give from then on
        self._quiet_from = float("-inf")
        #: when the controller's clock was last measured (at each connect, by the driver;
        #: then every CLOCK_CHECK_S: :meth:`_check_clock`)
        self._clock_at = time.monotonic()
        #: since when the results' loop has seen no bolt selected and the tool off (the clock
        #: is measured only after CLOCK_IDLE_S of that: never beside a disable being sent)
        self._idle_since = time.monotonic()

    async def _read_since(self, reads: int, timeout: float = 10 * RESULT_WAIT_S) -> None:
        """Until the results' loop has read the controller once more than ``reads`` (its
        count then), or ``timeout``."""
        await _until(lambda: self._reads > reads, timeout)

    def close(self) -> None:
        self._results_pool.shutdown(wait=True)
        self._curves_pool.shutdown(wait=True)

    async def results(self, wrench: Wrench) -> None:
        """The next pushed result (one blocking wait, in the results' thread); a link down
        raises to the wrench's keeper."""
        began = time.monotonic()
        self._waiting = self._results_pool.submit(wrench.wait_result, RESULT_WAIT_S,
                                                  acknowledge=False)
        result = await asyncio.wrap_future(self._waiting)
        self._waiting = None
        if result is not None:
            self.received.append(result)
        else:
            self._quiet_from = began
            await self._check_clock(wrench)
        if WRENCH in self.core.status().faults and not self._keeper.losing:
            # a refusal is a fault until the controller answers
            await self._feed(DeviceBack(time.time(), WRENCH, self._keeper.reconnects))
        if result is not None:
            # the ids it skipped first (its push lost): the core gets them in the order they
            # were made (a supervisor's trial: a NOK fetched after a later one went uncounted);
            # it is fed after them whatever the fetches did.  Not on a stop (cancelled): it
            # stays in ``received``, which the stop drains (feeding it here waited for the
            # lock the stop holds: a reviewer found the daemon hung)
            try:
                await self._live_gap(wrench, result)
            except Exception as exc:    # (any: the pushed one goes on all the same)
                log.error("results missed with the link up not fetched: %s", one_line(exc))
            await self._feed(await self.checked(
                result_input(time.time(), result, offset=wrench.clock_offset_s)))
            self.received.remove(result)
        self._reads += 1

    async def _check_clock(self, wrench: Wrench) -> None:
        """The controller's clock measured again every :data:`CLOCK_CHECK_S`, in the
        results' thread between two waits, once no bolt has been selected and the tool off for
        :data:`CLOCK_IDLE_S` (a command would wait behind it for at most the driver's clock
        timeout): a link up for days drifts by seconds, beyond the slack within which results
        fetched late are placed by their time."""
        now, status = time.monotonic(), self.core.status()
        if status.tool_on or status.bolt is not None:
            self._idle_since = now
            return
        if now - self._clock_at < CLOCK_CHECK_S or now - self._idle_since < CLOCK_IDLE_S:
            return
        self._clock_at = now
        try:
            await asyncio.wrap_future(self._results_pool.submit(wrench.check_clock))
        except DeviceError as exc:    # the link's own fault is the keeper's, at the next wait
            log.info("the controller's clock not measured again: %s", one_line(exc))

    async def checked(self, ev: ResultIn | UnreadableIn) -> ResultIn | ResultCopy | UnreadableIn:
        """``ev`` after asking the database whether it has this result stored already
        (:meth:`Records.copy_input`): a copy the controller sent again goes to the core as a
        :class:`ResultCopy`, which it never attributes to a bolt.  A database that cannot
        answer leaves ``ev`` as it is: the record's own transaction checks again, the last
        guard (and reports the database's fault)."""
        if self.records.repo is None:
            return ev
        try:
            if isinstance(ev, UnreadableIn):
                return await self._call(self.records.unreadable_input, ev)
            return await self._call(self.records.copy_input, ev, self.core.status().vin)
        except STATION_FAULTS as exc:
            tid = ev.unreadable.tightening_id if isinstance(ev, UnreadableIn) \
                else ev.result.tightening_id
            log.warning("tightening %s not checked against the stored results: %s",
                        "?" if tid is None else tid, one_line(exc))
            return ev

    async def curves(self, stop: asyncio.Event) -> None:
        """The controller's tightening curves when it sends them (``?curves=1`` in the
        wrench's URL), each stored with its rundown by tightening id.  A curve not stored is
        logged, never a fault: the rundown stands without it."""
        loop = asyncio.get_running_loop()
        while not stop.is_set():
            wrench = self._keeper.device
            if wrench is None or self.records.repo is None or not wrench.can_curves \
                    or not wrench.curves_on:
                await asyncio.sleep(CURVE_IDLE_S)
                continue
            try:
                curve = await loop.run_in_executor(self._curves_pool, wrench.wait_curve,
                                                   CURVE_WAIT_S)
            except (DeviceError, ValueError):     # closed: its keeper opens a new one
                await asyncio.sleep(CURVE_IDLE_S)
                continue
            if curve is None:
                continue
            try:
                await loop.run_in_executor(self._curves_pool, self.records.store_curve, curve)
            except STATION_FAULTS as exc:
                log.warning("curve (%s) of tightening %d not stored: %s", curve.name,
                            curve.tightening_id, one_line(exc))

    def came_back(self) -> None:
        """After the controller came (back): what it says it is (the journal, the devices
        panel, OPC UA's Identification: words and fields of one reading), and the results
        it made meanwhile, fetched."""
        wrench = self._keeper.device
        if wrench is not None:
            try:
                who = wrench.identification()
            except (DeviceError, ValueError):
                who = None
            if who is not None and who.words:   # the driver's own journal line said it
                self._tell(DeviceSaid.of(time.time(), WRENCH, who))
        self._accounted = None     # the catch-up says up to where (a result may come first)
        self._clock_at = time.monotonic()    # measured by the driver at the connect
        self._link += 1
        self._first_pushed = self._refused_after = None
        self._no_history = self._empty = False
        if self.catching_up is None or self.catching_up.done():
            self.catching_up = asyncio.get_running_loop().create_task(self._catch_ups())
        else:   # one of an earlier connection still runs: this one's follows it
            self._again = True

    async def _catch_ups(self) -> None:
        """The catch-up, again for each reconnect that came while one ran (its own
        connection's results, told as that connection's)."""
        while True:
            self._again = False
            await self._catch_up()
            if not self._again:
                return

    async def _catch_up(self) -> None:
        """Every tightening id between the last one recorded and the controller's newest,
        fetched and fed as any result (recorded to its bolt when the station can tell, else
        unattributed, never to a guessed bolt); one the controller no longer has is a gap.
        A controller that keeps no results (register-driven) has nothing to fetch.  The core
        is told how it ended (:class:`CaughtUp`: complete, or why not), which ends what a
        link cut during an enable left open; a link lost again meanwhile tells nothing (the
        next reconnect's catch-up will)."""
        wrench = self._keeper.device
        if wrench is None:
            return
        connection = self._keeper.reconnects
        self._unasked = self._restarted = False
        try:
            why = await self._caught_up(wrench)
        except RefusedError as exc:     # the controller said no: asking again will not help
            log.warning("results missed while the link was down not fetched: %s",
                        one_line(exc))
            why = f"the controller refused to give them ({one_line(exc)})"
        except (DeviceError, ValueError) as exc:
            if self._keeper.losing or not self._keeper.up:
                # the link went down again: the next reconnect's catch-up tells
                log.warning("results missed while the link was down not fetched yet: %s",
                            one_line(exc))
                return
            log.warning("results missed while the link was down not fetched: %s",
                        one_line(exc))
            why = f"fetching them failed ({one_line(exc)})"
        except STATION_FAULTS as exc:
            log.error("results missed while the link was down not fetched: %s", one_line(exc))
            why = f"the station's database failed ({one_line(exc)})"
        except Exception as exc:   # a driver's bug: still told, the core's watch ends (a
            # reviewer: the tool stayed off for every bolt until the next reconnect)
            log.error("results missed while the link was down not fetched: the catch-up "
                      "crashed", exc_info=exc)
            why = f"the catch-up failed ({type(exc).__name__}: {one_line(exc)})"
        await self._feed(CaughtUp(time.time(), why is None, why or "", connection,
                                  self._unasked, self._restarted))

    async def _caught_up(self, wrench: Wrench) -> str | None:
        """The catch-up's work: None where every result since the link was lost went
        through the core, else why not."""
        if self.records.repo is None:
            return "no database to count the results from"
        if not wrench.can_fetch:
            # a register-driven controller keeps its last result in its registers, and
            # publishes the next one it made only once that one is acknowledged: read by the
            # results' loop after the reconnect (recorded late, where it is the cut's) until
            # a read finds none left, before this is told (told after the first only, the
            # tool's second rundown during the cut came once the tool could go on again,
            # and was taken for the next bolt of its pset: a review)
            since = time.monotonic()
            await self._read_since(self._reads)
            await _until(lambda: self._quiet_from >= since, 10 * RESULT_WAIT_S)
            return "this controller keeps no results to fetch"
        while self._owed:       # ids not all asked for before the link was lost
            await self._owed_fetched(wrench)
        last = await self._call(self.records.last_tightening_id)
        try:
            newest = await self._call(wrench.fetch_result, 0)
        except RefusedError as exc:
            self._unasked = True    # what it made during the cut may still come, pushed
            await self._refused(wrench, last, exc)
            raise
        if newest is None:    # the controller has none: made none, or its memory cleared
            self._restarted = last is not None
            self._empty = self._accounted is None
            return None if last is None else (
                f"the controller has no results, though tightening {last} was recorded: "
                "cleared (restarted or replaced), what it made before is not known")
        if newest.tightening_id is None:   # unreadable, its id too: kept, nothing planned
            await self._feed(await self.checked(result_input(time.time(), newest,
                                                              fetched=True)))
            return "the controller's newest result could not be read"
        nid = int(newest.tightening_id)
        # from here the ids up to the controller's newest are this catch-up's; a pushed
        # result after them that skips one is a live gap (:meth:`_live_gap`)
        self._accounted = nid if self._accounted is None else max(self._accounted, nid)
        if last is None:
            return await self._first_results(wrench, newest, nid)
        if nid < last and await self._recorded_already(newest):
            # its newest is recorded already: a controller whose ids started again earlier
            # (replaced), counted from its own newest, not said again at every reload (a
            # technician's trial: "... older than the last recorded (5): its ids restarted"
            # at each SIGHUP, 1 and 2 this controller's and recorded)
            last = nid
        todo = plan_gaps(last, nid)
        if todo.why is not None:
            log.info("results: %s", gap_plan_words(todo))
        elif await self._count_restarted(wrench, last, newest):
            log.info("results: the controller's tightening %d is not the one recorded "
                     "under that id: its ids restarted", last)
            todo = GapPlan(why=NoFetch.IDS_RESTARTED, newest=nid, last_recorded=last)
        if todo.why is NoFetch.IDS_RESTARTED:   # a new count: no id to count from
            self._restarted = True
            return await self._first_results(wrench, newest, nid, restarted=True)
        return await self._fetch(wrench, todo, last, newest)

    async def _owed_fetched(self, wrench: Wrench) -> None:
        """The first ids :attr:`_owed` (the link lost while they were asked for), asked for
        now, one gap at a time, as they would have been: a push's skipped ids fed as
        fetched with the link up before that push (made then, not during a cut: the core
        never proves one the cut's result by its id alone, and holds the bolts whose result
        a gap of them may be), a cut's as the catch-up's; a refusal stores the rest as a gap
        (told with the link up for a push's).  A link lost again leaves those not asked for
        yet to the next catch-up."""
        first, end, before = self._owed[0]
        live = before is not None
        done: list[int] = []
        async with self._gaps:
            self._revealed_by = before
            try:
                await self._fetch(wrench, plan_gaps(first - 1, end), first - 1, live=live,
                                  done=done)
            except RefusedError as exc:    # stored as a gap (:meth:`_refused_from`)
                log.warning("results %s (%s) not fetched: %s", "missed with the link up"
                            if live else "made during an earlier link cut",
                            id_span(first, end), one_line(exc))
            except (DeviceError, ValueError):
                if done:
                    self._owed[0] = (done[-1] + 1, end, before)
                raise
            finally:
                self._revealed_by = None
        self._owed.pop(0)

    def _owe(self, todo: GapPlan, done: list[int], before: int | None) -> None:
        """The ids of ``todo`` the link's loss left not asked for (not in ``done``): owed
        to the next catch-up (:attr:`_owed`; ``before``: the push that skipped them)."""
        rest = [t for t in todo.fetch if t not in done]
        if rest:
            self._owed.append((rest[0], rest[-1], before))

    async def _recorded_already(self, newest: Received) -> bool:
        """Whether the controller's newest result is recorded already, the very same (its
        id, values and its own time: :meth:`_against_recorded`)."""
        return isinstance(await self._against_recorded(newest), ResultCopy)

    async def _against_recorded(self, got: Received | None) -> ResultIn | ResultCopy | None:
        """``got`` compared with what is recorded under its id (:meth:`Records.copy_input`):
        a :class:`ResultCopy` when it is the very same, else the result as read; None where
        it cannot be told: a result without the controller's own time (only that tells
        another result under the same id from the one stored), or the database failing."""
        if not isinstance(got, TighteningResult) or not got.controller_clock \
                or got.timestamp is None:
            return None
        ev = result_input(time.time(), got, fetched=True)
        if not isinstance(ev, ResultIn):
            return None
        try:
            asked = await self._call(self.records.copy_input, ev, self.core.status().vin)
        except STATION_FAULTS as exc:
            log.warning("tightening %s not checked against the one recorded: %s",
                        got.tightening_id, one_line(exc))
            return None
        return asked

    async def _count_restarted(self, wrench: Wrench, last: int, newest: Received) -> bool:
        """Whether the controller's ids started again though its newest is not below
        ``last``, the last id recorded (reset or replaced, it made as many results since):
        its result ``last`` is not the one stored under that id.  Counting on from ``last``
        would fetch only the ids above it, and take the first of them for the first result
        made after it.  Unknown (the controller no longer has it, or it does not read) is
        counted on as before, and so is a result without the controller's own time (only
        that tells another result under the same id from the one stored), and an id under
        which nothing read is stored (an unreadable message, a gap's end, an outcome a
        person entered: nothing to compare)."""
        repo = self.records.repo
        if repo is None:
            return False
        try:
            if not await self._call(repo.read_result_stored, last):
                return False
        except STATION_FAULTS as exc:
            log.warning("tightening %d not checked against the one recorded: %s", last,
                        one_line(exc))
            return False
        try:
            got = newest if newest.tightening_id == last else \
                await self._call(wrench.fetch_result, last)
        except RefusedError:        # not known: counted on (the fetches say the refusal)
            return False
        return isinstance(await self._against_recorded(got), ResultIn)

    async def _first_results(self, wrench: Wrench, newest: Received, nid: int,
                             restarted: bool = False) -> str | None:
        """No tightening of this controller recorded yet (or ``restarted``: its ids started
        again, reset or replaced, so the last one recorded says nothing of its new count), so
        no id to count from: the results
        it made since the station may have missed them (:meth:`StationCore.missed_since`: the
        enable a link cut came during, else the link lost) are found backwards from its
        newest by their own timestamps (through the clock offset measured at connect), at
        most ``MAX_FETCH``, and fed oldest first, each after the id of the last result made
        before that (the first one after it is what the core's proof of a result made under
        the cut enable asks for; unknown where the controller no longer has it or its time
        cannot be read: then nothing is proved, and what was found stays unattributed).
        What it made before is its history, not this station's: not fetched.  None where
        every result since was found, else why not."""
        since, offset = self.core.missed_since(), wrench.clock_offset_s
        found: list[tuple[int, Received]] = []
        follows: int | None = None
        got: Received | None = newest
        tid = nid
        unknown: str | None = None
        while since is not None and got is not None and len(found) < MAX_FETCH:
            at = made_at(got, offset)
            if at is None and offset is None:
                # no time can be placed: where the history begins is not known; the newest
                # is kept all the same (unattributed, or held against the cut's bolt)
                unknown = "the controller's clock is not known: its results cannot be " \
                          "placed before or after the link was lost"
                found.append((tid, got))
                break
            if at is not None and at < since - CLOCK_SLACK_S:
                follows = tid          # made before: the history ends here
                break
            found.append((tid, got))
            if tid <= 1:
                follows = 0            # the controller's first result: nothing before it
                if restarted:          # but its count started again since the link was lost
                    unknown = ("its first result since its count started again was made "
                               "after the link was lost: what it made before is not known")
                break
            tid -= 1
            try:
                got = await self._call(wrench.fetch_result, tid)
            except RefusedError as exc:     # what was found so far is kept all the same
                unknown = f"the controller refused to give tightening {tid} ({one_line(exc)})"
                break
        if since is not None and unknown is None and follows is None:
            unknown = f"the controller no longer has tightening {tid}" if got is None \
                else f"more than {MAX_FETCH} results made since the link was lost"
        if unknown is not None:
            log.warning("results: %s%s", "its tightening ids started again; " if restarted
                        else "", unknown)
        if not found:
            if not restarted:
                log.info("results: %s", gap_plan_words(plan_gaps(None, nid)))
            return unknown
        log.info("results: %s; %d made by the controller since the link was lost%s: fetched",
                 "its tightening ids started again" if restarted else
                 "no tightening recorded yet", len(found),
                 "" if follows is not None else " (where its history ends is not known)")
        for tid, got in reversed(found):
            await self._fetched(wrench, tid, got, follows, offset)
        return unknown

    def check_newest(self, serial: int | None = None, tool_on: bool = False) -> None:
        """The core's :class:`CheckNewest` (for the enable ``serial``): the controller's
        newest result asked for, and the ids after the last one heard fetched (their pushes
        lost), in a task of its own (it feeds the core, whose lock the caller holds); then
        the core is told (:class:`NewestChecked`: the enable it was for is owed nothing more,
        and the tool may go on again).  After a check or a catch-up running (the ids they
        fetch are not asked twice), and after a push on its way (made under that enable, it
        is its own).  ``tool_on``: the core's periodic check while the tool is on (its
        enable without a result yet): asked only where nothing else runs and no result waits
        to go through the core, else told at once as not asked (the next period asks)."""
        prev = self.checking
        if tool_on and (self.received or any(
                t is not None and not t.done() for t in (prev, self.catching_up))):
            why = "a result on its way" if self.received else "a check or catch-up running"
            self.checking = asyncio.get_running_loop().create_task(
                self._not_asked(serial, why))
        else:
            self.checking = asyncio.get_running_loop().create_task(
                self._checked(serial, prev, tool_on))
        self._checks.add(self.checking)
        self.checking.add_done_callback(self._checks.discard)

    async def _not_asked(self, serial: int | None, why: str) -> None:
        """A check with the tool on not asked (``why``): the core told, it waits no more."""
        await self._feed(NewestChecked(time.time(), unknown=f"not asked: {why}", serial=serial))

    def tasks(self) -> list[asyncio.Task[None]]:
        """Its tasks running now (the catch-up, every check): for a stop to end them all (a
        reviewer: a check chained on an earlier one, cancelled, left that one feeding the
        core after the stop)."""
        return [t for t in (self.catching_up, *self._checks) if t is not None and not t.done()]

    async def _checked(self, serial: int | None, prev: asyncio.Task[None] | None,
                       tool_on: bool = False) -> None:
        if prev is not None and not prev.done():
            await asyncio.wait({prev})
        catching = self.catching_up
        if catching is not None and not catching.done():
            await asyncio.wait({catching})
        if serial is not None and self.core.status().checking != serial:
            return      # the core gave up on it: asking now takes a later enable's result
        nothing, unknown = await self._check_newest(tool_on)
        await _until(lambda: not self.received, PUSH_FED_S)
        await self._feed(NewestChecked(time.time(), nothing_made=nothing, unknown=unknown,
                                       serial=serial))

    async def _check_newest(self, tool_on: bool = False) -> tuple[bool, str]:
        """Whether the controller's newest is the last one heard (no tightening made since),
        and where it could not tell, why (the core holds the bolt).  Only with every tool off
        and none enabled while it asks (else the newest may be the rundown of a bolt enabled
        now, fetched before its own push and stored as no bolt's: a reviewer); the link as it
        was.  A controller that keeps no results to give (it cannot fetch, or refused to at
        the connect's catch-up) tells nothing: the next result pushed does, by its id.
        ``tool_on``: the core's check while the tool is on for one enable (its rundown is
        what is looked for: fetched, the core records it to that enable and turns the tool
        off); void only where another enable came meanwhile."""
        wrench, before = self._keeper.device, self.core.status()
        if wrench is not None and (not wrench.can_fetch or self._no_history):
            return False, ""
        if wrench is None or not self._keeper.up or self._keeper.losing:
            return False, "the link to the controller was down"
        if self.records.repo is None:
            return False, "the station's database was not open"
        async with self._gaps:
            last, link = self._accounted, self._link
            self._asked_on = tool_on
            try:
                newest = await self._call(wrench.fetch_result, 0)
                now = self.core.status()
                if link != self._link or now.enables != before.enables or (
                        not tool_on and (now.tool_on or before.tool_on)):
                    return False, "the link or the tool changed while it was asked"
                if newest is None:   # none at all: made none, or its memory cleared
                    return last is None, "" if last is None else "the controller has none"
                if newest.tightening_id is None:
                    return False, "the controller's newest result could not be read"
                nid = int(newest.tightening_id)
                if last is None or nid < last:
                    return False, f"its newest is tightening {nid}, " + (
                        "none heard on this link" if last is None else f"{last} heard")
                if nid == last:
                    # nothing since the last one heard, and that one through the core
                    return not self.received, ""
                self._accounted, self._revealed_by = nid, None
                if self._refused_after is not None and nid > self._refused_after:
                    # the catch-up's newest not said (refused for the moment): the ids
                    # beyond the last recorded are fetched now, each found or a gap; a
                    # push beyond them must not tell them again as the cut's
                    self._refused_after = None
                log.warning("results: the controller's newest tightening is %d, the last one "
                            "heard %d: %s not pushed by the controller (the link up): asked for",
                            nid, last, id_span(last + 1, nid))
                await self._fetch(wrench, plan_gaps(last, nid), last, newest, live=True)
            except (RefusedError, DeviceError, ValueError) as exc:
                # (one that keeps no results refused it at the connect's catch-up already:
                # :meth:`_refused`; a refusal now is of this moment)
                log.warning("the controller's newest result not read: %s", one_line(exc))
                return False, one_line(exc)
            except STATION_FAULTS as exc:
                log.error("the controller's newest result not read: %s", one_line(exc))
                return False, f"the station's database failed: {one_line(exc)}"
        return False, ""

    async def _live_gap(self, wrench: Wrench, got: Received) -> None:
        """:meth:`_live_gap_alone`, one gap at a time (:meth:`check_newest`'s too)."""
        async with self._gaps:
            await self._live_gap_alone(wrench, got)

    async def _live_gap_alone(self, wrench: Wrench, got: Received) -> None:
        """A pushed result whose tightening id skips ahead of the last one accounted for on
        this link: the ids between were made and never pushed (a push lost with the link
        up).  They are fetched as after a reconnect, at most ``MAX_FETCH`` (older ones are
        one gap), and each only once: ids up to the controller's newest at a reconnect are
        the catch-up's, the pushed result itself is never asked for, and an id at or below
        the last accounted one (a result sent again) starts nothing."""
        if got.tightening_id is None:
            return
        tid, last = int(got.tightening_id), self._accounted
        self._accounted = tid if last is None else max(last, tid)
        if self._first_pushed is None:
            self._first_pushed = tid
        if self._refused_after is not None and tid > self._refused_after:
            # (a copy of one recorded, sent again first, says nothing of the cut)
            after, self._refused_after = self._refused_after, None
            if tid > after + 1:
                await self._cut_ids(wrench, after, tid)
            return           # the ids before it are the cut's, not lost with the link up
        if last is None and self._empty:
            last = await self._began_empty(wrench, tid)
        if last is None or tid <= last + 1 or not wrench.can_fetch or self.records.repo is None:
            return
        todo = plan_gaps(last, tid - 1)
        self._revealed_by = tid
        # the rundown is over: the tool off now, not after the fetches (a reviewer)
        await self._feed(ResultsSkipped(time.time(), tid))
        ids = id_span(last + 1, tid - 1)
        # ("asked for": each then fetched, or not, said on its own line; a trial read
        # "fetched" followed at once by "not fetched: refused")
        log.warning("results: tightening %d came after %d: %s not pushed by the controller "
                    "(the link up): asked for", tid, last, ids)
        await self._ask(wrench, todo, last, tid, ids)

    async def _began_empty(self, wrench: Wrench, tid: int) -> int | None:
        """The first result pushed since the catch-up found the controller empty: where its
        count began, 0 where it holds tightening 1 (its count began again at 1 since: the
        ids 1 to ``tid`` - 1 made since, their pushes lost, asked for as any live gap), else
        not known (a controller that cleared its results but counts on: the ids below are
        none of this link's; a reviewer: the id before alone took 1-499 for a gap).  An
        integrator's trial: a controller restarted with ids from 1, the push of 1 lost; 2
        and 3 were stored, 1 never asked for, nothing said."""
        self._empty = False
        if tid <= 1 or not wrench.can_fetch or self.records.repo is None:
            return None
        try:
            before = await self._call(wrench.fetch_result, 1)
        except DeviceError as exc:
            log.warning("results: tightening %d is the first since the controller had none; "
                        "whether it made %s before it is not known: %s", tid,
                        id_span(1, tid - 1), one_line(exc))
            return None
        return 0 if before is not None else None

    async def _cut_ids(self, wrench: Wrench, after: int, tid: int,
                       skipped: bool = True) -> None:
        """The ids between ``after``, the last recorded, and ``tid``, the first pushed since a
        reconnect whose catch-up did not say the controller's newest: made during the cut.
        Where the controller keeps none to give (it refused the catch-up's request as not
        supported) or cannot fetch, a gap; else asked for as the catch-up would have (made
        while the link was down, after ``after``), each found or a gap; ``skipped``: ``tid``
        is fed after them, the core told so first (else it came before the refusal, fed
        already).  A refusal of the moment (no answer in time, error 98) said nothing of
        them: a review found them stored as refused, never asked for, the controller still
        giving them."""
        if self._no_history or not wrench.can_fetch or self.records.repo is None:
            await self._gap(after + 1, tid - 1, REFUSED)
            return
        if skipped:
            await self._feed(ResultsSkipped(time.time(), tid))   # the rundown over: tool off
        ids = id_span(after + 1, tid - 1)
        log.warning("results: tightening %d came after %d (the catch-up after the reconnect "
                    "not done): %s made during the link cut, asked for", tid, after, ids)
        await self._ask(wrench, plan_gaps(after, tid - 1), after, None, ids)

    async def _ask(self, wrench: Wrench, todo: GapPlan, last: int, before: int | None,
                   ids: str) -> None:
        """The ids ``todo`` plans after ``last`` (``ids`` in words), asked for: ``before``,
        the pushed result that skipped them with the link up (:meth:`_live_gap_alone`), or
        None, a link cut's (:meth:`_cut_ids`).  A refusal stores them as a gap
        (:meth:`_refused_from`: asking again will not help); a link lost meanwhile leaves
        those not asked for yet to the next catch-up (:meth:`_owe`)."""
        what = "missed with the link up" if before is not None else \
            "made during the link cut"
        done: list[int] = []
        try:
            await self._fetch(wrench, todo, last, live=before is not None, done=done)
        except RefusedError as exc:
            log.warning("results %s (%s) not fetched: %s", what, ids, one_line(exc))
        except (DeviceError, ValueError) as exc:   # the link's keeper reports it
            self._owe(todo, done, before)  # asked for first by the next catch-up
            log.warning("results %s (%s) not fetched yet: %s", what, ids, one_line(exc))
        except STATION_FAULTS as exc:
            log.error("results %s (%s) not fetched: %s", what, ids, one_line(exc))

    async def _fetch(self, wrench: Wrench, todo: GapPlan, last: int | None,
                     newest: Received | None = None, live: bool = False,
                     done: list[int] | None = None) -> str | None:
        """The ids ``todo`` fetches, each fed as a fetched result (after ``last``, the id
        accounted for before; ``newest``: one fetched already), with its curves; its gap and
        each id the controller no longer has recorded as gaps.  None where none was missed,
        else why some were.  ``done``: each id fed or told as a gap is added to it (those
        a link lost meanwhile left are the others)."""
        missed: str | None = None
        if todo.gap is not None:
            missed = f"more than {MAX_FETCH} results missed"
            await self._gap(*todo.gap, missed, live)
        offset = wrench.clock_offset_s
        for tid in todo.fetch:
            try:
                got: Received | None = newest if newest is not None \
                    and tid == newest.tightening_id \
                    else await self._call(wrench.fetch_result, tid)
            except RefusedError:    # this one and those after it: asking again will not help
                await self._refused_from(wrench, tid, todo, last, newest, live)
                raise
            if got is None:
                missed = f"tightening {tid} no longer on the controller"
                await self._gap(tid, tid, "the controller no longer has it", live)
            else:
                await self._fetched(wrench, tid, got, last, offset, live)
            if done is not None:
                done.append(tid)
        return missed

    async def _fetched(self, wrench: Wrench, tid: int, got: Received, follows: int | None,
                       offset: float | None, live: bool = False) -> None:
        """One result fetched late, through the core as any result (``follows``: the id
        accounted for before it), then its curves."""
        log.info("tightening %d fetched %s", tid,
                 "after a reconnect" if not live else "after a later one came (the link up)"
                 if self._revealed_by is not None or self.checking is None else
                 "by a check of the controller's newest with the tool on (the link up)"
                 if self._asked_on else
                 "as an enable's late-result window ended (the link up)")
        await self._feed(await self.checked(result_input(
            time.time(), got, fetched=True, follows=follows, offset=offset, live=live,
            before=self._revealed_by if live else None)))
        if isinstance(got, TighteningResult):
            await self._late_curves(wrench, tid)

    async def _late_curves(self, wrench: Wrench, tid: int) -> None:
        """The curves of a result fetched late (MID 0900 asked for by its tightening id),
        where the controller offers them and the station takes curves; stored like any
        curve, linked to its rundown by tightening id.  None is never a fault."""
        if not wrench.can_curves or not wrench.curves_on:
            return
        try:
            curves = await self._call(wrench.fetch_curve, tid)
            for curve in curves:
                await self._call(self.records.store_curve, curve)
        except (DeviceError, ValueError) as exc:
            log.warning("curves of tightening %d (fetched late) not got: %s", tid,
                        one_line(exc))
        except STATION_FAULTS as exc:
            log.warning("curves of tightening %d (fetched late) not stored: %s", tid,
                        one_line(exc))

    async def _refused_from(self, wrench: Wrench, tid: int, todo: GapPlan, last: int | None,
                            newest: Received | None, live: bool) -> None:
        """The controller refused to give tightening ``tid`` (MID 0064): it and the ids after
        it up to the last planned are a gap, except the controller's newest where it gave
        that already (fed, after nothing known: its own data cannot prove it the first after
        ``last``)."""
        end = todo.fetch[-1]
        have = newest is not None and newest.tightening_id == end and end > tid
        if have:
            end -= 1
        await self._gap(tid, end, REFUSED, live)
        if have and newest is not None:
            await self._fetched(wrench, end + 1, newest, None, wrench.clock_offset_s, live)

    async def _refused(self, wrench: Wrench, last: int | None, exc: RefusedError) -> None:
        """The controller refused to say its newest result after a reconnect: the ids made
        during the cut are those between ``last``, the last one recorded, and the first one
        pushed since (told now where one came already, else when it comes), a gap.  Nothing
        recorded yet: no count to compare with.  Only a refusal of the request itself
        (``UNSUPPORTED``: unknown MID, ...) says the controller keeps no results to give;
        one of the moment (no answer in time, error 98) leaves the checks of the newest
        asking, each saying what it could not tell as any failure."""
        if exc.code in UNSUPPORTED:
            self._no_history = True
        if last is None:
            return
        if self._first_pushed is None or self._first_pushed <= last:
            self._refused_after = last       # the next push beyond it tells
        elif self._first_pushed > last + 1:    # (fed already: the core waits for none)
            await self._cut_ids(wrench, last, self._first_pushed, skipped=False)

    async def _gap(self, first: int, last: int, reason: str, live: bool = False) -> None:
        """What the controller cannot give any more, for the core (it stores and says it)."""
        await self._feed(ResultsMissed(time.time(), first, last, reason, live))

    async def drain(self) -> list[Received]:
        """At a stop (the station's lock held, its tasks cancelled): the result the wait was
        taking and those the driver still holds, for the core while the link is open (a
        reload lost a result that arrived as it began)."""
        waiting, self._waiting = self._waiting, None
        if waiting is not None and not waiting.cancelled():
            try:
                got = await asyncio.wrap_future(waiting)
            except Exception:   # the link went down meanwhile: its keeper's, not ours
                got = None
            if got is not None:
                self.received.append(got)
        wrench = self._keeper.device
        while wrench is not None and self._keeper.up:
            try:
                more = await self._call(_wait_briefly, wrench)
            except (DeviceError, ValueError):
                break
            if more is None:
                break
            self.received.append(more)
        received, self.received = self.received, []
        return received


def result_input(t: float, got: Received, *, fetched: bool = False, follows: int | None = None,
                 offset: float | None = None, live: bool = False,
                 before: int | None = None) -> ResultIn | UnreadableIn:
    """What the controller sent, as the core's input: a result (fetched ones with the last
    tightening id accounted for before, and the controller's timestamp on the station's
    clock where its offset is known; ``live``: fetched because a later one came with the
    link up), or one that could not be read."""
    if isinstance(got, UnreadableResult):
        return UnreadableIn(t, got)
    return ResultIn(t, got, fetched=fetched, follows=follows,
                    made_at=made_at(got, offset), live=live, before=before)


def made_at(result: Received, offset: float | None) -> float | None:
    """The result's controller timestamp (naive, the controller's local time) on the
    station's clock (epoch seconds): ``offset`` is the controller's local time minus the
    station's, measured at connect (None: unknown, and so is the time)."""
    if offset is None or not isinstance(offset, int | float):
        return None
    if result.timestamp is None:     # an unreadable result's, where it could not be read
        return None
    try:
        return result.timestamp.timestamp() - float(offset)
    except (AttributeError, OverflowError, OSError, ValueError):
        return None


def _wait_briefly(wrench: Wrench) -> Received | None:
    """A result the driver holds already, without acknowledging it (the core does)."""
    return wrench.wait_result(0.05, acknowledge=False)


async def _until(done: Callable[[], bool], timeout: float) -> None:
    """Until ``done()``, or ``timeout`` seconds, looking again every fifth of a results'
    wait."""
    end = time.monotonic() + timeout
    while not done() and time.monotonic() < end:
        await asyncio.sleep(RESULT_WAIT_S / 5)
