"""What a command's ``--out`` may replace, and writing it so that it is whole or untouched.

Why: a results export given ``--out stationd.db`` replaced the results database with a CSV,
and ``tune-color --out`` the same; an ``--out /dev/full`` said "wrote" (as root the rename
even replaced the device node).  Each command names the kinds of file it may replace (its own
earlier output); anything else that exists there (a database, a station file, a bolt table,
a calibration, a device) is refused with one line before any work is done.

The rule, for every command that writes a file (issue 19):

- an output is never written through or over a symbolic link: ``detect --draw link.png``,
  ``link.png`` pointing at the station file, replaced the station file with a PNG;
- an existing file is replaced only when it is of the kind the command writes (its own
  earlier output): a calibration of another kind (``calibrate camera --out pair.yaml``), a
  station file, a bolt table, an image the command did not write is refused, naming its kind;
- it is written whole or not at all (a temporary file renamed over it) with the mode of the
  file it replaces, a new one with the umask's mode (never the temporary file's 0600).

A PNG this program writes carries a ``tEXt`` chunk naming the command (:func:`stamp_png`), so
that its next run may replace it and any other PNG is left alone (``detect --draw``, ``probe
camera --save``, ``demo --vision --save``); an image in another format cannot carry the
stamp, so an existing one is never replaced.
"""

from __future__ import annotations

import contextlib
import os
import struct
import tempfile
import zlib
from pathlib import Path

from stationd.errors import ConfigError, InputError
from stationd.filekind import KINDS, described, kind_of_keys
from stationd.stopping import held
from stationd.yamlio import YamlNode, top_keys

