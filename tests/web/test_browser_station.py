"""The screens against the real main job and the real daemon, in both browsers.

``stationd demo --hold`` runs as a subprocess (the simulated station over loopback Modbus and
Open Protocol, eight rendering cameras): the operator screen's counters and colours follow the
simulated operator, the cameras screen shows the simulated cameras' frames with their
detection overlay, and the vehicle's page lists exactly the rundowns the demo printed, with
CSV and JSON exports that download them.  Then the daemon (``stationd.shell.serve.serve``, as
systemd runs it) on a copy of config/sim whose lift PLC is not answering: the operator screen
says FAULT and names the lift.
"""

from __future__ import annotations

import csv
import io
import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from drivers.wrench.sim.controller import SimController
from stationd.sim.devices_cli import psets_of
from stationd.sim.vin import is_valid, make_vin
from tests.shell.daemons import SIM, Proc, free_port
from tests.web.pages import Page
from tests.web.test_browser import check_fits

ROOT = Path(__file__).resolve().parents[2]
#: the demo's vehicle: a 17-character VIN (ISO 3779), its serial part the run's id
VEHICLE = r"^vehicle: (\w{17}) \(this run's own VIN: run id (\d{6})"
CYCLES = 10   # the run must outlast the walk to the cameras screen (a bolt takes ~2 s)
ICONS = {"OK": "\u2714", "NOK": "\u2716"}          # operator.js: a check mark, a cross
# the bolt's line: its result, then the torque (a NOK names the quantity that failed first)
LINE = re.compile(r"^(B\w+): pset (\d+), XY error [^,]+, (OK|NOK)\b.*?([\d.]+) Nm")


class Demo:
    """``stationd demo --hold`` in a subprocess; its stdout lines in a queue as they come."""

    def __init__(self, tmp: Path) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self.err = (tmp / "demo.err").open("w")
        env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
        self.p = subprocess.Popen(
            [sys.executable, "-m", "stationd", "demo", "--cycles", str(CYCLES), "--seed", "3",
             "--http", "127.0.0.1:0", "--hold"],
            cwd=tmp, env=env, stdout=subprocess.PIPE, stderr=self.err, text=True)
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            self.lines.put(line.rstrip("\n"))

    def expect(self, pattern: str, timeout: float = 60.0) -> re.Match[str]:
        """The next stdout line matching ``pattern`` (earlier ones are kept in ``seen``)."""
        rx = re.compile(pattern)
        while True:
            try:
                line = self.lines.get(timeout=timeout)
            except queue.Empty:
                raise AssertionError(f"{pattern!r} not printed; stdout so far: {self.seen}"
                                     ) from None
            self.seen.append(line)
            m = rx.search(line)
            if m:
                return m

    def stop(self) -> int:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
        try:
            return self.p.wait(60)
        finally:
            self.err.close()

    def kill(self) -> None:
        if self.p.poll() is None:
            self.p.kill()
            self.p.wait()


def marks(page: Page) -> dict[str, tuple[str, str, str]]:
    """Bolt -> (state, icon, title): on config/sim's dense 50-bolt map a done bolt keeps its
    icon and its hover title, not a state word (only the bolts that matter now keep those)."""
    got = page.js(
        "return [...document.querySelectorAll('#bolts g.bolt')].map(g => [g.dataset.bolt,"
        " g.dataset.state, g.querySelector('text.icon').textContent,"
        " g.querySelector('title').textContent])")
    return {b: (s, i, t) for b, s, i, t in got}


def counters(page: Page) -> tuple[int, int, int]:
    got = page.js("return ['done', 'total', 'nok'].map(i => document.getElementById(i)"
                  ".textContent)")
    return int(got[0]), int(got[1]), int(got[2])


