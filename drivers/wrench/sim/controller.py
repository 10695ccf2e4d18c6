"""A simulated tightening controller, and ``sim://wrench``, the backend that talks to it.

``SimController`` is a real Open Protocol server (``server.py``: TCP on loopback, RS-232
on a pty) with a controller's behaviour written from docs/PROTOCOLS.md: it knows a set of
psets, answers 0001 with 0002, commands with 0005 or 0004 and the specification's error
codes, mirrors 9999, drops a client silent for 15 s, and, when the operator pulls the
trigger with the tool enabled and a pset selected, reports a MID 0061 result with seeded
scatter around the pset's targets and NOKs at ``nok_rate``.  Its 0061 writer
(``results.py``) is a table of tags and widths, independent of the client's parser.

Revisions: 0001 (so 0002), 0060 (so the 0061 pushed) and 0064 (so its 0065) are served in
revisions 1 to 7, except those set to be refused (``refused_revisions``, answered MID 0004
``revision_refusal_code``, 97 by default) so that an integrator's step-down can be tested.
Every result is kept (the newest ``store_size``) for MID 0064; an id it no longer has is
MID 0004 error 15.  With ``keep_results_in(FILE)`` it keeps them in that file too, and a
simulator built anew on the same file has them (a real controller keeps its results when the
station restarts).  ``link_ack=True`` makes it acknowledge at link level (MID 9997/9998,
``server.py``) and say so in 0002 revision 6+: with an integrator that started at
revision 6 or later, or that numbers its messages.  Tightening curves: a session that
subscribes to MID 0900 with the generic subscription (MID 0008; MID 0009 stops it) gets,
after each result's 0061, one MID 0900 per trace type it asked for (angle and torque, from
the rundown model of ``curves.py``); it acknowledges each with MID 0005.  Built with
``curves=False`` it refuses the 0008 with MID 0004 ``curves_refusal_code`` (78,
"subscription on specific data not supported", by default), as a controller without curves.
A trace is ``curve_samples`` long (240); one whose message passes 9999 bytes goes in parts,
cut every ``part_size`` bytes of data (``curves.in_parts``).  MID 0008 may also subscribe
to MID 0901 (the plot parameters: one after each result's traces), and MID 0006 asks for MID
0902 (the result store's extent); each is acknowledged with MID 0005 naming it
(``data_acks`` counts them by MID).
Results of every type (``pull_trigger(result_type=N)``, 1-8 and codes the specification
does not name): a tightening, a loosening or a synchronized tightening has a rundown; the
others (3 batch increment, 4 batch decrement, 5 bypass, 6 abort job, 8 reference setup) are
controller events: no torque or angle, OK, the batch counter stepped for 3 and 4; each takes
a tightening id and is stored like any result.  Bodies that do not match their label, for the
driver's reading rules: ``mislabel=R`` is a controller that claims more than it implements
(a 0061/0065 asked for above revision R is laid out as revision R with fields appended,
labelled as asked), ``send_revision=R`` labels every 0061 honestly with revision R whatever
was subscribed, and ``garble_next_result()`` spoils one body so that it reads at no
revision; ``lose_next_push()`` keeps a result from its subscribers with the link up (a live
gap in the tightening ids).  Results made while no integrator is connected (a link cut) are
kept and fetchable with MID 0064 like the others.  MID 0080 is answered with its clock (MID
0081; ``clock``, or the local clock shifted by ``clock_offset_s``), and any MID can be
refused (``refuse_mid``).
``python -m drivers.wrench.sim`` serves it on a TCP port for any integrator
(``cli.py``).

``SimWrench`` is the real client (``client.OpenProtocolWrench``) plus the lifecycle of an
in-process controller: ``sim://wrench`` exercises the whole protocol path.
"""

from __future__ import annotations

import os
import random
import shutil
import tempfile
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any, Literal

from drivers.link import Link, SerialLink, TcpLink
from drivers.url import DeviceUrl
from drivers.wrench.openprotocol.client import OpenProtocolWrench
from drivers.wrench.openprotocol.options import OPTIONS, REFUSED, Spec, keyword_options
from drivers.wrench.sim.curves import PART_SIZE, in_parts, mid0900, mid0901, mid0902
from drivers.wrench.sim.results import (
    NM_PER,
    TIME,
    SimRecord,
    fixed,
    mislabelled_data,
    record_line,
    record_of,
    result_data,
    text,
)
from drivers.wrench.sim.server import OpenProtocolServer, Received, Session, message

#: Open Protocol's error 99, "unknown MID": what a controller answers a MID it does not know
UNKNOWN_MID = 99

VIN_WIDTH = 25
REVISIONS = range(1, 8)          # of 0001/0002, 0060/0061, 0064/0065 served
#: result types with a rundown (torque and angle): tightening, loosening, synchronized
RUNDOWN_TYPES = frozenset({1, 2, 7})
Garble = Literal["value", "layout"]


@dataclass(frozen=True)
class SimPset:
    """A parameter set as programmed on the controller: targets and limits."""

    torque_nm: float
    torque_min_nm: float
    torque_max_nm: float
    angle_deg: float
    angle_min_deg: float
    angle_max_deg: float
    batch_size: int = 1
    name: str = ""


