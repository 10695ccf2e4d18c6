"""``stationd probe camera URL``: connect to one camera, trigger it, grab one frame.

The commissioning check for a camera: does it answer, which camera is it, what does it send
and when.  Exit 0 with a frame, 1 when the camera cannot be reached or no frame arrives in
time (one line on stderr), 2 for a bad URL or option (raised as UrlError / InputError, which
the CLI turns into one line and exit 2).  ``add_camera_probe`` is called by ``stationd.probe``
with its sub-parsers.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import sys
import time
from pathlib import Path
from typing import Any

from drivers.errors import DeviceError, UrlError
from stationd.errors import InputError
from stationd.jsonout import strict_json

EXIT_OK, EXIT_NO_FRAME = 0, 1


def add_camera_probe(psub: Any) -> None:
    """Add ``camera`` to the ``stationd probe`` sub-parsers."""
    from drivers.camera import FORMS

    p = psub.add_parser("camera", help="trigger one camera, grab a frame, show what came")
    p.add_argument("url", help=FORMS)
    p.add_argument("--save", metavar="FRAME.png", help="write the frame (.png, .jpg, ...)")
    p.add_argument("--timeout", type=float, default=5.0,
                   help="seconds to wait for the frame (default 5)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--config", metavar="STATION.yaml",
                   help="for a sim:// camera: the station whose simulated world it renders "
                        "(default: config/sim/station.yaml)")
    p.set_defaults(func=probe_camera)


def _check_options(args: argparse.Namespace) -> None:
    """Bad options fail before anything is opened."""
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        raise UrlError(f"--timeout {args.timeout:g}: must be > 0 seconds", device=args.url)
    if args.save:
        import cv2

        save = Path(args.save)
        if not cv2.haveImageWriter(str(save)):
            kind = save.suffix or "a name without extension"
            raise InputError(f"--save {save}: no image writer for {kind} (use .png, .jpg, "
                             ".bmp or .tif)")
        if not save.parent.is_dir():
            raise InputError(f"--save {save}: no such directory {save.parent}")
        from stationd.outfile import refuse_to_replace

        # never through a link, never over a file of another kind: only an earlier frame
        refuse_to_replace(save, "the frame", ("frame",), option="--save")


SIM_CONFIG = Path(__file__).resolve().parents[1] / "config" / "sim" / "station.yaml"


def _sim_world(url: str, config: str | None = None) -> Any:
    """For ``sim://PAIR/SIDE``: the simulated world of the station ``config`` (default
    config/sim), so the probe shows what that camera sees, as ``sim://lift`` starts its own
    PLC.  ``None`` for other URLs, or when a world for the pair is already registered (inside
    a running demo)."""
    from drivers.devices import world_view

    view = world_view(url)   # its driver says; a malformed sim:// URL is a UrlError: exit 2
    if view is None:
        return None
    from drivers.camera.sim import registered_worlds

    pair = view[0]
    if pair in registered_worlds():
        return None
    from stationd.config import load_station_config
    from stationd.sim.world import World

    path = Path(config) if config else SIM_CONFIG
    cfg = load_station_config(path)
    if pair not in cfg.pairs:   # the file named whole: a user's own station is not config/sim
        hint = "" if config else "; --config STATION.yaml for another station's"
        raise UrlError(f"no pair {pair!r} in the simulated station ({path.resolve()} has "
                       f"{', '.join(cfg.pairs)}{hint})", device=url)
    from stationd import progress

    progress.note(f"probe: rendering {url} through the simulated station {path.resolve()} "
                  "(a few seconds for 20 MP)")
    return World(cfg, seed=0)


def probe_camera(args: argparse.Namespace) -> int:
    _check_options(args)
    from stationd.probelock import locked

    world = _sim_world(args.url, args.config)
    try:
        with locked(args, "camera"):
            return _probe(args)
    finally:
        if world is not None:
            world.close()


def _save_frame(path: Path, image: Any) -> None:
    """The frame written whole (a temporary file renamed over it), a PNG stamped as this
    command's own so that the next probe may replace it (``outfile``'s rule)."""
    import cv2

    from stationd.outfile import FRAME_STAMP, PNG_MAGIC, stamp_png, write_atomic

    ok, buf = cv2.imencode(path.suffix, image)
    if not ok:
        raise InputError(f"--save {path}: the image could not be encoded")
    data = buf.tobytes()
    write_atomic(path, stamp_png(data, FRAME_STAMP) if data.startswith(PNG_MAGIC) else data)


def _probe(args: argparse.Namespace) -> int:
    from drivers.devices import Kind, open_device

    try:
        with open_device(Kind.CAMERA, args.url, timeout=args.timeout) as cam:
            identity = cam.identity()
            start = time.monotonic()
            cam.trigger()
            frame = cam.grab(args.timeout)
            latency = time.monotonic() - start
    except UrlError:
        raise  # bad input: exit 2 through the CLI's error path
    except DeviceError as exc:
        if args.json:
            sys.stdout.write(strict_json({"device": args.url, "kind": "camera", "ok": False,
                                         "error": str(exc)}) + "\n")
        sys.stderr.write(f"stationd: camera: {exc}\n")
        return EXIT_NO_FRAME
    saved = None
    if args.save:
        _save_frame(Path(args.save), frame.image)
        saved = args.save
    when = dt.datetime.fromtimestamp(frame.timestamp, dt.UTC).isoformat(timespec="milliseconds")
    out = {"device": args.url, "kind": "camera", "ok": True, "identity": identity,
           "width": frame.width, "height": frame.height, "pixel_format": frame.pixel_format,
           "frame_id": frame.frame_id, "timestamp": frame.timestamp, "time_utc": when,
           "latency_s": round(latency, 4), "saved": saved}
    if args.json:
        sys.stdout.write(strict_json(out) + "\n")
    else:
        print(identity)
        print(f"  frame {frame.frame_id}: {frame.width}x{frame.height} BGR from "
              f"{frame.pixel_format}, timestamp {when} ({frame.timestamp:.6f}), "
              f"{latency * 1000:.0f} ms after the trigger")
        if saved:
            print(f"  saved {saved}")
    return EXIT_OK
