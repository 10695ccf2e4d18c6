"""Can an SQLite URL keep what is written to it?  Checked before anything opens it.

One check for every place a person names a database: the station file's ``database.url``
(``config check``, the daemon's start and reload) and every command's ``--db`` (``stationd db
import|export|report|spc``).  SQLite itself answers these mistakes badly or not at all: an
in-memory database takes an import and keeps nothing, a folder says "unable to open database
file" (or "disk I/O error"), a missing folder the same, a text file "file is not a database"
only once something reads it; opening a path also creates the file, and opening a FIFO blocks.
A folder on the way that the user cannot enter, or that is a file, or any other error of the
system's in looking at the path, is one line too (:mod:`db.reach`): Python's answer was a
traceback, and exit 1, which systemd restarts forever.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Collection
from pathlib import Path

from db.reach import file_above, not_a_folder, unreachable, user_name

#: the first 16 bytes of every SQLite database file (https://sqlite.org/fileformat.html)
SQLITE_HEADER = b"SQLite format 3\x00"
#: the systemd unit's StateDirectory: the one folder its ProtectSystem=strict lets it write
STATE_DIRECTORY = Path("/var/lib/stationd")
NOT_SQLITE = "not an SQLite database: "
#: what an in-memory database loses, in the station's words (a command says its own)
STATION_LOSES = "every result is lost when the station stops"


def sqlite_path(url: str) -> Path | None:
    """The file an SQLite URL names, resolved; None for another database or one in memory."""
    from sqlalchemy.engine import make_url

    u = make_url(url)
    if u.get_backend_name() != "sqlite" or not u.database or u.database == ":memory:":
        return None
    return Path(u.database).resolve()


def missing_folder(folder: Path) -> str:
    """A database's folder that does not exist: a typo, or a folder to create."""
    return (f"folder {folder} does not exist: create it, owned by the user the station runs "
            "as (or correct the path)")


def unwritable_folder(folder: Path, *, as_writer: bool = True) -> str | None:
    """Why no database can live in ``folder`` (SQLite creates its journal and the station its
    lock beside the file), or None.  ``as_writer``: this process is the one that will write
    (the daemon, a ``db`` command), so its own permission counts; otherwise (``config
    check``, maybe run by another user than the service's) only a folder nobody may write is
    refused: a read-only file system, or no write permission for anyone (``/proc``: even
    root cannot create a file there)."""
    try:
        read_only = bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
        mode = folder.stat().st_mode
    except OSError:
        return None   # not reachable to look at: what opens it says why
    if read_only:
        if folder.is_relative_to(STATE_DIRECTORY):
            # the unit's own StateDirectory, always written: the mount itself is read-only
            # (an IT administrator's trial was told to let the unit write this very folder)
            return f"folder {folder} is on a file system mounted read-only: remount it " \
                   "read-write (mount -o remount,rw, and see why it went read-only: " \
                   "dmesg; a disk error does that)"
        if os.environ.get("INVOCATION_ID"):
            # systemd runs this process (it sets INVOCATION_ID for each service): the unit's
            # ProtectSystem=strict shows every folder but its own read-only, whatever the
            # file system (a data partition "read-only" that is read-write from a shell)
            return f"folder {folder} is read-only to this service (the systemd unit's " \
                   "ProtectSystem=strict: only /var/lib/stationd is written): let the unit " \
                   f"write it (systemctl edit stationd: [Service] ReadWritePaths={folder}), " \
                   "or name a folder under /var/lib/stationd"
        return f"folder {folder} is on a read-only file system: name a folder that can be " \
               "written (e.g. /var/lib/stationd)"
    if not stat.S_IMODE(mode) & 0o222:
        return f"folder {folder} cannot be written by anyone (no write permission): name " \
               "a folder that can be written (e.g. /var/lib/stationd)"
    if as_writer and not os.access(folder, os.W_OK | os.X_OK):
        return f"folder {folder} cannot be written by user {user_name()}: give it " \
               "that user, or name another folder"
    return None


