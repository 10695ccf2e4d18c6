"""The screens in real browsers (headless Chromium and headless Firefox, the same assertions in
both): the operator's bolt map as the station works, a fault's reason, the cameras' frames,
the results and their export, and the layout at 1920x1080 and on a 1280x800 panel PC."""

from __future__ import annotations

import csv
import io
import re
from datetime import UTC, datetime

import numpy as np

from db.kinds import LOOSENING
from db.repository import Repository
from stationd.reasons import Reason, Why
from stationd.station.events import (
    Because,
    BoltSkipped,
    DeviceHealth,
    DeviceIdentified,
    Localized,
    Refused,
    ResultRecorded,
    StateChanged,
    StateReason,
)
from stationd.web.results import Results
from tests.web.conftest import SIZES
from tests.web.pages import Page
from tests.web.scenario import (
    VIN,
    fault,
    long_fault,
    opened,
    results_db,
    sim_vehicle,
    told,
    work,
)


def bolts(page: Page) -> dict[str, tuple[str, str]]:
    """Bolt -> (state, label text), read in one script (the map is redrawn live)."""
    got = page.js(
        "return [...document.querySelectorAll('#bolts g.bolt')].map(g => [g.dataset.bolt,"
        " g.dataset.state, g.querySelector('text.label').textContent])")
    return {b: (s, t) for b, s, t in got}


def bolt_states(page: Page) -> dict[str, str]:
    return {b: s for b, (s, _) in bolts(page).items()}


def overflow(page: Page, *selectors: str, long: bool = False) -> list[str]:
    """What does not fit the viewport: a horizontal scroll, or one of ``selectors`` whose box
    reaches outside the window (empty: everything visible without scrolling); ``long``: a
    list that may scroll down (a 50-bolt table), so only its width is checked."""
    got = page.js("""
        const out = [], w = window.innerWidth, h = window.innerHeight;
        if (document.documentElement.scrollWidth > w) out.push(
            `page ${document.documentElement.scrollWidth} px wide in ${w}`);
        for (const sel of arguments[0]) {
            const e = document.querySelector(sel);
            if (!e) { out.push(sel + ' missing'); continue; }
            const r = e.getBoundingClientRect();
            if (r.width < 1 || r.height < 1) out.push(sel + ' empty');
            // content cut off inside its box (an ellipsis, a clipped or scrolling panel)
            // (an inline element has no client box to clip in)
            if (getComputedStyle(e).display !== 'inline' &&
                (e.scrollWidth > e.clientWidth + 1 || e.scrollHeight > e.clientHeight + 1))
                out.push(`${sel} clipped: ${e.scrollWidth}x${e.scrollHeight} in ` +
                         `${e.clientWidth}x${e.clientHeight}`);
            if (r.left < 0 || r.right > w + 0.5 ||
                (!arguments[1] && (r.top < 0 || r.bottom > h + 0.5)))
                out.push(`${sel} at ${Math.round(r.left)},${Math.round(r.top)}-` +
                         `${Math.round(r.right)},${Math.round(r.bottom)} in ${w}x${h}`);
        }
        return out;""", list(selectors), long)
    return [str(x) for x in got]


def check_fits(page: Page, *selectors: str, long: bool = False) -> None:
    """At 1920x1080 and at a 1280x800 panel PC's size: see :func:`overflow`."""
    for w, h in SIZES:
        page.size(w, h)
        assert page.js("return [window.innerWidth, window.innerHeight]") == [w, h]
        assert overflow(page, *selectors, long=long) == [], f"{page.name} at {w}x{h}"
    page.size(*SIZES[0])


def click_centre(page: Page, css: str) -> None:
    """A real click event in the middle of the element (the crop is taken where one clicks)."""
    page.js("""const e = document.querySelector(arguments[0]), r = e.getBoundingClientRect();
               e.dispatchEvent(new MouseEvent('click', {bubbles: true,
                   clientX: r.left + r.width / 2, clientY: r.top + r.height / 2}));""", css)