@pytest.mark.timeout(240)
def test_demo_screens_follow_the_simulated_operator(page, shots, tmp_path):
    demo = Demo(tmp_path)
    try:
        found = demo.expect(VEHICLE)
        vin, run = found[1], found[2]
        assert is_valid(vin) and vin == make_vin(int(run))
        url = demo.expect(r"^screens: (http://127\.0\.0\.1:\d+/) \(operator\)")[1]
        page.get(url)
        page.wait(lambda p: p.text("#vin") == vin, 60, "the demo's vehicle")
        assert counters(page)[1] == 50                   # config/sim's model: 50 bolts
        # the done counter, sampled as the operator works: it only rises, to the first result
        done_seen = [counters(page)[0]]

        def first_done(p: Page) -> bool:
            done_seen.append(counters(p)[0])
            return bool(done_seen[-1] >= 1)
        page.wait(first_done, 90, "the first bolt done")
        first = LINE.match(demo.expect(LINE.pattern, 30)[0])
        assert first is not None
        state, icon, title = page.wait(lambda p: marks(p).get(first[1]), 10, "the bolt")
        assert state == first[3].lower() and title.startswith(f"{first[1]}: {first[3]}")
        assert icon == ICONS[first[3]]
        # the vehicle is open: the bolts not tightened yet are to do (or next), not "missing"
        # (a newcomer saw every bolt of an open vehicle drawn missing)
        open_states = {s for b, (s, _, _) in marks(page).items() if b != first[1]}
        assert open_states <= {"pending", "next", "selected", "tightening", "blocked"}, \
            open_states
        check_fits(page, "#bolts", "#headline", "#done")
        shots("demo-operator")

        # the cameras screen: the eight simulated cameras' frames, the marker found with its
        # ellipses while the wrench is on the next bolt
        page.get(url + "cameras")
        page.wait(lambda p: p.js("const i = [...document.querySelectorAll('.cam img')];"
                                 " return i.length === 8 && i.every(x => x.naturalWidth > 0)"),
                  30, "8 camera frames loaded")
        found = page.wait(lambda p: p.js(
            "return [...document.querySelectorAll('.cam')].filter(c =>"
            " c.querySelectorAll('svg ellipse').length >= 1 && c.querySelector('svg rect.roi')"
            " && c.innerText.includes('marker found')).map(c => c.dataset.camera)"),
            60, "a camera with the marker found and its overlay")
        assert all(re.fullmatch(r"pair\d/(left|right)", c) for c in found), found
        # each pair titled by its name once ("pair1", not "pair pair1")
        assert page.js("return [...document.querySelectorAll('#pairs h2')]"
                       ".map(h => h.textContent)") == ["pair1", "pair2", "pair3", "pair4"]
        text = page.text(f".cam[data-camera='{found[0]}']") or ""
        assert "5472x3648" in text and "sharpness" in text
        shots("demo-cameras")

        # back to the operator: every bolt printed is on the map with its result
        page.get(url)
        for _ in range(CYCLES - 1):
            demo.expect(LINE.pattern, 60)
        demo.expect(r"^run over \(\d+/\d+ bolts OK\); still serving", 30)
        printed = {m[1]: m for m in map(LINE.match, demo.seen) if m}
        assert len(printed) == CYCLES
        page.wait(lambda p: counters(p)[0] == CYCLES, 30, f"done = {CYCLES}")
        done_seen.append(counters(page)[0])
        assert done_seen == sorted(done_seen) and done_seen[0] < done_seen[-1] == CYCLES
        nok = sum(1 for m in printed.values() if m[3] == "NOK")
        assert counters(page) == (CYCLES, 50, nok)
        # the demo lowers the lift at the end of its run: the vehicle closes, and the bolts
        # it did not tighten are "missing" (none is left "next" on a vehicle that left)
        page.wait(lambda p: "closed" in (p.text("#headline") or ""), 30, "vehicle closed")
        on_map = marks(page)
        for bolt, m in printed.items():
            state, icon, title = on_map[bolt]
            assert (state, icon) == (m[3].lower(), ICONS[m[3]])
            assert title.startswith(f"{bolt}: {m[3]}")
        assert {s for b, (s, _, _) in on_map.items() if b not in printed} == {"missing"}

        # the results: the vehicle's page lists the printed rundowns; both exports download
        page.get(url + f"vehicles/{vin}")
        # a row per rundown, at least one per bolt of the model; those not tightened say so
        page.wait(lambda p: p.js("return new Set([...document.querySelectorAll("
                                 "'tr.rundown')].map(r => r.dataset.bolt)).size") == 50, 30,
                  "the model's 50 bolts")
        rows = [(b, t) for b, t in page.js("return [...document.querySelectorAll('tr.rundown')]"
                                           ".map(r => [r.dataset.bolt, r.innerText])")
                if "not tightened" not in t]
        # a bolt the demo's operator tightened NOK first has a row per rundown: its last one
        # is the printed result
        rows = list({b: t for b, t in rows}.items())
        assert sorted(b for b, _ in rows) == sorted(printed)
        ending = [b for b, p in printed.items() if p[3] == "NOK"]
        assert (f"bolts: {len(printed) - nok} OK, {nok} ending NOK"
                + (f" ({', '.join(sorted(ending))})" if ending else "")
                + f", 0 skipped, {50 - CYCLES} missing") in (page.text("#summary") or ""), (
                    page.text("#summary"))
        for b, text in rows:
            assert printed[b][3] in text and printed[b][4] in text     # status and torque
        check_fits(page, "#rundowns", long=True)
        shots("demo-vehicle")
        page.click("#csv")
        got = list(csv.DictReader(io.StringIO(
            page.wait_download(f"{vin}.csv").read_text())))
        # each bolt's rundowns (a release a row of its own among them), then the model's
        # other bolts, as missing
        done = [r for r in got if r["status"] not in ("missing", "released")]
        last = list({r["bolt"]: r for r in done}.values())   # each bolt's last rundown
        assert sorted((r["bolt"], r["status"]) for r in last) == \
            sorted((b, m[3].lower()) for b, m in printed.items())
        missing = [k for k, r in enumerate(got) if r["status"] == "missing"]
        assert missing == list(range(len(got) - len(missing), len(got)))
        assert sorted(got[k]["bolt"] for k in missing) == \
            sorted(b for b, (s, _, _) in on_map.items() if b not in printed)
        for r in last:
            assert abs(float(r["torque_nm"]) - float(printed[r["bolt"]][4])) < 0.051
        page.click("#json")
        doc = json.loads(page.wait_download(f"{vin}.json").read_text())
        runs = {b["bolt"]: b["rundowns"] for b in doc["bolts"] if b["rundowns"]}
        assert set(runs) == set(printed)
        assert all(r[-1]["rundown"] == "tightening" for r in runs.values())
        assert demo.stop() == 0
    finally:
        demo.kill()


