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
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
import yaml
from sqlalchemy import create_engine
from sqlalchemy.pool import NullPool

from drivers.counting import counted
from stationd.cli import main
from stationd.demo.services import Endpoints, line_summary
from stationd.errors import InputError
from stationd.linedb import results
from stationd.opcua.model import IJT_URI, MACHINERY_URI, RESULT_URI, load_client_types
from stationd.opcua.server import NAMESPACE
from stationd.opcua.uatypes import ua
from stationd.sim.vin import is_valid
from tests.shell.daemons import SIM
from tests.uaclient import Client

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

    def __init__(self, tmp: Path, *args: str, env: dict[str, str] | None = None) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "stationd", "demo", "--config", str(_one_pair(tmp)),
             "--json", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}, cwd=tmp)
        self.lines: queue.Queue[str] = queue.Queue()
        self.err: list[str] = []
        self.pump = threading.Thread(target=self._pump, daemon=True)
        self.pump.start()

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
        """The last line of standard output, once the demo ended and ``err`` has every line
        of its standard error (read by the pump alone: two readers would split it)."""
        assert self.proc.stdout is not None
        out = self.proc.stdout.read()
        self.proc.wait(timeout=120)
        self.pump.join(timeout=30)
        return dict(json.loads(out.strip().splitlines()[-1]))


class Collector:
    def __init__(self) -> None:
        self.events: list[Any] = []

    def event_notification(self, event: Any) -> None:
        self.events.append(event)


@pytest.mark.timeout(300)
def test_a_client_subscribed_at_the_demos_endpoint_gets_an_event_per_rundown(tmp_path):
    """Live events from the moment the client subscribed (on a loaded machine the run may
    start before it), and the ones before by RequestResults, as an MES that came late asks:
    together one event per rundown, none twice, no live one missing after the first."""
    demo = Demo(tmp_path, "--cycles", "2", "--seed", "7", "--no-http",
                "--opcua", "127.0.0.1:0", "--hold")
    handler = Collector()
    requested_types: set[Any] = set()

    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        found = await loop.run_in_executor(None, demo.expect, r"^OPC UA: (opc\.tcp://\S+) ")
        async with Client(found.group(1)) as client:   # anonymous, security none
            await load_client_types(client)
            uris = await client.get_namespace_array()
            ijt = uris.index(IJT_URI)
            etype = client.get_node(ua.NodeId(1007, ijt))
            sub = await client.create_subscription(50, handler)
            await sub.subscribe_events(client.nodes.server, etype)
            await loop.run_in_executor(None, demo.expect, r"^run over")
            await asyncio.sleep(1.5)        # the last event's publish cycle
            requested_types.update(c.nodeid for c in await client.get_node(
                ua.NodeId(1035, ijt)).get_children(refs=ua.ObjectIds.HasSubtype))
            machines = await client.nodes.objects.get_child(
                [f"{uris.index(MACHINERY_URI)}:Machines"])
            station = await machines.get_child([f"{uris.index(NAMESPACE)}:DEMO-1"])
            rm = await station.get_child([f"{uris.index(RESULT_URI)}:ResultManagement"])
            null = datetime(1601, 1, 1, tzinfo=UTC)
            out = await rm.call_method(     # 0, 0 and null times: every result
                f"{ijt}:RequestResults", ua.Variant(0, ua.VariantType.UInt64),
                ua.Variant(0, ua.VariantType.UInt64), ua.Variant(null, ua.VariantType.DateTime),
                ua.Variant(null, ua.VariantType.DateTime), ua.Variant(0.0, ua.VariantType.Double))
            assert out[1] == 0, out
            await asyncio.sleep(1.5)        # the requested results, 5 ms apart, and a cycle

    try:
        asyncio.run(scenario())
    finally:
        demo.proc.send_signal(signal.SIGTERM)
    summary = demo.summary()
    assert demo.proc.returncode == 0, "".join(demo.err)
    assert summary["verdict"].startswith("PASS")
    assert summary["opcua"].startswith("opc.tcp://127.0.0.1:")
    assert summary["recorded"] == summary["results"] >= 2
    live = [e for e in handler.events if e.EventType not in requested_types]
    asked = [e for e in handler.events if e.EventType in requested_types]
    for event in handler.events:
        meta = event.Result.ResultMetaData
        assert event.SourceName == "DEMO-1"
        assert meta.IsSimulated is True
        entities = {x.EntityType: x.EntityId for x in meta.AssociatedEntities}
        assert entities[20] == summary["vin"] and is_valid(entities[20])
    # every rundown asked for once, and the live ones a tail of them with none missing
    asked_seqs = [e.Result.ResultMetaData.SequenceNumber for e in asked]
    live_seqs = [e.Result.ResultMetaData.SequenceNumber for e in live]
    assert len(asked_seqs) == summary["recorded"] and asked_seqs == sorted(set(asked_seqs))
    assert live_seqs == asked_seqs[len(asked_seqs) - len(live_seqs):]
    assert {e.Result.ResultMetaData.ResultId for e in live} <= \
        {e.Result.ResultMetaData.ResultId for e in asked}
    assert "security none" in "".join(demo.err)