def test_operator_screen_follows_the_work_and_shows_the_fault(live_server, page, shots):
    srv = live_server()
    srv.publish(opened())
    page.get(srv.url)
    page.wait(lambda p: len(bolt_states(p)) == 4, what="4 bolts on the map")
    assert set(bolt_states(page).values()) == {"pending"}
    assert page.text("#vin") == VIN
    check_fits(page, "#bolts", "#headline", "#done", "#nok")
    shots("operator-opened")

    srv.publish(work())
    page.wait(lambda p: bolt_states(p).get("B3") == "tightening", what="B3 tightening")
    assert bolt_states(page) == {"B1": "ok", "B2": "nok", "B3": "tightening", "B4": "next"}
    # colour is never the only cue: each bolt carries its label
    labels = {b: t for b, (_, t) in bolts(page).items()}
    assert labels["B1"].startswith("OK") and labels["B2"].startswith("NOK")
    assert labels["B4"] == "next"
    assert (page.text("#done"), page.text("#total"), page.text("#nok")) == ("1", "4", "1")
    assert "B3 (pset 1): tighten" in (page.text("#headline") or "")
    assert page.count("#wrench-mark") == 1
    cls, text = page.js(
        "const r = document.querySelector('#results tr'); return [r.className, r.innerText]")
    assert cls == "res-nok" and "B2 NOK" in text and "[45.0-55.0]" in text
    # a loosening is said as one, never "B2 OK" under its NOK (a supervisor's trial)
    srv.publish([ResultRecorded(vin=VIN, bolt="B2", ok=True, torque_nm=36.0, angle_deg=446.0,
                                tightening_id=9, pset=4, torque_min=5.0, torque_max=150.0,
                                angle_min=90.0, angle_max=720.0, kind=LOOSENING)])
    page.wait(lambda p: p.js("return document.querySelector('#results tr').className")
              == "res-loosened", what="the loosening on top of the results")
    text = page.js("return document.querySelector('#results tr').innerText")
    assert "B2 loosened" in text and "OK" not in text, text
    check_fits(page, "#bolts", "#headline", "#done", "#nok")
    shots("operator-working")

    srv.publish([*told(BoltSkipped(bolt="B4", reason="thread damaged")), *fault()])
    page.wait(lambda p: "FAULT" in (p.text("#headline") or ""), what="FAULT headline")
    assert "lift: no answer from 10.0.0.7:502" in (page.text("#headline") or "")
    assert "stop" in page.js("return document.getElementById('headline').className")
    cls, text = page.js(
        "const li = document.querySelector('#devices li[data-device=lift]');"
        " return [li.className, li.textContent]")
    assert cls == "dev-bad" and "timeout" in text
    # a controller that said what it is and then went down: its hover says the fault first
    down = "openprotocol://10.0.0.5:4545: reconnect: connection refused"
    srv.publish([DeviceIdentified("wrench", "PF6000 (cell 1, channel 1), software 2.1"),
                 DeviceHealth("wrench", False, "down", down)])
    page.wait(lambda p: "wrench down" in (p.text("#devices") or ""), what="wrench down")
    title = page.js("return document.querySelector('#devices li[data-device=wrench]').title")
    assert title.splitlines() == [f"wrench down: {down}",
                                  "PF6000 (cell 1, channel 1), software 2.1"], title
    assert bolts(page)["B4"] == ("skipped", "skipped")
    check_fits(page, "#bolts", "#headline")
    shots("operator-fault")

    # every device down, with the long URLs a real station's reasons carry: the headline
    # wraps in large type, the devices panel wraps its URLs, nothing is clipped or cut
    srv.publish(long_fault())
    page.wait(lambda p: "pair2" in (p.text("#headline") or ""), what="the long fault")
    head = page.text("#headline") or ""
    assert "(PLC off, or not in RUN)" in head and "pair2" in head
    assert page.count("#devices li.dev-bad") == 4
    assert "packet_size=9000" in (page.text("#devices") or "")
    check_fits(page, "#bolts", "#headline", "#devices", "#legend", "#results", "#wrench")
    for w, h in SIZES:
        page.size(w, h)
        lines = page.js("const e = document.getElementById('headline');"
                        " return e.clientHeight / parseFloat(getComputedStyle(e).lineHeight)")
        assert lines > 1.5, f"{page.name} at {w}x{h}: the long fault on one line"
        size = page.js("return parseFloat(getComputedStyle("
                       "document.getElementById('headline')).fontSize)")
        assert size >= 32, f"{page.name} at {w}x{h}: headline type shrank to {size} px"
    page.size(*SIZES[0])
    shots("operator-long-fault")


