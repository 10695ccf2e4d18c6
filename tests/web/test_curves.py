"""Tightening curves on the vehicle's page and in its JSON export, end to end: the simulated
controller over TCP -> the driver (MID 0900) -> the database (``db.curves``) -> the results
API -> a torque-angle plot drawn as inline SVG with the rundown's limits (in real browsers
where they are installed)."""

from __future__ import annotations

import asyncio
import csv
import io
from pathlib import Path
from typing import Any

from aiohttp import ClientSession

from db.curves import store_curve
from db.repository import Repository
from drivers.wrench import TighteningResult, open_wrench
from drivers.wrench.openprotocol.curve import Curve
from drivers.wrench.sim.controller import SimController, SimPset
from stationd.boltfile import import_bolts
from stationd.bus import EventBus
from stationd.web.results import CSV_FIELDS, Results
from stationd.web.server import WebServer
from tests.web.scenario import BOLTS_YAML

VIN = "WCURVE0000000001"
#: the controller's pset 1 is the bolt table's pset 1 (50 N m 45-55, 30 deg 15-60)
PSETS = {1: SimPset(50.0, 45.0, 55.0, 30.0, 15.0, 60.0)}


def curve_fields(c: Curve) -> dict[str, Any]:
    """What the daemon stores of a driver's curve (the wiring in the report does the same)."""
    return {"tightening_id": c.tightening_id, "trace_type": c.trace_type, "unit": c.unit,
            "values": c.values, "sample_period_s": c.time_step_s,
            "times_s": None if c.time_step_s is not None else c.times_s}


def curves_db(tmp: Path) -> tuple[Repository, Any]:
    """B1 tightened on the simulated controller with curves on, recorded and its curves
    stored; B2 recorded without a curve."""
    (tmp / "bolts.yaml").write_text(BOLTS_YAML)
    repo = Repository.open(f"sqlite:///{tmp / 'station.db'}")
    import_bolts(repo, tmp / "bolts.yaml")
    repo.start_vehicle(VIN, "SEDAN")
    with SimController(PSETS, seed=5, nok_rate=0.0) as sim:
        port = sim.listen_tcp()
        with open_wrench(f"openprotocol://127.0.0.1:{port}?curves=1", timeout=0.5,
                         connect_timeout=0.5) as w:
            w.select_pset(1)
            w.enable_tool()
            sim.pull_trigger()
            r = w.wait_result(1.0)
            assert isinstance(r, TighteningResult)
            curves = [w.wait_curve(1.0) for _ in range(2)]
    kw: dict[str, Any] = {"position_mm": (0.0, 0.0, 0.0), "match_distance_mm": 1.0,
                          "tilt_deg": 1.0}
    repo.record_tightening(VIN, "B1", ok=r.ok, torque_nm=r.torque_nm, angle_deg=r.angle_deg,
                           tightening_id=r.tightening_id, **kw)
    repo.record_tightening(VIN, "B2", ok=True, torque_nm=50.0, angle_deg=30.0,
                           tightening_id=99, **kw)
    for c in curves:
        assert c is not None
        store_curve(repo, **curve_fields(c))
    return repo, r


def test_the_vehicle_json_and_its_export_carry_the_curve(tmp_path):
    repo, r = curves_db(tmp_path)

    async def main():
        srv = WebServer(EventBus(), results=Results(repo), listen="127.0.0.1:0")
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + f"api/vehicles/{VIN}") as resp:
                    doc = await resp.json()
                async with http.get(srv.url + f"api/vehicles/{VIN}/export.json") as resp:
                    exported = await resp.json(content_type=None)
                async with http.get(srv.url + f"api/vehicles/{VIN}/export.csv") as resp:
                    rows = list(csv.DictReader(io.StringIO(await resp.text())))
        finally:
            await srv.stop()
        return doc, exported, rows

    try:
        doc, exported, rows = asyncio.run(main())
    finally:
        repo.close()
    for d in (doc, exported):
        runs = {b["bolt"]: b["rundowns"] for b in d["bolts"]}
        (b1,) = runs["B1"]
        curve = b1["curve"]
        assert len(curve["torque_nm"]) == len(curve["angle_deg"]) == 240
        assert curve["torque_nm"][-1] == r.torque_nm
        assert abs(curve["angle_deg"][-1] - r.angle_deg) <= 0.6
        assert curve["sample_period_s"] == 0.002
        assert [(t["name"], t["unit"], t["tightening_id"]) for t in curve["traces"]] == [
            ("angle", "deg", r.tightening_id), ("torque", "Nm", r.tightening_id)]
        assert runs["B2"][0]["curve"] is None
    assert list(rows[0]) == list(CSV_FIELDS)     # the CSV stays one line per rundown


def test_the_vehicle_page_draws_the_torque_angle_plot(live_server, page, shots, tmp_path):
    repo, r = curves_db(tmp_path)
    try:
        srv = live_server(results=Results(repo))
        page.get(srv.url + f"vehicles/{VIN}")
        page.wait(lambda p: p.count("tr.rundown") == 4, what="4 rundown rows")
        page.wait(lambda p: p.count("tr.curve svg.curve-plot") == 1, what="one curve")
        got = page.js("""
            const s = document.querySelector('tr.curve svg.curve-plot');
            const box = s.getBoundingClientRect();
            return [s.closest('tr').dataset.bolt, s.dataset.tightening,
                    s.querySelector('polyline.trace').getAttribute('points').split(' ').length,
                    s.querySelectorAll('rect.limits').length,
                    s.querySelectorAll('circle.final').length,
                    box.width > 100 && box.right <= window.innerWidth,
                    !document.getElementById('curves-note').hidden]""")
        assert got == ["B1", str(r.tightening_id), 240, 1, 1, True, True]
        # the final point lies inside the limits window (an OK rundown)
        inside = page.js("""
            const s = document.querySelector('tr.curve svg.curve-plot');
            const w = s.querySelector('rect.limits'), c = s.querySelector('circle.final');
            const x = +c.getAttribute('cx'), y = +c.getAttribute('cy');
            const x0 = +w.getAttribute('x'), y0 = +w.getAttribute('y');
            return x >= x0 && x <= x0 + +w.getAttribute('width') &&
                   y >= y0 && y <= y0 + +w.getAttribute('height');""")
        assert inside is True
        shots("vehicle-curve")
    finally:
        repo.close()
