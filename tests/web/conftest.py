"""Fixtures of the screens' tests: a real server on a loop in a thread, and a page in each
real browser (headless Chromium through Selenium, headless Firefox through WebDriver BiDi:
``tests/web/pages.py``).

``--screenshots DIR`` saves each browser test's screens at 1920x1080 and 1280x800.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pytest

from stationd.bus import EventBus
from stationd.station.events import StationEvent
from stationd.web.frames import LatestFrames
from stationd.web.server import WebServer
from tests.web.pages import BROWSERS, FIRST_SIZE, Page, missing, open_page

SIZES = (FIRST_SIZE, (1280, 800))


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--screenshots", metavar="DIR", default=None,
                     help="save the screens' screenshots (1920x1080 and 1280x800) to DIR")


class LiveServer:
    """A :class:`WebServer` on its own loop thread, as it runs in the daemon."""

    def __init__(self, **kw: Any) -> None:
        self.bus = EventBus()
        self.frames = LatestFrames()
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._thread.start()
        self.server = WebServer(self.bus, frames=self.frames, listen="127.0.0.1:0", **kw)
        self.call(self.server.start())

    def call(self, coro: Any) -> Any:
        fut: Future[Any] = asyncio.run_coroutine_threadsafe(coro, self.loop)
        return fut.result(timeout=30)

    def publish(self, events: list[StationEvent]) -> None:
        for e in events:
            self.bus.publish(e)

    @property
    def url(self) -> str:
        return self.server.url

    def close(self) -> None:
        self.call(self.server.stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(10)
        self.loop.close()


@pytest.fixture
def live_server() -> Iterator[Callable[..., LiveServer]]:
    made: list[LiveServer] = []

    def make(**kw: Any) -> LiveServer:
        made.append(LiveServer(**kw))
        return made[-1]
    yield make
    for s in made:
        s.close()


class Browsers:
    """This worker's browsers, one of each kind, started when a test first needs it and kept
    for the session (a browser's start was most of a short browser test's time: Chromium's
    three seconds, Firefox's six, each test again); each test gets it :meth:`Page.fresh`, as
    a new one would be.  One that cannot be made fresh (a test left it broken) is started
    again."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.open: dict[str, Page] = {}

    def page(self, name: str) -> Page:
        why = missing(name)
        if why is not None:      # a browser not installed is a skip naming the package,
            pytest.skip(why)     # never a silent pass
        p = self.open.get(name)
        if p is not None:
            try:
                p.fresh()
                return p
            except Exception:         # left broken by the last test: a new one
                self._drop(name)
        folder = self.folder / name
        folder.mkdir(exist_ok=True)
        p = self.open[name] = open_page(name, folder)
        p.fresh()
        return p

    def _drop(self, name: str) -> None:
        p = self.open.pop(name)
        with contextlib.suppress(Exception):   # a browser that died may not close cleanly
            p.close()

    def close(self) -> None:
        for name in list(self.open):
            self._drop(name)


@pytest.fixture(scope="session")
def browsers(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Browsers]:
    b = Browsers(tmp_path_factory.mktemp("browsers"))
    yield b
    b.close()


@pytest.fixture(params=BROWSERS)
def page(request: pytest.FixtureRequest, browsers: Browsers) -> Page:
    """The same test in headless Chromium and in headless Firefox, each as a new browser is:
    no cookie (nobody signed in), nothing cached, a blank page at the first size, an empty
    downloads folder (:meth:`Page.fresh`)."""
    return browsers.page(str(request.param))


@pytest.fixture
def shots(request: pytest.FixtureRequest, page: Page) -> Callable[[str], None]:
    """``shots(name)``: with --screenshots DIR, the current page at both sizes, per browser."""
    out = request.config.getoption("--screenshots")

    def take(name: str) -> None:
        if not out:
            return
        Path(out).mkdir(parents=True, exist_ok=True)
        for w, h in SIZES:
            page.size(w, h)
            page.screenshot(Path(out) / f"{name}-{page.name}-{w}x{h}.png")
        page.size(*SIZES[0])
    return take