def label_overlaps(page: Page) -> list[str]:
    """Pairs of visible bolt labels whose boxes intersect (screen boxes, so each label's and
    its bolt's transforms are applied)."""
    got = page.js("""
        const boxes = [...document.querySelectorAll('#bolts g.bolt')].flatMap(g => {
            const l = g.querySelector('g.lbl');
            if (!l || getComputedStyle(l).visibility === 'hidden') return [];
            const r = l.getBoundingClientRect();
            return [[g.dataset.bolt, r.left, r.top, r.right, r.bottom]];
        });
        const out = [];
        for (let i = 0; i < boxes.length; i++) for (let j = i + 1; j < boxes.length; j++) {
            const a = boxes[i], b = boxes[j];
            if (a[1] < b[3] && b[1] < a[3] && a[2] < b[4] && b[2] < a[4])
                out.push(a[0] + '/' + b[0]);
        }
        return out;""")
    return [str(x) for x in got]


def test_dense_map_labels_never_overlap_and_between_bolts_is_neutral(live_server, page, shots):
    srv = live_server(devices=("lift", "wrench", "pair1", "pair2", "pair3", "pair4"))
    srv.publish([StateChanged(state="tracking", reason=StateReason(Because.TRACKING)),
                 sim_vehicle()])
    page.get(srv.url)
    page.wait(lambda p: p.count("#bolts g.bolt") == 50, what="50 bolts on the map")
    for w, h in SIZES:
        page.size(w, h)
        # the map redrawn for this size (its viewBox is the panel's box) with its labels
        page.wait(lambda p: p.js(
            "const b = document.getElementById('map').getBoundingClientRect();"
            " return document.getElementById('bolts').getAttribute('viewBox') ==="
            " `0 0 ${Math.max(200, b.width)} ${Math.max(150, b.height)}`"
            " && document.querySelectorAll('#bolts g.lbl').length === 50"), what="redrawn")
        assert label_overlaps(page) == [], f"{page.name} at {w}x{h}"
        shown = page.count("#bolts g.lbl:not(.hidden)")
        assert shown >= 25, f"{page.name} at {w}x{h}: only {shown} of 50 labels placed"
        # colour is never the only cue: every bolt keeps its state icon and hover title
        assert page.count("#bolts g.bolt text.icon") == 50
        assert page.count("#bolts g.bolt > title") == 50
    page.size(*SIZES[0])

    # the wrench out of view while tracking: a normal state, not a red alarm; the per-pair
    # reasons stay off the operator screen (the cameras screen has them)
    every = Reason(Why.NOT_LOCALIZED, per_pair=tuple(
        (f"pair{k}", side, "no purple region enclosing a ring in view")
        for k in range(1, 5) for side in ("left", "right")))
    srv.publish([Localized(point_mm=None, tilt_deg=None, reason=every, candidate=None,
                           distance_mm=None, age_ms=0.0), Refused(reason=every)])
    page.wait(lambda p: p.text("#headline") == "Bring the wrench to a bolt",
              what="the neutral headline")
    assert page.js("return document.getElementById('headline').dataset.tone") == "idle"
    assert "purple" not in (page.text(".side") or "")
    assert [d for d in page.js("return [...document.querySelectorAll('#devices li')]"
                               ".map(li => li.className + ' ' + li.textContent)")] == \
        [f"dev-ok {d}: ok" for d in ("lift", "wrench", "pair1", "pair2", "pair3", "pair4")]
    check_fits(page, "#bolts", "#headline", "#devices", "#legend")
    shots("operator-between-bolts")

    srv.publish([Refused(reason=Reason(Why.AMBIGUOUS, bolt="B41", distance_mm=4.0,
                                       other="B13", other_mm=5.1))])
    page.wait(lambda p: "ambiguous" in (p.text("#headline") or ""), what="amber refusal")
    assert page.js("return document.getElementById('headline').dataset.tone") == "act"
    shots("operator-ambiguous")


