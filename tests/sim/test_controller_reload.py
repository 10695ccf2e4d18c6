"""The in-daemon simulated controller across a reload: as a real controller, it goes on (its
tightening ids, its stored results, its scatter) rather than starting again at 1 with the
same results, which the station took for copies it had stored (the results were lost); and
across a restart of the daemon, its results kept in a file of its own."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from drivers.devices import Kind, build
from drivers.wrench import open_wrench
from drivers.wrench.sim.controller import SimController, SimWrench
from stationd.config import StationConfig
from stationd.sim.in_daemon import SimulatedStation, controller_memory


def _tighten(ctl: SimController, n: int) -> list[tuple[int, float, float]]:
    """``n`` tightenings with pset 1, the tool on: (id, torque, angle) of each."""
    ctl.pset, ctl.tool_enabled = 1, True
    out = []
    for _ in range(n):
        t = ctl.pull_trigger()
        assert t is not None
        out.append((t.tightening_id, t.torque_nm, t.angle_deg))
    return out


def test_each_reload_s_simulated_controller_goes_on_from_the_last(tmp_path):
    """Three stations in a row (a start, two reloads), each opening its own ``sim://wrench``
    with the same seed, as the daemon does: the ids go on (1-3, 4-6, 7-9), no station's
    results replay an earlier one's, and the results the controller keeps for MID 0064
    are there after the reload."""
    # no sim:// cameras: no world, only the controller (its file beside the database)
    cfg = StationConfig(database_url=f"sqlite:///{tmp_path / 'station.db'}")
    sim = SimulatedStation(cfg)
    stop = asyncio.Event()
    stop.set()                  # each station stops at once: only its start matters here
    made: list[list[tuple[int, float, float]]] = []
    for _ in range(3):
        wrench = build(Kind.WRENCH, "sim://wrench?seed=0")
        assert isinstance(wrench, SimWrench)
        ctl = wrench.controller
        ctl.start()
        try:
            # the parts of a station the simulator reads at its start and end (its devices,
            # its file, who is signed in)
            station = SimpleNamespace(wrench=wrench, lift=None, cfg=cfg, core=SimpleNamespace(
                status=lambda: SimpleNamespace(operator=None)))
            asyncio.run(sim.beside(cfg, station, stop))
            if made:
                assert ctl.call(lambda c=ctl: sorted(c._store)) == list(range(1, len(made) * 3 + 1))
            made.append(_tighten(ctl, 3))
        finally:
            ctl.close()
    assert [[i for i, _, _ in m] for m in made] == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]
    values = [[(t, a) for _, t, a in m] for m in made]
    assert values[1] != values[0] and values[2] not in values[:2]
    # what a controller built anew would have done (the bug): the first series again
    fresh = SimController(seed=0)
    fresh.start()
    try:
        assert _tighten(fresh, 3) == made[0]
    finally:
        fresh.close()


def test_a_restarted_daemon_s_simulated_controller_has_the_last_one_s_results(tmp_path):
    """Two daemons one after the other on one station (a restart): the second's simulated
    controller answers MID 0064 (the real client's fetch) with the first's results, its
    newest too, and numbers on after it.  A real controller keeps its results through the
    station's restart; the simulator lost them, and the catch-up after a restart found none
    ("the controller has no results, though tightening N was recorded"), the owed bolt held.
    Kept in a file of the controller's own beside the station's database, never read from
    that database."""
    cfg = StationConfig(database_url=f"sqlite:///{tmp_path / 'station.db'}")
    memory = controller_memory(cfg)
    assert memory == tmp_path / "station.db.sim-wrench.jsonl"
    stop = asyncio.Event()
    stop.set()
    made: list[list[tuple[int, float, float]]] = []
    fetched = []
    for _ in range(2):
        sim = SimulatedStation(cfg)     # a daemon of its own
        wrench = open_wrench("sim://wrench?seed=0", timeout=0.5, connect_timeout=0.5)
        assert isinstance(wrench, SimWrench)
        try:
            station = SimpleNamespace(wrench=wrench, lift=None, cfg=cfg, core=SimpleNamespace(
                status=lambda: SimpleNamespace(operator=None)))
            asyncio.run(sim.beside(cfg, station, stop))
            fetched.append((wrench.fetch_result(0), wrench.fetch_result(2)))
            made.append(_tighten(wrench.controller, 3))
        finally:
            wrench.close()
    assert fetched[0] == (None, None)        # the first daemon's controller: none yet
    newest, second = fetched[1]
    assert newest is not None and second is not None
    assert (newest.tightening_id, newest.torque_nm, newest.angle_deg) == made[0][2]
    assert (second.tightening_id, second.torque_nm, second.angle_deg) == made[0][1]
    assert [i for i, _, _ in made[1]] == [4, 5, 6]
    assert not (tmp_path / "station.db").exists()      # its own file, not the station's
