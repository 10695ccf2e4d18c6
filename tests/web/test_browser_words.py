"""Words that agree on the screens (issue 30, item 4), in both real browsers: one navigation
bar on every page; the counters say what they count (bolts OK, skipped bolts, bolts ending NOK
beside NOK results); "rework" only for a reopened vehicle (a try after a NOK is a repeat); a
NOK names every quantity out of its limits.

Why: the operator header's "NOK 0" and the results page's "NOK 0" after a run with 8 NOK
results, "10 / 50" with skipped bolts left out without saying, tries after a NOK called
"rework", a navigation bar that differed from page to page (no Line on the operator screen, no
Quality or Line on a vehicle's page)."""

from __future__ import annotations

from stationd.station.events import BoltSkipped
from stationd.web.results import Results
from tests.web.pages import Page
from tests.web.scenario import VIN, held, opened, results_db, told, work

NAV = ["Operator", "Cameras", "Results", "Quality", "Line"]
PAGES = {"": "Operator", "cameras": "Cameras", "vehicles": "Results",
         f"vehicles/{VIN}": "Results", "quality": "Quality", "line": "Line"}


def _nav(page: Page) -> tuple[list[str], list[str]]:
    got = page.js("return [[...document.querySelectorAll('nav a')].map(a => a.textContent),"
                  " [...document.querySelectorAll('nav a.here')].map(a => a.textContent)]")
    return list(got[0]), list(got[1])


def test_one_navigation_bar_on_every_page(live_server, page, tmp_path):
    repo = results_db(tmp_path)
    try:
        srv = live_server(results=Results(repo))
        for path, here in PAGES.items():
            page.get(srv.url + path)
            page.wait(lambda p: p.count("nav a") > 0, what=f"/{path}'s navigation bar")
            assert _nav(page) == (NAV, [here]), path
        # the quality page's NOK columns count results (rundowns), and say so
        page.get(srv.url + "quality")
        heads = page.js("return [...document.querySelectorAll('th')].map(t => t.textContent)")
        assert heads.count("NOK results") == 2 and "NOK" not in heads, heads
    finally:
        repo.close()


def test_the_counters_say_what_they_count(live_server, page):
    srv = live_server()
    srv.publish([*opened(), *work(), *told(BoltSkipped(bolt="B4", reason="bracket in the way"))])
    page.get(srv.url)
    page.wait(lambda p: p.text("#skipped") == "1", what="the skipped bolt counted")
    counters = " ".join((page.text(".counters") or "").split())
    # 1 OK of 4, B4 skipped (said, not left out of "1 / 4"), B2's last rundown a NOK
    assert counters == "1 / 4 bolts OK 1 skipped 1 bolt ending NOK", counters
    # the NOK's row names the quantity that failed (torque 41.0 below 45.0), not colour alone
    row = page.js("return document.querySelector('#results tr.res-nok').innerText")
    assert "B2 NOK: torque low" in row, row
    # a held bolt counted too, as `stationd status` counts it (a new user's trial: never said)
    srv.publish(held("B3", "tightening 9"))
    page.wait(lambda p: p.text("#held") == "1", what="the held bolt counted")
    counters = " ".join((page.text(".counters") or "").split())
    assert counters == "1 / 4 bolts OK 1 skipped 1 bolt ending NOK 1 held", counters


def test_the_vehicle_pages_count_bolts_and_results_and_say_rework_only_when_reopened(
        live_server, page, tmp_path):
    repo = results_db(tmp_path)      # B1 OK; B2 NOK (41.0 < 45.0) then OK
    try:
        srv = live_server(results=Results(repo))
        page.get(srv.url + "vehicles")
        page.wait(lambda p: p.count("#vehicles tbody tr") > 0, what="the vehicles' rows")
        heads = page.js("return [...document.querySelectorAll('#vehicles th')]"
                        ".map(t => t.textContent)")
        assert heads[3:9] == ["Bolts OK", "Bolts ending NOK", "Skipped", "Missing",
                              "Tighten again", "Held"], heads
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: p.count("tr.rundown") == 5, what="5 rundown rows")
        summary = page.text("#summary") or ""
        assert summary == ("bolts: 2 OK, 0 ending NOK, 0 skipped, 2 missing; rundowns: 3 "
                           "tightenings, 1 NOK result"), summary
        b2 = page.js("return [...document.querySelectorAll('tr.rundown[data-bolt=B2]')]"
                     ".map(r => [...r.cells].map(c => c.innerText))")
        assert b2[0][2] == "1" and b2[0][4] == "NOK: torque low", b2[0]
        assert b2[1][2] == "2 (repeat)", b2[1]       # a try after a NOK, not a rework
        assert "rework" not in (page.text("#rundowns") or "")

        repo.close_vehicle(VIN)                 # closed, then back for rework
        repo.start_vehicle(VIN, "SEDAN", reopen=True)
        kw = {"position_mm": (1.0, 1.0, 0.0), "match_distance_mm": 1.4, "tilt_deg": 2.0,
              "angle_deg": 31.0}
        repo.record_tightening(VIN, "B3", ok=True, torque_nm=50.0, tightening_id=103, **kw)
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: p.count("tr.rundown") == 5 and
                  "reworked" in (p.text("#title") or ""), what="the reworked vehicle")
        b3 = page.js("return [...document.querySelectorAll('tr.rundown[data-bolt=B3]')]"
                     ".map(r => [...r.cells].map(c => c.innerText))")
        assert b3[0][2] == "1 (rework)", b3        # tightened after the reopening
        b2 = page.js("return [...document.querySelectorAll('tr.rundown[data-bolt=B2]')]"
                     ".map(r => r.cells[2].innerText)")
        assert b2 == ["1", "2 (repeat)"], b2

        # a loosening (a loosen command) is no try at the bolt: never "(repeat)"/"(rework)"
        repo.record_tightening(VIN, "B2", ok=True, torque_nm=0.0, tightening_id=104,
                               kind="loosening", params_sent={"pset": 92, "torque": None,
                                                              "angle": None, "loosen": True},
                               **kw)
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: p.count("tr.rundown[data-bolt=B2]") == 3, what="B2's loosening")
        b2 = page.js("return [...document.querySelectorAll('tr.rundown[data-bolt=B2]')]"
                     ".map(r => [r.cells[2].innerText, r.cells[3].innerText])")
        assert b2[2] == ["3 (loosen pset 92)", "loosening"], b2
        # counted as db report counts it, beside the tightenings; B2 loosened last is to be
        # tightened again, counted with the bolts (it was in no count: an operator trial)
        summary = page.text("#summary") or ""
        assert summary.endswith("; rundowns: 4 tightenings, 1 NOK result, 1 loosening"), summary
        assert ", 1 to tighten again (B2);" in summary, summary
        page.get(srv.url + "vehicles")
        page.wait(lambda p: p.count("#vehicles tbody tr") > 0, what="the vehicles' rows")
        again = page.js("return document.querySelector(arguments[0]).cells[7].innerText",
                        f"#vehicles tr[data-vin='{VIN}']")
        assert again == "1 (B2)", again
    finally:
        repo.close()