def test_cameras_screen_shows_frames_overlay_and_refusal(live_server, page, shots):
    srv = live_server()
    rng = np.random.default_rng(5)
    img = (rng.integers(0, 60, (1200, 1600), dtype=np.uint8))
    img[500:700, 700:900] = 200
    ellipses = [[800, 600, 90, 80, 10], [800, 600, 45, 40, 10]]
    srv.frames.put("front", "left", img, {"found": True, "roi": [600, 400, 400, 400],
                                          "ellipses": ellipses, "centre": [800, 600],
                                          "exposure_us": 800,
                                          "reason": "marker tilted 9 deg (at most 5)"})
    srv.frames.put("front", "right", img, {"found": False, "reason": "marker not found"})
    page.get(srv.url + "cameras")
    page.wait(lambda p: p.count(".cam img") == 2, what="two frames")
    # reduced on the server to the width shown (half of 1920 rounded up to 320 px steps)
    page.wait(lambda p: p.js("const i = [...document.querySelectorAll('.cam img')];"
                             " return i.length === 2 && i.every(x => x.naturalWidth === 960)"),
              what="frames loaded at 960 px")
    left = ".cam[data-camera='front/left']"
    assert page.count(f"{left} ellipse") == 2
    assert page.count(f"{left} rect.roi") == 1
    text = page.text(left) or ""
    assert "sharpness" in text and "marker found" in text
    # seen and refused: red; none in view (a wrench elsewhere): said plainly, not refused
    assert page.text(f"{left} .refusal") == "refused: marker tilted 9 deg (at most 5)"
    right = ".cam[data-camera='front/right']"
    assert page.text(f"{right} .no-marker") == "no marker: marker not found"
    assert page.count(f"{right} .refusal") == 0
    check_fits(page, ".cam[data-camera='front/left'] img", ".cam[data-camera='front/right'] img")
    page.click("#live")                      # stop the refresh to click a frame
    click_centre(page, f"{left} img")
    page.wait(lambda p: p.js("return document.getElementById('crop-img').naturalWidth") == 512,
              what="the full-resolution crop")
    # where the click fell, in full-resolution pixels (within a pixel of the image's middle)
    m = re.search(r"at \((\d+), (\d+)\)", page.text("#crop-title") or "")
    assert m and abs(int(m[1]) - 800) <= 2 and abs(int(m[2]) - 600) <= 2
    shots("cameras")


def test_the_vehicles_list_has_a_held_column(live_server, page, tmp_path):
    """A supervisor's trial: the list had no word of a held bolt, which the vehicle's page
    says: a column of the held bolts, counted and named as the NOK ones are."""
    repo = results_db(tmp_path)
    repo.others.record_unreadable(mid=61, revision=7, raw="00230061007 garbled", error="short",
                                  vin=VIN, bolt="B3", controller_vin=None, tightening_id=7, pset=1,
                                  result_at=None)
    try:
        srv = live_server(results=Results(repo))
        page.get(srv.url + "vehicles")
        page.wait(lambda p: p.count("#vehicles tbody tr") > 0, what="the vehicles' rows")
        got = page.js("const i = [...document.querySelectorAll('#vehicles th')]"
                      ".findIndex(t => t.textContent === 'Held');"
                      "return i < 0 ? null : document.querySelector("
                      f"\"#vehicles tr[data-vin='{VIN}']\").cells[i].textContent")
        assert got == "1 (B3)"
        check_fits(page, "#vehicles")
    finally:
        repo.close()


def test_a_bolt_held_for_a_lost_push_is_not_said_never_tightened(live_server, page, tmp_path):
    """A supervisor's trial: the vehicle's page said "not tightened" of B3, held because
    tightening 41 (its push lost, fetched later, stored unattributed) may be its own: it says
    it is held and which result may be its own, in db report's words (the server's)."""
    from db.kinds import LOST_UNKNOWN, lost_unknown_note

    repo = results_db(tmp_path)
    repo.others.record_unattributed(vin=VIN, controller_vin=None, tightening_id=41, pset=1, ok=True,
                                    torque_nm=49.6, angle_deg=31.0, result_at=None,
                                    reason="fetched after a later one came, the link up")
    # fetched with this vehicle at height, made on another (a restore's catch-up): said
    repo.others.record_unattributed(vin=VIN, controller_vin="9SDST0099TL000042",
                                    tightening_id=52, pset=1, ok=True, torque_nm=49.0,
                                    angle_deg=30.0, result_at=None, reason="fetched")
    repo.others.record_controller_event(result_type=0, what=LOST_UNKNOWN, vin=VIN, bolt="B3",
                                        controller_vin=None, tightening_id=None, pset=1, ok=None,
                                        torque_nm=None, angle_deg=None, result_at=None,
                                        note=lost_unknown_note(41, 1, 1000.0))
    try:
        srv = live_server(results=Results(repo))
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: p.count("tr.rundown[data-bolt=B3]") == 1, what="B3's row")
        b3 = page.text("tr.rundown[data-bolt=B3]") or ""
        assert "not tightened" not in b3, b3
        assert "HELD: tightening 41 may be its own" in b3, b3
        assert ("held: no rundown recorded to it, but tightening 41 may be its own (OK 49.6 "
                "Nm, 31 deg, stored unattributed)") in b3, b3
        page.wait(lambda p: "made on" in (p.text("#others tbody") or ""), what="the others")
        others = (page.text("#others tbody") or "").splitlines()
        assert [line for line in others if "made on" in line] == [
            line for line in others if "52" in line and "made on 9SDST0099TL000042" in line]
    finally:
        repo.close()


