"""Run the IJT working group's conformance test client against this station's OPC UA server and
print which of its result and event test cases pass (issue 22; not part of the test suite).

Why a script and not a test: the client (umati/UA-for-Industrial-Joining-Technologies,
``OPC_UA_Clients/Release2/IJT_Test_Client``) is not vendored (its code stays in its
repository), asks for Python 3.14 (3.13 runs it), the asyncua commit it pins and its own
dependencies, and runs for minutes (its set-up: README.md, "The working group's
conformance client").  Here: a station
database in a temporary folder, the server on loopback (anonymous, or the user ``mes`` with the
password ``conformance``), a rundown recorded whenever the client's result trigger asks (a
station has no "simulate a result" method: the client's ``OPCUA_TRIGGER_CLASS`` hook gets a
small trigger, written into the temporary folder, that asks this script over loopback to
record one and returns once its event is published; batch and job results stay "external
trigger required", as for a real controller), each rundown's torque and angle agreeing with
its bolt's limits and its verdict (:func:`rundown`), optionally one every ``--every`` seconds, the
client's pytest run in
its own interpreter (its client logs in only through the URL: ``--user`` puts the user in
it), its summary per test file::

    python -m tests.opcua.ijt_conformance --client PATH/IJT_Test_Client \\
        --python PATH/python3.13 [--tests results events ...] [--user]

The capabilities given to the client claim what this server implements: the base, single
results, result events, GetLatestResult, GetResultById, RequestResults,
RequestUnacknowledgedResults, requested-result events and the RequestedResult variable, and
AcknowledgeResults (for users only: anonymous, its case is refused), and a result's Trace and
StepResults (the station has them when its controller sends curves, as the rundowns recorded
here do); :data:`NOT_CLAIMED` says what is left out and why.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import socket
import sys
import tempfile
import threading
from collections import Counter
from pathlib import Path

from db.bolts import Window
from db.curves import store_curve
from db.repository import BoltInfo, Repository
from stationd.access import hash_password
from stationd.boltfile import import_bolts
from stationd.opcua import OpcUaConfig
from stationd.opcua.results import TRACE_ANGLE, TRACE_TORQUE
from stationd.opcua.server import OpcUaServer
from tests.db.conftest import BASE, record

VIN = "WVWZZZ1JZXW000001"
MODEL = "SEDAN"
CURVE_POINTS = 50
CLAIMED = ("joining_system_base", "joining_system_identification", "result_management",
           "single_result", "basic_result", "result_event_access", "get_latest_result",
           "get_result_by_id", "joining_result_overall_result_values", "result_content",
           "request_results", "request_unacknowledged_results",
           "requested_result_event_access", "requested_result_variable_access",
           "acknowledge_results", "joining_result_trace", "joining_result_step_results")
#: not claimed, though a result event carries AssociatedEntities: the working group's unit
#: "IJT Event Payload Associated Entities" is about JoiningSystemEventType (tool connected,
#: program selected ...), events this station does not fire; claimed, its five cases wait
#: for such an event and skip
NOT_CLAIMED = ("event_payload_associated_entities",)
TESTS = ("results", "events", "specification_tests/test_result_management.py",
         "specification_tests/test_result_access.py", "specification_tests/test_events.py",
         "specification_tests/test_single_result_data.py")
# pytest -rA: "PASSED path::test", "SKIPPED [n] path:line: reason"
_OUTCOME = re.compile(r"^(PASSED|FAILED|SKIPPED|ERROR|XFAIL|XPASS)\s+(?:\[(\d+)\]\s+)?"
                      r"([^:\s]+)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _capabilities(folder: Path) -> Path:
    path = folder / "capabilities.yaml"
    lines = ["server: {name: stationd, vendor: stationd, version: 0.1.0}",
             "active_profile: basic_joining_system", "supported_facets: []", "cu_overrides:"]
    lines += [f"  {cu}: supported" for cu in CLAIMED]
    path.write_text("\n".join(lines) + "\n")
    return path


_TRIGGER = """
import asyncio
from helpers.trigger import ExternalResultTrigger, TriggerOutcome


class StationTrigger(ExternalResultTrigger):
    \"\"\"A single result: one rundown recorded at the station (stationd's conformance run).\"\"\"

    def __init__(self, client, folder, ns_app):
        super().__init__()

    @property
    def is_simulator(self):
        \"\"\"True: a result comes at once whenever asked for, as from the working group's
        simulator (the client's short waits, and its cases that need several results in a
        row, apply); batch and job results are still refused.\"\"\"
        return True

    async def trigger_single(self, result_type, include_traces=False):
        reader, writer = await asyncio.open_connection("127.0.0.1", {port})
        writer.write(b"rundown\\n")
        await writer.drain()
        answer = await reader.readline()
        writer.close()
        return TriggerOutcome(triggered=answer.strip() == b"ok", method="stationd rundown",
                              skip_reason=None if answer.strip() == b"ok" else "not recorded")
"""


def _measured(window: Window | None, ok: bool) -> float | None:
    """A value its ``window`` accepts (its target) for an OK rundown, one beyond its upper
    limit for a NOK one: a fake rundown whose values disagree with its verdict would make
    the client's checks of limits against evaluations meaningless."""
    if window is None:
        return None
    return window.target if ok else window.max + (window.max - window.min) / 2 + 1


