"""What a command's ``--out`` may replace, and writing it so that it is whole or untouched.

Why: a results export given ``--out stationd.db`` replaced the results database with a CSV,
and ``tune-color --out`` the same; an ``--out /dev/full`` said "wrote" (as root the rename
even replaced the device node).  Each command names the kinds of file it may replace (its own
earlier output); anything else that exists there (a database, a station file, a bolt table,
a calibration, a device) is refused with one line before any work is done.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from stationd.errors import ConfigError, InputError
from stationd.yamlio import YamlNode, file_kind, top_keys

SQLITE_MAGIC = b"SQLite format 3\x00"
#: how a results CSV export begins (stationd.web.results.CSV_FIELDS)
RESULTS_CSV_HEAD = "vin,model,bolt,"
#: configuration files are small: a larger file is data (an earlier export), not parsed
PARSE_LIMIT_BYTES = 5 * 2**20
#: the first bytes read to tell an SQLite database or a results export, at any size
HEAD_BYTES = 4096
NAMES = {
    "folder": "a folder",
    "device": "not a regular file (a device, a pipe or a socket)",
    "sqlite": "an SQLite database",
    "station": "a station file",
    "bolts": "a bolt table",
    "hsv": "an HSV range file",
    "yaml": "a YAML settings file (a calibration or registration?)",
    "json": "a JSON file",
    "results": "an earlier results export",
    "svg": "an SVG drawing",
    "text": "a text file (not one this command wrote)",
    "data": "a large data file",
    "unreadable": "a file that cannot be read",
}


def kind_of(path: Path) -> str | None:
    """The kind of what is at ``path`` (a key of :data:`NAMES`), None when nothing is."""
    if not path.exists() and not path.is_symlink():
        return None
    if path.is_dir():
        return "folder"
    if not path.is_file():
        return "device"
    try:
        with path.open("rb") as f:
            head = f.read(HEAD_BYTES)
        if head.startswith(SQLITE_MAGIC):
            return "sqlite"
        if _results_head(head.decode("utf-8", errors="replace").lstrip()):
            return "results"    # whatever its size: a shift's export passes 5 MB
        if path.stat().st_size > PARSE_LIMIT_BYTES:
            return "data"
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return "unreadable"
    start = text.lstrip()
    if start.rstrip() == "[]":
        return "results"    # a JSON export of a vehicle with no rundown and no bolt
    if start.startswith("{"):
        return "json"
    if start.startswith(("<?xml", "<svg")):
        return "svg"
    try:
        root = YamlNode.parse(text, str(path))
    except ConfigError:
        return "text"
    if not isinstance(root.value(), dict):
        return "text"
    keys = top_keys(root)
    kind = file_kind(keys)
    if kind is not None:
        return kind
    return "hsv" if keys == {"hsv"} else "yaml"


def _results_head(start: str) -> bool:
    """Whether a file's first bytes are a results export's: its CSV header, or a JSON
    list whose first object carries a VIN (``"vin"``, the export's first key)."""
    if start.startswith(RESULTS_CSV_HEAD):
        return True
    return start.startswith("[") and start[1:].lstrip().startswith('{"vin":')


def refuse_to_replace(path: Path, writing: str, may_replace: tuple[str, ...]) -> None:
    """Raise :class:`InputError` when ``path`` holds something other than the kinds in
    ``may_replace`` (the command's own earlier output); nothing there is fine."""
    kind = kind_of(path)
    if kind is None or kind in may_replace:
        return
    if kind == "folder":
        raise InputError(f"{path}: is a folder; --out takes a file name")
    raise InputError(f"{path}: is {NAMES[kind]}; writing {writing} would replace it (give "
                     "another --out)")


def write_atomic(path: Path, text: str) -> None:
    """``text`` into ``path`` via a temporary file in the same folder, flushed to disk and
    renamed over it: a reader sees the old file or the new one, never half of one; a full
    disk is an error (one line), not "wrote".  The file keeps the mode of the one it
    replaces (a new one: the umask's), not the temporary file's 0600."""
    try:
        mode = path.stat().st_mode & 0o7777 if path.is_file() else _default_mode()
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, mode)
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None


def _default_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask
