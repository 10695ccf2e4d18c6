"""Fixtures of the screens' tests: a real server on a loop in a thread, and a page in each
real browser (headless Chromium through Selenium, headless Firefox through WebDriver BiDi:
``tests/web/pages.py``).

``--screenshots DIR`` saves each browser test's screens at 1920x1080 and 1280x800.
"""

from __future__ import annotations

import asyncio
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
from tests.web.pages import BROWSERS, Page, missing, open_page

SIZES = ((1920, 1080), (1280, 800))


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


def _browser(name: str, folder: Path) -> Iterator[Page]:
    """A page in browser ``name`` (its downloads in ``folder``) for as long as the fixture
    holds it; a browser that is not installed is a skip that names the package, never a
    silent pass."""
    why = missing(name)
    if why is not None:
        pytest.skip(why)
    p = open_page(name, folder)
    try:
        yield p
    finally:
        p.close()


@pytest.fixture(params=BROWSERS)
def page(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Page]:
    """The same test in headless Chromium and in headless Firefox, a fresh browser each."""
    yield from _browser(request.param, tmp_path)


@pytest.fixture(scope="module", params=BROWSERS)
def module_page(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
                ) -> Iterator[Page]:
    """One browser of each kind for a whole module (a browser's start is most of a short
    browser test's time, Firefox's ten seconds on a busy machine): for tests that each load
    their own server's page and need nothing an earlier test left (no login: cookies are
    shared across ports; one download of a name per module)."""
    yield from _browser(request.param, tmp_path_factory.mktemp(request.param))


@pytest.fixture
def reused_page(module_page: Page) -> Page:
    """The module's browser as a new one starts: the first size, a blank page (the last
    test's page no longer polls its stopped server).  A module uses it as its ``page``."""
    module_page.size(*SIZES[0])
    module_page.get("about:blank")
    return module_page


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
