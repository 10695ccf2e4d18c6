"""The server over real HTTP on loopback: status, live events, cameras, results, guards."""

from __future__ import annotations

import asyncio
import csv
import io
import json
from typing import Any

import numpy as np
import pytest
from aiohttp import ClientSession

from db.kinds import LOOSENING
from stationd.bus import EventBus
from stationd.errors import InputError
from stationd.station.events import Because, Localized, PairFrames, StateChanged, StateReason
from stationd.web.frames import LatestFrames
from stationd.web.results import Results
from stationd.web.server import WebServer
from stationd.web.view import View
from tests.web.scenario import VIN, fault, opened, results_db, work


def serve(bus, **kw) -> WebServer:
    return WebServer(bus, listen="127.0.0.1:0", **kw)


async def _serving_opened(**kw) -> WebServer:
    """A started server whose bus holds the scenario's opened vehicle (``srv.bus``)."""
    bus = EventBus()
    for e in opened():
        bus.publish(e)
    srv = serve(bus, **kw)
    await srv.start()
    return srv


async def _read_snapshot(resp):
    buf = b""
    while b"\n\n" not in buf.split(b"data: ", 1)[-1]:
        buf += await resp.content.readany()
    body = buf.split(b"data: ", 1)[1].split(b"\n\n", 1)[0]
    return json.loads(body)


def test_status_healthz_and_live_events():
    async def main():
        srv = await _serving_opened()
        bus = srv.bus
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + "healthz") as r:
                    assert r.status == 200 and (await r.text()) == "ok\n"
                async with http.get(srv.url + "api/events") as stream:
                    first = await _read_snapshot(stream)   # the history, folded
                    assert first["vehicle"]["vin"] == VIN and first["counters"]["total"] == 4
                    for e in work() + fault():
                        bus.publish(e)
                    snap = first
                    while snap["state"] != "fault":
                        snap = await asyncio.wait_for(_read_snapshot(stream), 10)
                    assert snap["headline"].startswith("FAULT: lift")
                    assert srv.clients == 1
                async with http.get(srv.url + "api/status") as r:
                    st = await r.json()
                assert st["state"] == "fault" and st["counters"]["done"] == 1
                # the reason in words, and its kind beside them for a reader that acts on it
                assert (st["reason"], st["reason_kind"]) == (
                    "lift: no answer from 10.0.0.7:502 for 2.0 s", "fault")
                assert st["devices"]["lift"]["ok"] is False
                assert {"stationd", "aiohttp", "python"} <= set(st["versions"])
                async with http.post(srv.url + "api/status") as r:
                    assert r.status == 405            # read-only: nothing can be sent
        finally:
            await srv.stop()
    asyncio.run(main())


def test_token_guards_every_page_when_configured():
    async def main():
        srv = serve(EventBus(), token="a-long-token")  # noqa: S106 - a test token
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + "api/status") as r:
                    assert r.status == 401
                async with http.get(srv.url) as r:    # what a browser shows: how to get in
                    text = await r.text()
                    assert r.status == 401 and "/?token=TOKEN" in text
                    assert "a-long-token" not in text
                async with http.get(srv.url + "api/status",
                                    headers={"Authorization": "Bearer a-long-token"}) as r:
                    assert r.status == 200
                async with http.get(srv.url + "?token=a-long-token") as r:
                    assert r.status == 200 and "token" in r.cookies
        finally:
            await srv.stop()
    asyncio.run(main())


def test_open_bind_without_token_is_refused():
    with pytest.raises(InputError, match="needs a token"):
        WebServer(EventBus(), listen="0.0.0.0:0")


