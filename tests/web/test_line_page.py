"""The line page over real HTTP on loopback, reading a real PostgreSQL the forwarders wrote:
a VIN's rundowns at every station, newest first; no line section, a line database away and a
bad limit each answer one readable line."""

from __future__ import annotations

import asyncio
import time

from aiohttp import ClientSession

from db.repository import Repository
from stationd.boltfile import import_bolts
from stationd.bus import EventBus
from stationd.forward import Forwarder, LineConfig
from stationd.web.server import WebServer
from tests.db.conftest import BASE, record

VIN = "9SDST0010TL000001"


def _forwarded(tmp_path, url):
    table = tmp_path / "bolts.yaml"
    table.write_text(BASE)
    for sid, bolt in (("ST-A", "B1"), ("ST-B", "B2")):
        repo = Repository.open(f"sqlite:///{tmp_path / sid}.db")
        import_bolts(repo, table)
        repo.start_vehicle(VIN, "SEDAN")
        record(repo, VIN, bolt, ok=sid == "ST-A", tightening_id=1)
        time.sleep(0.01)
        f = Forwarder(repo, LineConfig(url, sid))
        f.step()
        f.line.dispose()
        repo.close()


def test_the_line_page_shows_every_stations_rundowns(tmp_path, pg_url, pg_server):
    _forwarded(tmp_path, pg_url)

    async def main() -> None:
        srv = WebServer(EventBus(), listen="127.0.0.1:0")
        await srv.start()
        try:
            async with ClientSession() as http:
                async with http.get(srv.url + "api/line/results") as r:
                    assert r.status == 404 and "no line section" in await r.text()
                srv.line_results.url = pg_url
                async with http.get(srv.url + f"api/line/results?vin={VIN}") as r:
                    doc = await r.json()
                assert [(x["station_id"], x["bolt"], x["ok"]) for x in doc["rundowns"]] == [
                    ("ST-B", "B2", False), ("ST-A", "B1", True)]
                assert doc["rundowns"][0]["parameters_version"] == 1
                async with http.get(srv.url + "api/line/results?station=ST-A&vin=") as r:
                    assert [x["bolt"] for x in (await r.json())["rundowns"]] == ["B1"]
                async with http.get(srv.url + "api/line/results?limit=0") as r:
                    assert r.status == 400 and "limit" in await r.text()
                async with http.get(srv.url + "line") as r:
                    assert r.status == 200 and "The line's results" in await r.text()
                async with http.get(srv.url + "static/line.js") as r:
                    assert "/api/line/results" in await r.text()
                srv.line_results.url = pg_url.replace(f":{pg_server.port}/", ":1/")
                async with http.get(srv.url + "api/line/results") as r:
                    text = await r.text()
                    assert r.status == 503 and "unreachable" in text
                    assert len(text.strip().splitlines()) == 1
        finally:
            await srv.stop()

    asyncio.run(main())