@pytest.mark.timeout(300)
def test_two_stations_forward_to_the_line_database_and_the_line_is_read_back(tmp_path, pg_url):
    demo = Demo(tmp_path, "--cycles", "1", "--seed", "7", "--no-http", "--opcua",
                "127.0.0.1:0", "--line-db", pg_url, "--stations", "2")
    summary = demo.summary()
    assert demo.proc.returncode == 0, "".join(demo.err)
    # the verdict and a total over both stations; the first station's keys as they were
    assert summary["verdict"].startswith("PASS: all 2 stations, "), summary["verdict"]
    (second,) = summary["stations"]
    every = summary["all_stations"]
    assert every["stations"] == ["DEMO-1", "DEMO-2"]
    assert every["ok"] == summary["ok"] + second["ok"]
    assert every["recorded"] == summary["recorded"] + second["recorded"]
    assert sum(every["operators"].values()) == every["recorded"]
    assert second["station_id"] == "DEMO-2" and second["opcua"] != summary["opcua"]
    line = summary["line"]
    assert line["all_forwarded"] is True and line["missing"] == 0
    # every station's records against the line's, read back at the end
    for sid, p in line["arrival"].items():
        assert p["arrived"] == p["records"] > 0, sid
    assert line["vins"] == [summary["vin"]]       # the vehicle went down the line
    assert line["rundowns"] == summary["recorded"] + second["recorded"]
    # each station tightened its own bolts: disjoint shares, said at the start
    assert summary["share"] and second["share"]
    assert not set(summary["share"]) & set(second["share"])
    for sid, share in (("DEMO-1", summary["share"]), ("DEMO-2", second["share"])):
        assert set(line["stations"][sid]["bolts"]) <= set(share)
    err = "".join(demo.err)
    assert "each tightens its own bolts of the same vehicle" in err
    for sid in ("DEMO-1", "DEMO-2"):
        assert re.search(rf"^{sid} tightens its own bolts, \d+ of the \d+ in view: ", err,
                         re.M), err
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


