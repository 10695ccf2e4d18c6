"""The vehicles list on a 1024x768 tablet, in both real browsers: no sideways scroll, and a
time wraps between its date and its clock, never inside the date.

Why: a supervisor's trial on a tablet: the list was wider than the window (Chromium broke
"2026-12-02T02:00:00" after the date's hyphen, "2026-12-" over "02T02:00:00", and was still 3 to
12 px too wide; Firefox found no place to break it: 1181 px in 1024)."""

from __future__ import annotations

from stationd.web.results import Results
from tests.web.scenario import VIN, results_db


def test_the_vehicles_list_fits_a_tablet_and_wraps_a_time_between_date_and_clock(
        live_server, page, tmp_path) -> None:
    repo = results_db(tmp_path)
    try:
        repo.close_vehicle(VIN)
        srv = live_server(results=Results(repo))
        page.size(1024, 768)
        page.get(srv.url + "vehicles")
        page.wait(lambda p: p.count("#vehicles tbody tr, table tbody tr") > 0, what="the list")
        lines = page.js("""
            const heads = [...document.querySelectorAll('th')].map(t => t.textContent);
            const row = document.querySelector('tbody tr');
            return ['Started (UTC)', 'Ended (UTC)'].map(h => row.cells[heads.indexOf(h)])
                .map(c => c.innerText.split('\\n'));""")
        for got in lines:
            assert len(got[0]) >= 10 and got[0][:10].count("-") == 2, lines   # the whole date
        assert page.js("return document.documentElement.scrollWidth <= window.innerWidth"), \
            page.js("return [document.documentElement.scrollWidth, window.innerWidth, "
                    "[...document.querySelectorAll('th, td, table, h1, p, main')]"
                    ".map(e => [e.tagName, e.textContent.slice(0, 30), "
                    "Math.round(e.getBoundingClientRect().right)])"
                    ".filter(x => x[2] > window.innerWidth)]")
    finally:
        repo.close()