def test_results_screens_and_csv_download(live_server, page, shots, tmp_path):
    repo = results_db(tmp_path)
    repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="screen", kind="skip",
                               vin=VIN, bolt="B4", comment="thread damaged")
    try:
        srv = live_server(results=Results(repo))
        page.get(srv.url + "vehicles")
        page.wait(lambda p: p.count("#vehicles tbody tr") > 0, what="the vehicles' rows")
        row = f"#vehicles tr[data-vin='{VIN}']"
        text = page.text(row) or ""
        assert "SEDAN" in text and "open" in text
        check_fits(page, "#vehicles")
        shots("vehicles")
        page.click(f"{row} a")
        page.wait(lambda p: p.count("tr.rundown") == 5, what="5 rundown rows")
        b2 = page.js("return [...document.querySelectorAll('tr.rundown[data-bolt=B2]')]"
                     ".map(r => r.innerText)")
        assert "NOK: torque low" in b2[0] and "2 (repeat)" in b2[1]
        # a bolt never run down: missing, or skipped by whom and why
        assert "not tightened" in (page.text("tr.rundown[data-bolt=B3]") or "")
        b4 = page.text("tr.rundown[data-bolt=B4]") or ""
        assert "SKIPPED" in b4 and "skipped by sam: thread damaged" in b4
        # no image directory, so no crop to show: the column is hidden, not left empty
        crops_shown = ("return getComputedStyle(document.querySelector('#rundowns th.crops'))"
                       ".display !== 'none'")
        assert page.js(crops_shown) is False
        check_fits(page, "#rundowns")
        shots("vehicle")
        page.click("#csv")
        rows = list(csv.DictReader(io.StringIO(page.wait_download(f"{VIN}.csv").read_text())))
        # the rundowns, then the bolts without any (B3 still to do: the vehicle is open;
        # B4 skipped)
        assert [(r["bolt"], r["status"]) for r in rows] == [("B1", "ok"), ("B2", "nok"),
                                                           ("B2", "ok"), ("B3", "pending"),
                                                           ("B4", "skipped")]
        assert (rows[-1]["skipped_by"], rows[-1]["comment"]) == ("sam", "thread damaged")
        # with the records' image directory, B2's saved crop is linked in its column
        srv = live_server(results=Results(repo), images_dir=tmp_path)
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: p.count("tr.rundown") == 5, what="5 rundown rows")
        assert page.js(crops_shown) is True
        assert page.js("return [...document.querySelectorAll('td.crops a')]"
                       ".map(a => a.getAttribute('href'))") == ["/images/img/B2-left.jpg"]
        assert "reworked" not in (page.text("#title") or "")
        # a bolt skipped after a NOK ends NOK, and says who skipped it and why
        repo.record_tightening(VIN, "B3", ok=False, position_mm=(1.0, 1.0, 0.0),
                               match_distance_mm=1.0, tilt_deg=1.0, torque_nm=20.0,
                               angle_deg=30.0, tightening_id=99)
        repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="screen",
                                   kind="skip", vin=VIN, bolt="B3", comment="stripped")
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: "then skipped" in (p.text("tr.rundown[data-bolt=B3]") or ""),
                  what="B3 skipped after its NOK")
        assert "NOK, then skipped by sam: stripped" in (
            page.text("tr.rundown[data-bolt=B3]") or "")
        assert "ending NOK (B3 skipped by sam), 1 skipped" in (page.text("#summary") or "")
        repo.close_vehicle(VIN)                 # closed, then back for rework
        repo.start_vehicle(VIN, "SEDAN", reopen=True)
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: p.text("#title") == f"{VIN} (SEDAN, reworked)", what="reworked")
        page.get(srv.url + "vehicles")
        page.wait(lambda p: "open, reworked" in (p.text(row) or ""), what="reworked in the list")
    finally:
        repo.close()
    # more vehicles than the list shows: it says how many, and where the others are
    (tmp_path / "more").mkdir()
    more = results_db(tmp_path / "more")
    try:
        more.start_vehicle("VINNEW", "SEDAN")
        res = Results(more)
        res.list_limit = 1
        srv = live_server(results=res)
        page.get(srv.url + "vehicles")
        page.wait(lambda p: p.count("#vehicles tbody tr.more") == 1, what="the list's limit")
        assert page.count("#vehicles tr[data-vin]") == 1 and \
            page.count("#vehicles tr[data-vin='VINNEW']") == 1
        assert "The newest 1 of 2 vehicles" in (page.text("#vehicles tr.more") or "") and \
            "db shift" in (page.text("#vehicles tr.more") or "")
    finally:
        more.close()
    empty = Repository.open(f"sqlite:///{tmp_path / 'empty.db'}")
    try:
        srv = live_server(results=Results(empty))
        page.get(srv.url + "vehicles")
        page.wait(lambda p: p.count("#vehicles tbody tr") == 1, what="the empty list's row")
        assert "No vehicles yet" in (page.text("#vehicles tbody") or "")
        shots("vehicles-empty")
    finally:
        empty.close()


def test_cameras_screen_fetches_again_only_the_frames_in_view(live_server, page):
    """Four pairs of 20 MP-sized frames: after the first load, only the pairs in the window
    are fetched each second (the daemon encodes nothing nobody sees); scrolled down, the last
    pair is fetched again and the first no longer."""
    srv = live_server()
    img = np.random.default_rng(2).integers(0, 60, (1200, 1800), dtype=np.uint8)
    pairs = ("p1", "p2", "p3", "p4")
    for p in pairs:
        for side in ("left", "right"):
            srv.frames.put(p, side, img, {"found": False, "reason": "marker not found"})
    page.get(srv.url + "cameras")
    page.js("performance.setResourceTimingBufferSize(100000)")
    page.wait(lambda p: p.js("const i = [...document.querySelectorAll('.cam img')];"
                             " return i.length === 8 && i.every(x => x.naturalWidth > 0)"),
              what="8 frames loaded")

    def fetched() -> dict[str, int]:
        got = page.js("return performance.getEntriesByType('resource').map(e => e.name)"
                      ".filter(n => n.includes('frame.jpg'))")
        return {p: sum(f"/cameras/{p}/" in n for n in got) for p in pairs}
    page.wait(lambda p: fetched()["p1"] >= 8, 20, "p1 fetched 4 more times")
    now = fetched()
    assert now["p4"] == 2, now             # once per side, at the first load only
    page.js("document.querySelector(\".cam[data-camera='p4/left']\").scrollIntoView()")
    page.wait(lambda p: fetched()["p4"] >= 6, 20, "p4 fetched again once in view")
    p1 = fetched()["p1"]
    page.wait(lambda p: fetched()["p4"] >= 10, 20, "p4 fetched twice more")
    assert fetched()["p1"] == p1           # out of view now


