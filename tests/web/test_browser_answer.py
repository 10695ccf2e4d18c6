"""The Commands panel's answer, in both real browsers: seen where the command was given.

Why: a supervisor's trial at 1280x800 and on a 1024x768 tablet, signed in with two bolts
locked: the panel's forms reach below the window, so the answer line under them (accepted,
or refused with its reason) was out of sight; the Release button gave no visible feedback
and the lock leaving the Locked panel was the only sign the release was taken.  The panel
did not scroll in its own box as meant (its tiny shrink factor took only 5 % of the room it
had to give up): the whole page scrolled, and an answer brought into view took the headline
and the top of the bolt map out of the window."""

from __future__ import annotations

from typing import Any

import pytest

from stationd.access import AccessConfig, hash_password
from stationd.station.commands import Answer, Command, Issuer
from stationd.yamlio import YamlNode
from tests.web.pages import Page
from tests.web.scenario import VIN, held, locked, opened, work
from tests.web.test_browser_commands import _answer, _shown, _signed_in

PASSWORD = "pw-of-sue-1234"  # noqa: S105 - a test user's


def _page_fits(page: Page) -> bool:
    """No vertical scroll of the page, and the headline in the window."""
    return bool(page.js("""
        const h = document.getElementById('headline').getBoundingClientRect();
        return document.documentElement.scrollHeight <= window.innerHeight + 1 &&
               h.top >= 0 && h.bottom <= window.innerHeight;"""))


def _in_view(page: Page, element_id: str) -> list[float]:
    """The element's box clipped by the window and each scrolling box it is in: its visible
    height against its own (all of it in view: the two equal)."""
    return list(page.js("""
        const e = document.getElementById(arguments[0]), r = e.getBoundingClientRect();
        let top = Math.max(r.top, 0), bottom = Math.min(r.bottom, window.innerHeight);
        for (let p = e.parentElement; p; p = p.parentElement) {
          const s = getComputedStyle(p);
          if (!/(auto|scroll|hidden)/.test(s.overflowY)) continue;
          const b = p.getBoundingClientRect();
          top = Math.max(top, b.top); bottom = Math.min(bottom, b.bottom);
        }
        return [Math.max(0, bottom - top), r.height];""", element_id))


def _accepting(live_server: Any) -> Any:
    """A screens' server whose supervisor sue signs in and whose every command the station
    accepts (the station's rules are not these tests' subject)."""
    srv = live_server(devices=("lift", "wrench", "pair1"))
    srv.server.commands.access = AccessConfig.from_node(YamlNode.parse(
        f"users:\n  sue: {{role: supervisor, password: '{hash_password(PASSWORD)}'}}\n",
        "station.yaml"))

    async def submit(command: Command, issuer: Issuer) -> Answer:
        return Answer(1, command, issuer)
    srv.server.commands.submit = submit
    return srv


@pytest.mark.parametrize("size", [(1280, 800), (1024, 768)])
def test_a_commands_answer_is_in_view_on_a_small_screen(live_server, page, size: Any) -> None:
    srv = _accepting(live_server)
    srv.publish([*opened(), *work(), *locked("B2", 3), *locked("B4", 3)])
    page.size(*size)
    page.get(srv.url)
    page.wait(lambda p: p.text("#vin") == VIN, what="the vehicle on the screen")
    _signed_in(page, "sue", PASSWORD)
    page.wait(lambda p: (p.text("#who") or "").startswith("sue"), 30, "sue logged in")
    page.wait(lambda p: _shown(p, "release"), 30, "the Release form")
    page.wait(lambda p: p.js("return [...document.querySelectorAll('#release-bolt option')]"
                             ".map(o => o.value).includes('B2')"), 30, "B2 offered")
    page.js("window.scrollTo(0, 0)")
    assert _page_fits(page), f"{page.name} at {size}: the page scrolls"

    # a refusal on the screen itself (no bolt chosen), then the station's acceptance
    shown = page.text("#cmd-answer") or ""
    page.click("#release button")
    assert _answer(page, shown) == "choose the locked bolt to release"
    seen, height = _in_view(page, "cmd-answer")
    assert height > 0 and seen >= height - 1, f"{page.name} at {size}: {seen} of {height} px"
    assert _page_fits(page), f"{page.name} at {size}: the headline out of the window"

    page.js("window.scrollTo(0, 0); document.querySelector('.side .commands').scrollTop = 0;"
            "document.getElementById('release-bolt').value = 'B2';"
            "document.getElementById('release-comment').value = 'joint checked'")
    page.click("#release button")
    got = _answer(page, "choose the locked bolt to release")
    assert "accepted" in got or got.startswith("command"), got
    seen, height = _in_view(page, "cmd-answer")
    assert height > 0 and seen >= height - 1, f"{page.name} at {size}: {seen} of {height} px"
    assert _page_fits(page), f"{page.name} at {size}: the headline out of the window"


def test_an_entered_outcome_leaves_no_value_for_the_next_hold(live_server, page) -> None:
    """A supervisor's trial: after an outcome was entered (NOK, 40 N·m, 20 deg) the form kept
    NOK and both values, only the comment emptied; the next held bolt, another tightening,
    was one click and a comment away from being given the last one's outcome."""
    srv = _accepting(live_server)
    srv.publish([*opened(), *held("B2", "the controller's result could not be read")])
    page.get(srv.url)
    page.wait(lambda p: p.text("#vin") == VIN, what="the vehicle on the screen")
    _signed_in(page, "sue", PASSWORD)
    page.wait(lambda p: _shown(p, "enter"), 30, "the Enter outcome form")
    page.wait(lambda p: p.js("return [...document.querySelectorAll('#enter-bolt option')]"
                             ".map(o => o.value).includes('B2')"), 30, "B2 offered")
    shown = page.text("#cmd-answer") or ""
    page.js("const v = (id, x) => { document.getElementById(id).value = x; };"
            "v('enter-bolt', 'B2'); v('enter-ok', 'nok'); v('enter-torque', '40');"
            "v('enter-angle', '20'); v('enter-comment', 'controller shows NOK');"
            "document.querySelector('#enter button').click()")
    assert _answer(page, shown).startswith("command"), page.text("#cmd-answer")
    left = page.js("return ['enter-ok', 'enter-torque', 'enter-angle', 'enter-comment']"
                   ".map(id => document.getElementById(id).value)")
    assert left == ["", "", "", ""], left


def test_a_reopen_without_a_vin_is_answered_in_the_panel(live_server, page) -> None:
    """A supervisor's trial: Reopen for rework with the VIN left empty said nothing in the
    panel (the browser's own bubble, where it shows one, beside the field), and the answer
    line went on showing the last command's answer, read as this one's."""
    srv = live_server(devices=("lift", "wrench", "pair1"))
    srv.server.commands.access = AccessConfig.from_node(YamlNode.parse(
        f"users:\n  sue: {{role: supervisor, password: '{hash_password(PASSWORD)}'}}\n",
        "station.yaml"))
    srv.publish(opened())
    page.get(srv.url)
    page.wait(lambda p: p.text("#vin") == VIN, what="the vehicle on the screen")
    _signed_in(page, "sue", PASSWORD)
    page.wait(lambda p: _shown(p, "reopen"), 30, "the Reopen form")
    page.click("#loosen button")
    assert _answer(page, "logged in as sue") == "choose the bolt to loosen"
    page.click("#reopen button")
    assert _answer(page, "choose the bolt to loosen") == "type the VIN of the vehicle to reopen"
    assert page.js("return document.getElementById('cmd-answer').dataset.ok") == "0"
