"""``python -m drivers.wrench.sim``: the simulated controller on a TCP port of its own.

Why: so that an Open Protocol client that is not ours (an integrator's library, a vendor's
test tool) can be pointed at the same controller the station's tests use, and so that a
person can watch the exchange.  It serves until SIGINT or SIGTERM; with ``--trigger-every``
the "operator" pulls the trigger at that interval whenever the tool is enabled and a pset
selected, so results flow without a test driving it.

    python -m drivers.wrench.sim --port 4545 --link-ack --refuse 1:7,6 --trigger-every 2
    python -m drivers.wrench.sim --trigger-every 1 --result-types 1,1,3,2,9 --mislabel 1

The behaviour options (``add_behaviour_options``: result types, a mislabelled body, the
clock's offset) are shared with ``stationd sim controller``.  The trigger keeps being pulled
while no integrator is connected (a link cut): those results are kept for MID 0064.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from itertools import cycle
from types import FrameType
from typing import Any, TextIO

from drivers.errors import DriverError
from drivers.link import bind_words
from drivers.wrench.sim.controller import UNKNOWN_MID, SimController, parse_result_types


class ListenError(DriverError):
    """The simulator cannot listen on its port (in use, not allowed): each command says it
    in one line of its own words, exit 2 (``stationd sim controller``: ``stationd: error:
    cannot listen on 127.0.0.1:4545: the port is in use (another program, or another stationd,
    serves there)``)."""


def refusal(text: str) -> tuple[int, set[int]]:
    """``MID:REV[,REV...]`` -> (MID, revisions), e.g. ``1:7,6`` or ``60:7``."""
    mid, _, revs = text.partition(":")
    try:
        return int(mid), {int(r) for r in revs.split(",") if r}
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MID:REV[,REV...], not {text!r}") \
            from None


def result_types(text: str) -> list[int]:
    """``1,3,2`` -> [1, 3, 2]: result type codes (2 digits), pulled in turn."""
    try:
        return parse_result_types(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_behaviour_options(p: argparse.ArgumentParser) -> None:
    """The options of what the controller reports (here and in ``stationd sim
    controller``)."""
    p.add_argument("--result-types", type=result_types, default=[1], metavar="CODES",
                   help="result type of each trigger pull, in turn (MID 0061 revision 3+ "
                        "parameter 49: 1 tightening, 2 loosening, 3 batch increment, 4 batch "
                        "decrement, 5 bypass, 6 abort job, 7 synchronized, 8 reference "
                        "setup; others: unknown), e.g. 1,1,1,3 (default 1)")
    p.add_argument("--mislabel", type=int, choices=range(1, 8), metavar="REV",
                   help="claim more than it implements: results asked for above revision "
                        "REV are laid out as REV with fields appended, labelled as asked")
    p.add_argument("--clock-offset", type=float, default=0.0, metavar="SECONDS",
                   help="the controller's clock (MID 0081, result timestamps) this far from "
                        "the local one (0)")
    # the troubles the in-daemon sim://wrench URL takes (a new user's trial: only there)
    p.add_argument("--lose-push-every", type=_count, default=0, metavar="N",
                   help="lose every N-th result push (kept for MID 0064: found by a later "
                        "push's id or the station's check) (0: never)")
    p.add_argument("--garble-every", type=_count, default=0, metavar="N",
                   help="spoil every N-th result's body (a result that cannot be read) "
                        "(0: never)")
    p.add_argument("--no-old-results", action="store_true",
                   help="keep no results to give: refuse MID 0064 as an unknown MID (a push "
                        "lost is then lost)")


def _count(text: str) -> int:
    """A count of 0 or more (0: never)."""
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, not {text!r}")
    return n


def troubles_words(args: argparse.Namespace) -> str:
    """The troubles asked for, as the simulator's first line says them ("" for none): who
    starts it sees what it will do (a supervisor's trial: not named)."""
    said = ([f"1 push in {args.lose_push_every} lost"] if args.lose_push_every else []) \
        + ([f"1 result in {args.garble_every} unreadable"] if args.garble_every else []) \
        + (["no old results (MID 0064 refused)"] if args.no_old_results else [])
    return "; " + ", ".join(said) if said else ""


def behaviour(args: argparse.Namespace) -> dict[str, Any]:
    """SimController keywords from ``add_behaviour_options``' arguments."""
    return {"mislabel": args.mislabel, "clock_offset_s": args.clock_offset,
            "lose_push_every": args.lose_push_every, "garble_every": args.garble_every,
            "refused_mids": {64: UNKNOWN_MID} if args.no_old_results else None}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m drivers.wrench.sim",
                                description="A simulated Open Protocol tightening controller "
                                            "on TCP.")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (127.0.0.1)")
    p.add_argument("--port", type=int, default=4545, help="TCP port, 0 for any (4545)")
    p.add_argument("--seed", type=int, default=0, help="seed of the result scatter (0)")
    p.add_argument("--nok-rate", type=float, default=0.05, help="share of NOKs (0.05)")
    p.add_argument("--name", default="SimController", help="controller name in MID 0002")
    p.add_argument("--link-ack", action="store_true",
                   help="acknowledge at link level (MID 9997/9998) and say so in MID 0002")
    p.add_argument("--refuse", type=refusal, action="append", default=[],
                   metavar="MID:REVS", help="refuse these revisions of MID 1, 60 or 64 "
                                            "(repeatable), e.g. 1:7,6")
    p.add_argument("--refusal-code", type=int, default=97,
                   help="MID 0004 code for a refused revision (97; some controllers: 76)")
    p.add_argument("--no-curves", action="store_true",
                   help="give no tightening curves: refuse MID 0008 for MID 0900 (with MID "
                        "0004 --curves-refusal-code) as a controller without them")
    p.add_argument("--curves-refusal-code", type=int, default=78,
                   help="MID 0004 code refusing the curves' subscription (78; or 99)")
    p.add_argument("--curve-samples", type=int, default=240, metavar="N",
                   help="samples per trace (240); a trace past one message's 9999 bytes "
                        "(about 4900 samples) is sent in parts")
    p.add_argument("--part-size", type=int, default=9979, metavar="BYTES",
                   help="data bytes per part of a message sent in parts (9979, the most; "
                        "less sends shorter traces in parts too)")
    p.add_argument("--trigger-every", type=float, default=0.0, metavar="SECONDS",
                   help="pull the trigger at this interval when the tool may run (off)")
    add_behaviour_options(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    refused: dict[int, set[int]] = {}
    for mid, revs in args.refuse:
        refused.setdefault(mid, set()).update(revs)
    try:
        sim = SimController(seed=args.seed, nok_rate=args.nok_rate, name=args.name,
                            link_ack=args.link_ack, refused_revisions=refused,
                            revision_refusal_code=args.refusal_code,
                            curves=not args.no_curves,
                            curves_refusal_code=args.curves_refusal_code,
                            curve_samples=args.curve_samples, part_size=args.part_size,
                            **behaviour(args))
        return serve(sim, args.host, args.port, args.trigger_every, stop,
                     lambda port: f"listening on {args.host}:{port}{troubles_words(args)}",
                     types=args.result_types)
    except (ValueError, ListenError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


def serve(sim: SimController, host: str, port: int, trigger_every: float,
          stop: threading.Event, said: Callable[[int], str], out: TextIO = sys.stdout,
          types: Sequence[int] = (1,)) -> int:
    """Serve ``sim`` on ``host:port`` until ``stop`` (``said(port)`` printed once it listens),
    pulling the trigger every ``trigger_every`` seconds when set (a result of each of
    ``types`` in turn, whenever the tool may run, connected or not); :class:`ListenError`
    if it cannot listen."""
    kinds = cycle(types)
    kind = next(kinds)
    with sim:
        try:
            bound = sim.listen_tcp(host, port)
        except OSError as e:
            raise ListenError(f"cannot listen on {host}:{port}: {bind_words(e)}") from None
        print(said(bound), file=out, flush=True)
        while not stop.wait(trigger_every or 0.5):
            if trigger_every and sim.pull_trigger(kind) is not None:
                kind = next(kinds)
    return 0
