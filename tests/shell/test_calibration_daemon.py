"""The calibration check through the running daemon, in the simulator (its lift PLC over Modbus
and its controller over Open Protocol, its cameras rendering the reference markers): vehicle 1
is tightened once its pairs are checked; pair2 is knocked before vehicle 2 arrives, the check
at the arrival finds it moved (journal, ``PairChecked``), a bolt only pair2 sees is refused
with that figure and nothing is sent for it while pair1's bolts still work; pair2 put back,
the next check (a person's command) trusts it again; after a restart no pair is trusted until
checked.  Every parameter send is checked when it happens: each pair that localized the
wrench was trusted at that moment."""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from stationd.config import load_station_config
from stationd.demo.station import simulators
from stationd.localize import Localization
from stationd.reasons import Why
from stationd.shell.daemon import Station
from stationd.sim.devices_cli import psets_of
from stationd.sim.render import Scene
from stationd.sim.world import World, wrench_at
from stationd.station.actions import SendParams
from stationd.station.commands import CheckCalibration, Issuer, Right
from stationd.station.events import Localized, PairChecked, ResultRecorded, VehicleClosed
from stationd.station.trust import MeasureReferences
from stationd.words import check_asked_words, reason_words, state_words
from tests.shell.daemons import running, until_async
from tests.shell.refstation import station_dir

PAIRS = ("pair1", "pair2")
B1, B2, B9 = "B01", "B02", "B09"   # seen by pair1, pair2, pair1 only (the simulator's table)
ENGINEER = Issuer("erik", frozenset({Right.CALIBRATE}), "cli 127.0.0.1")
#: the simulator renders 20 MP frames on shared cores: old frames are accepted (the wiring is
#: tested here; freshness is the core's, tested in test_core)
MAX_AGE_S = 30.0


class Run:
    """A station on the file with its simulated world, every action seen before it is done."""

    def __init__(self, cfg: Any, world: World) -> None:
        self.world = world
        self.st = Station(cfg, device_kw={"wrench": {"psets": psets_of(cfg.bolts_path)}})
        self.st.on_action = self._seen
        self.sends: list[str] = []
        self.untrusted_sends: list[tuple[str, tuple[str, ...], dict[str, Any]]] = []
        self.measures: list[str] = []   # why each check was measured, in words
        self.st.open()
        assert self.st.repo is not None
        self.bolts = {b.bolt_id: np.array(b.position)
                      for b in self.st.repo.bolts_for_model("SIM-1")}
        self.rng = np.random.default_rng(4)

    def _seen(self, a: Any) -> None:
        """The test's invariant, at the moment of each send: every pair that made the bolt
        end was trusted."""
        if isinstance(a, MeasureReferences):
            self.measures.append(check_asked_words(a.why))
        if not isinstance(a, SendParams):
            return
        self.sends.append(a.bolt)
        loc = a.selection.evidence
        pairs = loc.pairs if isinstance(loc, Localization) else ()
        trust = self.st.core.trust
        why = trust.untrusted() if trust is not None else {}
        if not pairs or any(p in why for p in pairs):
            self.untrusted_sends.append((a.bolt, pairs, why))

    def checks(self, pair: str) -> list[PairChecked]:
        return [e for e in self.st.bus.of(PairChecked)
                if isinstance(e, PairChecked) and e.pair == pair]

    def on(self, bolt: str | None) -> None:
        self.world.set_wrench(None if bolt is None else wrench_at(
            self.bolts[bolt], self.rng, self.st.cfg.tool.length_mm, 3.0))

    async def tighten(self, bolt: str) -> None:
        """The wrench on ``bolt`` until the tool is on, a trigger pull, the result stored."""
        ctl = simulators(self.st)[1]
        self.on(bolt)
        await until_async(lambda: self.st.core.bolt == bolt and ctl.tool_enabled, 60,
                          f"tool on for {bolt}: {state_words(self.st.core.reason)}")
        n = self.st.bus.count(ResultRecorded)
        assert ctl.pull_trigger() is not None
        await until_async(lambda: self.st.bus.count(ResultRecorded) > n, 30, "result recorded")
        self.on(None)

    async def arrive(self, vin: str) -> None:
        plc = simulators(self.st)[0]
        plc.set_vehicle(1, vin)
        plc.raise_lift()
        await until_async(lambda: self.st.vin == vin, 30, f"{vin} loaded")


