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
``stationd.web.status_cli.add_status_parser(subparsers)`` adds ``stationd status [--url]``.
``stationd.web.bench.fanout_bench`` measures the live fan-out with two clients.
"""

from stationd.web.config import HttpConfig, check_http, open_bind_problem
from stationd.web.frames import LatestFrames
from stationd.web.results import Results
from stationd.web.server import WebServer

__all__ = ["HttpConfig", "LatestFrames", "Results", "WebServer", "check_http",
           "open_bind_problem"]
