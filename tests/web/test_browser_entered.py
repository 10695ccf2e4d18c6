"""The operator screen's Enter outcome form, with the daemon over the real protocols: a bolt
held (its result could not be read) is in the Locked panel, which says a user with the release
right releases it or enters the outcome the controller shows; an operator is not offered the
form, a supervisor is, enters OK with torque, angle and a comment, and the bolt is drawn OK;
the vehicle's page says the rundown was entered and lists the result that could not be read."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.shell.daemons import free_port, tool_on, tracking, until
from tests.shell.test_commands_daemon import PASSWORD, _station
from tests.web.test_browser_commands import _answer, _login, _shown
from tests.web.test_browser_nok import _b05

VIN = "ENTERSCREENVIN001"


@contextmanager
def _b05_held(page: Any, tmp_path: Path) -> Iterator[tuple[Any, Any, Path, int, Any]]:
    """A daemon over the real protocols whose supervisor may release, its screen open, B05
    held (its result did not read): (the daemon, the controller, the pose file, the screens'
    port, the result made)."""
    http_port = free_port()
    pose = tmp_path / "pose"

    def edit(text: str) -> str:
        return _station(http_port)(text).replace("    supervisor: [skip, reopen]\n",
                                                 "    supervisor: [skip, reopen, release]\n")

    with tracking(tmp_path, VIN, edit=edit) as (d, _, ctl):
        page.get(f"http://127.0.0.1:{http_port}/")
        page.wait(lambda p: p.text("#vin") == VIN, 60, "the vehicle on the screen")
        tool_on(d, ctl, pose, "B05")
        ctl.garble_next_result("layout")
        bad = ctl.pull_trigger()
        assert bad is not None
        until(lambda: not ctl.tool_enabled, 30, "the tool off")
        pose.write_text("")
        page.wait(lambda p: _b05(p, "state") == "locked", 30, "B05 drawn held")
        yield d, ctl, pose, http_port, bad


@pytest.mark.timeout(300)
def test_a_supervisor_enters_the_outcome_of_a_held_bolt_on_the_screen(page, shots, tmp_path):
    with _b05_held(page, tmp_path) as (d, _ctl, _pose, http_port, bad):
        page.wait(lambda p: _shown(p, "locks"), 30, "the locked panel")
        # drawn held, not locked (its result not known; no lock of NOKs: a supervisor's trial)
        drawn = page.js("const g = document.querySelector('g.bolt[data-bolt=B05]');"
                        "return [g.getAttribute('class'), g.querySelector('text.icon')"
                        ".textContent]")
        assert drawn == ["bolt bolt-held", "?"], drawn
        assert page.text("#locks-title") == "Held"
        assert page.text("#release-by") == ("Enter the outcome the controller shows, or "
                                            "release to tighten again: a user with the "
                                            "release right (supervisor)")

        _login(page, "olga", PASSWORD)
        page.wait(lambda p: (p.text("#who") or "").startswith("olga"), 30, "olga logged in")
        assert not _shown(page, "enter") and not _shown(page, "release")
        page.click("#logout")
        page.wait(lambda p: _shown(p, "login"), 30, "logged out")
        _login(page, "sam", PASSWORD)
        page.wait(lambda p: (p.text("#who") or "").startswith("sam"), 30, "sam logged in")
        assert _shown(page, "enter")
        page.wait(lambda p: p.js("return [...document.querySelectorAll("
                                 "'#enter-bolt option')].map(o => o.value)") == ["", "B05"],
                  30, "B05 offered for an outcome")
        before = page.text("#cmd-answer") or ""
        page.js("document.getElementById('enter-bolt').value = 'B05';"
                "document.querySelector('#enter button').click()")   # no verdict yet
        got = _answer(page, before)
        assert got == "choose OK or NOK, as the controller shows it", got
        page.js("document.getElementById('enter-ok').value = 'ok';"
                "document.getElementById('enter-torque').value = '49.6';"
                "document.getElementById('enter-angle').value = '31';"
                "document.getElementById('enter-comment').value = 'read on the controller';"
                "document.querySelector('#enter button').click()")
        got = _answer(page, got)
        assert got.endswith(": accepted") and "enter-outcome B05" in got, got
        d.wait_log(f"command enter-outcome B05 of {VIN}: OK 49.6 Nm, 31.0 deg ('read on the "
                   "controller') by sam (screen 127.0.0.1): accepted")
        page.wait(lambda p: _b05(p, "state") == "ok", 30, "B05 drawn OK")
        page.wait(lambda p: not _shown(p, "locks"), 30, "the locked panel gone")
        shots("operator-outcome-entered")

        # the vehicle's page: the rundown entered says so, and the result that could not be
        # read is listed with its bolt's hold ended (a supervisor's trial: neither was shown)
        page.get(f"http://127.0.0.1:{http_port}/vehicles/{VIN}")
        page.wait(lambda p: p.count("tr.rundown[data-bolt=B05]") == 1, 30, "B05's rundown")
        status = page.js("return document.querySelector('tr.rundown[data-bolt=B05]')"
                         ".children[4].textContent")
        assert status == "OK, entered by sam, not measured", status
        page.wait(lambda p: p.count("#others tr.other") == 1, 30, "the unreadable result")
        other = page.js("return [...document.querySelector('#others tr.other').children]"
                        ".map(c => c.textContent)")
        # cut short before its tightening id (parameter 41): no id, its pset picked
        assert other[1:5] == ["could not be read", "-", str(bad.pset),
                              "B05 (held then, no longer)"], other
        assert other[5].startswith("MID 0061 revision 7: parameter 38"), other
        shots("vehicle-entered")


@pytest.mark.timeout(300)
def test_a_released_hold_is_drawn_check_first_and_its_selection_says_so(page, shots, tmp_path):
    """A supervisor releases a held bolt on the screen (its result not known): the operator's
    map draws it "check first", not "to do", and the wrench back on it reads, in amber, that
    it may be tightened already (a supervisor's trial: the operator tightened it twice)."""
    with _b05_held(page, tmp_path) as (d, ctl, pose, _, _made):
        _login(page, "sam", PASSWORD)
        page.wait(lambda p: _shown(p, "release"), 30, "the release form")
        page.wait(lambda p: p.js("return [...document.querySelectorAll("
                                 "'#release-bolt option')].map(o => o.value)") == ["", "B05"],
                  30, "B05 offered for release")
        before = page.text("#cmd-answer") or ""
        page.js("document.getElementById('release-bolt').value = 'B05';"
                "document.getElementById('release-comment').value = 'tighten again';"
                "document.querySelector('#release button').click()")
        got = _answer(page, before)
        assert "release B05" in got and "may be tightened already" in got, got
        page.wait(lambda p: _b05(p, "state") == "pending", 30, "B05 open again")
        drawn = page.js("const g = document.querySelector('g.bolt[data-bolt=B05]');"
                        "return [g.getAttribute('class'), g.querySelector('text.icon')"
                        ".textContent, g.querySelector('title').textContent]")
        assert drawn[:2] == ["bolt bolt-check", "\u26a0"], drawn
        assert "may be tightened already" in drawn[2], drawn
        assert _b05(page, "label") == "check first"
        # the wrench back on it: the tool goes on (the supervisor's decision), the operator
        # is told to check the controller first, in amber
        tool_on(d, ctl, pose, "B05")
        # (said already as the wrench settles on it; then its selection's headline)
        page.wait(lambda p: (p.text("#headline") or "").startswith("B05 (pset "), 30,
                  "B05 selected")
        assert "may be tightened already" in page.text("#headline")
        assert "act" in page.js("return document.getElementById('headline').className")
        shots("operator-check-first")
        # its own rundown ends it: drawn OK
        made = ctl.pull_trigger()
        assert made is not None and made.ok
        page.wait(lambda p: _b05(p, "state") == "ok", 30, "B05 drawn OK")
        assert page.js("return document.querySelector('g.bolt[data-bolt=B05]')"
                       ".getAttribute('class')") == "bolt bolt-ok"
