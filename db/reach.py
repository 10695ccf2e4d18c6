"""Why a path cannot be reached, in words a person on the line can act on.

Why: the station's files are read by the service's user (the unit's ``User=``), often not
the user who put them in place.  Python answers a closed folder with a traceback ending in
``PermissionError: [Errno 13] Permission denied: '/root/x/bolts.yaml'``, which names neither
the folder that is closed nor the user it is closed to, and exits 1 (systemd restarts that
forever).  Every reader of a path a station's file names turns the ``OSError`` of any kind
into one of these phrases, put after the path it is about: ``bolt file /root/x/bolts.yaml:
folder /root/x cannot be reached by user nobody (permission denied: /root is closed to
that user)``.

A leaf of plain functions, in db because the database's file is the first path it words
(:mod:`db.location`) and db imports nothing of stationd; the station's readers of its files
(:mod:`stationd.yamlio`, :mod:`stationd.configread`...) import it from here, as they import
:mod:`drivers.counting` (pyproject.toml lets the pure layers import both).
"""

from __future__ import annotations

import errno
import os
import pwd
import stat
from pathlib import Path


def user_name(uid: int | None = None) -> str:
    """The user this process runs as (its effective uid), the one a folder is closed to:
    not ``$USER``, which a process started as another user (``runuser``, ``sudo -u``, a
    parent that changed uid) may have inherited; or the user of ``uid`` (a file's owner)."""
    uid = os.geteuid() if uid is None else uid
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return f"uid {uid}"


def closed_folder(path: Path) -> Path | None:
    """The first folder above ``path`` (from ``/`` down) this user may not enter, or None."""
    for folder in reversed(Path(os.path.abspath(path)).parents):
        if not os.access(folder, os.X_OK):
            return folder
    return None


def file_above(path: Path) -> Path | None:
    """The first of ``path``'s folders (from ``/`` down) that is there and no folder (a
    file written where a folder was meant), or None."""
    for folder in reversed(Path(os.path.abspath(path)).parents):
        try:
            mode = os.stat(folder).st_mode
        except OSError:
            return None
        if not stat.S_ISDIR(mode):
            return folder
    return None


def not_a_folder(path: Path, above: Path) -> str:
    """What a file at ``above``, where a folder of ``path`` was meant, makes of ``path``."""
    if above == Path(os.path.abspath(path)).parent:
        return f"{above} is a file, not a folder"
    return f"folder {path.parent} cannot be reached: {above} is a file, not a folder"


def unreachable(path: Path, exc: OSError, doing: str = "read") -> str:
    """Why ``path`` cannot be used, from the ``exc`` that trying gave, as a phrase to put
    after the path: which folder is closed and to whom, which folder is a file, or the
    system's own words for any other error (a name too long, a loop of links...).
    ``doing``: what could not be done to the file itself when every folder is open."""
    if isinstance(exc, PermissionError) or exc.errno in (errno.EACCES, errno.EPERM):
        closed = closed_folder(path)
        if closed is None:
            return f"cannot be {doing} by user {user_name()} (permission denied)"
        where = "" if closed == Path(os.path.abspath(path)).parent \
            else f": {closed} is closed to that user"
        return (f"folder {path.parent} cannot be reached by user {user_name()} (permission "
                f"denied{where})")
    if isinstance(exc, NotADirectoryError):
        above = file_above(path)
        if above is not None:
            return not_a_folder(path, above)
    said = exc.strerror or str(exc)
    return f"cannot be reached ({said[:1].lower()}{said[1:]})"


__all__ = ["closed_folder", "file_above", "not_a_folder", "unreachable", "user_name"]
