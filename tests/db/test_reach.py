"""Why a path cannot be reached, in words (``db.reach``), and the database's check that says
it (``db.location.sqlite_problem``): a folder closed to this user, a file where a folder was
meant, any other error of the system's, one line each where a traceback was."""

from __future__ import annotations

import os
import pwd
from pathlib import Path

import pytest

from db.location import sqlite_problem, unwritable_folder
from db.reach import file_above, unreachable, user_name


def _error(path: Path) -> OSError:
    """The error the system gives for looking at ``path``."""
    with pytest.raises(OSError) as ei:
        os.stat(path)
    return ei.value


def test_a_file_where_a_folder_is_meant_is_named(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x\n")
    below = afile / "x.db"
    assert file_above(below) == afile
    assert unreachable(below, _error(below)) == f"{afile} is a file, not a folder"
    deeper = afile / "sub" / "x.db"
    assert unreachable(deeper, _error(deeper)) == \
        f"folder {afile / 'sub'} cannot be reached: {afile} is a file, not a folder"
    assert file_above(tmp_path / "gone" / "x.db") is None   # missing is not this


def test_any_other_error_is_the_systems_words_in_one_phrase(tmp_path):
    long = tmp_path / ("a" * 300) / "x.db"
    assert unreachable(long, _error(long)) == "cannot be reached (file name too long)"


def test_the_user_named_is_the_process_s_not_the_environment_s(monkeypatch, tmp_path):
    """``$USER`` is inherited by a process started as another user (``runuser``, a test's
    ``subprocess.run(user=...)``): the folder is closed to the user the process runs as."""
    me = pwd.getpwuid(os.geteuid()).pw_name
    monkeypatch.setenv("USER", "someone-else")
    monkeypatch.setenv("LOGNAME", "someone-else")
    assert user_name() == me
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, *a, **kw: False if Path(p) == tmp_path
                        and mode & os.W_OK else real(p, mode, *a, **kw))
    assert unwritable_folder(tmp_path) == (f"folder {tmp_path} cannot be written by user {me}: "
                                           "give it that user, or name another folder")


def test_the_database_s_check_says_it_in_one_line(tmp_path):
    """``sqlite_problem`` raised the OSError of ``Path.is_dir`` (a traceback from ``config
    check``, ``stationd run``, ``db import``), and took a file where a folder was meant for a
    folder to create."""
    afile = tmp_path / "afile"
    afile.write_text("x\n")
    assert sqlite_problem(f"sqlite:///{afile}/x.db") == \
        f"database {afile}/x.db: {afile} is a file, not a folder"
    long = tmp_path / ("a" * 300)
    assert sqlite_problem(f"sqlite:///{long}/x.db") == \
        f"database {long}/x.db: cannot be reached (file name too long)"
    # a missing folder is still one to create
    assert sqlite_problem(f"sqlite:///{tmp_path}/gone/x.db").startswith(
        f"folder {tmp_path}/gone does not exist: create it")


class _ReadOnly:
    """``os.statvfs``'s answer for a folder the unit's ``ProtectSystem=strict`` mounted
    read-only in the service's view (the file system itself is read-write)."""

    f_flag = os.ST_RDONLY


def test_a_folder_read_only_under_the_unit_says_how_the_unit_lets_it_be_written(
        monkeypatch, tmp_path):
    """A commissioning trial: a data partition's folder for the database (or the images)
    under the systemd unit, whose ``ProtectSystem=strict`` shows every folder but its
    ``StateDirectory`` (and ``/run/lock``) read-only.  The daemon said "on a read-only file
    system: name a folder that can be written", of a file system an engineer finds
    read-write from a shell.  Under systemd (``INVOCATION_ID``, which it sets for each
    service it runs) the words say why and what to add to the unit; elsewhere they are as
    they were."""
    monkeypatch.setattr(os, "statvfs", lambda path: _ReadOnly())
    monkeypatch.delenv("INVOCATION_ID", raising=False)
    plain = unwritable_folder(tmp_path)
    assert plain == f"folder {tmp_path} is on a read-only file system: name a folder that " \
                    "can be written (e.g. /var/lib/stationd)"
    monkeypatch.setenv("INVOCATION_ID", "0123456789abcdef0123456789abcdef")
    said = unwritable_folder(tmp_path)
    assert said is not None and said.startswith(f"folder {tmp_path} is read-only to this "
                                                "service"), said
    assert "ProtectSystem=strict" in said and f"ReadWritePaths={tmp_path}" in said
    assert "systemctl edit stationd" in said and "\n" not in said


def test_the_units_own_folder_read_only_is_a_read_only_mount(monkeypatch):
    """/var/lib/stationd, the unit's StateDirectory, read-only: the unit writes it always,
    so the file system is mounted read-only (an IT administrator's trial was told to add
    ``ReadWritePaths=/var/lib/stationd`` to the unit, the folder it names already)."""
    from db.location import STATE_DIRECTORY

    monkeypatch.setattr(os, "statvfs", lambda path: _ReadOnly())
    monkeypatch.setattr(Path, "stat", lambda self: os.stat("/"))
    for invocation in ("0123456789abcdef0123456789abcdef", None):
        if invocation is None:
            monkeypatch.delenv("INVOCATION_ID", raising=False)
        else:
            monkeypatch.setenv("INVOCATION_ID", invocation)
        said = unwritable_folder(STATE_DIRECTORY / "images")
        assert said is not None and "mounted read-only: remount it read-write" in said, said
        assert "ReadWritePaths" not in said and "\n" not in said