@pytest.mark.timeout(180)
def test_a_pair_knocked_between_vehicles_is_found_moved_refused_then_trusted_again(
        tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="stationd")
    cfg = load_station_config(station_dir(tmp_path, PAIRS))
    cfg = replace(cfg, matching=replace(cfg.matching, max_age_s=MAX_AGE_S))
    assert cfg.references is not None and cfg.references.pairs == PAIRS
    # a plain background (no texture, no vignetting): 20 MP backgrounds render faster
    world = World(cfg, seed=1, scene=Scene(blur_sigma=0.8, noise_sigma=2.0))
    run = Run(cfg, world)
    st = run.st
    # no pair is trusted before its first check
    assert set(st.core.trust.untrusted()) == set(PAIRS)
    assert all(r.kind is Why.PAIR_UNCHECKED for r in st.core.trust.untrusted().values())

    async def main() -> None:
        async with running(st):
            # vehicle 1: checked at its arrival, then tightened
            await run.arrive("CHECKVIN000000001")
            # (the start's check and the arrival's may be one grab: the loop merges them)
            await until_async(lambda: not st.core.trust.untrusted() and all(
                run.checks(p) and run.checks(p)[-1].trusted for p in PAIRS), 60,
                "the arrival's check")
            assert all(run.checks(p)[-1].verdict == "ok" for p in PAIRS)
            assert run.measures[:2] == ["station started", "vehicle CHECKVIN000000001 arrived"]
            await run.tighten(B2)
            simulators(st)[0].lower_lift()
            await until_async(lambda: st.bus.count(VehicleClosed) == 1, 30, "vehicle 1 closed")

            # pair2 knocked (0.3 degrees about its vertical axis) before vehicle 2 arrives
            world.move_pair("pair2", rotation_deg=(0.0, 0.3, 0.0))
            n2 = len(run.checks("pair2"))
            await run.arrive("CHECKVIN000000002")
            await until_async(lambda: len(run.checks("pair2")) > n2, 60, "vehicle 2's check")
            moved = run.checks("pair2")[-1]
            assert moved.verdict == "moved" and not moved.trusted and moved.reference == "R2"
            assert moved.why is not None and moved.why.kind is Why.PAIR_MOVED
            assert moved.offset_mm is not None and moved.offset_mm > cfg.references.tolerance_mm
            assert run.checks("pair1")[-1].trusted
            assert f"pair2 moved: reference R2 off by {moved.offset_mm:.1f}" in caplog.text

            # the bolt only pair2 sees: refused with the figure, nothing sent
            sent = len(run.sends)
            t0 = time.time()
            run.on(B2)
            await until_async(lambda: any(
                e.t > t0 and e.reason is not None and e.reason.kind is Why.PAIR_MOVED
                for e in st.bus.of(Localized)), 30, "B02 refused")
            await asyncio.sleep(1.5)
            assert run.sends[sent:] == []
            refusal = next(e.reason for e in st.bus.of(Localized) if e.t > t0
                           and e.reason is not None and e.reason.kind is Why.PAIR_MOVED)
            assert refusal.pair == "pair2" and refusal.reference == "R2"
            # pair1's bolt still works
            await run.tighten(B1)
            assert run.sends[sent:] == [B1]

            # pair2 put back: the engineer's check trusts it again, and B02 works
            world.move_pair("pair2")
            answer = await st.submit(CheckCalibration("pair2 put back"), ENGINEER, 60.0)
            assert answer.accepted and answer.result is not None
            assert {p: v["verdict"] for p, v in answer.result.items()} == \
                {"pair1": "ok", "pair2": "ok"}
            assert run.checks("pair2")[-1].trusted
            assert "pair2 checked: reference R2 within" in caplog.text
            await run.tighten(B2)

    try:
        asyncio.run(main())
    finally:
        st.close()
    assert run.untrusted_sends == []

    # a restart: no pair trusted until the start's check; the vehicle resumes
    again = Run(cfg, world)
    st = again.st
    assert set(st.core.trust.untrusted()) == set(PAIRS)
    assert reason_words(st.core.trust.untrusted()["pair1"]) == \
        "pair1 not checked against the references: not checked since the start"
    again.on(B9)     # the wrench waits on a bolt from the start: sent only once checked

    async def restarted() -> None:
        async with running(st):
            await again.arrive("CHECKVIN000000002")
            await until_async(lambda: B9 in again.sends, 60, "B09 sent after the restart")

    try:
        asyncio.run(restarted())
    finally:
        st.close()
        world.close()
    assert again.measures[0] == "station started"
    assert again.untrusted_sends == []
    assert all(again.checks(p) for p in PAIRS)
