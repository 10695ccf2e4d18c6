"""``stationd calibrate check --config STATION.yaml``: check every pair against the station's
reference markers now, with the cameras opened here.

Why only while the daemon is not running: the cameras and the records are the daemon's (one
process per station, its lock beside the database: :mod:`stationd.lock`); a second process
grabbing from them would steal frames from the vision loop, and a pair it found moved would
not stop the daemon using it.  While the daemon runs, the check on demand is its own (the
``calibration-check`` command, right ``calibrate``): it measures, records and, for a moved
pair, refuses that pair's bolts.  Here, the lock is taken for the check, each pair is grabbed
once and checked (:func:`stationd.localize.check.check_pair`), one line per pair is printed,
and each check is recorded in the station's database (it joins the results feed).

Exit codes: 0 every pair in place, 1 a pair moved or not checked, 2 bad input (no
``references:`` in the file, the daemon running, a camera that does not open).
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime
from typing import Any

from stationd.errors import InputError
from stationd.jsonout import strict_json

EXIT_OK, EXIT_NOT_OK = 0, 1


def _grab(cfg: Any, name: str) -> tuple[Any, Any] | str:
    """One stereo grab of pair ``name`` (its two cameras opened and closed here), or why not."""
    from drivers.camera import open_camera
    from drivers.camera.pair import StereoGrabber
    from drivers.errors import DriverError

    pc = cfg.pairs[name]
    if pc.left is None or pc.right is None:
        return "the pair names no cameras"
    cams: list[Any] = []
    try:
        for cam in (pc.left, pc.right):
            cams.append(open_camera(cfg.cameras[cam]))
        left, right = StereoGrabber(cams[0], cams[1], pc.max_skew_s, name=name).grab(5.0)
        return left.image, right.image
    except (DriverError, OSError, ValueError) as exc:
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return text
    finally:
        for c in cams:
            try:
                c.close()
            except (DriverError, OSError):
                pass


def cmd_calibrate_check(args: argparse.Namespace) -> int:
    """Check each pair that sees a reference; print, record, exit 0 only if all are in place."""
    from db.checks import record_check
    from db.repository import Repository
    from stationd.config import load_station_config
    from stationd.localize.check import Verdict, check_pair, not_checked
    from stationd.lock import LockHeldError, StationLock, lock_path
    from stationd.station.trust import reason_of, summary
    from stationd.words import reason_words

    cfg = load_station_config(args.config, station=True)
    refs = cfg.references
    if refs is None:
        raise InputError(f"{args.config}: no references: section: no calibration check "
                         "configured (every pair is trusted)")
    path = lock_path(cfg.database_url, cfg.records.images_dir)
    lock = StationLock(path) if path is not None else None
    if lock is not None:
        try:
            lock.acquire()
        except LockHeldError as exc:
            raise InputError(f"the station's daemon is running (pid {exc.pid}): it owns the "
                             "cameras; ask it for a check (the calibration-check command, "
                             "right calibrate) instead") from None
    try:
        results = []
        for name in refs.pairs:
            pc = cfg.pairs[name]
            got = _grab(cfg, name)
            if isinstance(got, str):
                results.append(not_checked(name, refs.tolerance_mm, got))
                continue
            results.append(check_pair(name, pc.calibration, pc.to_vehicle, got[0], got[1],
                                      refs.of(name), tolerance_mm=refs.tolerance_mm,
                                      search_mm=refs.exclusion_mm, vision=cfg.vision,
                                      marker=cfg.marker, lift_at_height=args.lift_at_height))
        at = datetime.now(UTC)
        repo = Repository.open(cfg.database_url)
        try:
            for c in results:
                why = None if c.why is None else c.why.value + (f": {c.note}" if c.note else "")
                record_check(repo, at=at, pair=c.pair, verdict=c.verdict.value,
                             reference=c.reference, offset_mm=c.offset_mm,
                             tolerance_mm=c.tolerance_mm, reason=why,
                             references=summary(c)["references"])
        finally:
            repo.close()
    finally:
        if lock is not None:
            lock.release()
    if args.json:
        print(strict_json({c.pair: summary(c) for c in results}))
    else:
        for c in results:
            said = reason_of(c)
            print(reason_words(said) if said is not None else
                  f"{c.pair} in place: reference {c.reference} off by {c.offset_mm:.2f} mm "
                  f"(<= {c.tolerance_mm:g} mm)")
    ok = all(c.verdict is Verdict.OK for c in results)
    if not ok:
        sys.stderr.write("stationd: calibrate check: a pair is moved or not checked\n")
    return EXIT_OK if ok else EXIT_NOT_OK


def add_check_parser(csub: Any) -> None:
    """Add ``check`` to the ``calibrate`` sub-parsers."""
    k = csub.add_parser(
        "check", help="check every pair against the reference markers (daemon stopped)",
        description="Grabs each pair that sees a reference marker once, measures the "
                    "references where they should be and prints per pair: in place, moved "
                    "(the worst reference and its offset), or not checked (why). Each check "
                    "is recorded in the station's database. Only while the daemon is not "
                    "running (it holds the cameras: ask it with the calibration-check "
                    "command). Exit 0 all in place, 1 a pair moved or not checked, 2 bad "
                    "input.")
    k.add_argument("--config", required=True, metavar="STATION.yaml",
                   help="the station file (its references: section)")
    k.add_argument("--lift-at-height", action="store_true",
                   help="the lift is at working height: measure the references on it too")
    k.add_argument("--json", action="store_true", help="print the checks as one JSON object")
    k.set_defaults(func=cmd_calibrate_check)


__all__ = ["add_check_parser", "cmd_calibrate_check"]
