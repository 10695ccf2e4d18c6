"""Screens that agree with the headline (issue 19 item 7), in real browsers at 1920x1080 and
1280x800: one bolt pointed out "next" when the table has no order, labels that cannot be
confused in the 50-bolt map's clusters, no crosshair for a wrench out of view, a devices
panel that fits in a fault with the Commands in view, a start-up headline that says the
station is starting.  One browser per module (each test its own server): a browser's start
is most of a browser test's time."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from stationd.reasons import Reason, Why
from stationd.station.events import (
    Because,
    BoltLocked,
    BoltsChanged,
    DeviceHealth,
    Localized,
    Refused,
    ResultRecorded,
    State,
    StateChanged,
    StateReason,
    StationEvent,
)
from tests.web.conftest import SIZES
from tests.web.mapgeo import confusable, map_geometry
from tests.web.pages import Page
from tests.web.scenario import sim_vehicle, told
from tests.web.test_browser import label_overlaps
from tests.web.test_browser_fixes import bolt_states, ok, redrawn

PAIRS = tuple(f"pair{k}" for k in range(1, 9))
DEVICES = ("lift", "wrench", *PAIRS)
VEHICLE = sim_vehicle()
EVERY = tuple(b.bolt for b in VEHICLE.bolts)
POSITION = {b.bolt: (b.x_mm, b.y_mm) for b in VEHICLE.bolts}
SHORT = (1280, 657)   # a real 1280x800 window's viewport
CLUSTER = ("B17", "B49", "B21", "B25")      # the newcomer's: "B21" read as B25's
NOT_SEEN = Reason(Why.NOT_LOCALIZED, per_pair=tuple(
    (p, side, "no purple region enclosing a ring in view") for p in PAIRS[:4]
    for side in ("left", "right")))


@pytest.fixture
def shots(request: pytest.FixtureRequest, page: Page) -> Callable[[str], None]:
    out = request.config.getoption("--screenshots")

    def take(name: str) -> None:
        if out:
            Path(out).mkdir(parents=True, exist_ok=True)
            for w, h in (*SIZES, SHORT):
                page.size(w, h)
                page.screenshot(Path(out) / f"{name}-{page.name}-{w}x{h}.png")
        page.size(*SIZES[0])
    return take


@pytest.fixture
def screen(live_server: Callable[..., Any], page: Page) -> Callable[..., Any]:
    """``screen(events)``: a server with the 8-pair station's devices and ``events``, the
    operator screen open on it at 1920x1080."""
    def show(events: list[StationEvent]) -> Any:
        srv = live_server(devices=DEVICES)
        srv.publish(events)
        page.size(*SIZES[0])
        page.get(srv.url)
        return srv
    return show


def at(bolt: str, dx: float = 0.0, dy: float = 0.0, allowed: tuple[str, ...] = EVERY
       ) -> Localized:
    x, y = POSITION[bolt]
    return Localized(point_mm=(x + dx, y + dy, 0.0), tilt_deg=1.0, reason=None,
                     candidate=bolt, distance_mm=float(np.hypot(dx, dy)), age_ms=30.0,
                     allowed=allowed)


def lost(reason: Reason) -> Localized:
    return Localized(point_mm=None, tilt_deg=None, reason=reason, candidate=None,
                     distance_mm=None, age_ms=30.0, allowed=EVERY)


def tracking() -> list[StationEvent]:
    return [StateChanged(state=State.TRACKING, reason=StateReason(Because.TRACKING)), VEHICLE]


def nexts(page: Page) -> list[str]:
    return sorted(b for b, s in bolt_states(page).items() if s == "next")


# -- one "next" ------------------------------------------------------------------------------
def test_without_an_order_one_bolt_is_pointed_out_next(screen, page, shots):
    """Every open bolt is allowed (config/sim's table has no order): one is "next", the
    nearest to the wrench, the others "to do"; out of view it stays; its label says next."""
    srv = screen([*tracking(), lost(NOT_SEEN)])
    page.wait(lambda p: len(bolt_states(p)) == 50, what="50 bolts")
    page.wait(lambda p: nexts(p) == ["B01"], what="the table's first open bolt next")
    srv.publish([at("B25", 3.0, -2.0)])
    page.wait(lambda p: nexts(p) == ["B25"], what="the bolt nearest the wrench next")
    assert set(bolt_states(page).values()) == {"next", "pending"}
    for w, h in SIZES:
        page.size(w, h)
        page.wait(redrawn, what=f"redrawn at {w}x{h}")
        tag = page.js("return document.querySelector('#bolts g.bolt[data-bolt=B25] text.tag')"
                      "?.textContent")
        assert tag == "next", f"{page.name} at {w}x{h}"
    shots("agree-one-next")
    srv.publish([at("B03", -1.0, 1.0)])
    page.wait(lambda p: nexts(p) == ["B03"], what="the pointer follows the wrench")
    srv.publish([lost(NOT_SEEN), Refused(reason=NOT_SEEN)])
    page.wait(lambda p: p.count("#wrench-mark") == 0, what="no crosshair out of view")
    assert nexts(page) == ["B03"]          # out of view: the pointer stays


def test_a_nok_bolt_s_label_shows_the_value_that_failed(screen, page):
    """An operator trial read "B11 NOK 50.8" for a NOK whose torque was within its window and
    whose angle was 0 deg: an angle NOK shows its angle, a torque NOK its torque."""
    def nok(bolt: str, tid: int, torque: float, angle: float) -> list[StationEvent]:
        return told(ResultRecorded(vin=VEHICLE.vin, bolt=bolt, ok=False, torque_nm=torque,
                                   angle_deg=angle, tightening_id=tid, pset=1,
                                   torque_min=22.0, torque_max=28.0, angle_min=10.0,
                                   angle_max=60.0), VEHICLE)

    def tag(p: Page, bolt: str) -> str | None:
        got = p.js("return document.querySelector(`#bolts g.bolt[data-bolt=${arguments[0]}] "
                   "text.tag`)?.textContent", bolt)
        return None if got is None else str(got)

    screen([*tracking(), *nok("B25", 1, 25.3, 0.0), *nok("B03", 2, 19.4, 30.0)])
    page.wait(lambda p: tag(p, "B25") == "NOK 0\u00b0", what="B25's angle on its label")
    page.wait(lambda p: tag(p, "B03") == "NOK 19.4", what="B03's torque on its label")


def test_a_held_bolt_says_held_on_the_50_bolt_map(screen, page):
    """A new user's trial: on the 50-bolt map a locked bolt said "locked" under its name, a
    held one only its icon."""
    b17 = next(b for b in VEHICLE.bolts if b.bolt == "B17")
    screen([*tracking(), BoltsChanged(VEHICLE.vin, (replace(b17, held="tightening 9"),)),
            BoltLocked("B17", 0, held="tightening 9")])
    page.wait(lambda p: p.js("return document.querySelector('#bolts g.bolt[data-bolt=B17] "
                             "text.tag')?.textContent") == "held", what="B17's label: held")


# -- labels in a cluster ---------------------------------------------------------------------
@pytest.mark.parametrize("state", ["no order", "all to do"])
def test_cluster_labels_cannot_be_confused_on_the_50_bolt_map(screen, page, shots, state):
    """At both sizes every shown label is nearest its own dot (box edge and centre), or is
    joined to it by a leader line that passes no other dot; no two labels overlap; the
    B17/B49/B21/B25 cluster is labelled."""
    events = [*tracking(), at("B25", 3.0, -2.0)] if state == "no order" else tracking()
    screen(events)
    page.wait(lambda p: len(bolt_states(p)) == 50, what="50 bolts")
    if state == "no order":
        page.wait(lambda p: nexts(p) == ["B25"], what="B25 next")
    for w, h in (*SIZES, SHORT):
        page.size(w, h)
        page.wait(redrawn, what=f"redrawn at {w}x{h}")
        geo = map_geometry(page)
        where = f"{page.name} at {w}x{h} ({state})"
        assert confusable(geo) == [], where
        assert label_overlaps(page) == [], where
        assert set(CLUSTER) <= set(geo["labels"]), where
        assert len(geo["labels"]) >= 45, f"{where}: {len(geo['labels'])} of 50 labelled"
    if state == "no order":
        page.size(1280, 800)
        shots("agree-cluster-labels")


# -- the wrench ------------------------------------------------------------------------------
def test_a_wrench_out_of_view_has_no_crosshair_and_the_panel_says_the_headlines_reason(
        screen, page, shots):
    srv = screen([*tracking(), at("B47", 1.0, 1.0)])
    page.wait(lambda p: p.count("#wrench-mark") == 1, what="the crosshair")
    assert (page.text("#wrench") or "").endswith("near B47 (1.4 mm)")
    srv.publish([lost(NOT_SEEN), Refused(reason=NOT_SEEN)])
    page.wait(lambda p: p.text("#headline") == "Bring the wrench to a bolt", what="neutral")
    assert page.count("#wrench-mark") == 0
    assert page.text("#wrench") == "not in view (details: Cameras)"
    shots("agree-wrench-out-of-view")
    # seen but tilted: the panel gives the headline's reason, not "not in view"
    tilted = Reason(Why.TILTED, angle_deg=41.4, limit=10.0)
    srv.publish([lost(tilted), Refused(reason=tilted)])
    said = "wrench tilted 41.4 deg (> 10 deg)"
    page.wait(lambda p: p.text("#headline") == said, what="tilted headline")
    assert page.text("#wrench") == f"seen, not used: {said}"
    assert page.count("#wrench-mark") == 0
    srv.publish([at("B47", 0.5, 0.0)])
    page.wait(lambda p: p.count("#wrench-mark") == 1, what="the crosshair back")


# -- the devices panel in a fault ------------------------------------------------------------
def pair_reason(p: str) -> str:
    return (f"left camera sim://{p}/left: no simulated world for pair '{p}' (none "
            f"registered); the world must call drivers.camera.sim.register_world('{p}', "
            f"source) first; right camera sim://{p}/right: no simulated world for pair "
            f"'{p}' (none registered); the world must call drivers.camera.sim."
            f"register_world('{p}', source) first")


def faults(reason: Callable[[str], str]) -> list[StationEvent]:
    return [*(DeviceHealth(device=p, ok=False, kind="down", reason=reason(p)) for p in PAIRS),
            StateChanged(state=State.FAULT, reason=StateReason(
                Because.FAULT, faults=tuple((p, reason(p)) for p in PAIRS)))]


PANEL_JS = """
    const vh = window.innerHeight, c = document.getElementById('commands')
        .getBoundingClientRect(), login = document.getElementById('login')
        .getBoundingClientRect();
    const rows = [...document.querySelectorAll('#devices li')].map(li => {
        const r = li.getBoundingClientRect();
        return [li.dataset.device, r.height, parseFloat(getComputedStyle(li).lineHeight)
                || parseFloat(getComputedStyle(li).fontSize) * 1.2, li.textContent, li.title];
    });
    return {vh, commands: [c.top, c.bottom], login: [login.top, login.bottom], rows};"""


def check_panel(page: Page, where: str) -> dict[str, Any]:
    got: dict[str, Any] = page.js(PANEL_JS)
    vh = got["vh"]
    assert 0 <= got["commands"][0] and got["login"][1] <= vh, f"{where}: Commands out: {got}"
    for name, height, line, _, _ in got["rows"]:
        assert height <= 1.5 * line, f"{where}: {name} takes {height / line:.1f} lines"
    return got


def test_pair_faults_fit_the_devices_panel_with_the_commands_in_view(screen, page, shots):
    """Eight pairs down for one cause: one line with the count, each pair's whole reason on
    hover; eight different long reasons: one line each, cut, the whole on a click; at both
    sizes the Commands panel stays in the window."""
    # a vehicle half done (the last results take their room), then the pairs go down
    srv = screen([*tracking(), *(ok(b, k) for k, b in enumerate(EVERY[:6])),
                  *faults(pair_reason)])
    page.wait(lambda p: p.count("#devices li[data-count]") == 1, what="one grouped line")
    for w, h in (*SIZES, SHORT):
        page.size(w, h)
        got = check_panel(page, f"{page.name} at {w}x{h}, alike")
        (row,) = [r for r in got["rows"] if r[0] == "pair1"]
        assert row[3].startswith("pair1-8 (8 devices) down: left camera sim://pair1/left")
        assert all(pair_reason(p) in row[4] for p in PAIRS)     # each one whole, on hover
    shots("agree-faults-alike")

    def own(p: str) -> str:   # a reason of its own per pair: one line each
        return (f"left camera gige://192.168.10.{20 + int(p[4:])}/?exposure_us=800&gain_db=0.0"
                f"&trigger=software&packet_size=9000: no frames for 3.0 s (cable, power or "
                f"the camera's IP configuration)")
    srv.publish(faults(own))
    # eight lines once seven reasons differ: wait for the eighth pair's own reason too
    page.wait(lambda p: p.count("#devices li.dev-bad") == 8
              and "192.168.10.28" in (p.text("#devices") or ""), what="eight lines, each own")
    for w, h in (*SIZES, SHORT):
        page.size(w, h)
        got = check_panel(page, f"{page.name} at {w}x{h}, different")
        for name, _, _, text, title in got["rows"]:
            if name in PAIRS:
                assert text == f"{name} down: {own(name)}" and title == text
    page.size(1280, 800)
    page.click("#devices li[data-device=pair3]")
    (row,) = [r for r in page.js(PANEL_JS)["rows"] if r[0] == "pair3"]
    assert row[1] > 1.5 * row[2], "a click shows the whole reason"
    page.click("#devices li[data-device=pair3]")
    check_panel(page, f"{page.name} closed again")
    shots("agree-faults-different")


# -- start-up --------------------------------------------------------------------------------
def test_the_start_up_headline_says_starting_not_stale(screen, page):
    stale = Reason(Why.STALE, age_ms=7524.0, limit=500.0)
    first = Localized(point_mm=(1200.0, -300.0, 0.0), tilt_deg=1.0, reason=stale,
                      candidate=None, distance_mm=None, age_ms=7524.0, allowed=EVERY, t=100.0)
    srv = screen([StateChanged(state=State.STARTING, reason=StateReason(Because.OPENING)),
                  *tracking(), first, Refused(reason=stale, t=100.0)])
    page.wait(lambda p: (p.text("#headline") or "").startswith("Starting"), what="starting")
    assert page.text("#headline") == "Starting: the cameras' first frames are late (7524 ms old)"
    assert page.js("return document.getElementById('headline').dataset.tone") == "idle"
    # fresh frames came: a stale localization after them is the stale alarm
    again = Reason(Why.STALE, age_ms=812.0, limit=500.0)
    srv.publish([at("B25", 40.0, 0.0), Refused(reason=NOT_SEEN),
                 Localized(point_mm=(1200.0, -300.0, 0.0), tilt_deg=1.0, reason=again,
                           candidate=None, distance_mm=None, age_ms=812.0, allowed=EVERY),
                 Refused(reason=again)])
    page.wait(lambda p: p.text("#headline") == ("camera frames too old (812 ms): the cameras "
                                               "or the station's computer fall behind"),
              what="the stale alarm")
    assert page.js("return document.getElementById('headline').dataset.tone") == "act"