@pytest.mark.timeout(240)
def test_daemon_with_its_lift_down_shows_fault_naming_the_lift(page, shots, tmp_path):
    http_port, lift_port, ctl_port = free_port(), free_port(), free_port()
    ctl = SimController(psets_of(SIM / "bolts.yaml"), seed=2, nok_rate=0.0)
    ctl.start()
    ctl.listen_tcp(port=ctl_port)       # the controller answers; the lift PLC never does

    def serve_screens(text: str) -> str:
        return text + f"\nhttp: {{listen: '127.0.0.1:{http_port}'}}\n"

    d = Proc(tmp_path, lift_port, ctl_port, edit=serve_screens)
    try:
        d.wait_log("fault: lift")
        page.get(f"http://127.0.0.1:{http_port}/")
        head = page.wait(lambda p: p.text("#headline") if "FAULT" in (p.text("#headline")
                                                                       or "") else None,
                         30, "FAULT on the operator screen")
        assert "lift" in head and f"127.0.0.1:{lift_port}" in head, head
        assert "stop" in page.js("return document.getElementById('headline').className")
        cls = page.js("const li = document.querySelector('#devices li[data-device=lift]');"
                      " return li && li.className")
        assert cls == "dev-bad"
        check_fits(page, "#bolts", "#headline")
        shots("daemon-lift-fault")
        assert d.stop() == 0
    finally:
        d.kill()
        ctl.close()
