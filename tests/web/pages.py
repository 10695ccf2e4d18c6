"""One small page-driving interface over two real browsers, so that the screens' tests run the
same assertions in Chromium and in Firefox.

* Chromium: Debian's ``chromium`` and ``chromium-driver`` through Selenium (WebDriver).
* Firefox: Debian's ``firefox-esr`` through its built-in WebDriver BiDi endpoint
  (``--remote-debugging-port``), spoken here over one websocket (``websocket-client``, which
  Selenium already depends on).  There is no geckodriver in Debian and npm's geckodriver
  downloads from GitHub, so Selenium cannot start Firefox on a station or CI machine; BiDi is
  the W3C protocol Firefox ships natively, needs no extra binary, and the few commands the
  tests use (navigate, evaluate, viewport, screenshot) are stable parts of the standard.

Everything a test asks of a page goes through JavaScript (``js``): the DOM is the same in both
browsers, so one query is one assertion in both.
"""

from __future__ import annotations

import base64
import json
import queue
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
FIREFOX = shutil.which("firefox-esr") or shutil.which("firefox")
BROWSERS = ("chromium", "firefox")


#: the viewport a browser starts with (a panel PC's 1280x800 is the screenshots' second)
FIRST_SIZE = (1920, 1080)


class PageTimeoutError(AssertionError):
    """A condition the page never reached: the test fails with what was last seen."""


class Page:
    """A browser tab: ``get(url)``, ``js(body, *args)`` (a function body, ``arguments`` are
    the args, ``return`` gives a JSON-like value), ``size(w, h)`` (the viewport),
    ``screenshot(path)``; ``downloads`` is where a clicked download lands."""

    name = "?"
    downloads: Path

    def get(self, url: str) -> None:
        raise NotImplementedError

    def js(self, body: str, *args: Any) -> Any:
        raise NotImplementedError

    def size(self, width: int, height: int) -> None:
        raise NotImplementedError

    def screenshot(self, path: Path) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def forget(self) -> None:
        """Forget every cookie (a sign-in is a cookie of 127.0.0.1, which every port shares)
        and, where the browser lets one, its cached responses."""
        raise NotImplementedError

    def fresh(self) -> None:
        """The browser as a newly started one is for a test: a blank page (the last test's
        page no longer polls its stopped server), no cookie, no cached response to reuse
        unasked (Chromium's cache emptied; the screens' responses are no-cache or no-store),
        the first size, an empty downloads folder (the screens keep nothing in the
        browser's storage).  Raises when the browser does not answer."""
        self.get("about:blank")
        self.forget()
        for f in self.downloads.iterdir():
            f.unlink()
        self.size(*FIRST_SIZE)

    # -- built on js() -----------------------------------------------------------------------
    def wait(self, cond: Callable[[Page], Any], timeout: float = 15.0, what: str = "") -> Any:
        """Poll ``cond(page)`` until it is truthy (its value is returned); no fixed sleeps in
        the tests, only this bounded wait for the page to catch up with the station."""
        end = time.monotonic() + timeout
        last: Any = None
        while True:
            try:
                last = cond(self)
            except Exception as exc:   # the page is being redrawn: try again
                last = exc
            else:
                if last:
                    return last
            if time.monotonic() > end:
                raise PageTimeoutError(f"{self.name}: {what or 'condition'} not reached in "
                                  f"{timeout:.0f} s; last: {last!r}")
            time.sleep(0.05)

    def text(self, css: str) -> str | None:
        """The element's rendered text (``innerText``), None when there is none."""
        got = self.js("const e = document.querySelector(arguments[0]);"
                      " return e ? e.innerText : null", css)
        return None if got is None else str(got)

    def count(self, css: str) -> int:
        return int(self.js("return document.querySelectorAll(arguments[0]).length", css))

    def click(self, css: str) -> None:
        self.js("document.querySelector(arguments[0]).click()", css)

    def wait_download(self, name: str, timeout: float = 15.0) -> Path:
        """The downloaded file once complete (no partial file beside it)."""
        target = self.downloads / name

        def done(_: Page) -> bool:
            parts = [p for p in self.downloads.iterdir()
                     if p.suffix in (".part", ".crdownload")]
            return target.exists() and target.stat().st_size > 0 and not parts
        self.wait(done, timeout, f"download of {name}")
        return target