DEFAULT_PSETS: dict[int, SimPset] = {
    1: SimPset(25.0, 22.5, 27.5, 90.0, 60.0, 120.0),
    2: SimPset(45.0, 40.5, 49.5, 120.0, 90.0, 150.0),
    3: SimPset(110.0, 99.0, 121.0, 45.0, 30.0, 60.0),
}


@dataclass(frozen=True)
class SimTightening:
    """What the controller reported for one trigger pull (the simulation's ground truth)."""

    tightening_id: int
    pset: int
    ok: bool
    torque_nm: float
    angle_deg: float
    torque_status: int
    angle_status: int
    vin: str
    timestamp: datetime
    message: bytes = field(repr=False)     # MID 0061 revision 1: header + data, no NUL
    record: SimRecord | None = field(default=None, repr=False)   # for any other revision


class SimController(OpenProtocolServer):
    """The simulated controller; ``start()`` it (or use ``with``), then ``listen_tcp()``
    and/or ``open_pty()``.  ``refusals`` maps a pset to the error code its selection gets;
    ``refused_revisions`` maps a MID (1, 60, 64) to the revisions it refuses, and
    ``refused_mids`` a MID to the error code every one of it gets (:meth:`refuse_mid`)."""

    def __init__(self, psets: Mapping[int, SimPset] | None = None, *, seed: int = 0,
                 nok_rate: float = 0.05, name: str = "SimController", cell: int = 1,
                 channel: int = 1, silence_timeout: float = 15.0,
                 refusals: Mapping[int, int] | None = None,
                 clock: Callable[[], datetime] | None = None,
                 resend_unacked: bool = False, link_ack: bool = False,
                 refused_revisions: Mapping[int, Iterable[int]] | None = None,
                 revision_refusal_code: int = 97, store_size: int = 1000,
                 torque_unit: int = 1, software: str = "stationd-sim 1.0",
                 serial: str = "SIM0000001", curves: bool = True,
                 curves_refusal_code: int = 78, curve_samples: int = 240,
                 part_size: int = PART_SIZE, mislabel: int | None = None,
                 send_revision: int | None = None, clock_offset_s: float = 0.0,
                 result_types: Sequence[int] = (1,), garble_every: int = 0,
                 lose_push_every: int = 0,
                 refused_mids: Mapping[int, int] | None = None) -> None:
        if not 0.0 <= nok_rate <= 1.0:
            raise ValueError(f"nok_rate must be in [0, 1], not {nok_rate}")
        if silence_timeout <= 0:
            raise ValueError("silence_timeout must be > 0")
        if torque_unit not in NM_PER:
            raise ValueError(f"torque_unit must be one of {sorted(NM_PER)}, not {torque_unit}")
        if store_size < 1:
            raise ValueError("store_size must be >= 1")
        if not 2 <= curve_samples <= 30_000:
            raise ValueError(f"curve_samples must be 2-30000, not {curve_samples}")
        if not 100 <= part_size <= PART_SIZE:
            raise ValueError(f"part_size must be 100-{PART_SIZE}, not {part_size}")
        if not result_types or any(not 0 <= c <= 99 for c in result_types):
            raise ValueError(f"result_types must be codes 0-99, not {list(result_types)}")
        if garble_every < 0 or lose_push_every < 0:
            raise ValueError("garble_every and lose_push_every must be >= 0 (0: never)")
        for option, rev in (("mislabel", mislabel), ("send_revision", send_revision)):
            if rev is not None and rev not in REVISIONS:
                raise ValueError(f"{option} must be a revision 1-{REVISIONS[-1]}, not {rev}")
        super().__init__()
        self.psets = dict(DEFAULT_PSETS if psets is None else psets)
        self.nok_rate, self.name, self.cell, self.channel = nok_rate, name, cell, channel
        self.silence_timeout = silence_timeout
        self.link_ack, self.torque_unit = link_ack, torque_unit
        self.software, self.serial = software, serial
        self.revision_refusal_code = revision_refusal_code
        self.store_size = store_size
        self.curves, self.curves_refusal_code = curves, curves_refusal_code
        self.curve_samples, self.part_size = curve_samples, part_size
        self.curves_sent = 0                     # MID 0900 sent (a message in parts: one)
        self.parts_sent = 0                      # of which parts (messages on the wire)
        self.curve_acks = 0                      # MID 0005 "0900" received
        self.data_acks: dict[int, int] = {}      # MID 0005 for subscribed data, by MID
        self._rng = random.Random(seed)  # noqa: S311 - seeded simulation scatter, not security
        self.mislabel, self.send_revision = mislabel, send_revision
        self._garble: Garble | None = None       # the next result's body spoiled so
        self.clock_offset_s = clock_offset_s     # read at each tick: may be changed live
        self._clock = clock or (lambda: (datetime.now() + timedelta(
            seconds=self.clock_offset_s)).replace(microsecond=0))
        self._refuse_pset: dict[int, int] = dict(refusals or {})
        self._refuse_mid: dict[int, int] = dict(refused_mids or {})
        self._refuse_newest: int | None = None   # MID 0064's id 0 refused with this code
        self._ignore_mid: set[int] = set()      # answered with nothing (:meth:`ignore_mid`)
        self._hung = False                      # nothing answered at all (:meth:`hang`)
        self._refuse_rev: dict[int, set[int]] = {
            mid: set(revs) for mid, revs in (refused_revisions or {}).items()}
        self.pset: int | None = None
        self.tool_enabled = False
        self.vin = ""
        self.acks = 0                            # MID 0062 received
        self.acked_ids: list[int] = []           # the tightenings those 0062 acknowledged
        self._pset_changed = self._clock()
        self._batch_counter = self._tid = 0
        # as some controllers do: results nobody acknowledged (MID 0062) are sent again to
        # the next subscriber, oldest first
        self.resend_unacked = resend_unacked
        self._unacked: dict[int, SimRecord] = {}     # tightening id -> its record
        self._store: OrderedDict[int, SimRecord] = OrderedDict()   # for MID 0064
        self._kept: Path | None = None           # the file it keeps them in as well
        self._kept_lines = 0                     # the lines that file holds
        self._rundown: int | None = None         # the pset of a rundown under way
        self._lose_pushes = 0                    # the next results kept but never pushed
        # what the trigger makes when no type is asked: these types in turn, every
        # ``garble_every``-th result's body spoiled, every ``lose_push_every``-th push lost
        # (0: never), so a whole station can be run against a troubled controller
        self.result_types = tuple(result_types)
        self.garble_every, self.lose_push_every = garble_every, lose_push_every
        self._pulls = 0                          # trigger pulls that made a result

    def __enter__(self) -> SimController:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- controls for the simulation and tests ----------------------------------------------
    def pull_trigger(self, result_type: int | None = None) -> SimTightening | None:
        """The operator pulls the trigger: a tightening with the selected pset, reported to
        subscribed integrators; None (nothing happens) if the tool is disabled or no pset.
        ``result_type`` (MID 0061 revision 3+, parameter 49) makes it another kind of
        result: 2 a loosening, 7 a synchronized tightening (with a rundown too), 3-6 and 8
        a controller event (see the module docstring), any other code 0-99 a type the
        specification does not name, with a rundown.  None: the controller's schedule
        (``result_types`` in turn, with its spoiled bodies and lost pushes; a tightening
        without one)."""
        if result_type is not None and not 0 <= result_type <= 99:
            raise ValueError(f"result_type must be a 2-digit code, not {result_type}")
        return self.call(lambda: self._tighten(result_type))

    def press(self, result_type: int = 3) -> SimTightening | None:
        """Someone at the controller's own panel makes a result that is no rundown (3 batch
        increment, 4 batch decrement, 5 bypass, 6 abort job, 8 reference setup), whether the
        station has the tool enabled or not, with the pset last selected; None before any
        pset was selected."""
        if result_type not in (3, 4, 5, 6, 8):
            raise ValueError(f"a panel result is of type 3, 4, 5, 6 or 8, not {result_type}")
        return self.call(lambda: None if self.pset is None
                         else self._result(self.pset, result_type))

    def garble_next_result(self, how: Garble = "value") -> None:
        """Spoil the body of the next result message (0061 or 0065) so that it reads at no
        revision: "value" puts letters in its torque (the layout intact, the tightening id,
        pset and VIN still readable), "layout" cuts it in the middle of a parameter."""
        if how not in ("value", "layout"):
            raise ValueError(f"how must be value or layout, not {how!r}")
        self.call(lambda: setattr(self, "_garble", how))

    def start_rundown(self) -> bool:
        """The trigger pulled, the rundown under way (its result comes with
        :meth:`finish_rundown`, whatever happens to the tool meanwhile: a rundown started
        is finished); False (nothing happens) if the tool is disabled or no pset."""
        def do() -> bool:
            if not self.tool_enabled or self.pset is None:
                return False
            self._rundown = self.pset
            return True
        return self.call(do)

    def finish_rundown(self) -> SimTightening:
        """The rundown started by :meth:`start_rundown` ends: its result is reported."""
        def do() -> SimTightening:
            if self._rundown is None:
                raise RuntimeError("no rundown under way")
            pset, self._rundown = self._rundown, None
            return self._result(pset)
        return self.call(do)

    def refuse_pset(self, pset: int, code: int) -> None:
        self.call(lambda: self._refuse_pset.__setitem__(pset, code))

    def refuse_mid(self, mid: int, code: int) -> None:
        """Refuse every command ``mid`` with ``code`` (MID 0004)."""
        self.call(lambda: self._refuse_mid.__setitem__(mid, code))

    def refuse_newest(self, code: int) -> None:
        """Refuse MID 0064 asking for the newest result (id 0) with ``code``, an id asked by
        number still given: the integrator's checks of the newest tell nothing, while a
        pushed result that skipped ids still has them fetched (what the pushes alone decide,
        whenever the checks would have run; :meth:`clear_refusals` ends it)."""
        self.call(lambda: setattr(self, "_refuse_newest", code))

    def ignore_mid(self, mid: int) -> None:
        """Answer nothing to ``mid`` (no reply, no MID 0004), as a controller that ignores a
        MID it does not know (:meth:`clear_refusals` ends it)."""
        self.call(lambda: self._ignore_mid.add(mid))

    def hang(self) -> None:
        """Answer nothing at all, the keep-alive neither, the connection kept open: a
        controller whose software hangs (:meth:`clear_refusals` ends it)."""
        self.call(lambda: setattr(self, "_hung", True))

    def refuse_revisions(self, mid: int, revisions: Iterable[int]) -> None:
        """Refuse ``mid`` (1, 60, 64) at these ``revisions`` (MID 0004 with
        ``revision_refusal_code``), as a controller that does not know them."""
        revs = set(revisions)
        self.call(lambda: self._refuse_rev.__setitem__(mid, revs))

    def clear_refusals(self) -> None:
        def do() -> None:
            self._refuse_pset.clear()
            self._refuse_mid.clear()
            self._ignore_mid.clear()
            self._hung = False
            self._refuse_rev.clear()
            self._refuse_newest = None
        self.call(do)

    def lose_next_push(self, count: int = 1) -> None:
        """The next ``count`` results are made and kept (MID 0064 gives them, and MID 0900
        their curves) but neither their MID 0061 nor their curves reach a subscriber, with
        the link up: a push a controller's firmware or a device on the way lost, which the
        integrator sees only as a tightening id skipped by the next result."""
        if count < 1:
            raise ValueError(f"count must be >= 1, not {count}")
        self.call(lambda: setattr(self, "_lose_pushes", self._lose_pushes + count))

    def forget_results(self, *tightening_ids: int) -> None:
        """The controller no longer has these results (its store is bounded)."""
        def forget() -> None:
            for t in tightening_ids:
                self._store.pop(t, None)
            self._rewrite()
        self.call(forget)

    def clear_results(self) -> None:
        """The controller's result database cleared (a reset, or another controller put in
        its place): its tightening ids start again from 1, and it keeps no results."""
        def clear() -> None:
            self._tid, self._store, self._unacked = 0, OrderedDict(), {}
            self._rewrite()
        self.call(clear)

    def keep_results_in(self, path: Path) -> None:
        """Keep the results for MID 0064 in the file ``path`` as well, and take those it holds
        (beside any kept already): its newest id is where its count goes on.  A real
        controller is a box of its own and keeps its results through the station's restart;
        a simulator in the station's process lost them with it, so the catch-up after a
        restart found the controller empty and held the bolt whose result was owed (its
        result "not known").  Each result is a line appended as it is made; the file is
        written again, the newest ``store_size`` alone, when it is taken and when it holds
        twice as many lines (bounded).  A line that does not read (the process killed while
        writing it) is left out.  A file that cannot be written is said in ``errors``: the
        results are kept in memory as before."""
        def take() -> None:
            found: list[SimRecord] = []
            try:
                with path.open(encoding="utf-8") as f:
                    found = [r for r in map(record_of, f) if r is not None]
            except FileNotFoundError:
                pass
            except (OSError, UnicodeDecodeError) as exc:
                self.errors.append(f"results kept in {path} not read: {exc}")
            for r in found:
                if r.tightening_id not in self._store:
                    self._store[r.tightening_id] = r
            self._store = OrderedDict(sorted(self._store.items())[-self.store_size:])
            self._tid = max(self._tid, next(reversed(self._store), 0))
            self._kept = path
            self._rewrite()
        self._at_rest_or_call(take)

    def _remember(self, record: SimRecord) -> None:
        """``record`` appended to the file the results are kept in (if any); the file
        written again once it holds twice ``store_size`` lines."""
        if self._kept is None:
            return
        if self._kept_lines >= 2 * self.store_size:
            self._rewrite()
            return
        try:
            with self._kept.open("a", encoding="utf-8") as f:
                f.write(record_line(record) + "\n")
            self._kept_lines += 1
        except OSError as exc:
            self.errors.append(f"tightening {record.tightening_id} not kept in "
                               f"{self._kept}: {exc}")

    def _rewrite(self) -> None:
        """The file the results are kept in (if any) written again with those kept now,
        whole or not at all (a new file put in its place)."""
        if self._kept is None:
            return
        part = self._kept.with_name(self._kept.name + ".part")
        try:
            part.write_text("".join(record_line(r) + "\n" for r in self._store.values()),
                            encoding="utf-8")
            os.replace(part, self._kept)
            self._kept_lines = len(self._store)
        except OSError as exc:
            self.errors.append(f"results not kept in {self._kept}: {exc}")

    def _at_rest_or_call(self, fn: Callable[[], None]) -> None:
        """``fn`` now where the controller's thread does not run yet, else on it."""
        if self._thread is None:
            fn()
        else:
            self.call(fn)

    def go_on_after(self, last_id: int, seed: int) -> None:
        """Number on after tightening ``last_id`` (the newest its station recorded), its
        scatter drawn anew from ``seed`` and that id: the station restarted, and a real
        controller outlives that with its count.  A simulator built anew numbered from 1 with
        the same scatter, and the station took its new results for copies of stored ones (a
        supervisor's trial: a real rundown's values thrown away).  What it kept for MID 0064
        is gone with the last process, unless kept in a file (:meth:`keep_results_in`: its
        newest id counts too)."""
        def take() -> None:
            self._tid = max(self._tid, int(last_id))
            self._rng.seed(f"{seed}:{last_id}")
        self._at_rest_or_call(take)

    def go_on_from(self, before: SimController) -> None:
        """Go on where ``before`` (closed: the simulator of the same controller, built by the
        daemon before a reload) stopped: its tightening ids, its batch counter, the results
        it keeps for MID 0064 (and those it still resends, where this one resends), and its
        random scatter.

        Why: a real controller is a box of its own, and a station's reload does not reset it:
        its ids go on and its next result is a new one.  A simulator built anew at each
        reload numbered its tightenings from 1 again and, with the same seed, made the same
        torques and angles: the station took them for copies of results it had stored, and
        the rundowns were lost.  Its connection, tool and pset are the new station's to set,
        as they are after a real controller's reconnect."""
        tid, batch = before._tid, before._batch_counter
        store, unacked = list(before._store.items()), dict(before._unacked)
        scatter = before._rng.getstate()

        def take() -> None:
            self._tid, self._batch_counter = tid, batch
            self._store = OrderedDict(store[-self.store_size:])
            self._unacked = unacked if self.resend_unacked else {}
            self._rng.setstate(scatter)
        self._at_rest_or_call(take)

    def on_power_on(self) -> None:
        """Volatile state is lost in a power cycle; the selected pset is kept."""
        self.tool_enabled, self.vin = False, ""

    # -- the controller ---------------------------------------------------------------------
    def _refuse(self, s: Session, mid: int, code: int) -> None:
        self.reply(s, mid, 4, f"{mid:04d}{code:02d}".encode())

    def _ok(self, s: Session, mid: int) -> None:
        self.reply(s, mid, 5, f"{mid:04d}".encode())

    def _revision_refused(self, s: Session, msg: Received) -> bool:
        """MID 0004 for a revision this controller does not serve (or is set to refuse)."""
        if msg.mid not in (1, 60, 63, 64):
            return False
        if msg.revision in REVISIONS and msg.revision not in self._refuse_rev.get(msg.mid, ()):
            return False
        self._refuse(s, msg.mid, self.revision_refusal_code)
        return True

    def handle(self, s: Session, msg: Received) -> None:
        mid, data = msg.mid, msg.data
        if self._hung:
            return
        if mid == 9999:
            self.reply(s, 9999, 9999)
        elif mid == 1:
            if self._revision_refused(s, msg):
                pass
            elif s.started and s.kind == "tcp":
                self._refuse(s, mid, 96)
            else:   # on a serial line a new 0001 starts a new session
                s.started, s.subscribed, s.traces, s.plot = True, False, (), False
                s.replaying = False
                s.out.clear()
                s.start_link_level(False)
                self.reply(s, mid, 2, self._identity(msg.revision), msg.revision)
                # from the message after 0002 on, with an integrator that can know it
                # (0002 revision 6+ says so), or one that numbers its messages
                s.start_link_level(self.link_ack and msg.revision >= 6, self.link_ack)
        elif not s.started:
            self.errors.append(f"MID {mid:04d} before communication start ignored")
        elif mid in self._ignore_mid:
            pass
        elif mid in self._refuse_mid:
            self._refuse(s, mid, self._refuse_mid[mid])
        elif self._revision_refused(s, msg):
            pass
        elif mid == 3:
            self._ok(s, mid)
            s.started = s.subscribed = s.plot = s.replaying = False
            s.traces = ()
        elif mid == 5:    # the generic acknowledgement of subscribed data (MID 0900-0902)
            if data[:4] in (b"0900", b"0901", b"0902"):
                self.data_acks[int(data[:4])] = self.data_acks.get(int(data[:4]), 0) + 1
                self.curve_acks += data[:4] == b"0900"
            else:
                self.errors.append(f"MID 0005 acknowledging {data[:4]!r} ignored")
        elif mid == 6:    # data message request: MID 0902, the result store's extent
            if data[:4] != b"0902":
                self._refuse(s, mid, 73)
            else:
                self.post(s, mid0902(self.store_size, list(self._store.values())))
        elif mid == 8:
            if data[:4] == b"0901":
                if s.plot:
                    self._refuse(s, mid, 71)
                else:
                    s.plot = True
                    self._ok(s, mid)
            else:
                self._data_subscription(s, data)
        elif mid == 9:
            if data[:4] == b"0901" and s.plot:
                s.plot = False
                self._ok(s, mid)
            elif data[:4] not in (b"0900", b"0901"):
                self._refuse(s, mid, 73)
            elif data[:4] == b"0901" or not (s.traces or s.replaying):
                self._refuse(s, mid, 72)      # subscription does not exist
            else:
                s.traces, s.replaying = (), False
                self._ok(s, mid)
        elif mid == 18:
            self._select(s, data)
        elif mid in (42, 43):
            self.tool_enabled = mid == 43
            self._ok(s, mid)
        elif mid == 50:
            if len(data) > VIN_WIDTH or not data.isascii():
                self._refuse(s, mid, 1)
            else:
                self.vin = data.decode().strip()
                self._ok(s, mid)
        elif mid in (60, 63):
            self._subscription(s, mid, msg.revision)
        elif mid == 62:   # 0062 names no result: it acknowledges the oldest one sent
            self.acks += 1
            if s.unacked:
                tid = s.unacked.pop(0)
                self.acked_ids.append(tid)
                self._unacked.pop(tid, None)
        elif mid == 64:
            self._old_result(s, msg)
        elif mid == 80:   # read time request -> MID 0081 YYYY-MM-DD:HH:MM:SS
            self.reply(s, 80, 81, self._clock().strftime(TIME).encode())
        else:
            self._refuse(s, mid, 99)

    def _identity(self, revision: int) -> bytes:
        """MID 0002 data: revision 1's cell, channel and name, and each later revision's
        parameters after them (numbered on).  Revision 6 (specification R2.8.0, table 16)
        brings parameters 12-16: sequence number support (link-level acknowledgement),
        linking handling support (messages in parts, which this controller sends: a long
        trace), station id and name, client id.  R2.8.0 names no revision 7: it is answered
        with revision 6's parameters."""
        values = [fixed(self.cell, 4), fixed(self.channel, 2), text(self.name, 25)]
        extra = ([text("SIM", 3)],
                 [text("2.8.0", 19), text(self.software, 19), text("sim tool 1.0", 19)],
                 [text("simulated RBU", 24), text(self.serial, 10)],
                 ["000", "000"],
                 [str(int(self.link_ack)), "1", text("1", 10), text("simulated station", 25),
                  "1"])
        for more in extra[:revision - 1]:
            values += more
        return "".join(f"{tag:02d}{v}" for tag, v in enumerate(values, 1)).encode("ascii")

    def _subscription(self, s: Session, mid: int, revision: int) -> None:
        if s.subscribed == (mid == 60):    # already (un)subscribed
            self._refuse(s, mid, 9 if mid == 60 else 10)
            return
        s.subscribed = mid == 60
        if s.subscribed:
            s.result_revision = revision
        self._ok(s, mid)
        if s.subscribed and self.resend_unacked:
            for tid, record in self._unacked.items():
                if tid not in s.unacked:
                    self.post(s, self._render(61, s.result_revision, record))
                    s.unacked.append(tid)

    def _data_subscription(self, s: Session, data: bytes) -> None:
        """MID 0008: subscribed MID 4, its revision 3, extra data length 2, extra data (R2.8.0
        table 158 for MID 0900: send alternative 1; for 0-2 the time stamp 19 and index 10
        identifiers, for 3 the first and last index 10 each; then the number of trace types
        2 and each trace type 3).  Only MID 0900 revision 1 is served, angle and torque
        traces, new data (alternative 0, time and index unused) or the stored traces of the
        tightenings between two indexes (alternative 3: sent at once, after the 0005; the
        subscription then stays, sending nothing new, until MID 0009); other alternatives
        are refused with 78, an index range this controller has no result of with 01."""
        if data[:4] != b"0900":
            self._refuse(s, 8, 73)            # subscribed MID unsupported
            return
        if not self.curves:
            self._refuse(s, 8, self.curves_refusal_code)
            return
        if data[4:7].strip(b" ") not in (b"", b"000", b"001"):
            self._refuse(s, 8, 74)            # subscribed MID revision unsupported
            return
        if s.traces or s.replaying:
            self._refuse(s, 8, 71)            # subscription already exists
            return
        extra = data[9:]
        alternative = extra[:1]
        if alternative == b"3":
            span, kinds_at = (extra[1:11], extra[11:21]), 21
        elif alternative == b"0" or not alternative:
            span, kinds_at = None, 30
        else:
            self._refuse(s, 8, 78)            # stored data by time: not kept here
            return
        count = extra[kinds_at:kinds_at + 2]
        kinds = [int(extra[kinds_at + 2 + 3 * i:kinds_at + 5 + 3 * i])
                 for i in range(int(count))
                 if extra[kinds_at + 2 + 3 * i:kinds_at + 5 + 3 * i].isdigit()] \
            if count.isdigit() else []
        if not kinds:
            kinds = [1, 2]
        if any(k not in (1, 2) for k in kinds):
            self._refuse(s, 8, 78)        # a trace type this controller does not make
            return
        if span is None:
            s.traces = tuple(kinds)
            self._ok(s, 8)
            return
        if not all(i.isdigit() for i in span):
            self._refuse(s, 8, 1)
            return
        first, last = (int(i) for i in span)
        records = [r for tid, r in self._store.items() if first <= tid <= last]
        if not records:
            self._refuse(s, 8, 1)             # no such result (any more)
            return
        s.replaying = True
        self._ok(s, 8)
        for record in records:
            self._send_traces(s, record, kinds)

    def _send_traces(self, s: Session, record: SimRecord, kinds: Iterable[int]) -> None:
        """MID 0900 of ``record`` for each trace type (in parts when long)."""
        for kind in kinds:
            for part in in_parts(mid0900(record, kind, self.curve_samples), self.part_size):
                self.post(s, part)
                self.parts_sent += 1
            self.curves_sent += 1

    def _old_result(self, s: Session, msg: Received) -> None:
        """MID 0064 (a tightening id, 0 = the newest) -> MID 0065 of its revision, or 0004
        error 15 for an id this controller does not have (any more)."""
        if len(msg.data) != 10 or not msg.data.isdigit():
            self._refuse(s, 64, 1)
            return
        if int(msg.data) == 0 and self._refuse_newest is not None:
            self._refuse(s, 64, self._refuse_newest)
            return
        tid = int(msg.data) or next(reversed(self._store), 0)
        record = self._store.get(tid)
        if record is None:
            self._refuse(s, 64, 15)
            return
        raw = self._render(65, msg.revision, record)
        self.reply(s, 64, 65, raw[20:], msg.revision)

    def _render(self, mid: int, revision: int, record: SimRecord) -> bytes:
        """A result message labelled ``revision``: its body as that revision, or as
        ``mislabel``'s with fields appended, and spoiled if ``garble_next_result`` said so."""
        if self.mislabel is not None and revision > self.mislabel:
            data = mislabelled_data(mid, self.mislabel, record)
        else:
            data = result_data(mid, revision, record)
        how, self._garble = self._garble, None
        if how == "value":
            data = _spoil_torque(mid, revision, data)
        elif how == "layout":
            data = data[:len(data) // 2 + 1]
        return message(mid, data, revision)

    def _select(self, s: Session, data: bytes) -> None:
        if len(data) != 3 or not data.isdigit():
            self._refuse(s, 18, 1)
        elif int(data) in self._refuse_pset:
            self._refuse(s, 18, self._refuse_pset[int(data)])
        elif int(data) not in self.psets:
            self._refuse(s, 18, 2)
        else:
            if int(data) != self.pset:
                self.pset, self._pset_changed = int(data), self._clock()
                self._batch_counter = 0
            self._ok(s, 18)

    def _tighten(self, result_type: int | None = None) -> SimTightening | None:
        if not self.tool_enabled or self.pset is None:
            return None
        if result_type is None:      # the schedule's turn
            n, self._pulls = self._pulls, self._pulls + 1
            result_type = self.result_types[n % len(self.result_types)]
            if self.garble_every and (n + 1) % self.garble_every == 0:
                self._garble = "value"
            if self.lose_push_every and (n + 1) % self.lose_push_every == 0:
                self._lose_pushes += 1
        return self._result(self.pset, result_type)

    def _result(self, pset: int, result_type: int = 1) -> SimTightening:
        """A tightening with ``pset``, reported to every subscribed session."""
        p, rng = self.psets[pset], self._rng
        t_lo, t_hi = round(p.torque_min_nm * 100), round(p.torque_max_nm * 100)
        a_lo, a_hi = round(p.angle_min_deg), round(p.angle_max_deg)
        torque = min(max(rng.gauss(p.torque_nm * 100, (t_hi - t_lo) / 12), t_lo), t_hi)
        angle = min(max(rng.gauss(p.angle_deg, (a_hi - a_lo) / 12), a_lo), a_hi)
        if rng.random() < self.nok_rate:        # a NOK: one value just outside its limits
            side = rng.choice(("torque_low", "torque_high", "angle_low", "angle_high"))
            miss = rng.uniform(0.02, 0.2)
            lo, hi = (t_lo, t_hi) if side.startswith("torque") else (a_lo, a_hi)
            value = lo - miss * (hi - lo) - 1 if side.endswith("low") else \
                hi + miss * (hi - lo) + 1
            torque, angle = (value, angle) if side.startswith("torque") else (torque, value)
        t_val, a_val = max(round(torque), 0), max(round(angle), 0)
        t_stat = 0 if t_val < t_lo else 2 if t_val > t_hi else 1
        a_stat = 0 if a_val < a_lo else 2 if a_val > a_hi else 1
        ok = t_stat == a_stat == 1
        step = int(ok)
        if result_type not in RUNDOWN_TYPES and result_type in range(3, 9):
            # a controller event: no rundown; a batch step moves the counter
            t_val = a_val = 0
            t_stat = a_stat = 1
            ok, angle = True, 0.0
            step = {3: 1, 4: -1}.get(result_type, 0)
        self._batch_counter = max(self._batch_counter + step, 0)
        self._tid += 1
        now = self._clock()
        record = SimRecord(
            tightening_id=self._tid, cell=self.cell, channel=self.channel, name=self.name,
            vin=self.vin, pset=pset, pset_name=p.name or f"pset {pset}",
            batch_size=p.batch_size, batch_counter=self._batch_counter,
            batch_status=int(self._batch_counter >= p.batch_size), ok=ok,
            torque_status=t_stat, angle_status=a_stat, torque_min=t_lo, torque_max=t_hi,
            torque_target=round(p.torque_nm * 100), torque=t_val, angle_min=a_lo,
            angle_max=a_hi, angle_target=round(p.angle_deg), angle=a_val,
            angle_exact=max(angle, 0.0), timestamp=now, pset_changed=self._pset_changed,
            result_type=result_type, torque_unit=self.torque_unit)
        self._store[self._tid] = record
        while len(self._store) > self.store_size:
            self._store.popitem(last=False)
        self._remember(record)
        lost = self._lose_pushes > 0
        self._lose_pushes -= lost
        if self.resend_unacked and not lost:
            self._unacked[self._tid] = record
        for s in self.sessions():
            if s.started and s.subscribed and not lost:
                rev = self.send_revision or s.result_revision
                self.post(s, self._render(61, rev, record))
                s.unacked.append(self._tid)
        for s in self.sessions():       # the curves after every result: never before one
            if s.started and not lost:
                self._send_traces(s, record, s.traces)
                if s.plot:
                    self.post(s, mid0901(record))
        return SimTightening(self._tid, pset, ok, t_val / 100, float(a_val), t_stat,
                             a_stat, self.vin, now,
                             message(61, result_data(61, 1, record), 1), record)


def _spoil_torque(mid: int, revision: int, data: bytes) -> bytes:
    """``data`` with letters where its torque's digits are (the layout kept)."""
    if revision == 1:      # the torque's value at bytes 141-146 (0061) or 82-87 (0065)
        start = 140 - 20 if mid == 61 else 81 - 20
    else:                  # parameter 24 (0061) or 19 (0065), found by tag as written
        widths, torque = (_TAG_WIDTHS, b"24") if mid == 61 else (_TAG_WIDTHS_0065, b"19")
        start = pos = 0
        while not start:
            tag = data[pos:pos + 2]
            if tag == torque:
                start = pos + 2
            elif tag.isdigit() and int(tag) in widths:
                pos += 2 + widths[int(tag)]
            else:
                raise AssertionError(f"no torque in {data[:40]!r}")
    return data[:start] + b"TORQUE" + data[start + 6:]


#: the widths of MID 0061 revision 2-7 parameters 01-23 (to find parameter 24, the torque)
_TAG_WIDTHS = dict(enumerate((4, 2, 25, 25, 4, 3, 2, 5, 4, 4, 1, 1, 1, 1, 1, 1, 1, 1, 1, 10,
                              6, 6, 6), start=1))
#: ... and of MID 0065 revision 2-7 parameters 01-18 (to find parameter 19, the torque)
_TAG_WIDTHS_0065 = dict(enumerate((10, 25, 4, 3, 2, 5, 4, 4, 1, 1, 1, 1, 1, 1, 1, 1, 1, 10),
                                  start=1))


def parse_result_types(text: str, name: str = "") -> list[int]:
    """``1,3,2`` -> [1, 3, 2]: result type codes (2 digits), made in turn; ValueError with
    the words for anything else (``name``: the option's, before them)."""
    try:
        codes = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise ValueError(f"{name}expected codes like 1,3,2, not {text!r}") from None
    if not codes or any(not 0 <= c <= 99 for c in codes):
        raise ValueError(f"{name}expected codes 0-99 like 1,3,2, not {text!r}")
    return codes


class SimWrench(OpenProtocolWrench):
    """``sim://wrench[?transport=tcp|serial&seed=0&nok_rate=0.05&result_types=1,2,1&
    garble_every=0&lose_push_every=0]``: starts a SimController in-process and talks to it
    with the real Open Protocol client.  ``controller`` is the simulation's handle on it
    (pull the trigger, refuse, inject faults, power cycle); the trouble options make the
    trigger's results those types in turn, spoil every Nth body and lose every Nth push."""

    simulated = True

    def __init__(self, controller: SimController, *, transport: str = "tcp",
                 device: str = "sim://wrench", **kw: Any) -> None:
        if transport not in ("tcp", "serial"):
            raise ValueError(f"transport must be tcp or serial, not {transport!r}")
        super().__init__(None, device=device, **kw)
        self.controller = controller
        self.transport = transport
        self._pty_dir: str | None = None

    @classmethod
    def from_url(cls, url: DeviceUrl, **kw: Any) -> SimWrench:
        """Options: transport, seed, nok_rate and the client's; keywords: those, plus the
        controller's psets, refusals, clock, silence_timeout, mislabel, send_revision and
        clock_offset_s."""
        if url.host != "wrench" or url.path not in ("", "/"):
            raise url.error("expected sim://wrench")
        spec: Spec = {**OPTIONS, "transport": (str, "tcp"), "seed": (int, 0),
                      "nok_rate": (float, 0.05), "result_types": (str, "1"),
                      "garble_every": (int, 0), "lose_push_every": (int, 0),
                      "old_results": (int, 1)}
        sim_kw = {k: kw.pop(k) for k in ("psets", "refusals", "clock", "silence_timeout",
                                         "mislabel", "send_revision", "clock_offset_s")
                  if k in kw}
        opts = url.typed_options(spec, "sim://wrench?transport=serial&seed=1&nok_rate=0.1")
        opts.update(keyword_options(kw, spec))
        try:
            codes = parse_result_types(str(opts.pop("result_types")), "result_types: ")
            # old_results=0: a controller that keeps no results to fetch (MID 0064 refused as
            # an unknown MID): what a push lost becomes when it cannot be found
            keeps = opts.pop("old_results")
            controller = SimController(seed=opts.pop("seed"), nok_rate=opts.pop("nok_rate"),
                                       result_types=codes,
                                       garble_every=opts.pop("garble_every"),
                                       lose_push_every=opts.pop("lose_push_every"),
                                       refused_mids=None if keeps else {64: UNKNOWN_MID},
                                       **sim_kw)
            return cls(controller, device=url.text, **opts)
        except ValueError as e:
            raise url.error(str(e)) from None

    def _make_link(self) -> Link:
        self.controller.start()
        if self.transport == "serial":   # behind a symlink, so a power cycle keeps the path
            self._pty_dir = tempfile.mkdtemp(prefix="sim-wrench-")
            return SerialLink(self.controller.open_pty(os.path.join(self._pty_dir, "tty")))
        return TcpLink("127.0.0.1", self.controller.listen_tcp(), REFUSED)

    def _release(self) -> None:
        """The controller started by ``_make_link`` and the folder of its pty's link."""
        self.controller.close()
        if self._pty_dir is not None:
            shutil.rmtree(self._pty_dir, ignore_errors=True)

