"""Fixtures of the screens' tests: a real server on a loop in a thread, and headless Chromium
driven by Selenium (Debian's ``chromium`` and ``chromium-driver``).

``--screenshots DIR`` saves each browser test's screens at 1920x1080 and 1280x800.
"""

from __future__ import annotations

import asyncio
import shutil
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pytest

from stationd.station.events import EventBus, StationEvent
from stationd.web.frames import LatestFrames
from stationd.web.server import WebServer

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
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


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Any]:
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("chromium and chromium-driver are not installed "
                    "(as root: apt-get install chromium chromium-driver, see .ci/bootstrap)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
              "--disable-background-networking", "--disable-component-update",
              "--disable-sync", "--disable-dev-shm-usage", f"--user-data-dir={tmp_path / 'p'}",
              "--window-size=1920,1080", "--hide-scrollbars"):
        opts.add_argument(a)
    downloads = tmp_path / "downloads"
    downloads.mkdir()
    opts.add_experimental_option("prefs", {"download.default_directory": str(downloads),
                                           "download.prompt_for_download": False})
    drv = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER))
    drv.execute_cdp_cmd("Browser.setDownloadBehavior",
                        {"behavior": "allow", "downloadPath": str(downloads)})
    drv.downloads = downloads  # type: ignore[attr-defined]  # where the test finds files
    try:
        yield drv
    finally:
        drv.quit()


@pytest.fixture
def shots(request: pytest.FixtureRequest, browser: Any) -> Callable[[str], None]:
    """``shots(name)``: with --screenshots DIR, the current page at both sizes."""
    out = request.config.getoption("--screenshots")

    def take(name: str) -> None:
        if not out:
            return
        Path(out).mkdir(parents=True, exist_ok=True)
        for w, h in SIZES:
            browser.set_window_size(w, h)
            browser.execute_script("window.dispatchEvent(new Event('resize'))")
            browser.save_screenshot(str(Path(out) / f"{name}-{w}x{h}.png"))
        browser.set_window_size(*SIZES[0])
    return take
