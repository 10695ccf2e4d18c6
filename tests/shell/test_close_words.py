"""What the station's close journals of what its database never took
(:meth:`stationd.shell.daemon.Station.close`): each in full at a stop, the only copy left;
counted at a reload, which carries them to the next station (an IT administrator's trial:
"UNSAVED at shutdown" at every reload)."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import pytest

from stationd.config import StationConfig
from stationd.shell.daemon import Station
from stationd.station.actions import Record
from tests.db.conftest import url_of
from tests.shell.test_records_copies import _result, _sel


@pytest.mark.parametrize("final", [True, False], ids=["stop", "reload"])
def test_a_result_not_written_is_journaled_in_full_at_a_stop_and_counted_at_a_reload(
        tmp_path: Path, caplog, final):
    station = Station(StationConfig(database_url=url_of(tmp_path / "st.db")))
    unsaved = station.records.unsaved_result(
        Record("VIN1", "B1", _result(), _sel("B1"), t=time.time()), None)
    station.records.carry([unsaved], [])
    with caplog.at_level(logging.INFO):
        station.close(final)
    lines = [r.getMessage() for r in caplog.records]
    full = [line for line in lines if line.startswith("UNSAVED at shutdown: ")]
    counted = [line for line in lines if line.startswith("reload: 1 results")]
    assert (len(full), len(counted)) == ((1, 0) if final else (0, 1)), lines
    assert station.unsaved() == [unsaved]      # kept for the next station either way


def test_what_is_told_as_the_station_closes_is_dropped(tmp_path: Path):
    """The line forwarder and OPC UA end as the devices close: a word told then (the line's
    link state) never reaches a station shutting down (a reviewer)."""
    import asyncio

    from stationd.station.inputs import LineLinkIn

    station = Station(StationConfig(database_url=url_of(tmp_path / "st.db")))
    station.close()

    async def main() -> int:
        station.tell(LineLinkIn(time.time(), False, "down", None))
        await asyncio.sleep(0)
        return len(station._told)

    assert asyncio.run(main()) == 0