SQLITE_MAGIC = b"SQLite format 3\x00"
#: how a results CSV export begins (stationd.web.results.CSV_FIELDS)
RESULTS_CSV_HEAD = "vin,model,bolt,"
#: every file this process put in place, in order (:func:`written`)
_WRITTEN: list[Path] = []
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: the ``tEXt`` keyword of :func:`stamp_png` (PNG's registered keyword for the program)
PNG_STAMP_KEY = b"Software"
#: what marks a PNG as ``detect --draw``'s own: it may be replaced by the next drawing
DRAWING_STAMP = "stationd detect --draw"
#: ``probe camera --save``'s frames and the images of ``demo --vision --save``, likewise
FRAME_STAMP = "stationd probe camera --save"
DEMO_IMAGE_STAMP = "stationd demo --vision --save"
#: the kind of each stamped PNG (a key of :data:`NAMES`)
STAMPS = {DRAWING_STAMP: "drawing", FRAME_STAMP: "frame", DEMO_IMAGE_STAMP: "demo-image"}
_IMAGE_MAGIC = (b"\xff\xd8\xff", b"II*\x00", b"MM\x00*", b"BM", b"GIF8", b"RIFF")
#: configuration files are small: a larger file is data (an earlier export), not parsed
PARSE_LIMIT_BYTES = 5 * 2**20
#: the first bytes read to tell an SQLite database or a results export, at any size
HEAD_BYTES = 4096
NAMES = {
    "folder": "a folder",
    "device": "not a regular file (a device, a pipe or a socket)",
    "sqlite": "an SQLite database",
    **{kind: described(kind) for kind in KINDS},   # the station's YAML files
    "yaml": "a YAML settings file",
    "json": "a JSON file",
    "results": "an earlier results export",
    "svg": "an SVG drawing",
    "drawing": "an earlier drawing of detect --draw",
    "frame": "an earlier frame of probe camera --save",
    "demo-image": "an earlier image of demo --vision --save",
    "png": "a PNG image that this program did not write",
    "image": "an image",
    "text": "a text file (not one this command wrote)",
    "data": "a large data file",
    "unreadable": "a file that cannot be read",
}


def kind_of(path: Path) -> str | None:
    """The kind of what is at ``path`` (a key of :data:`NAMES`; through a link, of its
    target), None when nothing is (a link to nothing too)."""
    if not path.exists():
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
        if head.startswith(PNG_MAGIC):
            return next((kind for stamp, kind in STAMPS.items() if _stamp(stamp) in head),
                        "png")
        if head.startswith(_IMAGE_MAGIC):
            return "image"
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
    return kind_of_keys(top_keys(root)) or "yaml"


def _results_head(start: str) -> bool:
    """Whether a file's first bytes are a results export's: its CSV header, or a JSON
    list whose first object carries a VIN (``"vin"``, the export's first key)."""
    if start.startswith(RESULTS_CSV_HEAD):
        return True
    return start.startswith("[") and start[1:].lstrip().startswith('{"vin":')


def refuse_to_replace(path: Path, writing: str, may_replace: tuple[str, ...],
                      option: str = "--out") -> None:
    """Raise :class:`InputError` when ``path`` is a symbolic link (whatever it points at) or
    holds something other than the kinds in ``may_replace`` (the command's own earlier
    output); nothing there is fine.  ``option`` is what the user gave the path with."""
    if path.is_symlink():
        target = os.readlink(path)
        kind = kind_of(path)
        what = "which does not exist" if kind is None else NAMES[kind]
        raise InputError(f"{path}: is a symbolic link to {target}, {what}; an output is "
                         f"never written through or over a link: give {option} the file's "
                         "own path")
    kind = kind_of(path)
    if kind is None or kind in may_replace:
        return
    if kind == "folder":
        raise InputError(f"{path}: is a folder; {option} takes a file name")
    raise InputError(f"{path}: is {NAMES[kind]}; writing {writing} would replace it (give "
                     f"another {option})")


def _stamp(text: str) -> bytes:
    return PNG_STAMP_KEY + b"\0" + text.encode("latin-1")


def stamp_png(png: bytes, text: str) -> bytes:
    """``png`` with a ``tEXt`` chunk ``Software: text`` right after its header (within the
    bytes :func:`kind_of` reads), so this program knows the file as its own output."""
    if not png.startswith(PNG_MAGIC) or png[12:16] != b"IHDR":
        raise ValueError("not a PNG")
    end = 8 + 12 + struct.unpack(">I", png[8:12])[0]    # the signature, then IHDR
    data = _stamp(text)
    chunk = (struct.pack(">I", len(data)) + b"tEXt" + data
             + struct.pack(">I", zlib.crc32(b"tEXt" + data)))
    return png[:end] + chunk + png[end:]


def write_atomic(path: Path, data: str | bytes, *, mode: int | None = None) -> None:
    """``data`` (text is written as UTF-8) into ``path`` via a temporary file in the same
    folder, flushed to disk and renamed over it: a reader sees the old file or the new one,
    never half of one; a full disk is an error (one line), not "wrote".  The file keeps the
    mode of the one it replaces (a new one: the umask's), not the temporary file's 0600;
    ``mode`` gives it one (a private key's 0600: never readable by others, not even while
    it is written)."""
    write_all([(path, data)], mode=mode)


def write_all(files: list[tuple[Path, str | bytes]], *, mode: int | None = None) -> None:
    """Write every file or none (as :func:`write_atomic` each): all are written to temporary
    files beside them first, and renamed only once all are (a full disk or a missing folder
    leaves nothing half-written behind, and none of the files replaced); ``mode``: each
    file's, else as :func:`write_atomic` says."""
    temps: list[tuple[str, Path]] = []
    current = files[0][0] if files else Path()
    try:
        try:
            for path, data in files:
                current = path
                given = mode if mode is not None else path.stat().st_mode & 0o7777 \
                    if path.is_file() else _default_mode()
                fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
                temps.append((tmp, path))
                with os.fdopen(fd, "wb") as f:
                    f.write(data.encode("utf-8") if isinstance(data, str) else data)
                    f.flush()
                    os.fsync(f.fileno())
                os.chmod(tmp, given)
            # a signal between two renames would leave some files new and some old, and
            # one just after a rename a file in place that the command's stop never names
            with held():
                for tmp, path in temps:
                    current = path
                    os.replace(tmp, path)
                    _WRITTEN.append(path)
        except BaseException:
            for tmp, _ in temps:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            raise
    except FileNotFoundError:
        if not current.parent.is_dir():
            raise InputError(folder_missing(current)) from None
        raise InputError(f"{current}: cannot write: No such file or directory") from None
    except OSError as exc:
        raise InputError(f"{current}: cannot write: {exc.strerror or exc}") from None


def written() -> tuple[Path, ...]:
    """The files this process has put in place since :func:`forget_written`: a command
    stopped by a signal after writing one says so (its stop line), not as if nothing was."""
    return tuple(_WRITTEN)


def forget_written() -> None:
    """A new command begins (a caller running several in one process, as the tests do)."""
    _WRITTEN.clear()


def folder_missing(path: Path, option: str = "--out") -> str:
    """The one line for an output whose folder does not exist (nothing creates folders: a
    typo in a path must not leave a tree of them behind)."""
    return f"{path}: folder {path.parent} does not exist (create it first, or give another " \
           f"{option})"


def need_folder(path: Path, option: str = "--out") -> None:
    """Raise :class:`InputError` when ``path``'s folder does not exist: asked before the work
    (a database read, a computation), so that a typo costs nothing."""
    if not path.parent.is_dir():
        raise InputError(folder_missing(path, option))


def _default_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask
