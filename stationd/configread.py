"""Reading a configuration file's sections: each parsed by its component, every error told.

The generic half of the configuration, at the bottom of the house: it knows YAML nodes,
errors and kinds of file, and no section of any file.  What a section means is its
component's (``MarkerSpec.from_node``, ``OpcUaConfig.from_node``...); which key is read by
which component is the file's assembly (:mod:`stationd.config` for the station file).

Why one reader for raising and collecting: a daemon wants the first error (a yes or no), a
person checking a file wants all of them.  The sections are parsed by the same code and only
what happens to an error differs: with ``collect`` it is recorded and reading goes on with
the default, each section (and each entry a caller guards) on its own, so independent
mistakes are all reported; without, it is raised as it is found.

Relative paths in a file are relative to the file (for a symbolic link, to the file it points
to: :func:`base_folder`); there are no hidden sources.  A path it names that cannot be looked
at (a folder closed to the service's user, a file where a folder was meant, any error of the
system's) is an error at its key, like any other (:func:`present`), never a traceback.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Callable, Collection
from pathlib import Path
from typing import ParamSpec, TypeVar

from db.reach import unreachable
from stationd.errors import ConfigError
from stationd.filekind import expect
from stationd.yamlio import YamlNode, missing_keys, unknown_key

T = TypeVar("T")
P = ParamSpec("P")

#: the most errors told of one section (each found by reading it again without the last)
MAX_SECTION_ERRORS = 50


class SectionReader:
    """Reads the top-level sections of one file, raising the first error or collecting all.

    ``errors`` and ``warnings`` are what collecting found (warnings are told in both modes:
    what a reader accepts but a person setting it up wants to know); ``top`` the file's
    sections once :meth:`sections` has read them; ``unreadable`` whether the top-level
    mapping itself could not be read (its sections are then not "missing": not read).
    """

    def __init__(self, *, collect: bool) -> None:
        self.collect = collect
        self.errors: list[ConfigError] = []
        self.warnings: list[ConfigError] = []
        self.top: dict[str, YamlNode] = {}
        self.unreadable = False

    def guard(self, default: T, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
        """``fn(...)``; when collecting, an error is recorded and ``default`` returned."""
        if not self.collect:
            return fn(*args, **kwargs)
        try:
            return fn(*args, **kwargs)
        except ConfigError as exc:
            self.errors.append(exc)
            return default

    def refuse(self, error: ConfigError) -> None:
        """Raise ``error``, or record it when collecting: a check of entries already read
        (two of them that clash) that is no parse of its own."""
        self.guard(None, _raise, error)

    def section(self, key: str, default: T, parse: Callable[[YamlNode], T]) -> T:
        """The section ``key`` parsed (``default`` without it).  When collecting, each error
        is recorded and the section read again without the entry it names, until it reads
        or an error is the section's own: every error of a section is told, not the first
        (a typo'd key hid ``max_age_s: 500`` below it), and the default is returned."""
        if key not in self.top:
            return default
        if not self.collect:
            return parse(self.top[key])
        node: YamlNode | None = self.top[key]
        found: list[ConfigError] = []
        while node is not None and len(found) < MAX_SECTION_ERRORS:
            try:
                value = parse(node)
            except ConfigError as exc:
                if any(str(exc) == str(e) for e in found):
                    break      # nothing new: stop
                if exc.missing:
                    # a key missing because it was left out is not told, one missing as
                    # written is: a user told its wrong role lacks its password too
                    really = missing_as_written(exc, found)
                    if really is not None:
                        found.append(really)
                elif not left_out(exc, found):
                    found.append(exc)
                # what leaving an entry out did (a user without the role told wrong misses
                # it) is not told, and the mapping holding it is left out in turn: the
                # entries after it are still read (five bad users were told one a run)
                node = node.without(exc)
                continue
            if not found:
                return value
            break
        self.errors.extend(found)
        return default

    def sections(self, root: YamlNode, kind: str, keys: Collection[str]) -> dict[str, YamlNode]:
        """The top-level sections of a file of ``kind`` (a key of ``filekind.KINDS``) whose
        sections are ``keys``, kept as :attr:`top`.  ``YamlNode.mapping`` stops at the first
        unknown key; when collecting, each unknown key is reported at its own line (the known
        sections are still read) by accepting it and reading the mapping again."""
        # another kind of file given: one line, not one per unknown section
        expect(root, kind, keys)
        unknown: set[str] = set()
        while True:
            duplicates: list[ConfigError] | None = [] if self.collect else None
            try:
                m = root.mapping((*keys, *unknown), duplicates=duplicates)
                self.top = {k: v for k, v in m.items() if k not in unknown}
                # a section written twice: told, the first one read on (the others' errors
                # too: a duplicate hid every other error of the file)
                self.errors.extend(duplicates or ())
                return self.top
            except ConfigError as exc:
                if not self.collect:
                    raise
                key = exc.key
                if key is None or key in keys or key in unknown:
                    self.errors.append(exc)  # not a mapping, a duplicate or a non-string key
                    self.unreadable = True
                    self.top = {}
                    return self.top
                unknown.add(key)
                self.errors.append(ConfigError(unknown_key(key, keys), path=exc.path,
                                               line=exc.line, key=key))


def _raise(error: ConfigError) -> None:
    raise error


def left_out(error: ConfigError, told: list[ConfigError]) -> bool:
    """Whether ``error`` is about what :meth:`SectionReader.section` changed by leaving out
    the entries it told: it is at one of them or at a mapping holding one (a required key
    left out is missing; a pair sees no reference once the one it saw, mistyped, is left
    out), not a second mistake of the file."""
    if error.key is None:
        return False
    return any(e.key is not None and (e.key == error.key or e.key.startswith(
        (error.key + ".", error.key + "["))) for e in told)


def missing_as_written(error: ConfigError, told: list[ConfigError]) -> ConfigError | None:
    """A "missing key" ``error`` with only the keys that are missing as the file is written:
    those :meth:`SectionReader.section` left out, having told them (``told``), are not; None
    when no other is missing."""
    prefix = f"{error.key}." if error.key else ""
    kept = [k for k in error.missing
            if not any(e.key is not None and (e.key == prefix + k or e.key.startswith(
                (prefix + k + ".", prefix + k + "["))) for e in told)]
    if not kept:
        return None
    if len(kept) == len(error.missing):
        return error
    return missing_keys(kept, path=error.path, line=error.line, key=error.key)


def in_order(errors: list[ConfigError], path: str) -> list[ConfigError]:
    """The errors of the file at ``path`` in line order (its sections are read in a fixed
    order, not the file's), then those of the files it names, in the order found."""
    own = sorted((e for e in errors if e.path == path), key=lambda e: e.line or 0)
    return own + [e for e in errors if e.path != path]


def base_folder(path: Path) -> Path:
    """The folder the relative paths of the file at ``path`` are relative to: its own, or
    for a symbolic link (``/etc/stationd/station.yaml -> /opt/line/station.yaml``, the
    natural install) the folder of the file it points to, where the files it names are kept
    with it (``/opt/line``), wherever the link is.  A file that cannot be looked at is taken
    as no link: reading it says why (a loop of links too: ``resolve`` raises RuntimeError
    for it, which a command told as a traceback: a maintenance technician's trial)."""
    target = _target(path)
    return path.parent if target is None else target.parent


def _target(path: Path) -> Path | None:
    """The file the link ``path`` points to, or None: no link, or one that cannot be
    followed (a loop of links: reading the file says why)."""
    if not _is_link(path):
        return None
    try:
        return path.resolve()
    except (OSError, RuntimeError):
        return None


def _is_link(path: Path) -> bool:
    try:
        return path.is_symlink()
    except OSError:   # a folder on the way closed to this user: the file's read says so
        return False


def is_local(host: str) -> bool:
    """True for a loopback address or ``localhost``: only this machine can connect (the
    screens' and the OPC UA server's listen addresses)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def link_note(path: Path, what: str) -> str:
    """What a missing relative path's message adds when the file at ``path`` (``what``: "the
    station file") is a link: both names, and which folder was read."""
    target = _target(path)
    if target is None:
        return ""
    return (f" (relative paths are read from {target.parent}, the folder of {target}, which "
            f"{what} {path} links to)")


def relative_path(node: YamlNode, base: Path) -> Path:
    """The path a node names, relative to ``base`` (:func:`base_folder`) unless absolute.  A
    NUL character is the node's error (no file system takes one: Python's ValueError was a
    traceback)."""
    text = node.text()
    if "\0" in text:
        raise node.error("a path cannot contain a NUL character (\\0)")
    p = Path(text)
    return p if p.is_absolute() else base / p


def present(node: YamlNode, path: Path, what: str) -> bool:
    """Whether ``path`` (named at ``node``) is there; a path that cannot be looked at is the
    node's error, naming ``what`` it is and why (:func:`db.reach.unreachable`): Python's
    ``Path.exists`` raises a PermissionError for a folder closed to this user (a traceback,
    exit 1) and answers False for a file where a folder was meant ("does not exist")."""
    try:
        path.stat()
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise node.error(f"{what} {path}: {unreachable(path, exc)}") from None
    return True


def existing_file(node: YamlNode, base: Path, what: str, note: str = "") -> Path:
    """A path (relative to ``base``) that must name an existing file; ``note`` is added to
    the message (where relative paths were read from, for a linked file: :func:`link_note`).
    One that cannot be looked at is refused saying why (:func:`present`)."""
    p = relative_path(node, base)
    if not present(node, p, what):
        raise node.error(f"{what} {p} does not exist{note}")
    return p


def named_items(node: YamlNode) -> list[tuple[str, YamlNode]]:
    """A mapping name -> settings (a station's pairs and cameras): any names, at least one;
    the settings are their reader's to check."""
    items = node.named()
    if not items:
        raise node.error("expected a mapping of names to their settings")
    return items


__all__ = ["MAX_SECTION_ERRORS", "SectionReader", "base_folder", "existing_file", "in_order",
           "is_local", "left_out", "link_note", "missing_as_written", "named_items", "present",
           "relative_path"]
