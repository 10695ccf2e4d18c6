"""Teach-in from the commissioning screen, in both real browsers, against the real daemon
(``station_proc.py``: its serve loop, its lift PLC over Modbus TCP and controller over Open
Protocol on loopback, the simulated cameras): an operator is not offered teaching; an engineer
logs in (the login shared with the operator screen, ``session.js``), a teach point before teach
mode is refused with the station's reason, teach mode starts for SIM-1, two bolts are taught
with the simulated wrench held on each, each is listed against the CAD table of the daemon's
database, teach mode stops and the taught table is downloaded: its positions are the truth
within the teach tolerance, the other bolts and every parameter as they were."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim.controller import SimController
from stationd.access import hash_password
from stationd.sim.devices_cli import psets_of
from stationd.station.teaching import TEACH_STEADY_MM
from tests.shell.daemons import SIM, Proc, at_height, free_port
from tests.test_teach_cli import PASSWORD, _station
from tests.web.pages import Page
from tests.web.test_browser_commands import _answer, _login, _shown

VIN = "TEACHSCREEN000001"


def _teach(page: Page, bolt: str) -> str:
    """Type ``bolt`` and press its Teach button; the station's answer."""
    shown = page.text("#cmd-answer") or ""
    page.js("const b = document.getElementById('teach-bolt'); b.value = arguments[0];"
            "b.dispatchEvent(new Event('input'));", bolt)
    assert page.text("#teach-point-go") == f"Teach {bolt}"
    page.click("#teach-point-go")
    return _answer(page, shown)


@pytest.mark.timeout(300)
def test_an_engineer_teaches_two_bolts_from_the_screen_and_downloads_the_table(
        page, shots, tmp_path):
    http_port, lift_port, ctl_port = free_port(), free_port(), free_port()
    plc = SimulatedPlc()
    ctl = SimController(psets_of(SIM / "bolts.yaml"), seed=5, nok_rate=0.0)
    d = Proc(tmp_path, lift_port, ctl_port, edit=_station(http_port, hash_password(PASSWORD)))
    pose = tmp_path / "pose"
    try:
        at_height(d, plc, ctl, lift_port, ctl_port, VIN)
        page.get(f"http://127.0.0.1:{http_port}/cameras")
        page.wait(lambda p: _shown(p, "login"), 30, "the login form")

        _login(page, "olga", PASSWORD)        # an operator: no teaching offered
        page.wait(lambda p: (p.text("#who") or "").startswith("olga"), 30, "olga logged in")
        assert not _shown(page, "teach-controls")
        page.click("#logout")
        page.wait(lambda p: _shown(p, "login"), 30, "logged out")

        _login(page, "ed", PASSWORD)
        page.wait(lambda p: _shown(p, "teach-controls"), 30, "the teach controls")
        got = _teach(page, "B01")             # not in teach mode yet: the station says so
        assert got.startswith("refused: ") and "teach" in got
        # the CAD table of the daemon's database is offered
        page.wait(lambda p: p.js("return [...document.querySelectorAll('#teach-models option')]"
                                 ".map(o => o.value).includes('SIM-1')"), 30, "SIM-1 offered")
        shown = page.text("#cmd-answer") or ""
        page.js("document.getElementById('teach-model').value = 'SIM-1';"
                "document.querySelector('#teach-start button').click()")
        assert _answer(page, shown).endswith(": accepted")
        page.wait(lambda p: (p.text("#teach-state") or "").startswith("teaching SIM-1 (ed)"),
                  30, "teach mode on the screen")
        page.wait(lambda p: p.js("return [...document.querySelectorAll('#teach-bolts option')]"
                                 ".map(o => o.value).includes('B02')"), 30, "B02 offered")
        for bolt in ("B01", "B02"):
            pose.write_text(bolt)             # the engineer holds the tool on the bolt
            d.wait_log("teaching SIM-1 (ed)")
            got = _teach(page, bolt)
            assert got.startswith(f"{bolt} taught: ") and "dispersion" in got, got
            page.wait(lambda p, b=bolt: p.count(f"#taught tr[data-bolt={b}]") == 1, 30,
                      f"{bolt} listed")
        pose.write_text("")
        rows = page.js("return [...document.querySelectorAll('#taught tr')].map("
                       "r => [...r.cells].map(c => c.innerText))")
        assert [r[0] for r in rows] == ["B01", "B02"]
        for r in rows:
            assert float(r[5]) < TEACH_STEADY_MM and r[6] == "ok", r    # near CAD, no flag
        shots("cameras-teach")

        shown = page.text("#cmd-answer") or ""
        page.click("#teach-stop")
        assert _answer(page, shown).endswith(": accepted")
        d.wait_log("teach mode ended")
        assert _shown(page, "teach-download")
        page.click("#teach-download")
        table = page.wait_download("bolts.taught.SIM-1.yaml", 30)
        assert "tightening bolt" not in d.log()
        assert d.stop() == 0
    finally:
        d.kill()
        ctl.close()
        plc.close()
    assert "Traceback" not in d.log()
    cad = {b["id"]: b for b in yaml.safe_load((tmp_path / "bolts.yaml").read_text())
           ["models"]["SIM-1"]["bolts"]}
    doc = yaml.safe_load(table.read_text())
    new = {b["id"]: b for b in doc["models"]["SIM-1"]["bolts"]}
    assert set(new) == set(cad)
    for bolt in ("B01", "B02"):      # the simulated world's bolts are where the CAD says
        moved = np.array(new[bolt]["position"]) - np.array(cad[bolt]["position"])
        assert np.hypot(*moved[:2]) < TEACH_STEADY_MM, (bolt, moved)
        assert new[bolt]["pset"] == cad[bolt]["pset"]
    assert all(new[b]["position"] == pytest.approx(cad[b]["position"], abs=0.05)
               and new[b].get("pset") == cad[b].get("pset") for b in cad
               if b not in ("B01", "B02"))
