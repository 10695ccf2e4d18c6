"""The station's screens: operator guidance (``/``), commissioning (``/cameras``) and results
(``/vehicles``), served by the daemon on its own asyncio loop; read-only.

Wiring (the daemon, ``stationd demo``)::

    from stationd.web import HttpConfig, LatestFrames, Results, WebServer, check_http
    frames = LatestFrames()      # the grab loop: frames.put(pair, side, img, summary)
    web = WebServer(station.bus, Results(repo), frames,
                    listen=cfg.http.listen, token=cfg.http.token, images_dir=records_dir)
    await web.start(); print("screens:", web.url)
    ...
    await web.stop()

``HttpConfig.from_node(node)`` reads the station file's ``http: {listen, token}`` section;
``open_bind_problem(cfg)`` is the config checker's test (a non-local bind without a token).
``stationd.web.status_cli.format_status`` gives ``stationd status`` its lines.
``stationd.web.bench.fanout_bench`` measures the live fan-out with two clients.

Importing this package is cheap (``stationd status`` imports its CLI module): the server and
its dependencies (aiohttp, OpenCV) load on first use of a name below.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

_WHERE = {"HttpConfig": "config", "check_http": "config", "open_bind_problem": "config",
          "LatestFrames": "frames", "Results": "results", "WebServer": "server"}
__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module 'stationd.web' has no attribute {name!r}")
    return getattr(import_module(f"stationd.web.{_WHERE[name]}"), name)
