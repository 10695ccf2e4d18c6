"""A station database that opens but takes no writes (a maintenance technician's trial: the
file replaced by root's copy, mode 0644, under a daemon running as ``stationd``).  SQLite opens
such a file read-only without a word, every read answers, and every write fails with "attempt
to write a readonly database": the database's way back (``Records.probe``) read one query,
said "database: back", and the station offered the next bolt, whose tool enable failed again
(a flip-flop, 12 in a minute).  The way back must prove a write, and reopen its connections
(SQLite's read-only connection stays so after a chown); the fault says what to do.

Root writes any file whatever its mode, so here the connections are made read-only by SQLite
itself (``PRAGMA query_only``: the same "attempt to write a readonly database"); the daemon on a
file it may not write, as another user, is ``tests/shell/test_readonly_daemon.py``."""

from __future__ import annotations

import os
import pwd
import time
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import event

from db.errors import DbError
from drivers.errors import DeviceError
from stationd.station.actions import LoadVehicle, RecordCommand
from stationd.station.commands import Issuer, Right, SkipBolt
from stationd.station.inputs import VehicleLoaded
from tests.shell.test_records_words import _records


def _read_only(dbapi_connection: Any, _record: Any) -> None:
    dbapi_connection.execute("PRAGMA query_only=1")


def test_the_way_back_proves_a_write_and_reopens_once_the_file_takes_writes(tmp_path: Path):
    records = _records(tmp_path)
    repo = records.repo
    assert repo is not None
    event.listen(repo.engine, "connect", _read_only)
    repo.engine.dispose()          # every connection from now on opens read-only
    try:
        with pytest.raises(DbError, match="readonly database"):
            records.load_vehicle(LoadVehicle(12, "VIN1"))
        with pytest.raises(DbError, match="readonly database"):
            records.record_command(RecordCommand(0, SkipBolt("VIN1", "B1", "no access"),
                                                 Issuer("sam", frozenset(Right), "cli"),
                                                 time.time()), "VIN1")
        # its reads answer: a probe that only reads said "back" (the flip-flop)
        assert repo.models()
        with pytest.raises(DeviceError, match="readonly database"):
            records.probe(repo)
        with pytest.raises(DeviceError, match="readonly database"):
            records.probe(repo)       # a lasting fault: each attempt fails the same
    finally:
        # the file chowned: connections opened from now on write
        event.remove(repo.engine, "connect", _read_only)
    # the way back reopens its connections (the read-only ones stay read-only): back with
    # no reload, and the write that failed now succeeds
    records.probe(repo)
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    repo.close()


def _name(uid: int) -> str:
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return f"uid {uid}"


def test_a_file_another_user_owns_is_said_with_its_owner_its_mode_and_the_chown(tmp_path):
    """What the fault says: the file, whose it is, its mode and what to do, in one line."""
    from db.location import unwritable_file

    db = tmp_path / "stationd.db"
    db.write_bytes(b"")
    os.chown(db, 0, 0)
    db.chmod(0o644)
    nobody = _name(65534)
    assert unwritable_file(db, "this daemon's user", uid=65534, gids=(65534,)) == (
        f"the database file {db} is not writable by this daemon's user ({nobody}; the file "
        f"is {_name(0)}'s, mode 0644): chown it to {nobody}")
    assert unwritable_file(db, uid=0, gids=(0,)) is None                 # root writes it
    db.chmod(0o664)
    assert unwritable_file(db, uid=65534, gids=(0,)) is None             # by its group
    os.chown(db, 65534, 65534)
    db.chmod(0o444)                                                      # its own, no w
    assert unwritable_file(db, "this daemon's user", uid=65534, gids=(65534,)) == (
        f"the database file {db} is not writable by this daemon's user ({nobody}; the file "
        f"is {nobody}'s, mode 0444): chmod u+w it")
    db.chmod(0o644)
    wal = tmp_path / "stationd.db-wal"                                   # its WAL: root's
    wal.write_bytes(b"")
    os.chown(wal, 0, 0)
    wal.chmod(0o644)
    assert unwritable_file(db, "this daemon's user", uid=65534, gids=(65534,)) == (
        f"the database file {wal} is not writable by this daemon's user ({nobody}; the file "
        f"is {_name(0)}'s, mode 0644): chown it to {nobody}")
