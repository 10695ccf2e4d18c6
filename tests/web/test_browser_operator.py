"""The operator signed in at the station, on the operator screen in both real browsers against
the real daemon (``station_proc.py``: its serve loop, its lift PLC over Modbus TCP and
controller over Open Protocol on loopback), with ``access.operator_required``: the header says
nobody is signed in and the wrench on a bolt reads "sign in to tighten"; a logged-in operator
signs in at the station from the Commands panel (the header names her), the bolt is tightened
and the vehicle's page shows her with the rundown; she signs out."""

from __future__ import annotations

import pytest

from tests.shell.daemons import free_port, tracking, until
from tests.shell.test_commands_daemon import PASSWORD, _station
from tests.web.test_browser_commands import _answer, _login, _shown

VIN = "SIGNINVIN00000001"


@pytest.mark.timeout(300)
def test_an_operator_signs_in_at_the_station_from_the_screen_and_her_rundown_shows_her(
        page, shots, tmp_path):
    http_port = free_port()

    def edit(text: str) -> str:
        return str(_station(http_port)(text)) + "  operator_required: true\n"

    url = f"http://127.0.0.1:{http_port}/"
    with tracking(tmp_path, VIN, seed=9, edit=edit) as (d, _, ctl):
        page.get(url)
        page.wait(lambda p: p.text("#vin") == VIN, 60, "the vehicle on the screen")
        page.wait(lambda p: p.text("#operator") == "nobody signed in: sign in to tighten",
                  30, "nobody signed in, in the header")
        (tmp_path / "pose").write_text("B05")
        page.wait(lambda p: (p.text("#headline") or "").startswith("sign in to tighten"), 30,
                  "the refusal in large words")
        assert page.js("return document.getElementById('headline').dataset.tone") == "act"

        _login(page, "olga", PASSWORD)
        page.wait(lambda p: (p.text("#who") or "").startswith("olga"), 30, "logged in")
        assert _shown(page, "sign-in") and not _shown(page, "sign-out")
        shown = page.text("#cmd-answer") or ""
        page.click("#sign-in")
        got = _answer(page, shown)
        assert got.startswith("command sign-in by olga") and got.endswith(": accepted")
        page.wait(lambda p: p.text("#operator") == "operator: olga", 30, "olga in the header")
        page.wait(lambda p: _shown(p, "sign-out") and not _shown(p, "sign-in"), 30,
                  "sign-out offered")
        d.wait_log("tightening: tightening bolt B05")
        until(lambda: ctl.tool_enabled, 30, "tool enabled")
        shot = ctl.pull_trigger()
        assert shot is not None and shot.ok
        until(lambda: shot.tightening_id in ctl.acked_ids, 30, "result stored")
        (tmp_path / "pose").write_text("")
        shots("operator-signed-in")

        page.get(f"{url}vehicles/{VIN}")
        page.wait(lambda p: p.js("return [...document.querySelectorAll("
                                 "'#rundowns tr.rundown[data-bolt=B05] td.operator')]"
                                 ".map(t => t.textContent).join()") == "olga", 30,
                  "the rundown's operator on the vehicle's page")

        page.get(url)
        page.wait(lambda p: _shown(p, "sign-out"), 30, "sign-out offered again")
        shown = page.text("#cmd-answer") or ""
        page.click("#sign-out")
        assert _answer(page, shown).endswith(": accepted")
        page.wait(lambda p: p.text("#operator") == "nobody signed in: sign in to tighten",
                  30, "nobody signed in again")
