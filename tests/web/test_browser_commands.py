"""Commands from the operator screen, in both real browsers, against the real daemon
(``station_proc.py``: its serve loop, its lift PLC over Modbus TCP and controller over Open
Protocol on loopback): a wrong password is refused, an operator logs in and skips a bolt (the
map shows it skipped and the station never selects it), a supervisor's reopen of the vehicle
at the station is refused with its reason, a log out ends the session."""

from __future__ import annotations

import pytest

from tests.shell.daemons import free_port, tracking
from tests.shell.test_commands_daemon import PASSWORD, _station
from tests.web.pages import Page
from tests.web.test_browser import check_fits

VIN = "SCREENVIN00000001"


def _login(page: Page, user: str, password: str) -> None:
    page.js("document.getElementById('login-user').value = arguments[0];"
            "document.getElementById('login-password').value = arguments[1];"
            "document.querySelector('#login button').click()", user, password)


def _signed_in(page: Page, user: str, password: str) -> None:
    """Log in and wait for the login's own answer: the screen can show the forms (the
    session asked again) before the login's answer comes, and that answer, arriving after
    the next command's, replaced it (seen under load)."""
    _login(page, user, password)
    page.wait(lambda p: p.text("#cmd-answer") == f"logged in as {user}", 30, "the login's answer")


def _shown(page: Page, element_id: str) -> bool:
    """Whether the element is drawn (its ``hidden`` attribute is not overridden by CSS)."""
    return bool(page.js("const e = document.getElementById(arguments[0]);"
                        " return getComputedStyle(e).display !== 'none'", element_id))


def _answer(page: Page, before: str) -> str:
    """The next answer the commands panel shows (it differs from ``before``)."""
    return str(page.wait(lambda p: (t := p.text("#cmd-answer")) and t != before and t, 30,
                         "the station's answer"))


@pytest.mark.timeout(300)
def test_operator_screen_logs_in_skips_a_bolt_and_shows_a_refusal(page, shots, tmp_path):
    http_port = free_port()
    with tracking(tmp_path, VIN, seed=7, edit=_station(http_port)) as (d, _, _):
        page.get(f"http://127.0.0.1:{http_port}/")
        page.wait(lambda p: p.text("#vin") == VIN, 60, "the vehicle on the screen")
        assert not _shown(page, "signed") and _shown(page, "login")

        _login(page, "olga", "not her password")
        assert "wrong user or password" in _answer(page, "")
        d.wait_log("login refused for user 'olga'")
        assert not _shown(page, "signed")

        _login(page, "olga", PASSWORD)
        page.wait(lambda p: (p.text("#who") or "").startswith("olga"), 30, "logged in")
        assert page.text("#who") == "olga (skip)"
        # her role may skip, not reopen: the screen offers only what she may do
        assert not _shown(page, "reopen") and not _shown(page, "login")
        assert _shown(page, "skip")
        page.wait(lambda p: p.js("return [...document.querySelectorAll('#skip-bolt option')]"
                                 ".map(o => o.value).includes('B05')"), 30, "B05 offered")
        shown = page.text("#cmd-answer") or ""
        page.js("document.getElementById('skip-bolt').value = 'B05';"
                "document.getElementById('skip-comment').value = 'bracket in the way';"
                "document.querySelector('#skip button').click()")
        got = _answer(page, shown)
        assert got.endswith(": accepted") and "skip B05" in got and "olga" in got
        # the comment was this command's: the form is empty for the next one
        assert page.js("return document.getElementById('skip-comment').value") == ""
        page.wait(lambda p: p.js("const g = document.querySelector("
                                 "'#bolts g.bolt[data-bolt=B05]'); return g && g.dataset.state")
                  == "skipped", 30, "B05 drawn skipped")
        d.wait_log("command skip B05 of SCREENVIN00000001 ('bracket in the way') by olga "
                   "(screen 127.0.0.1): accepted")
        (tmp_path / "pose").write_text("B05")
        d.wait_log("no bolt: B05 skipped: olga's command (bracket in the way)")
        assert "tightening bolt B05" not in d.log()
        check_fits(page, "#bolts", "#headline", "#commands")
        shots("operator-commands")

        # log out: the session is gone (a command now needs a login)
        page.click("#logout")
        page.wait(lambda p: _shown(p, "login") and not _shown(p, "signed"), 30,
                  "the login form back")
        assert page.js("return fetch('/api/me').then(r => r.json()).then(j => j.user)") \
            is None

        # a supervisor's reopen of the vehicle at the station: refused, with its reason
        _login(page, "sam", PASSWORD)
        page.wait(lambda p: (p.text("#who") or "").startswith("sam"), 30, "sam logged in")
        shown = page.text("#cmd-answer") or ""
        page.js("document.getElementById('reopen-vin').value = arguments[0];"
                "document.querySelector('#reopen button').click()", VIN)
        got = _answer(page, shown)
        assert got == f"refused: vehicle {VIN} is open at the station"
        assert page.js("return document.getElementById('cmd-answer').dataset.ok") == "0"
        # the session gone behind the screen's back (a daemon restarted has none): when the
        # screen is live again it asks, and offers the login, not the forms of a session
        # gone (a supervisor's trial: the first command typed after a restart was lost)
        page.js("return fetch('/api/logout', {method: 'POST', credentials: 'same-origin', "
                "headers: {'Content-Type': 'application/json'}, body: '{}'})"
                ".then(r => r.status)")
        assert _shown(page, "signed")
        page.js("window.dispatchEvent(new Event('station-live'))")
        page.wait(lambda p: _shown(p, "login") and not _shown(p, "signed"), 30,
                  "the login form back once live again")

        # the station gone (stopped as systemd stops it): a command, a log out say that
        # nothing reached it (an operator trial: the Release button then did nothing at all)
        _login(page, "sam", PASSWORD)
        page.wait(lambda p: (p.text("#who") or "").startswith("sam"), 30, "sam logged in")
        assert d.stop() == 0
        shown = page.text("#cmd-answer") or ""
        page.js("document.getElementById('reopen-vin').value = arguments[0];"
                "document.querySelector('#reopen button').click()", VIN)
        assert _answer(page, shown) == "no connection to the station: not sent"
        assert page.js("return document.getElementById('cmd-answer').dataset.ok") == "0"
        page.click("#logout")
        assert _answer(page, "no connection to the station: not sent") == \
            "no connection to the station: not logged out"
        assert _shown(page, "signed")       # the session is the station's: not ended here