class ChromiumPage(Page):
    """Headless Chromium through Selenium and chromedriver."""

    name = "chromium"

    def __init__(self, tmp: Path) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        assert CHROMIUM is not None and CHROMEDRIVER is not None
        opts = webdriver.ChromeOptions()
        opts.binary_location = CHROMIUM
        for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage",
                  f"--user-data-dir={tmp / 'chromium-profile'}", "--window-size=1920,1080",
                  "--hide-scrollbars"):
            opts.add_argument(a)
        self.downloads = tmp / "downloads"
        self.downloads.mkdir(exist_ok=True)
        opts.add_experimental_option("prefs", {"download.default_directory": str(self.downloads),
                                               "download.prompt_for_download": False})
        self.driver = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER))
        self.driver.execute_cdp_cmd("Browser.setDownloadBehavior",
                                    {"behavior": "allow", "downloadPath": str(self.downloads)})

    def get(self, url: str) -> None:
        self.driver.get(url)

    def js(self, body: str, *args: Any) -> Any:
        return self.driver.execute_script(body, *args)

    def size(self, width: int, height: int) -> None:
        # the viewport, exactly (a headless window's outer size is not the page's)
        self.driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                                    {"width": width, "height": height,
                                     "deviceScaleFactor": 1, "mobile": False})
        self.driver.execute_script("window.dispatchEvent(new Event('resize'))")

    def screenshot(self, path: Path) -> None:
        self.driver.save_screenshot(str(path))

    def close(self) -> None:
        self.driver.quit()

    def forget(self) -> None:
        self.driver.execute_cdp_cmd("Network.clearBrowserCookies", {})
        self.driver.execute_cdp_cmd("Network.clearBrowserCache", {})


FIREFOX_PREFS = {
    # downloads land in the test's folder without a dialog
    "browser.download.folderList": 2,
    "browser.download.useDownloadDir": True,
    "browser.download.always_ask_before_handling_new_types": False,
    "browser.helperApps.neverAsk.saveToDisk": "text/csv,application/json",
    "browser.download.start_downloads_in_tmp_dir": False,
    # an offline machine: no update checks, telemetry or remote settings in the way
    "app.update.enabled": False, "app.update.auto": False,
    "datareporting.policy.dataSubmissionEnabled": False,
    "toolkit.telemetry.enabled": False, "browser.shell.checkDefaultBrowser": False,
    "browser.startup.homepage_override.mstone": "ignore",
    "services.settings.server": "http://127.0.0.1:9/",
    "network.captive-portal-service.enabled": False,
    "browser.aboutwelcome.enabled": False,
}


