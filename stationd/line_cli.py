"""``stationd line status|quarantine``: the store-and-forward to the line database, from the
station's own files (the daemon need not run).

    stationd line status --config STATION.yaml            # backlog, lag, quarantine
    stationd line quarantine --config STATION.yaml [--retry] [--export FILE.json]

Why on the station's side: the quarantine (records the line database refused for good) lives
in the station's database; a quality engineer retries it after the line database was fixed,
or exports it to hand over.  Exit 0: nothing waits; 1: a backlog or a quarantine remains;
2: bad input; 3: the line database cannot be reached (``--retry``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from db.repository import Repository
from stationd.config import load_station_config
from stationd.errors import InputError
from stationd.forward import Forwarder, LineDown
from stationd.outfile import write_atomic

EXIT_WAITING, EXIT_UNREACHABLE = 1, 3


def _forwarder(args: argparse.Namespace) -> Forwarder:
    cfg = load_station_config(args.config)
    if cfg.line is None:
        raise InputError(f"{args.config}: no line section: nothing is forwarded")
    return Forwarder(Repository.open(cfg.database_url), cfg.line)


def cmd_line_status(args: argparse.Namespace) -> int:
    fwd = _forwarder(args)
    try:
        st = fwd.status()
    finally:
        fwd.repo.close()
    if args.json:
        print(json.dumps(st))
    else:
        print(f"line database {st['url']} as station {st['station_id']} "
              f"(local database {st['db_id']})")
        print(f"forwarded up to record {st['cursor']} of {st['last_seq']}: {st['backlog']} "
              f"waiting ({st['backlog_bytes'] / 1e6:.2f} MB), the oldest for "
              f"{st['lag_s']:.0f} s; {st['quarantined']} quarantined")
        if st["alarm"]:
            print(f"ALARM: {st['alarm']}")
    return EXIT_WAITING if st["backlog"] or st["quarantined"] else 0


def cmd_line_quarantine(args: argparse.Namespace) -> int:
    fwd = _forwarder(args)
    try:
        if args.export:
            out = Path(args.export)
            if out.exists() or out.is_symlink():
                raise InputError(f"--export {out}: exists (a new file is written)")
            rows: list[dict[str, Any]] = fwd.repo.ledger.quarantined()
            write_atomic(out, json.dumps(rows, indent=1))
            print(f"{len(rows)} quarantined record(s) written to {out}")
        if args.retry:
            try:
                taken, refused = fwd.retry_quarantined()
            except LineDown as exc:
                sys.stderr.write(f"stationd: line database unreachable: {exc}\n")
                return EXIT_UNREACHABLE
            finally:
                fwd.line.dispose()
            print(f"retried: {taken} taken by the line database, {refused} still refused")
        left = fwd.repo.ledger.quarantined()
    finally:
        fwd.repo.close()
    if not args.export and not args.retry:
        for q in left:
            print(f"record {q['seq']} ({q['kind']}, {q['at']}): {q['reason']}")
    return EXIT_WAITING if left else 0


def add_line_parser(sub: Any) -> None:
    ln = sub.add_parser("line", help="the store-and-forward to the line database")
    lsub = ln.add_subparsers(dest="line_command", required=True)
    st = lsub.add_parser("status", help="backlog, lag and quarantine of the forwarding")
    st.add_argument("--config", required=True, metavar="STATION.yaml")
    st.add_argument("--json", action="store_true", help="print one JSON object")
    st.set_defaults(func=cmd_line_status)
    q = lsub.add_parser("quarantine", help="records the line database refused for good: "
                        "list, --retry, --export")
    q.add_argument("--config", required=True, metavar="STATION.yaml")
    q.add_argument("--retry", action="store_true", help="push them to the line database again")
    q.add_argument("--export", metavar="FILE.json", help="write them to a new JSON file")
    q.set_defaults(func=cmd_line_quarantine)


__all__ = ["add_line_parser", "cmd_line_quarantine", "cmd_line_status"]
