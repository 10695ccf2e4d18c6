"""Each pair's trust in real browsers (headless Chromium and Firefox): the operator screen's
devices panel and the cameras screen say which pair is trusted, which is not checked (why) and
which moved (its figure, red), from the events the pure core publishes for the calibration
check; a vehicle's arrival unchecks the pairs until its check answers."""

from __future__ import annotations

from typing import Any

from stationd.station.actions import Publish
from stationd.station.events import Because, StateChanged, StateReason, StationEvent
from stationd.station.inputs import Started
from stationd.station.trust import ReferencesChecked
from tests.station.test_trust import _core, _loaded, moved, ok
from tests.web.test_browser import check_fits

DEVICES = ("lift", "wrench", "pair1", "pair2")


def _published(acts: list[Any]) -> list[StationEvent]:
    return [a.event for a in acts if isinstance(a, Publish)]


def _li(page: Any, device: str, what: str) -> Any:
    return page.js(f"const e = document.querySelector('#devices li[data-device={device}]');"
                   f" return e && e.{what}")


def test_pairs_trust_on_the_devices_panel_and_the_cameras_screen(live_server, page, shots):
    srv = live_server(devices=DEVICES)
    core = _core()
    srv.publish([StateChanged("waiting for vehicle", StateReason(Because.WAITING_LIFT)),
                 *_published(core.feed(Started(1.0)))])
    page.get(srv.url)
    page.wait(lambda p: _li(p, "pair1", "textContent") == "pair1 not checked against the "
              "references: not checked since the start", what="pair1 not checked")
    assert _li(page, "pair1", "className") == "dev-wait"

    srv.publish(_published(core.feed(ReferencesChecked(2.0, (ok("pair1"),
                                                             moved("pair2", 3.4))))))
    page.wait(lambda p: _li(p, "pair2", "textContent")
              == "pair2 moved: reference R1 off by 3.4 mm (> 2 mm)", what="pair2 moved")
    assert _li(page, "pair2", "className") == "dev-bad"
    assert _li(page, "pair2", "dataset.trust") == "moved"
    assert _li(page, "pair1", "textContent") == "pair1: ok, trusted"
    assert "within 0.1 mm" in _li(page, "pair1", "title")
    # the moved pair is listed first, with the faulty; the station itself is not in fault
    order = page.js("return [...document.querySelectorAll('#devices li')]"
                    ".map(e => e.dataset.device)")
    assert order.index("pair2") < order.index("lift")
    assert page.js("return document.getElementById('headline').dataset.tone") != "stop"
    check_fits(page, "#devices")
    shots("operator-pair-moved")

    # a vehicle arrives: pair1 waits for its check, pair2 stays moved
    srv.publish(_published(_loaded(core, 10.0)))
    page.wait(lambda p: "checking for vehicle VIN1" in (_li(p, "pair1", "textContent") or ""),
              what="pair1 unchecked at the arrival")
    assert _li(page, "pair2", "dataset.trust") == "moved"

    page.get(srv.url + "cameras")
    section = "section.pair[data-pair=pair2]"
    page.wait(lambda p: p.text(f"{section} .pair-trust")
              == "pair2 moved: reference R1 off by 3.4 mm (> 2 mm)", what="cameras: moved")
    assert page.js(f"return document.querySelector('{section}').classList"
                   ".contains('pair-bad')")
    assert "checking for vehicle VIN1" in (page.text("section.pair[data-pair=pair1] "
                                                     ".pair-trust") or "")
    srv.publish(_published(core.feed(ReferencesChecked(12.0, (ok("pair1"), ok("pair2"))))))
    page.wait(lambda p: (p.text(f"{section} .pair-trust") or "").startswith("trusted ("),
              what="cameras: pair2 trusted again")
    assert not page.js(f"return document.querySelector('{section}').classList"
                       ".contains('pair-bad')")
    shots("cameras-pairs-trusted")