class FirefoxPage(Page):
    """Headless Firefox ESR through its native WebDriver BiDi websocket."""

    name = "firefox"

    def __init__(self, tmp: Path, width: int = 1920, height: int = 1080) -> None:
        import websocket

        assert FIREFOX is not None
        profile = tmp / "firefox-profile"
        profile.mkdir(exist_ok=True)
        self.downloads = tmp / "downloads"
        self.downloads.mkdir(exist_ok=True)
        prefs = {**FIREFOX_PREFS, "browser.download.dir": str(self.downloads)}
        (profile / "user.js").write_text("".join(f"user_pref({json.dumps(k)}, {json.dumps(v)});\n"
                                                 for k, v in prefs.items()))
        self.log = (tmp / "firefox.log").open("w+")
        self.proc = subprocess.Popen(
            [FIREFOX, "--headless", "--no-remote", "--profile", str(profile),
             "--remote-debugging-port", "0", f"--width={width}", f"--height={height}",
             "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        url = self._endpoint()
        # Firefox refuses a websocket with an Origin header it does not allow: send none
        self.ws = websocket.create_connection(url + "/session", timeout=60, suppress_origin=True)
        self._id = 0
        self.cmd("session.new", {"capabilities": {"alwaysMatch": {"acceptInsecureCerts": True}}})
        tree = self.cmd("browsingContext.getTree", {})
        self.context = tree["contexts"][0]["context"]
        self.size(width, height)

    def _endpoint(self, timeout: float = 60.0) -> str:
        """The ``ws://`` address Firefox prints on stderr once it listens (port 0: its own
        choice, so parallel tests never collide); its other output goes to firefox.log."""
        lines: queue.Queue[str] = queue.Queue()
        stderr = self.proc.stderr
        assert stderr is not None

        def pump() -> None:
            for line in stderr:
                try:
                    self.log.write(line)
                    self.log.flush()
                except ValueError:   # closed by close(): Firefox's last words are not kept
                    return
                lines.put(line)
        threading.Thread(target=pump, daemon=True).start()
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = lines.get(timeout=0.5)
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            if "WebDriver BiDi listening on " in line:
                return line.split("listening on ", 1)[1].strip()
        self.close()
        self.log.seek(0)
        raise RuntimeError("firefox did not open its WebDriver BiDi port: "
                           f"{self.log.read()[-2000:]}")

    def cmd(self, method: str, params: dict[str, Any]) -> Any:
        """One BiDi command; events that arrive meanwhile are not subscribed to, so the next
        message with our id is the answer."""
        self._id += 1
        self.ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") != self._id:
                continue
            if msg.get("type") == "error" or "error" in msg:
                raise RuntimeError(f"{method}: {msg.get('error')}: {msg.get('message')}")
            return msg["result"]

    def get(self, url: str) -> None:
        self.cmd("browsingContext.navigate", {"context": self.context, "url": url,
                                               "wait": "complete"})

    def js(self, body: str, *args: Any) -> Any:
        r = self.cmd("script.callFunction", {
            "functionDeclaration": f"function() {{ {body} }}", "awaitPromise": True,
            "target": {"context": self.context}, "arguments": [_local(a) for a in args],
            "resultOwnership": "none"})
        if r.get("type") == "exception":
            d = r["exceptionDetails"]
            raise RuntimeError(f"page script: {d.get('text')}")
        return _remote(r["result"])

    def size(self, width: int, height: int) -> None:
        self.cmd("browsingContext.setViewport", {"context": self.context,
                                                  "viewport": {"width": width,
                                                               "height": height}})
        self.js("window.dispatchEvent(new Event('resize'))")

    def screenshot(self, path: Path) -> None:
        data = self.cmd("browsingContext.captureScreenshot", {"context": self.context})["data"]
        path.write_bytes(base64.b64decode(data))

    def forget(self) -> None:
        # the cookies of every site; Firefox keeps no cache between the tests' pages (the
        # screens' responses are no-cache or no-store)
        self.cmd("storage.deleteCookies", {})

    def close(self) -> None:
        try:
            if getattr(self, "ws", None) is not None:
                try:   # briefly: Firefox may close the socket without an answer
                    self.ws.settimeout(2)
                    self.cmd("session.end", {})
                except Exception:  # noqa: S110 - Firefox may close the socket first
                    pass
                self.ws.close()
        finally:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
            self.log.close()


def _local(v: Any) -> dict[str, Any]:
    """A Python value as a BiDi LocalValue (the few kinds the tests pass)."""
    if v is None:
        return {"type": "null"}
    if isinstance(v, bool):
        return {"type": "boolean", "value": v}
    if isinstance(v, int | float):
        return {"type": "number", "value": v}
    if isinstance(v, str):
        return {"type": "string", "value": v}
    if isinstance(v, list | tuple):
        return {"type": "array", "value": [_local(x) for x in v]}
    raise TypeError(f"cannot pass {type(v).__name__} to the page")


def _remote(r: dict[str, Any]) -> Any:
    """A BiDi RemoteValue as the Python value Selenium would give (nodes as None: the tests
    read DOM state through values, not handles)."""
    t = r.get("type")
    if t in ("undefined", "null"):
        return None
    if t in ("string", "boolean"):
        return r["value"]
    if t == "number":
        v = r["value"]
        return float(v) if isinstance(v, str) else v     # "NaN", "Infinity", "-0"
    if t in ("array", "set", "nodelist", "htmlcollection"):
        return [_remote(x) for x in r.get("value", [])]
    if t in ("object", "map"):
        return {(k if isinstance(k, str) else str(_remote(k))): _remote(v)
                for k, v in r.get("value", [])}
    return None


def open_page(name: str, tmp: Path) -> Page:
    if name == "chromium":
        return ChromiumPage(tmp)
    if name == "firefox":
        return FirefoxPage(tmp)
    raise ValueError(name)


def missing(name: str) -> str | None:
    """Why ``name`` cannot run here (the skip reason), None when it can."""
    if name == "chromium" and (CHROMIUM is None or CHROMEDRIVER is None):
        return ("chromium and chromium-driver are not installed (as root: apt-get install "
                "chromium chromium-driver, see .ci/bootstrap)")
    if name == "firefox" and FIREFOX is None:
        return ("firefox-esr is not installed (as root: apt-get install firefox-esr, see "
                ".ci/bootstrap)")
    return None