def test_cameras_frames_and_crops_on_demand():
    async def main():
        frames = LatestFrames()
        img = np.random.default_rng(3).integers(0, 255, (480, 640), dtype=np.uint8)
        frames.put("front", "left", img, {"found": False, "reason": "no marker",
                                          "roi": [100, 100, 200, 200]})
        bus = EventBus()
        bus.publish(PairFrames(pair="front", exposure_t=12.5,
                               sides={"left": {"ellipses": [[1, 2, 3, 4, 0]], "reason": "old"}}))
        srv = serve(bus, frames=frames)
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + "api/cameras") as r:
                    cams = await r.json()
                assert [(c["pair"], c["side"]) for c in cams] == [("front", "left")]
                assert cams[0]["summary"]["sharpness"] > 0 and cams[0]["width"] == 640
                # the pair's published summary fills in; the frame's own summary wins
                assert cams[0]["summary"]["ellipses"] == [[1, 2, 3, 4, 0]]
                assert cams[0]["summary"]["reason"] == "no marker"
                assert cams[0]["summary"]["exposure_t"] == 12.5
                # the focus figure is kept per frame (asked each second by every cameras
                # page), and a new frame gets its own: a flat one has none of the noise's
                async with http.get(srv.url + "api/cameras") as r:
                    again = (await r.json())[0]["summary"]["sharpness"]
                assert again == cams[0]["summary"]["sharpness"]
                frames.put("front", "left", np.full_like(img, 90),
                           {"found": False, "roi": [100, 100, 200, 200]})
                async with http.get(srv.url + "api/cameras") as r:
                    assert (await r.json())[0]["summary"]["sharpness"] == 0.0
                async with http.get(srv.url + "api/cameras/front/left/frame.jpg?w=320") as r:
                    assert r.content_type == "image/jpeg" and (await r.read())[:2] == b"\xff\xd8"
                async with http.get(srv.url + "api/cameras/front/left/crop.jpg?x=5&y=5") as r:
                    assert r.status == 200
                async with http.get(srv.url + "api/cameras/front/right/frame.jpg") as r:
                    assert r.status == 404
                async with http.get(srv.url + "api/cameras/front/left/frame.jpg?w=x") as r:
                    assert r.status == 400
        finally:
            await srv.stop()
    asyncio.run(main())


def test_a_camera_the_station_has_not_is_said_so_not_awaited():
    """``/api/cameras/pair9/left/frame.jpg`` of a station without pair9 said "no frame from
    pair9/left yet", as if one would come (a new user's trial)."""
    async def main():
        frames = LatestFrames()
        srv = serve(EventBus(), frames=frames, devices=("lift", "wrench", "front"))
        await srv.start()
        try:
            async with ClientSession() as http:
                for path, said in (
                        ("pair9/left/frame.jpg", "no pair 'pair9' at this station (its pairs: "
                                                 "front)"),
                        ("front/middle/crop.jpg", "no side 'middle': left or right"),
                        ("front/left/frame.jpg", "no frame from front/left yet")):
                    async with http.get(srv.url + "api/cameras/" + path) as r:
                        assert (r.status, (await r.text()).strip()) == (404, said)
                # a frame kept is served whatever its pair (one of before a reload)
                frames.put("gone", "left", np.full((48, 64), 90, np.uint8), {})
                async with http.get(srv.url + "api/cameras/gone/left/frame.jpg") as r:
                    assert r.status == 200 and r.content_type == "image/jpeg"
        finally:
            await srv.stop()
    asyncio.run(main())


def test_results_and_exports_from_a_real_database(tmp_path):
    repo = results_db(tmp_path)
    (tmp_path / "img").mkdir()
    (tmp_path / "img" / "B2-left.jpg").write_bytes(b"\xff\xd8jpeg")

    async def main():
        srv = serve(EventBus(), results=Results(repo), images_dir=tmp_path / "img")
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + "api/vehicles") as r:
                    (v,) = await r.json()
                assert v["vin"] == VIN and v["status"] == "open" and v["missing"] == ["B3", "B4"]
                async with http.get(srv.url + f"api/vehicles/{VIN}") as r:
                    doc = await r.json()
                b2 = next(b for b in doc["bolts"] if b["bolt"] == "B2")
                assert [x["status"] for x in b2["rundowns"]] == ["nok", "ok"]
                assert b2["rundowns"][1]["image_urls"] == ["/images/B2-left.jpg"]
                async with http.get(srv.url + "images/B2-left.jpg") as r:
                    assert r.status == 200
                async with http.get(srv.url + "images/..%2Fstation.db") as r:
                    assert r.status == 404
                async with http.get(srv.url + f"api/vehicles/{VIN}/export.csv") as r:
                    assert "attachment" in r.headers["Content-Disposition"]
                    rows = list(csv.DictReader(io.StringIO(await r.text())))
                assert [(x["bolt"], x["status"], x["attempt"]) for x in rows] == [
                    ("B1", "ok", "1"), ("B2", "nok", "1"), ("B2", "ok", "2"),
                    *((b, "pending", "0") for b in doc["missing"])]   # open: to do
                assert all(x["torque_min_nm"] and x["torque_max_nm"] for x in rows[:3])
                async with http.get(srv.url + "api/vehicles/NOPE/export.csv") as r:
                    assert r.status == 404
        finally:
            await srv.stop()
            repo.close()
    asyncio.run(main())


def test_the_vehicle_page_labels_a_loosening_with_its_loosen_pset_not_as_a_repeat(tmp_path):
    """A trial's vehicle page showed B2's loosening (the NOK policy's loosen step) as "3
    (repeat)", a repeat tightening: the page's Attempt words say a loosening with its loosen
    pset; the tightenings around it stay a first try and repeats, and after the vehicle is
    reopened a tightening is a rework but a loosening still a loosening."""
    repo = results_db(tmp_path)      # B1 OK; B2 NOK then OK
    kw = {"position_mm": (1.0, 1.0, 0.0), "match_distance_mm": 1.4, "tilt_deg": 2.0,
          "angle_deg": 320.0}
    loosen = {"pset": 92, "torque": None, "angle": None, "loosen": True}
    repo.record_tightening(VIN, "B2", ok=True, torque_nm=0.0, tightening_id=103,
                           kind=LOOSENING, params_sent=loosen, **kw)
    repo.record_tightening(VIN, "B2", ok=True, torque_nm=50.0, tightening_id=104, **kw)

    async def words() -> dict[str, list[str]]:
        srv = serve(EventBus(), results=Results(repo))
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + f"api/vehicles/{VIN}") as r:
                    doc = await r.json()
            return {b["bolt"]: [x["attempt_words"] for x in b["rundowns"]]
                    for b in doc["bolts"] if b["rundowns"]}
        finally:
            await srv.stop()

    try:
        assert asyncio.run(words()) == {
            "B1": ["1"], "B2": ["1", "2 (repeat)", "3 (loosen pset 92)", "4 (repeat)"]}
        repo.close_vehicle(VIN)                 # closed, then back for rework
        repo.start_vehicle(VIN, "SEDAN", reopen=True)
        repo.record_tightening(VIN, "B1", ok=True, torque_nm=0.0, tightening_id=105,
                               kind=LOOSENING, params_sent=loosen, **kw)
        repo.record_tightening(VIN, "B1", ok=True, torque_nm=50.0, tightening_id=106, **kw)
        assert asyncio.run(words())["B1"] == ["1", "2 (loosen pset 92)", "3 (rework)"]
    finally:
        repo.close()


def test_numpy_values_and_an_odd_event_do_not_stop_the_live_view():
    async def main():
        bus = EventBus()
        srv = serve(bus)
        await srv.start()
        try:
            for e in opened():
                bus.publish(e)
            bus.publish(Localized(point_mm=tuple(np.float32([1.5, 2.0, 3.0])),
                                  tilt_deg=np.float32(2.5), reason=None, candidate="B1",
                                  distance_mm=1.0, age_ms=30.0))
            bus.publish(Localized(point_mm=(1.0,), tilt_deg=None,
                                  reason=None, candidate=None, distance_mm=None, age_ms=1.0))
            bus.publish(StateChanged(state="bolt selected",
                                     reason=StateReason(Because.SELECTED, bolt="B1", pset=1)))
            async with ClientSession() as http:
                for _ in range(100):
                    async with http.get(srv.url + "api/view") as r:
                        v = await r.json()
                    if v["reason"] == "bolt B1 selected":
                        break
                    await asyncio.sleep(0.05)
            assert (v["reason"], v["reason_kind"]) == ("bolt B1 selected", "selected")
            assert srv.errors == 1
            assert abs(v["wrench"]["x"] - 1.5) < 1e-6 and abs(v["wrench"]["tilt"] - 2.5) < 1e-6
        finally:
            await srv.stop()
    asyncio.run(main())


