"""The screens' fixes from a newcomer's trial, in both browsers: a closed vehicle's missing
bolts, the bolt map's labels and size on a short panel, a screen that lost the station, the
cameras screen's faults, old frames and crop, the favicon and an unknown VIN."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from stationd.station.events import (
    Because,
    BoltSelected,
    DeviceHealth,
    Localized,
    ResultRecorded,
    StateChanged,
    StateReason,
    StationEvent,
    VehicleClosed,
)
from stationd.web.server import WebServer
from tests.web.mapgeo import confusable, map_geometry
from tests.web.pages import Page
from tests.web.scenario import LIFT_LOW, VIN, fault_state, opened, sim_vehicle, told, work
from tests.web.test_browser import label_overlaps

SIM_VIN = "SIMVIN0000000001"
SHORT = ((1280, 800), (1280, 657))   # a panel PC; a real 1280x800 window's viewport


def bolt_states(page: Page) -> dict[str, str]:
    """Bolt -> state (a dense map shows no state words beside most bolts)."""
    got = page.js("return [...document.querySelectorAll('#bolts g.bolt')]"
                  ".map(g => [g.dataset.bolt, g.dataset.state])")
    return dict(got)


def nok(bolt: str) -> list[StationEvent]:
    """A NOK of ``bolt`` of the simulated vehicle: the core's change, then the result."""
    return told(ResultRecorded(vin=SIM_VIN, bolt=bolt, ok=False, torque_nm=18.0,
                               angle_deg=20.0, tightening_id=7, pset=1, torque_min=22.0,
                               torque_max=28.0, angle_min=10.0, angle_max=60.0), sim_vehicle())


def ok(bolt: str, tid: int) -> list[StationEvent]:
    """An OK of ``bolt`` of the simulated vehicle: the core's change, then the result."""
    return told(ResultRecorded(vin=SIM_VIN, bolt=bolt, ok=True, torque_nm=25.0,
                               angle_deg=30.0, tightening_id=tid, pset=1, torque_min=22.0,
                               torque_max=28.0, angle_min=10.0, angle_max=60.0), sim_vehicle())


def redrawn(page: Page) -> bool:
    return bool(page.js(
        "const b = document.getElementById('map').getBoundingClientRect();"
        " return document.getElementById('bolts').getAttribute('viewBox') ==="
        " `0 0 ${Math.max(200, b.width)} ${Math.max(150, b.height)}`"
        " && document.querySelectorAll('#bolts g.lbl').length === 50"))


def misread_labels(geo: dict[str, Any]) -> list[str]:
    """Each shown label an operator could read as another bolt's (``tests.web.mapgeo``)."""
    return confusable(geo)


def overlapping_dots(geo: dict[str, Any]) -> list[str]:
    items = list(geo["dots"].items())
    return [f"{a}/{b}" for i, (a, (ax, ay, ar)) in enumerate(items)
            for b, (bx, by, br) in items[i + 1:] if np.hypot(ax - bx, ay - by) < ar + br]


def test_bolt_map_labels_read_as_their_own_bolt_and_the_map_keeps_its_size(live_server, page,
                                                                            shots):
    srv = live_server(devices=("lift", "wrench", "pair1", "pair2", "pair3", "pair4"))
    allowed = ("B05", "B06", "B07", "B20", "B36")
    srv.publish([StateChanged(state="tracking", reason=StateReason(Because.TRACKING)),
                 sim_vehicle(), *nok("B04"), *nok("B13"),
                 Localized(point_mm=(0.0, 0.0, 0.0), tilt_deg=1.0, reason=None, candidate="B41",
                           distance_mm=1.0, age_ms=30.0, allowed=allowed),
                 BoltSelected(bolt="B41", pset=1, point_mm=(0.0, 0.0, 0.0), distance_mm=1.0,
                              tilt_deg=1.0)])
    page.get(srv.url)
    page.wait(lambda p: bolt_states(p).get("B41") == "selected", what="B41 selected")
    for w, h in (*SHORT, (1920, 1080)):
        page.size(w, h)
        page.wait(redrawn, what=f"map redrawn at {w}x{h}")
        geo = map_geometry(page)
        assert misread_labels(geo) == [], f"{page.name} at {w}x{h}"
        assert overlapping_dots(geo) == [], f"{page.name} at {w}x{h}"
        assert label_overlaps(page) == [], f"{page.name} at {w}x{h}"
        assert min(r for _, _, r in geo["dots"].values()) >= 6
        # the bolts that matter are labelled first: both NOK, the selected one
        assert {"B04", "B13", "B41"} <= set(geo["labels"]), f"{page.name} at {w}x{h}"
        mw, mh = geo["map"]
        assert mw >= 700 and mh >= 300, f"{page.name} at {w}x{h}: map {mw:.0f}x{mh:.0f}"
        shown = len(geo["labels"])
        assert shown >= 20, f"{page.name} at {w}x{h}: only {shown} of 50 labels shown"
    page.size(1280, 657)
    shots("fixes-map-selected-nok")


def test_a_closed_incomplete_vehicle_is_an_alarm_with_missing_bolts(live_server, page, shots):
    srv = live_server(devices=("lift", "wrench", "pair1", "pair2", "pair3", "pair4"))
    names = [f"B{k:02d}" for k in range(1, 51)]
    done = [b for b in names[:12] if b != "B04"]
    missing = tuple(b for b in names if b not in done and b != "B04")
    srv.publish([StateChanged(state="tracking", reason=StateReason(Because.TRACKING)),
                 sim_vehicle(),
                 *(e for i, b in enumerate(done) for e in ok(b, i)), *nok("B04"),
                 Localized(point_mm=(0.0, 0.0, 0.0), tilt_deg=1.0, reason=None, candidate=None,
                           distance_mm=None, age_ms=30.0, allowed=missing),
                 VehicleClosed(vin=SIM_VIN, missing=missing, nok=("B04",)),
                 StateChanged(state="waiting for vehicle", reason=LIFT_LOW)])
    page.get(srv.url)
    page.wait(lambda p: "closed" in (p.text("#headline") or ""), what="the closed headline")
    head = page.text("#headline") or ""
    assert head == f"{SIM_VIN} closed: {len(missing)} missing (B13, B14, B15, ...); NOK B04"
    assert page.js("return document.getElementById('headline').dataset.tone") == "nok"
    assert page.js("return getComputedStyle(document.getElementById('headline'),"
                   " '::before').content").strip("\"' ").startswith("\u2716")
    title = page.js("return document.getElementById('headline').title")
    assert all(b in title for b in missing)
    states = bolt_states(page)
    assert "next" not in states.values()
    assert sorted(b for b, s in states.items() if s == "missing") == sorted(missing)
    assert states["B04"] == "nok"
    # colour is not the only cue: the missing bolts' icon, and the legend names them
    assert page.js("return document.querySelector('#bolts g.bolt-missing text.icon')"
                   ".textContent") == "!"
    assert "missing" in (page.text("#legend") or "")
    for w, h in SHORT:
        page.size(w, h)
        lines = page.js("const e = document.getElementById('headline');"
                        " return e.clientHeight / parseFloat(getComputedStyle(e).lineHeight)")
        assert lines < 2.6, f"{page.name} at {w}x{h}: the headline takes {lines:.1f} lines"
        page.wait(redrawn, what="redrawn")
        assert misread_labels(map_geometry(page)) == []
    shots("fixes-closed-incomplete")


def test_the_operator_screen_says_it_is_not_live_when_the_station_is_gone(live_server, page,
                                                                          shots):
    srv = live_server(devices=("lift", "wrench"))
    srv.publish(opened() + work())
    page.get(srv.url)
    page.wait(lambda p: "tighten" in (p.text("#headline") or ""), what="live headline")
    port = int(srv.url.rsplit(":", 1)[1].strip("/"))
    srv.call(srv.server.stop())
    t0 = time.monotonic()
    page.wait(lambda p: p.js("return document.body.classList.contains('not-live')"), 6,
              "marked not live")
    assert time.monotonic() - t0 < 5
    assert page.text("#headline") == "No connection to the station: this screen is not live"
    assert page.js("return document.getElementById('headline').dataset.tone") == "offline"
    assert page.count("#devices li.dev-ok") == 0
    assert float(page.js("return getComputedStyle(document.getElementById('map')).opacity")) < 0.5
    shots("fixes-not-live")
    # the station is back on its address: the screen recovers by itself
    srv.server = WebServer(srv.bus, frames=srv.frames, listen=f"127.0.0.1:{port}",
                           devices=("lift", "wrench"))
    srv.call(srv.server.start())
    page.wait(lambda p: "tighten" in (p.text("#headline") or ""), 15, "live again")
    assert not page.js("return document.body.classList.contains('not-live')")
    assert page.count("#devices li.dev-ok") == 2
    assert float(page.js("return getComputedStyle(document.getElementById('map')).opacity")) == 1