def rundown(repo: Repository, vin: str, bolt: BoltInfo, ok: bool, tightening_id: int) -> None:
    """Record a rundown of ``bolt`` whose torque and angle agree with its limits and
    ``ok`` (an unlimited angle: the pset's default of 35 degrees), then its torque and angle
    curves, as a controller that sends curves does (ramps to the final values, 2 ms apart):
    the station's results then carry a Trace and a StepResult naming it."""
    p = bolt.parameters
    angle = _measured(p.angle, True) or 35.0
    torque = _measured(p.torque, ok) or 0.0   # a torque window is always there
    record(repo, vin, bolt.bolt_id, ok=ok, torque_nm=torque, angle_deg=angle,
           parameters_id=bolt.parameters_id, tightening_id=tightening_id)
    for kind, unit, final in ((TRACE_TORQUE, "Nm", torque), (TRACE_ANGLE, "deg", angle)):
        store_curve(repo, tightening_id=tightening_id, trace_type=kind, unit=unit,
                    values=[final * i / (CURVE_POINTS - 1) for i in range(CURVE_POINTS)],
                    sample_period_s=0.002)


class _Rundowns:
    """Rundowns recorded at the station on demand, each returned once its event is out."""

    def __init__(self, repo: Repository, srv: OpcUaServer) -> None:
        self.repo, self.srv, self.n = repo, srv, 0
        self.bolts = repo.bolts_for_model(MODEL)
        self._lock = threading.Lock()

    def record(self) -> None:
        with self._lock:
            rundown(self.repo, VIN, self.bolts[self.n % len(self.bolts)], ok=self.n % 5 != 4,
                    tightening_id=1000 + self.n)
            self.n += 1

    async def one(self) -> bool:
        published = self.srv.published
        await asyncio.get_running_loop().run_in_executor(None, self.record)
        for _ in range(100):
            if self.srv.published > published:
                return True
            await asyncio.sleep(0.05)
        return False

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while await reader.readline():
            writer.write(b"ok\n" if await self.one() else b"no\n")
            await writer.drain()
        writer.close()


def _feeder(rundowns: _Rundowns, every: float, stop: threading.Event) -> None:
    while every > 0 and not stop.wait(every):
        rundowns.record()


async def _run(args: argparse.Namespace) -> int:
    folder = Path(tempfile.mkdtemp(prefix="ijt-conformance-"))
    table = folder / "bolts.yaml"
    table.write_text(BASE)
    repo = Repository.open(f"sqlite:///{folder / 'station.db'}")
    import_bolts(repo, table)
    repo.start_vehicle(VIN, MODEL)
    for n, bolt in enumerate(repo.bolts_for_model(MODEL)):
        rundown(repo, VIN, bolt, ok=True, tightening_id=n + 1)
    port = _free_port()
    cfg = OpcUaConfig(endpoint=f"opc.tcp://127.0.0.1:{port}", station_id="ST-IJT",
                      security=("none",), users={"mes": hash_password("conformance")})
    srv = OpcUaServer(cfg, simulated=True)
    await srv.start()
    stop = asyncio.Event()
    task = asyncio.create_task(srv.run(stop, repo))
    rundowns = _Rundowns(repo, srv)
    trigger = await asyncio.start_server(rundowns.serve, "127.0.0.1", 0)
    trigger_port = trigger.sockets[0].getsockname()[1]
    (folder / "stationd_trigger.py").write_text(_TRIGGER.replace("{port}", str(trigger_port)))
    feeding = threading.Event()
    feeder = threading.Thread(target=_feeder, args=(rundowns, args.every, feeding),
                              daemon=True)
    feeder.start()
    login = "mes:conformance@" if args.user else ""   # asyncua reads a user from the URL
    env = {**os.environ, "OPCUA_SERVER_URL": f"opc.tcp://{login}127.0.0.1:{port}",
           "OPCUA_CAPABILITIES_FILE": str(_capabilities(folder)),
           "OPCUA_TRIGGER_CLASS": "stationd_trigger.StationTrigger",
           "PYTHONPATH": f"{folder}{os.pathsep}{args.client}"}
    log_path = folder / "client.log"
    print(f"the client's output: {log_path}", flush=True)
    try:
        with log_path.open("wb") as log:   # as it goes: a long run can be followed
            proc = await asyncio.create_subprocess_exec(
                args.python, "-m", "pytest", "-rA", "-q", "-p", "no:cacheprovider",
                "--timeout", str(args.timeout), *args.tests, cwd=args.client, env=env,
                stdout=log, stderr=asyncio.subprocess.STDOUT)
            await proc.wait()
    finally:
        feeding.set()
        trigger.close()
        stop.set()
        await task
        await srv.stop()
        repo.close()
    text = log_path.read_text(errors="replace")
    per_file: dict[str, Counter[str]] = {}
    for line in text.splitlines():
        m = _OUTCOME.match(line)
        if m:
            per_file.setdefault(m.group(3), Counter())[m.group(1)] += int(m.group(2) or 1)
    total: Counter[str] = Counter()
    for name, counts in sorted(per_file.items()):
        total.update(counts)
        print(f"{name}: " + ", ".join(f"{k.lower()} {v}" for k, v in sorted(counts.items())))
    print("total: " + ", ".join(f"{k.lower()} {v}" for k, v in sorted(total.items())))
    return 0 if per_file else 2


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--client", type=Path, required=True, help="the IJT_Test_Client folder")
    p.add_argument("--python", default=sys.executable, help="the client's interpreter")
    p.add_argument("--tests", nargs="+", default=list(TESTS), help="its test paths")
    p.add_argument("--every", type=float, default=0.0,
                   help="seconds between rundowns besides the triggered ones (0: none)")
    p.add_argument("--user", action="store_true", help="log in as the user mes")
    p.add_argument("--timeout", type=int, default=60, help="seconds per client test")
    args = p.parse_args(argv)
    if not (args.client / "conftest.py").is_file():
        print(f"{args.client}: not the IJT_Test_Client folder (no conftest.py)",
              file=sys.stderr)
        return 2
    return asyncio.run(_run(args))


if __name__ == "__main__":
    sys.exit(main())