def test_healthz_answers_a_probe_without_the_token_and_says_only_ok_or_fault():
    async def main():
        srv = await _serving_opened(token="a-long-token",  # noqa: S106
                                    devices=("lift", "wrench"))
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + "healthz") as r:
                    assert r.status == 200 and (await r.text()) == "ok\n"
                for path in ("", "api/status", "api/view", "api/vehicles", "cameras",
                             "api/cameras", "healthz/../api/status"):
                    async with http.get(srv.url + path) as r:
                        assert r.status == 401, path
                for e in fault():
                    srv.bus.publish(e)
                while srv.view.state != "fault":
                    await asyncio.sleep(0.02)
                async with http.get(srv.url + "healthz") as r:
                    # nothing of the reason: the probe is not authenticated
                    assert r.status == 503 and (await r.text()) == "fault\n"
                async with http.get(srv.url + "api/status",
                                    headers={"Authorization": "Bearer a-long-token"}) as r:
                    devices = (await r.json())["devices"]
                assert devices["lift"]["ok"] is False and devices["wrench"]["ok"] is True
        finally:
            await srv.stop()
    asyncio.run(main())


def test_a_quiet_station_sends_its_snapshot_again_every_heartbeat(monkeypatch):
    """With nothing to tell, the latest snapshot goes out again every HEARTBEAT_S (and says
    the period): a screen that hears nothing for three of them knows its stream stalled."""
    import time

    import stationd.web.server as server

    monkeypatch.setattr(server, "HEARTBEAT_S", 0.3)

    async def main():
        srv = await _serving_opened()
        try:
            async with ClientSession() as http, http.get(srv.url + "api/events") as stream:
                first = await _read_snapshot(stream)
                assert first["heartbeat_s"] == 0.3
                t0 = time.monotonic()
                again = [await asyncio.wait_for(_read_snapshot(stream), 5) for _ in range(3)]
                took = time.monotonic() - t0
                assert all(a == first for a in again)      # the same view, nothing new
                assert took >= 0.6                          # one per heartbeat, not a spin
        finally:
            await srv.stop()

    asyncio.run(main())


def test_spc_serves_each_groups_last_results_and_limits_and_refuses_a_bad_count(tmp_path):
    repo = results_db(tmp_path)      # B1 OK 50.2; B2 NOK 41.0 then OK 49.7 (pset 1: 45/50/55)

    async def main():
        srv = serve(EventBus(), results=Results(repo))
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + "api/spc") as r:
                    doc = await r.json()
                b2 = next(b for b in doc["bolts"] if b["bolt"] == "B2")
                assert [(p["torque"], p["ok"]) for p in b2["last"]] == [(41.0, False),
                                                                        (49.7, True)]
                assert b2["limits"] == {"torque": {"min": 45, "target": 50, "max": 55},
                                        "angle": {"min": 15, "target": 30, "max": 60}}
                async with http.get(srv.url + "api/spc?last=1") as r:
                    doc = await r.json()
                b2 = next(b for b in doc["bolts"] if b["bolt"] == "B2")
                assert [p["torque"] for p in b2["last"]] == [49.7]
                for bad in ("0", "x", "-3", "100000"):
                    async with http.get(srv.url + f"api/spc?last={bad}") as r:
                        assert r.status == 400 and "last:" in await r.text()
                async with http.get(srv.url + "api/spc?model=SEDAN") as r:
                    assert r.status == 200 and (await r.json())["bolts"]
                async with http.get(srv.url + "api/spc?model=NOPE") as r:   # as `db spc`
                    assert r.status == 404 and "no such model (models: SEDAN)" in await r.text()
        finally:
            await srv.stop()
            repo.close()
    asyncio.run(main())