def unwritable_file(path: Path, who: str = "this process's user", *, uid: int | None = None,
                    gids: Collection[int] | None = None) -> str | None:
    """Why ``uid`` (this process's effective user unless told, in ``gids``) may not write the
    SQLite database at ``path``, in the words of what to do: the file or its ``-wal`` or
    ``-shm`` beside it (SQLite writes all three, and opens a file it may not write read-only
    without a word: every read answers, every write fails with "attempt to write a readonly
    database"), or their file system mounted read-only; None when it may (or where looking
    fails: the caller keeps SQLite's own words).  ``who``: the user's role in the words ("this
    daemon's user").  From the files' owners and modes (no ACLs); root writes any file."""
    uid = os.geteuid() if uid is None else uid
    gids = {os.getegid(), *os.getgroups()} if gids is None else set(gids)
    for f in (path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
        try:
            st = f.stat()
            read_only = bool(os.statvfs(f).f_flag & os.ST_RDONLY)
        except OSError:
            continue   # not there (SQLite creates the -wal and -shm), or out of reach
        if read_only:
            return f"the database file {f} is on a read-only file system: remount it " \
                   "read-write, or name a database on one"
        if uid == 0 or _may_write(st, uid, gids):
            continue
        user = user_name(uid)
        fix = f"chown it to {user}" if st.st_uid != uid else "chmod u+w it"
        return (f"the database file {f} is not writable by {who} ({user}; the file is "
                f"{user_name(st.st_uid)}'s, mode {stat.S_IMODE(st.st_mode):04o}): {fix}")
    return None


def _may_write(st: os.stat_result, uid: int, gids: Collection[int]) -> bool:
    """The owner's, the group's or the others' write bit, whichever applies to ``uid``."""
    if st.st_uid == uid:
        return bool(st.st_mode & stat.S_IWUSR)
    if st.st_gid in gids:
        return bool(st.st_mode & stat.S_IWGRP)
    return bool(st.st_mode & stat.S_IWOTH)


def sqlite_problem(url: str, *, read_header: bool = True, loses: str = STATION_LOSES,
                   as_writer: bool = True) -> str | None:
    """Why the SQLite database of ``url`` cannot keep what is written, in the words of what
    to do; None when it can (or ``url`` is another database, checked when it connects).
    ``url`` has parsed already (``db.engine.make_engine``).  ``read_header``: a file that is
    there must start as an SQLite database (off where reading the file would drop the
    caller's own SQLite locks on it: the daemon's reload).  ``loses``: what an in-memory
    database loses, for the message.  ``as_writer``: see :func:`unwritable_folder`."""
    from sqlalchemy.engine import make_url

    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        return None
    name = parsed.database or ""
    if name in ("", ":memory:") or "mode=memory" in name:
        return (f"{url} is a database in memory: {loses} (name a file, e.g. "
                "sqlite:///stationd.db)")
    if name.startswith("file:"):   # an SQLite URI: its own options, checked when it opens
        return None
    if parsed.query:   # SQLAlchemy would make them part of the file's name ("x.db?mode=ro")
        return (f"{url}: an SQLite file's URL takes no options after '?' "
                f"({', '.join(sorted(parsed.query))}): write sqlite:///{name}")
    path = Path(name)
    try:
        return _file_problem(path, read_header=read_header, as_writer=as_writer)
    except OSError as exc:   # a folder closed to this user, a name too long...
        return f"database {path}: {unreachable(path, exc, 'opened')}"


def _file_problem(path: Path, *, read_header: bool, as_writer: bool) -> str | None:
    """:func:`sqlite_problem` of the file at ``path``; an OSError in looking is raised."""
    if path.is_dir():
        return f"{path} is a folder, not a database file (name a file in it, e.g. " \
               f"sqlite:///{path / 'stationd.db'})"
    if not path.parent.is_dir():
        above = file_above(path)
        if above is not None:   # "does not exist: create it" would mislead
            return f"database {path}: {not_a_folder(path, above)}"
        return missing_folder(path.parent)
    unwritable = unwritable_folder(path.parent, as_writer=as_writer)
    if unwritable is not None:
        return unwritable
    if not path.exists():
        return None   # created when first opened
    if not path.is_file():
        return f"{path} is not a regular file (a FIFO or a device?): name a database file"
    if not read_header:
        return None
    with path.open("rb") as f:
        head = f.read(len(SQLITE_HEADER))
    if head and head != SQLITE_HEADER:   # an empty file is a new database
        return f"{NOT_SQLITE}{path} is another kind of file: name the station's " \
               "database, or a new file"
    return None