def test_cameras_show_a_pair_that_is_down_old_frames_and_the_crop_in_view(live_server, page,
                                                                          shots):
    srv = live_server(devices=("lift", "wrench", "pair1", "pair2", "pair3"))
    reason = "left camera file:///nonexist/left_*.png: no such files"
    srv.publish([DeviceHealth(device="pair1", ok=False, kind="down", reason=reason),
                 fault_state(("pair1", reason))])
    img = np.random.default_rng(5).integers(0, 60, (1200, 1600), dtype=np.uint8)
    now = time.time()
    for k in range(5):      # pair3's last frames 25 s old
        for side in ("left", "right"):
            srv.frames.put("pair3", side, img, {"found": False}, grabbed_at=now - 25.4 + k / 10)
    # pair2 grabs at 10 fps for the whole test: frames put once before the page loads would
    # rightly be "old" by the time a loaded machine has drawn them
    grabbing = threading.Event()

    def grab() -> None:
        while not grabbing.wait(0.1):
            for side in ("left", "right"):
                srv.frames.put("pair2", side, img, {"found": False}, grabbed_at=time.time())

    feeder = threading.Thread(target=grab, daemon=True)
    feeder.start()
    try:
        _cameras_down_old_and_crop(srv, page, shots, reason)
    finally:
        grabbing.set()
        feeder.join()


def _cameras_down_old_and_crop(srv: Any, page: Page, shots: Any, reason: str) -> None:
    page.get(srv.url + "cameras")
    page.wait(lambda p: p.count(".cam img") == 4, what="four frames")
    p1 = page.text("section[data-pair=pair1]") or ""
    assert reason in p1 and "No frames from this pair yet" in p1
    assert page.js("return document.querySelector('section[data-pair=pair1] .pair-health')"
                   ".className").endswith("dev-bad")
    assert [s for s in page.js("return [...document.querySelectorAll('#pairs section')]"
                               ".map(s => s.dataset.pair)")] == ["pair1", "pair2", "pair3"]
    fresh = page.text(".cam[data-camera='pair2/left'] .facts") or ""
    assert "fps" in fresh, fresh
    page.wait(lambda p: "OLD FRAME" in (p.text(".cam[data-camera='pair3/left']") or ""),
              what="pair3 marked old")
    old = page.text(".cam[data-camera='pair3/left'] .facts") or ""
    assert "fps" not in old and "no new frame for 2" in old, old
    shots("fixes-cameras-faults")
    page.click("#live")
    page.js("""const e = document.querySelector(".cam[data-camera='pair3/right'] img");
               e.scrollIntoView(); const r = e.getBoundingClientRect();
               e.dispatchEvent(new MouseEvent('click', {bubbles: true,
                   clientX: r.left + r.width / 2, clientY: r.top + r.height / 2}));""")
    page.wait(lambda p: p.js("return document.getElementById('crop-img').naturalWidth") == 512,
              what="the crop")
    # in the window, over the frames, whatever the scroll
    top, bottom, height = page.js("const r = document.getElementById('crop')"
                                  ".getBoundingClientRect(); return [r.top, r.bottom,"
                                  " window.innerHeight]")
    assert top >= 0 and bottom <= height, (top, bottom, height)
    shots("fixes-cameras-crop")
    page.click("#crop-close")
    assert page.js("return document.getElementById('crop').hidden") is True


def test_favicon_unknown_vin_and_unavailable_results(live_server, page, tmp_path):
    srv = live_server(results_error="unable to open database file")
    page.get(srv.url + "vehicles")
    page.wait(lambda p: p.text("#error"), what="the error")
    assert page.text("#error") == "results database unavailable: unable to open database file"
    assert page.js("return fetch('/static/favicon.svg').then(r => r.status)") == 200
    assert page.js("return fetch('/favicon.ico').then(r => r.status)") == 200
    assert page.js("return document.querySelector('link[rel=icon]').getAttribute('href')") \
        == "/static/favicon.svg"
    from stationd.web.results import Results
    from tests.web.scenario import results_db
    repo = results_db(tmp_path)
    try:
        srv = live_server(results=Results(repo))
        page.get(srv.url + "vehicles/NOPE")
        page.wait(lambda p: p.text("#title") == "no vehicle NOPE", what="no vehicle NOPE")
        assert page.js("return [document.getElementById('exports').hidden,"
                       " document.getElementById('rundowns').hidden]") == [True, True]
        assert page.js("return [...document.querySelectorAll('a[download]')]"
                       ".every(a => a.offsetParent === null)")    # none shown
    finally:
        repo.close()