def test_the_line_database_down_is_amber_in_the_devices_never_a_station_fault(live_server,
                                                                              page):
    """The store-and-forward's state on the operator screen: the records waiting while the
    line database is down, in the devices panel, never as a fault (the station tightens on)."""
    srv = live_server()
    state = {"up": True, "backlog": 0, "alarm": None, "last_error": None,
             "url": "postgresql+psycopg://stationd@line-db/line"}
    srv.server.line = lambda: dict(state)
    srv.publish(opened())
    page.get(srv.url)
    page.wait(lambda p: p.text("#devices li[data-device=line]") == "line database: 0 behind",
              what="the line database forwarding")
    state.update(up=False, backlog=7, last_error="connection refused")
    srv.publish(work())                    # any event (or the heartbeat) brings the news
    page.wait(lambda p: p.text("#devices li[data-device=line]")
              == "line database down: 7 records wait", what="the line database down")
    # counted in the journal's words (it said "7 record(s) wait", the journal "7 records
    # wait"), also for one and for none yet (the forwarder asks at its start)
    for n, words in ((1, "1 record waits"), (0, "no record waits yet")):
        state.update(backlog=n)
        srv.publish(work())
        page.wait(lambda p, w=words: p.text("#devices li[data-device=line]")
                  == f"line database down: {w}", what=f"the line database down, {words}")
    assert page.js("return document.querySelector('#devices li[data-device=line]')"
                   ".className") == "dev-wait"
    assert page.js("return document.getElementById('headline').dataset.tone") != "stop"


def test_the_quality_screen_shows_capability_and_the_nok_trend(live_server, page, tmp_path):
    repo = results_db(tmp_path)
    for i, torque in enumerate((49.5, 50.5, 50.0, 49.8, 50.3)):    # five more OK on B1
        repo.start_vehicle(f"VINQ{i}", "SEDAN")
        repo.record_tightening(f"VINQ{i}", "B1", ok=True, torque_nm=torque, angle_deg=31.0,
                               position_mm=(1.0, 1.0, 0.0), match_distance_mm=1.0,
                               tilt_deg=1.0, tightening_id=200 + i)
    srv = live_server(results=repo)
    page.get(srv.url + "quality")
    page.wait(lambda p: p.count("#spc tbody tr") >= 2, what="the capability table")
    row = page.js("return [...document.querySelectorAll('#spc tr[data-bolt=B1] td')]"
                  ".map(td => td.textContent)")
    assert row[1] == "B1" and row[3] == "v1" and row[4] == "6" and row[5] == "0"
    assert float(row[6]) > 1.33                                      # Cp: a capable bolt
    trend = page.js("return [...document.querySelectorAll('#trend tbody td')]"
                    ".map(td => td.textContent)")
    assert trend[1:4] == ["8", "1", "12.5 %"]                        # 8 results, 1 NOK


def test_a_refused_reload_is_said_in_the_devices_panel(live_server, page):
    """An operator trial: a refused reload showed only in ``stationd status``; the screens
    said nothing while the file on disk would not start the station at the next reboot."""
    srv = live_server()
    page.get(srv.url)
    page.wait(lambda p: p.text("#vin") == "no vehicle", what="the screen, no vehicle yet")
    # no vehicle, no counters ("0 / 0 bolts OK 0 bolts ending NOK": an operator trial)
    drawn = "return document.getElementById('counters').getClientRects().length > 0"
    assert page.js(drawn) is False
    srv.publish(opened())
    page.wait(lambda p: p.text("#vin") == VIN, what="the vehicle on the screen")
    page.wait(lambda p: p.js(drawn) is True, what="its counters")
    assert page.count("#devices li[data-device=config]") == 0
    srv.server.reload_refused = "station.yaml:12: nok.max_nok: 0 is out of range 1-99"
    srv.publish(opened()[:1])              # the next snapshot
    page.wait(lambda p: p.count("#devices li[data-device=config]") == 1,
              what="the refused reload in the devices panel")
    assert page.text("#devices li[data-device=config]") == (
        "configuration: reload refused (station.yaml:12: nok.max_nok: 0 is out of range 1-99):"
        " running on the file read before")
    # a long one whole, wrapped, not cut to one line (a line engineer's trial on a touch
    # panel: its file and line showed only on a mouse's hover)
    long = "/etc/stationd/bolts/" + "sedan-2027-" * 8 + "bolts.yaml:218: models.SEDAN.bolts[50]"
    srv.server.reload_refused = long
    srv.publish(opened()[:1])
    page.wait(lambda p: long in (p.text("#devices li[data-device=config]") or ""),
              what="the long refusal")
    assert page.js("const e = document.querySelector('#devices li[data-device=config]');"
                   " return e.scrollWidth <= e.clientWidth + 1") is True
    srv.server.reload_refused = None       # a reload that went through
    srv.publish(opened()[:1])
    page.wait(lambda p: p.count("#devices li[data-device=config]") == 0,
              what="the line gone after a good reload")
