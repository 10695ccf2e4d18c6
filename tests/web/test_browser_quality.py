"""The quality screen's plots in both real browsers, against a real results database: per
bolt and pset row a small SVG of its last results (torque, and angle behind the toggle) with
the min, target and max lines of the limits that group was tightened with, NOKs marked.  The
SVG's coordinates are read back and checked against the values recorded: every point and
every limit line lies on one vertical scale, a NOK beyond a limit is drawn beyond its line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from db.repository import Repository
from stationd.boltfile import import_bolts
from stationd.web.results import Results
from tests.web.pages import Page
from tests.web.test_browser import check_fits

N_BOLTS = 50
KW: dict[str, Any] = {"position_mm": (1.0, 1.0, 0.0), "match_distance_mm": 1.0, "tilt_deg": 1.0}
PSET_1 = {"torque": (45.0, 50.0, 55.0), "angle": (15.0, 30.0, 60.0)}       # min, target, max
OWN = {"torque": (23.0, 25.0, 27.0), "angle": (10.0, 30.0, 50.0)}          # B49's own


def _bolts_yaml() -> str:
    rows = [f"      - {{id: B{i:02d}, name: b{i}, position: [{150 * (i % 10)}, "
            f"{150 * (i // 10)}, 0], pset: 1}}" for i in range(N_BOLTS - 1)]
    rows.append("      - {id: B49, name: b49, position: [1500, 900, 0], "
                "torque: {target: 25, min: 23, max: 27}, angle: {target: 30, min: 10, max: 50}}")
    return ("psets:\n  - id: 1\n    name: M10\n    torque: {target: 50, min: 45, max: 55}\n"
            "    angle: {target: 30, min: 15, max: 60}\nmodels:\n  SEDAN:\n    code: 12\n"
            "    bolts:\n" + "\n".join(rows) + "\n")


def _database(tmp: Path) -> tuple[Repository, dict[str, list[tuple[float, float, bool]]]]:
    """50 bolts; B00 with 32 known results (NOKs above the max, below the min, and one that
    falls out of the last 30), B49 under its own limits, the others a few OK results."""
    (tmp / "bolts.yaml").write_text(_bolts_yaml())
    repo = Repository.open(f"sqlite:///{tmp / 'station.db'}")
    import_bolts(repo, tmp / "bolts.yaml")
    repo.start_vehicle("VINQUALITY0000001", "SEDAN")
    rng = np.random.default_rng(7)
    sent: dict[str, list[tuple[float, float, bool]]] = {}
    nok_at = {1: 41.0, 10: 57.5, 20: 43.0, 31: 56.0}
    tid = 0

    def put(bolt: str, torque: float, angle: float, ok: bool) -> None:
        nonlocal tid
        tid += 1
        repo.record_tightening("VINQUALITY0000001", bolt, ok=ok, torque_nm=torque,
                               angle_deg=angle, tightening_id=tid, **KW)
        sent.setdefault(bolt, []).append((torque, angle, ok))
    for i in range(32):
        angle = float(rng.normal(35, 4))
        put("B00", nok_at.get(i, float(rng.normal(50, 1.5))), angle, i not in nok_at)
    for b in range(1, N_BOLTS - 1):
        for _ in range(3):
            put(f"B{b:02d}", float(rng.normal(50, 1)), float(rng.normal(35, 4)), True)
    for torque, ok in ((24.6, True), (25.3, True), (27.8, False), (25.0, True)):
        put("B49", torque, float(rng.normal(30, 3)), ok)
    return repo, sent


def _plot(page: Page, bolt: str, kind: str) -> dict[str, Any]:
    """The row's plot read back: its height, its limit lines' y, its points in x order."""
    got = page.js("""
        const svg = document.querySelector(`#spc tr[data-bolt=${arguments[0]}] svg.plot.`
                                           + arguments[1]);
        const lines = {};
        for (const l of svg.querySelectorAll('line.lim')) {
            const k = ['min', 'target', 'max'].find(c => l.classList.contains(c));
            lines[k] = [Number(l.getAttribute('y1')), Number(l.getAttribute('y2'))];
        }
        const pts = [...svg.querySelectorAll('.pt')].map(p => [
            Number(p.getAttribute('cx')), Number(p.getAttribute('cy')),
            p.classList.contains('nok'), p.tagName.toLowerCase()]);
        return {h: svg.viewBox.baseVal.height, w: svg.viewBox.baseVal.width, lines, pts,
                shown: getComputedStyle(svg).display !== 'none'};""", bolt, kind)
    assert isinstance(got, dict)
    return got


def _check_scale(plot: dict[str, Any], limits: tuple[float, float, float],
                 values: list[tuple[float, bool]]) -> None:
    """The limit lines where their values are and every point on the same scale: the scale
    is taken from the min and max lines (SVG y grows downwards), then checked on the target
    line and on each recorded value; all inside the plot's box."""
    lo, aim, hi = limits
    y_min, y_max = float(plot["lines"]["min"][0]), float(plot["lines"]["max"][0])
    assert all(y1 == y2 for y1, y2 in plot["lines"].values())          # horizontal lines
    assert y_min > y_max                                               # a higher value is up
    per_unit = (y_min - y_max) / (hi - lo)

    def y(v: float) -> float:
        return y_max + (hi - v) * per_unit
    assert plot["lines"]["target"][0] == pytest.approx(y(aim), abs=0.02)
    pts = sorted(plot["pts"])
    assert len(pts) == len(values)
    assert [x for x, *_ in pts] == sorted(x for x, *_ in pts)
    for (_, cy, nok, tag), (v, ok) in zip(pts, values, strict=True):
        assert tag == "circle" and nok == (not ok)
        assert cy == pytest.approx(y(v), abs=0.02)
        assert 0 <= cy <= plot["h"]
        if v > hi:
            assert cy < y_max
        if v < lo:
            assert cy > y_min