def test_an_explicit_screens_port_in_use_is_refused_at_start(capsys):
    """``--http`` on a busy port ran without screens ("tried again every 5 s") and exited 0;
    the user chose that port: refused as ``--opcua``'s is."""
    import socket

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        busy = held.getsockname()[1]
        code = main(["demo", "--http", f"127.0.0.1:{busy}", "--cycles", "1", "--no-opcua"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err
    assert f"--http 127.0.0.1:{busy}: the port is in use" in err


def test_the_default_screens_port_in_use_moves_to_the_next_free_one_and_says_so():
    """Without ``--http`` (the station file's http.listen, config/sim's 127.0.0.1:8080), a
    port in use left the demo's screens unserved ("tried again every 5 s") while OPC UA moved
    on: they move on too, and say where; ``--http`` keeps the port it names."""
    import argparse
    import socket
    from dataclasses import replace

    from stationd.config import load_station_config
    from stationd.demo.station import SIM_CONFIG, _listen
    from stationd.web.config import HttpConfig

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        busy = held.getsockname()[1]
        cfg = replace(load_station_config(SIM_CONFIG), http=HttpConfig(f"127.0.0.1:{busy}"))
        listen, why = _listen(argparse.Namespace(http=None, no_http=False), cfg)
        assert listen is not None and listen.startswith("127.0.0.1:")
        assert int(listen.rpartition(":")[2]) > busy
        assert why == f"{busy} is in use: the next free port; commands give --url"
        given = _listen(argparse.Namespace(http=f"127.0.0.1:{busy}", no_http=False), cfg)
        assert given == (f"127.0.0.1:{busy}", None)
    assert _listen(argparse.Namespace(http=None, no_http=True), cfg) == (None, None)


def _kept(summary: dict[str, Any], err: str, temp: Path, missing: int) -> None:
    """The demo's folder is kept with its station database, whose unforwarded records are
    said (``kept``, and one line before the summary) and which no later demo's sweep removes
    (no pid file); ``summary["kept_folder"]`` set to its name."""
    from stationd.demo.leftovers import PID_FILE, PREFIX, sweep

    [(sid, where)] = summary["kept"].items()
    db = Path(where.rsplit(" (", 1)[0])
    assert sid == "DEMO-1" and where == f"{db} ({counted(missing, 'record')})"
    assert db.is_file() and db.parent.parent.parent == temp, where
    folder = db.parent.parent
    assert folder.name.startswith(PREFIX) and not (folder / PID_FILE).exists()
    assert (f"records not forwarded to the line database, kept (the demo's folder is not "
            f"removed): DEMO-1 {where}; ") in err
    sweep(temp)
    assert db.is_file()
    summary["kept_folder"] = folder.name


@pytest.mark.timeout(300)
def test_a_line_database_that_never_answers_is_a_fail_that_counts_the_lost_records(tmp_path):
    """``--line-db`` on a port where nothing listens: PASS and exit 0 before, the records
    gone with the demo's temporary database unsaid; said at the start now too.  Also: the
    demo's start removes the folders demos killed with SIGKILL left behind (their process
    gone), not a live one's."""
    import socket

    from stationd.demo.leftovers import PID_FILE, PREFIX

    with socket.socket() as s:                   # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    temp = tmp_path / "temp"
    temp.mkdir()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    (temp / f"{PREFIX}killed").mkdir()
    (temp / f"{PREFIX}killed" / PID_FILE).write_text(f"{gone.pid} -\n")
    (temp / f"{PREFIX}live").mkdir()
    (temp / f"{PREFIX}live" / PID_FILE).write_text(f"{os.getpid()} -\n")
    demo = Demo(tmp_path, "--cycles", "1", "--seed", "7", "--no-http", "--no-opcua",
                "--line-db", f"postgresql+psycopg://line@127.0.0.1:{port}/line",
                env={"TMPDIR": str(temp)})
    summary = demo.summary()
    err = "".join(demo.err)
    assert demo.proc.returncode == 1, err
    line = summary["line"]
    assert line["missing"] == line["arrival"]["DEMO-1"]["missing"] >= summary["recorded"]
    assert line["missing_rundowns"] == summary["recorded"] >= 1
    assert summary["verdict"] == (f"FAIL: {counted(line['missing'], 'record')} "
                                  f"({counted(summary['recorded'], 'rundown')}) did not "
                                  "reach the line database")
    assert line["error"] == f"the line database at 127.0.0.1:{port} does not answer " \
        "(connection refused)"
    assert f"line database: not read back: {line['error']}; {counted(line['missing'], 'record')}" \
        in err
    # ... and said at the start (issue 30), in one line, before the run: what happens and
    # what to do, not only at the end
    start = (f"line database: {line['error']} at the start; the demo runs and its forwarder "
             "keeps trying, but records it has not handed over by the end are not in the "
             "line database (verdict FAIL; the demo keeps its station database with them): "
             "start the line database, or give another --line-db\n")
    assert err.count(start) == 1 and err.index(start) < err.index("vehicle: "), err[:3000]
    assert "they stay in the demo's station database, kept when the demo ends" in err
    assert "OperationalError" not in err and "Traceback" not in err
    # the killed demo's folder removed, the live one's not; this demo's kept with the
    # records the line database never took (their only copy), said where
    _kept(summary, err, temp, line["missing"])
    assert sorted(p.name for p in temp.iterdir() if p.name != summary["kept_folder"]) == [
        f"{PREFIX}live"]


@pytest.mark.timeout(300)
def test_a_role_that_may_not_write_the_line_is_a_fail_and_keeps_the_records(tmp_path, pg_url):
    """The trial: a role that connects but has no privilege on the line's tables (made by
    another role) had every record quarantined, the verdict "PASS ... every result
    recorded", exit 0, and the station database removed: every record lost.  Now the start
    says the role cannot write, the records wait, the verdict is FAIL and the station
    database is kept."""
    from tests.test_forward import _as_role

    other = _as_role(pg_url, "demo_noprivs")
    temp = tmp_path / "temp"
    temp.mkdir()
    demo = Demo(tmp_path, "--cycles", "2", "--seed", "7", "--no-http", "--no-opcua",
                "--line-db", other, env={"TMPDIR": str(temp)})
    summary = demo.summary()
    err = "".join(demo.err)
    assert demo.proc.returncode == 1, err
    assert "for good" not in err and "quarantine" not in err, err
    line = summary["line"]
    assert line["missing"] >= summary["recorded"] >= 1
    assert summary["verdict"].startswith(f"FAIL: {counted(line['missing'], 'record')} ")
    assert "permission denied" in line["error"]          # the read-back, as this role
    assert re.search(r"^line database: the line database at \S+: role demo_noprivs lacks "
                     r"INSERT and SELECT on line_feed, INSERT on line_parameters: .* at the "
                     r"start; ", err, re.M), err[:3000]
    _kept(summary, err, temp, line["missing"])
