"""``stationd demo`` with OPC UA and a line: an MES client subscribed at the demo's endpoint
gets one result event per rundown (IsSimulated true, the vehicle's VIN), and ``--stations 2``
forwards both stations' records to a real PostgreSQL, where the line's results are read back.
The demo runs as a process on one pair of config/sim (two cameras: fast), as a person runs it;
the client is asyncua's, over OPC UA on loopback."""

from __future__ import annotations

import asyncio
import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest
import yaml
from asyncua.client.client import Client
from sqlalchemy import create_engine
from sqlalchemy.pool import NullPool

from stationd.cli import main
from stationd.demo.services import Endpoints, line_summary
from stationd.errors import InputError
from stationd.linedb import results
from stationd.opcua.model import IJT_URI, load_client_types
from stationd.opcua.uatypes import ua
from stationd.sim.vin import is_valid, make_vin
from tests.station.test_daemon_faults import SIM

ROOT = Path(__file__).resolve().parents[2]


def _one_pair(tmp: Path) -> Path:
    """config/sim with pair1 only (two cameras to render); a loaded machine renders late,
    which is not these tests' subject."""
    for f in SIM.glob("*.yaml"):
        (tmp / f.name).write_text(f.read_text())
    doc = yaml.safe_load((tmp / "station.yaml").read_text())
    doc["pairs"] = {"pair1": doc["pairs"]["pair1"]}
    doc["cameras"] = {n: c for n, c in doc["cameras"].items() if n.startswith("pair1_")}
    doc["matching"]["max_age_s"] = 5.0
    path = tmp / "station.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


class Demo:
    """``stationd demo ARGS --json`` as a process; its standard error read line by line."""

    def __init__(self, tmp: Path, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "stationd", "demo", "--config", str(_one_pair(tmp)),
             "--json", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=tmp)
        self.lines: queue.Queue[str] = queue.Queue()
        self.err: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.err.append(line)
            self.lines.put(line.rstrip("\n"))

    def expect(self, pattern: str, timeout: float = 120) -> re.Match[str]:
        while True:
            found = re.search(pattern, self.lines.get(timeout=timeout))
            if found:
                return found

    def summary(self) -> dict[str, Any]:
        out, _ = self.proc.communicate(timeout=120)
        return dict(json.loads(out.strip().splitlines()[-1]))


class Collector:
    def __init__(self) -> None:
        self.events: list[Any] = []

    def event_notification(self, event: Any) -> None:
        self.events.append(event)


@pytest.mark.timeout(300)
def test_a_client_subscribed_at_the_demos_endpoint_gets_an_event_per_rundown(tmp_path):
    demo = Demo(tmp_path, "--cycles", "2", "--seed", "7", "--no-http",
                "--opcua", "127.0.0.1:0", "--hold")
    handler = Collector()

    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        found = await loop.run_in_executor(None, demo.expect, r"^OPC UA: (opc\.tcp://\S+) ")
        async with Client(found.group(1)) as client:   # anonymous, security none
            await load_client_types(client)
            uris = await client.get_namespace_array()
            etype = client.get_node(ua.NodeId(1007, uris.index(IJT_URI)))
            sub = await client.create_subscription(50, handler)
            await sub.subscribe_events(client.nodes.server, etype)
            await loop.run_in_executor(None, demo.expect, r"^run over")
            await asyncio.sleep(1.5)        # the last event's publish cycle

    try:
        asyncio.run(scenario())
    finally:
        demo.proc.send_signal(signal.SIGTERM)
    summary = demo.summary()
    assert demo.proc.returncode == 0, "".join(demo.err)
    assert summary["verdict"].startswith("PASS")
    assert summary["opcua"].startswith("opc.tcp://127.0.0.1:")
    assert summary["recorded"] == summary["results"] >= 2
    assert len(handler.events) == summary["recorded"]
    seqs = []
    for event in handler.events:
        meta = event.Result.ResultMetaData
        assert event.SourceName == "DEMO-1"
        assert meta.IsSimulated is True
        entities = {x.EntityType: x.EntityId for x in meta.AssociatedEntities}
        assert entities[20] == make_vin(1) and is_valid(entities[20])
        seqs.append(meta.SequenceNumber)
    assert seqs == sorted(set(seqs))
    assert "security none" in "".join(demo.err)


@pytest.mark.timeout(300)
def test_two_stations_forward_to_the_line_database_and_the_line_is_read_back(tmp_path, pg_url):
    demo = Demo(tmp_path, "--cycles", "1", "--seed", "7", "--no-http", "--opcua",
                "127.0.0.1:0", "--line-db", pg_url, "--stations", "2")
    summary = demo.summary()
    assert demo.proc.returncode == 0, "".join(demo.err)
    assert summary["verdict"].startswith("PASS") and "1 more station(s) PASS" in \
        summary["verdict"]
    (second,) = summary["stations"]
    assert second["station_id"] == "DEMO-2" and second["opcua"] != summary["opcua"]
    line = summary["line"]
    assert line["all_forwarded"] is True
    assert line["vins"] == [make_vin(1)]          # the vehicle went down the line
    assert line["rundowns"] == summary["recorded"] + second["recorded"]
    engine = create_engine(pg_url, poolclass=NullPool)
    try:
        rows = results(engine)
    finally:
        engine.dispose()
    by_station = {r.station_id for r in rows}
    assert by_station == {"DEMO-1", "DEMO-2"}
    assert line_summary(rows, ["DEMO-1", "DEMO-2"])["stations"] == line["stations"]


def test_a_line_database_that_is_not_postgresql_is_one_line_and_exit_2(capsys):
    code = main(["demo", "--line-db", "sqlite:///line.db", "--cycles", "1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err
    assert "--line-db" in err and "PostgreSQL" in err


def test_opcua_options_that_contradict_or_do_not_parse_are_refused(capsys):
    assert main(["demo", "--opcua", "nowhere", "--cycles", "1"]) == 2
    assert "--opcua" in capsys.readouterr().err
    assert main(["demo", "--opcua", "127.0.0.1:4999", "--no-opcua"]) == 2
    assert main(["demo", "--hold", "--no-http", "--no-opcua"]) == 2
    assert main(["demo", "--stations", "0"]) == 2


def test_the_default_endpoint_moves_to_the_next_free_port_and_says_so():
    import socket

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        busy = held.getsockname()[1]
        taken: set[int] = set()
        endpoint, why = Endpoints("127.0.0.1", busy, given=False).take(taken)
        assert endpoint != f"opc.tcp://127.0.0.1:{busy}"
        assert why == f"{busy} is in use: the next free port"
        second, _ = Endpoints("127.0.0.1", busy, given=False).take(taken)
        assert second != endpoint and len(taken) == 2
        with pytest.raises(InputError, match="in use"):
            Endpoints("127.0.0.1", busy, given=True).take(set())