def test_each_row_plots_its_last_results_against_its_limits(live_server, page, tmp_path, shots):
    repo, sent = _database(tmp_path)
    srv = live_server(results=Results(repo))
    page.get(srv.url + "quality")
    page.wait(lambda p: p.count("#spc tbody tr svg.plot.angle") == N_BOLTS, what="50 plots")
    assert page.count("#spc tbody tr") == N_BOLTS
    assert page.count("#spc tbody tr svg.plot.torque") == N_BOLTS
    # a plot per row, as many points as results (B00: the last 30 of its 32)
    counts = page.js("return [...document.querySelectorAll('#spc tbody tr')].map(tr => "
                     "[tr.dataset.bolt, tr.querySelectorAll('svg.torque .pt').length, "
                     "tr.querySelectorAll('svg.angle .pt').length])")
    assert {b: (t, a) for b, t, a in counts} == {
        b: (min(30, len(r)),) * 2 for b, r in sent.items()}

    last = sent["B00"][-30:]
    torque = _plot(page, "B00", "torque")
    assert torque["shown"]
    assert sum(nok for *_, nok, _ in torque["pts"]) == 3               # 57.5, 43.0, 56.0
    _check_scale(torque, PSET_1["torque"], [(t, ok) for t, _, ok in last])
    _check_scale(_plot(page, "B00", "angle"), PSET_1["angle"], [(a, ok) for _, a, ok in last])
    # another group, its own limits: its own lines
    b49 = sent["B49"]
    _check_scale(_plot(page, "B49", "torque"), OWN["torque"], [(t, ok) for t, _, ok in b49])
    _check_scale(_plot(page, "B49", "angle"), OWN["angle"], [(a, ok) for _, a, ok in b49])

    # the parameter version each row's results were tightened with, its limits on hover (a
    # bolt whose limits changed has a row per version: they read as the same row twice)
    got = page.js("const c = document.querySelector('#spc tr[data-bolt=B49] td.version');"
                  "return [c.textContent, c.title];")
    assert got == ["v1", f"torque: min {OWN['torque'][0]:g} Nm, max {OWN['torque'][2]:g} "
                         f"Nm; angle: min {OWN['angle'][0]:g} \u00b0, max "
                         f"{OWN['angle'][2]:g} \u00b0"], got
    check_fits(page, "#spc", long=True)
    shots("quality-plots")
    page.click("input[name=plot][value=angle]")
    page.wait(lambda p: _plot(p, "B00", "angle")["shown"], what="the angle plots")
    assert not _plot(page, "B00", "torque")["shown"]
    check_fits(page, "#spc", long=True)
    repo.close()