def test_a_server_started_late_shows_what_the_core_decided_not_what_its_history_lost():
    """A screens' server started hours into a run (its port freed late): the bus's bounded
    history has lost, to the localizations since, the fault of a camera pair and the
    operator's sign-in.  Folding the history alone, the screen said the station was starting
    and every device ok; seeded with the running core's snapshot, it says the fault, with its
    kind and words, and who is signed in, and the events after it are folded on it."""
    from drivers.keeper import FaultKind
    from stationd.station.actions import Publish
    from stationd.station.commands import SignIn
    from stationd.station.inputs import DeviceBack, DeviceFault
    from stationd.words import worded
    from tests.station.test_core import _ready
    from tests.station.test_operator import OLGA

    d = _ready(operator_required=True)
    d.command(1, SignIn(), OLGA)
    d.feed(DeviceFault(d.t, "pair2", FaultKind.DOWN, "pair2: camera unplugged"))
    bus = EventBus(history=50)
    for _, acts in d.log:
        for a in acts:
            if isinstance(a, Publish):
                bus.publish(worded(a.event))
    for i in range(60):     # hours of tracking since, in a history of 50
        bus.publish(Localized(point_mm=None, tilt_deg=None, reason=None, candidate=None,
                              distance_mm=None, age_ms=30.0, allowed=(), t=float(i)))

    async def status(seeded: bool) -> dict:
        srv = serve(bus, devices=("lift", "wrench", "pair1", "pair2"))
        await srv.start()
        try:
            if seeded:
                srv.seed(d.core.status())
            async with ClientSession() as http, http.get(srv.url + "api/status") as r:
                doc: dict[str, Any] = await r.json()
                return doc
        finally:
            await srv.stop()

    lost = asyncio.run(status(seeded=False))
    assert lost["state"] == "starting" and lost["operator"]["user"] is None   # the flaw
    st = asyncio.run(status(seeded=True))
    assert st["state"] == "fault" and st["reason_kind"] == "fault"
    assert {k: st["devices"]["pair2"][k] for k in ("ok", "kind", "reason")} == {
        "ok": False, "kind": "down", "reason": "pair2: camera unplugged"}
    assert st["devices"]["pair1"]["ok"] is True and st["devices"]["lift"]["ok"] is True
    assert st["operator"] == {"user": "olga", "required": True}
    # the events after the snapshot are folded on it: the pair back, the station with it
    view = View(configured=("pair2",))
    view.seed(d.core.status())
    for a in d.feed(DeviceBack(d.t, "pair2", reconnects=1)):
        if isinstance(a, Publish):
            view.apply(worded(a.event))
    assert view.devices["pair2"]["ok"] is True and view.state != "fault"


def test_the_seed_takes_the_calibration_trust_and_the_vehicle_too():
    """A review of the seed: a pair the check found moved, whose PairChecked the history lost,
    showed "pair2: ok"; a vehicle whose opening it lost showed none."""
    from types import MappingProxyType

    from stationd.reasons import Reason, Why
    from stationd.station.events import Because, State, StateReason
    from stationd.station.state import CoreStatus

    moved = Reason(Why.PAIR_MOVED, pair="pair2", reference="R2")
    now = CoreStatus(State.TRACKING, StateReason(Because.TRACKING), MappingProxyType({}),
                     "VIN7", None, False, None, MappingProxyType({"pair2": moved}),
                     model="SEDAN")
    view = View(configured=("pair1", "pair2"))
    view.checks["pair1"] = {"trusted": False, "verdict": "not checked", "words": "x"}
    view.seed(now)
    assert view.checks["pair2"]["trusted"] is False and view.checks["pair2"]["verdict"] == \
        "moved"
    assert view.checks["pair1"]["trusted"] is True      # the core no longer distrusts it
    doc = view.to_json()
    assert doc["vehicle"] == {"vin": "VIN7", "model": "SEDAN", "rework": False,
                              "at_station": True, "reopened_by": None}
    health = doc["devices"]["pair2"]
    assert health["check"]["trusted"] is False and "moved" in health["check"]["words"]


def test_the_screens_results_export_names_the_station_on_every_row(tmp_path):
    """The vehicle's CSV export from the screens names the station that made each result
    (its id as the serve loop gives the server, the one ``/api/status`` says), as the
    command's export does: a plant collects them from several stations."""
    repo = results_db(tmp_path)

    async def main():
        srv = serve(EventBus(), results=Results(repo))
        srv.station = {"id": "ST-07", "config": "/etc/stationd/station.yaml"}
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + f"api/vehicles/{VIN}/export.csv") as r:
                    rows = list(csv.DictReader(io.StringIO(await r.text())))
            assert rows and {x["station"] for x in rows} == {"ST-07"}
        finally:
            await srv.stop()
            repo.close()
    asyncio.run(main())