def test_last_results_keep_each_range_on_one_line(live_server, page):
    srv = live_server()
    srv.publish(opened() + work())
    page.get(srv.url)
    page.wait(lambda p: p.count("#results tr") == 2, what="two results")
    for w, h in SHORT:
        page.size(w, h)
        got = page.js("return [...document.querySelectorAll('#results small.rng')]"
                      ".map(e => [e.textContent, e.getClientRects().length])")
        assert got and all(n == 1 for _, n in got), f"{page.name} at {w}x{h}: {got}"


def test_a_stream_that_stalls_without_breaking_is_not_live_then_reconnects(
        live_server, page, monkeypatch):
    """The helper's caveat: a stream that stays open but carries nothing (a dead link, a hung
    loop) never fires onerror.  The snapshot comes again every heartbeat; three heartbeats of
    silence mark the screen not live and it connects again, and is live once it hears."""
    import stationd.web.server as server

    monkeypatch.setattr(server, "HEARTBEAT_S", 0.5)
    srv = live_server(devices=("lift", "wrench"))
    srv.publish(opened() + work())
    page.get(srv.url)
    page.wait(lambda p: "tighten" in (p.text("#headline") or ""), what="live headline")
    time.sleep(2.0)      # several heartbeats: still live while they come
    assert not page.js("return document.body.classList.contains('not-live')")
    pump = srv.server._pump
    srv.call(_cancel(pump))          # the stream stays open, nothing more is sent on it
    page.wait(lambda p: p.js("return document.body.classList.contains('not-live')"), 10,
              "marked not live after three silent heartbeats")
    page.wait(lambda p: srv.server.requests["/api/events"] >= 2, 10, "a new stream")
    # the new stream's first message (the server's last snapshot) does not make it live: it
    # stays not live while the station feeds nothing
    time.sleep(1.0)
    assert page.js("return document.body.classList.contains('not-live')")


async def _cancel(task: Any) -> None:
    import asyncio
    import contextlib

    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task


def test_last_results_mark_an_entered_outcome_and_judge_a_loosening_by_its_status(
        live_server, page):
    """A supervisor's trial of the Last results: an outcome entered from the controller's own
    screen (``enter-outcome``) read as one measured; a loosening's NOK, whose result came
    with the bolt's tightening window, read "NOK: torque low" against it, the range beside
    its torque.  An entered outcome says who entered it; a loosening is said by its own
    status ("loosening NOK"), with no window (as the vehicle's page gives it none)."""
    from db.kinds import LOOSENING

    srv = live_server()
    srv.publish([*opened(), *work(),
                 ResultRecorded(vin=VIN, bolt="B2", ok=False, torque_nm=12.0,
                                angle_deg=400.0, tightening_id=9, pset=1, torque_min=45.0,
                                torque_max=55.0, angle_min=10.0, angle_max=60.0,
                                kind=LOOSENING),
                 ResultRecorded(vin=VIN, bolt="B3", ok=True, torque_nm=50.0, angle_deg=30.0,
                                tightening_id=0, pset=1, torque_min=45.0, torque_max=55.0,
                                entered_by="sue")])
    page.get(srv.url)
    page.wait(lambda p: p.count("#results tr") == 4, what="four results")
    rows = page.js("return [...document.querySelectorAll('#results tr')]"
                   ".map(r => [r.className, r.innerText, r.title,"
                   " r.querySelectorAll('.rng, .out').length])")
    entered, loosening = rows[0], rows[1]
    assert "B3 OK" in entered[1] and "entered by sue" in entered[1], entered
    assert entered[2] == "entered by sue from the controller's screen, not measured"
    assert loosening[0] == "res-nok" and "B2 loosening NOK" in loosening[1], loosening
    assert "low" not in loosening[1] and "high" not in loosening[1] and "[" not in loosening[1]
    assert loosening[3] == 0, loosening                 # no window, nothing marked out of it
    assert "entered" not in rows[2][1] and rows[2][2] == ""    # measured: no mark
    for w, h in SHORT:
        page.size(w, h)
        got = page.js("return [...document.querySelectorAll('#results .entered')]"
                      ".map(e => e.getClientRects().length)")
        assert got == [1], f"{page.name} at {w}x{h}: {got}"
