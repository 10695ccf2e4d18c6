"""YAML read into typed values, with errors that name file, line and key.

A thin layer over PyYAML's node graph (``yaml.compose``): every value keeps the line it
came from, so a wrong type, an unknown key or a K that is not 3x3 is reported as
``station.yaml:12: vision.hsv.h: expected two numbers``.  No hidden sources: what is not in
the file is a default written in code, never an environment variable.
"""

from __future__ import annotations

import difflib
import math
import re
import stat
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from yaml.constructor import SafeConstructor

from db.reach import unreachable
from drivers.counting import noun
from stationd.errors import ConfigError, printable


def _construct(node: yaml.Node) -> Any:
    """The plain Python value of ``node`` (deep), by a constructor of its own.  PyYAML's
    constructor keeps every node it built, and the value built from it, until the end of
    its document (``construct_document``), which a constructor shared by every call never
    reaches: the module's one kept every node and value ever read alive (a daemon grew by
    each reload, a test process by a million objects that every garbage collection walked)."""
    return SafeConstructor().construct_object(node, deep=True)


#: numbers YAML 1.1 reads as text: an exponent without a dot or sign (1e9, 2E-3)
_EXPONENT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")
#: a number written with a decimal comma (300,5)
_DECIMAL_COMMA = re.compile(r"[-+]?\d+,\d+")


#: the largest YAML file read: a station file or a calibration is a few kB, a bolt table of
#: 10 000 bolts about 2 MB; more is not one of them (and is not read into memory)
MAX_YAML_BYTES = 16 * 2**20

#: the first bytes of the files most often given by mistake, and what they are
_MAGIC = ((b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"),
          (b"II*\x00", "a TIFF image"), (b"MM\x00*", "a TIFF image"), (b"BM", "a BMP image"),
          (b"SQLite format 3\x00", "an SQLite database"), (b"%PDF", "a PDF document"),
          (b"PK\x03\x04", "a ZIP archive (or an .xlsx, .docx, .ods file)"),
          (b"\x1f\x8b", "a gzip archive"), (b"\x7fELF", "a program (ELF)"),
          (b"\xff\xfe", "UTF-16 text"), (b"\xfe\xff", "UTF-16 text"))


def read_text_file(path: Path, max_bytes: int, expected: str) -> str:
    """The UTF-8 text of the regular file at ``path``; a :class:`ConfigError` in a person's
    words otherwise, at once: a FIFO or a device is never opened (a FIFO would block until a
    writer comes, /dev/zero would fill memory), a file over ``max_bytes`` is not read, and a
    file that is not UTF-8 text is told by the kind of file it looks like (``expected``: what
    was expected, e.g. "a YAML file").  A folder on the way closed to this user, or any other
    error of the system's, is said in words (:func:`db.reach.unreachable`), never raised."""
    where = str(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise ConfigError("file not found", path=where) from None
    except OSError as exc:
        raise ConfigError(unreachable(path, exc), path=where) from None
    if stat.S_ISDIR(st.st_mode):
        raise ConfigError(f"a folder, not a file ({expected} was expected)", path=where)
    if not stat.S_ISREG(st.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" \
            if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "a socket" \
            if stat.S_ISSOCK(st.st_mode) else "not a regular file"
        raise ConfigError(f"{kind}, not a file ({expected} was expected): give the path of "
                          "a regular file", path=where)
    if st.st_size > max_bytes:
        raise ConfigError(f"{st.st_size} bytes: too large for {expected} (at most "
                          f"{max_bytes // 2**20} MB); is it the right file?", path=where)
    try:
        with path.open("rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise ConfigError(unreachable(path, exc), path=where) from None
    if len(data) > max_bytes:   # grew, or a special file that says size 0
        raise ConfigError(f"too large for {expected} (more than {max_bytes // 2**20} MB)",
                          path=where)
    return decode_text(data, where, expected)


def decode_text(data: bytes, where: str, expected: str) -> str:
    """``data`` as UTF-8 text (a leading byte-order mark dropped); otherwise a ConfigError
    that says what the file looks like instead."""
    for magic, kind in _MAGIC:
        if data.startswith(magic):
            what = "UTF-16 text, not UTF-8" if kind == "UTF-16 text" else \
                f"not a text file: it looks like {kind}"
            raise ConfigError(f"{what} ({expected} was expected)", path=where)
    if b"\x00" in data[:8192]:
        raise ConfigError(f"not a text file: binary data ({expected} was expected)",
                          path=where)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        start = data.rfind(b"\n", 0, exc.start) + 1
        end = data.find(b"\n", exc.start)
        shown = data[start:end if end >= 0 else len(data)].decode("cp1252", "replace").strip()
        raise ConfigError(f"not UTF-8 text (Latin-1 or Windows-1252?): {shown[:60]!r}; save "
                          "the file as UTF-8", path=where, line=line) from None


def missing_keys(keys: Sequence[str], *, path: str | None, line: int | None,
                 key: str | None) -> ConfigError:
    """The error of a mapping (at ``path``, ``line``, ``key``) without the required
    ``keys``: "missing key: role", "missing keys: role, password"."""
    return ConfigError(f"missing {noun(len(keys), 'key')}: {', '.join(keys)}", path=path,
                       line=line, key=key, missing=tuple(keys))


#: how deep a file's collections may nest: the station's files nest a few levels; PyYAML and
#: the readers walk a document recursively, and 300 levels exhausted Python's stack (a
#: traceback, and a daemon that died on a reload)
MAX_DEPTH = 64


def _walk(root: yaml.Node) -> Iterator[tuple[yaml.Node, int]]:
    """Every node of a document with its depth (the root's: 1), each once (an alias is
    walked once), without recursion: a document nested deeper than Python's stack must be
    refused, not crash its reader."""
    todo: list[tuple[yaml.Node, int]] = [(root, 1)]
    seen: set[int] = set()
    while todo:
        node, depth = todo.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        yield node, depth
        if isinstance(node, yaml.SequenceNode):
            todo.extend((child, depth + 1) for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            todo.extend((part, depth + 1) for pair in node.value for part in pair)


def _holding_itself(root: yaml.Node) -> yaml.Node | None:
    """Where an alias names a collection it is inside of (``a: &x {b: *x}``: the key ``b``,
    or the list holding the alias), or None: the document's graph has a cycle, which no
    value can be built from.  A depth-first walk
    without recursion (the depth already checked), the collections on the way kept."""
    on_way: set[int] = set()
    done: set[int] = set()
    todo: list[tuple[yaml.Node, bool]] = [(root, False)]
    while todo:
        node, leaving = todo.pop()
        if leaving:
            on_way.discard(id(node))
            done.add(id(node))
            continue
        if not isinstance(node, yaml.CollectionNode) or id(node) in done:
            continue
        on_way.add(id(node))
        todo.append((node, True))
        # each child with where an alias to it is written: a mapping's key, a list itself
        children = [(child, node) for child in node.value] \
            if isinstance(node, yaml.SequenceNode) else \
            [(part, key) for key, value in node.value for part in (key, value)]
        for child, at in children:
            if id(child) in on_way:
                return at
            todo.append((child, False))
    return None


def _too_deep(root: yaml.Node) -> yaml.Node | None:
    """The first collection nested deeper than :data:`MAX_DEPTH`, or None (a scalar nests
    nothing)."""
    return next((node for node, depth in _walk(root)
                 if depth > MAX_DEPTH and isinstance(node, yaml.CollectionNode)), None)


#: libyaml's parser (PyYAML's wheels carry it): the same node graph, marks and resolver as the
#: pure-Python one, eight times faster; None where PyYAML was built without it
_FAST_LOADER: type[yaml.SafeLoader] | None = getattr(yaml, "CSafeLoader", None) \
    if yaml.__with_libyaml__ else None


def _compose(text: str) -> yaml.Node | None:
    """The document's node graph.  Parsed by libyaml where PyYAML has it; a document libyaml
    refuses is parsed again by the pure-Python parser, whose error (problem and line) is
    the one told, word for word as ever, whichever parser the machine has."""
    if _FAST_LOADER is not None:
        try:
            root = yaml.compose(text, Loader=_FAST_LOADER)
        except (yaml.YAMLError, RecursionError):
            pass
        else:
            _as_pure(root)
            return root
    return yaml.compose(text, Loader=yaml.SafeLoader)


def _as_pure(root: yaml.Node | None) -> None:
    """libyaml marks a plain scalar's style ``''`` where the pure-Python parser says None:
    made None, so that what is plain (a number, not quoted text) reads the same from both.
    A collection's flow style, which the parsers also mark differently, is read by nothing
    here."""
    if root is None:
        return
    for node, _ in _walk(root):
        if isinstance(node, yaml.ScalarNode) and node.style == "":
            node.style = None


def unknown_key(name: str, accepted: Iterable[str]) -> str:
    """The words for a key no reader takes: the keys that are, and the one meant where one is
    close ("pest" for pset: a newcomer's trial read the list of eight to find it)."""
    keys = sorted(accepted)
    close = difflib.get_close_matches(name, keys, n=1, cutoff=0.6)
    return f"unknown key ({f'did you mean {close[0]}? ' if close else ''}accepted: " \
           f"{', '.join(keys)})"


class YamlNode:
    """One node of a YAML document, with its file, line and dotted key path."""

    def __init__(self, node: yaml.Node, path: str, key: str) -> None:
        self._node = node
        self.path = path
        self.key = key

    # -- construction -------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path) -> YamlNode:
        """Read a YAML file; a missing file or a syntax error is a :class:`ConfigError`."""
        p = Path(path)
        return cls.parse(read_text_file(p, MAX_YAML_BYTES, "a YAML file"), str(p))

    @classmethod
    def parse(cls, text: str, path: str = "<string>") -> YamlNode:
        """Parse YAML text; ``path`` is only used in messages."""
        try:
            node = _compose(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line = mark.line + 1 if mark is not None else None
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            # where what it was reading began, when on another line (an unclosed "{" on
            # line 9 was told at line 10 alone: a line engineer's trial)
            context, begun = getattr(exc, "context", None), getattr(exc, "context_mark", None)
            where = f" (in the {_OPENED.get(context, context)} opened at line " \
                f"{begun.line + 1})" if context and begun is not None \
                and begun.line + 1 != line else ""
            raise ConfigError(f"malformed YAML: {_plain(problem)}{where}", path=path,
                              line=line) from None
        except RecursionError:   # PyYAML parses nested collections recursively
            raise ConfigError(f"collections nested more than {MAX_DEPTH} levels deep: not a "
                              "station's file", path=path) from None
        if node is None:
            raise ConfigError("the file is empty", path=path)
        deep = _too_deep(node)
        if deep is not None:   # refused here, before anything walks it recursively
            raise ConfigError(f"collections nested more than {MAX_DEPTH} levels deep: not a "
                              "station's file", path=path,
                              line=int(deep.start_mark.line) + 1)
        loop = _holding_itself(node)
        if loop is not None:   # (a technician's trial: PyYAML's ConstructorError, a traceback)
            raise ConfigError("an alias (*name) names a collection it is inside of: it would "
                              "hold itself, not a station's file", path=path,
                              line=int(loop.start_mark.line) + 1)
        return cls(node, path, "")

    # -- errors -------------------------------------------------------------------------
    @property
    def line(self) -> int:
        return int(self._node.start_mark.line) + 1

    def error(self, message: str) -> ConfigError:
        """A :class:`ConfigError` located at this node."""
        return ConfigError(message, path=self.path, line=self.line, key=self.key or None)

    def _child_key(self, name: str | int) -> str:
        if isinstance(name, int):
            return f"{self.key}[{name}]"
        return f"{self.key}.{name}" if self.key else name

    def without(self, error: ConfigError) -> YamlNode | None:
        """This node with the mapping entry ``error`` is about left out (the entry at its
        key path, or the one holding it), or None when it is this node's own (a section that
        is not a mapping, a required key missing from it).

        Why: a checker that reports every error of a section reads it again without the
        entry it has told (its default then), so that a typo'd key does not hide a value out
        of range two lines below it (issue 30: ``max_age_s: 500`` under a misspelt key)."""
        if error.key is None or error.path != self.path:
            return None
        kept = _without(self._node, self.key, error.key, error.line)
        return None if kept is None else YamlNode(kept, self.path, self.key)

    # -- containers ---------------------------------------------------------------------
    def mapping(self, allowed: Iterable[str], required: Iterable[str] = (),
                duplicates: list[ConfigError] | None = None) -> dict[str, YamlNode]:
        """The children of a mapping; unknown keys and missing required keys are errors.  A
        duplicate key is one too; with ``duplicates`` it is added there instead and the
        first one kept (a checker reporting every error reads on)."""
        if not isinstance(self._node, yaml.MappingNode):
            raise self.error("expected a mapping (key: value)")
        allowed_set = set(allowed)
        out: dict[str, YamlNode] = {}
        previous: yaml.Node | None = None
        previous_name = ""
        for key_node, value_node in self._node.value:
            name = _construct(key_node)
            if not isinstance(name, str):
                where = YamlNode(key_node, self.path, self.key)
                if isinstance(name, int) and previous is not None \
                        and _comma_split(previous, key_node, value_node):
                    written = f"{previous.value},{key_node.value}"
                    raise YamlNode(previous, self.path, self._child_key(previous_name)).error(
                        f"{written}: a decimal comma? write "
                        f"{written.replace(',', '.')} (in {{...}} a comma separates keys)")
                raise where.error(f"key {name!r} is not a string")
            previous, previous_name = value_node, name
            child = YamlNode(value_node, self.path, self._child_key(name))
            if name not in allowed_set:
                raise YamlNode(key_node, self.path, child.key).error(
                    unknown_key(str(name), allowed_set))
            if name in out:
                error = YamlNode(key_node, self.path, child.key).error("duplicate key")
                if duplicates is None:
                    raise error
                duplicates.append(error)
                continue
            out[name] = child
        missing = [k for k in required if k not in out]
        if missing:
            raise missing_keys(missing, path=self.path, line=self.line, key=self.key or None)
        return out

    def named(self, what: str = "names to their settings") -> list[tuple[str, YamlNode]]:
        """The children of a mapping whose keys are names the file chooses (pairs, users,
        roles, bolts): each with its node; an error "expected a mapping of ``what``"."""
        value = self.value()
        if not isinstance(value, dict):
            raise self.error(f"expected a mapping of {what}")
        children = list(self.mapping(tuple(str(k) for k in value)).items())
        for name, node in children:
            if not name.isprintable():   # a name shows in journals, screens and messages
                raise node.error(f"the name '{printable(name)}' has a control character "
                                 "(an escape, a bell, a direction override...): names are "
                                 "printable text")
        return children

    def pairs(self) -> list[tuple[object, YamlNode]]:
        """The key/value pairs of a mapping whose keys may be any scalar (pset numbers)."""
        if not isinstance(self._node, yaml.MappingNode):
            raise self.error("expected a mapping (key: value)")
        out: list[tuple[object, YamlNode]] = []
        for key_node, value_node in self._node.value:
            key = _construct(key_node)
            if any(k == key for k, _ in out):
                raise YamlNode(key_node, self.path, self._child_key(str(key))).error(
                    "duplicate key")
            out.append((key, YamlNode(value_node, self.path, self._child_key(str(key)))))
        return out

    def items(self) -> list[YamlNode]:
        """The elements of a sequence."""
        if not isinstance(self._node, yaml.SequenceNode):
            raise self.error("expected a list")
        return [YamlNode(n, self.path, self._child_key(i)) for i, n in enumerate(self._node.value)
                if not isinstance(n, _LeftOut)]

    # -- scalars ------------------------------------------------------------------------
    def value(self) -> Any:
        """The plain Python value of this node (deep)."""
        return _construct(self._node)

    def number(self, *, lo: float = -math.inf, hi: float = math.inf) -> float:
        """A finite number within [lo, hi].  ``1e9`` written plainly is one (YAML 1.1, which
        PyYAML reads, wants ``1.0e+9``); ``300,5`` is told as a decimal comma."""
        v = self.value()
        plain = isinstance(self._node, yaml.ScalarNode) and self._node.style is None
        if plain and isinstance(v, str) and _EXPONENT.fullmatch(v):
            v = float(v)
        if isinstance(v, bool) or not isinstance(v, int | float):
            if isinstance(v, str) and _DECIMAL_COMMA.fullmatch(v.strip()):
                raise self.error(f"expected a number, got {v!r}: a decimal comma? write "
                                 f"{v.strip().replace(',', '.')}")
            raise self.error(f"expected a number, got {v!r}")
        if not math.isfinite(v):
            raise self.error("expected a finite number")
        if not lo <= v <= hi:
            raise self.error(f"{v} is out of range [{lo}, {hi}]")
        return float(v)

    def integer(self, *, lo: int | None = None, hi: int | None = None) -> int:
        v = self.value()
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(f"expected an integer, got {v!r}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise self.error(f"{v} is out of range [{lo}, {hi}]")
        return v

    def text(self, choices: Sequence[str] | None = None, *, secret: bool = False) -> str:
        """The value, a string (one of ``choices`` where given).  ``secret``: a token or a
        password, whose value a refusal never repeats (it went to the journal and
        ``/api/status``), only its type."""
        v = self.value()
        if not isinstance(v, str):
            got = f"a {_type_words(v)} (not shown: a secret)" if secret else repr(v)
            raise self.error(f"expected a string, got {got}")
        if choices is not None and v not in choices:
            raise self.error(f"{v!r} is not one of: {', '.join(choices) or '(none given)'}")
        return v

    def flag(self) -> bool:
        v = self.value()
        if not isinstance(v, bool):
            raise self.error(f"expected true or false, got {v!r}")
        return v

    def vector(self, lengths: Sequence[int]) -> np.ndarray:
        """A flat list of numbers whose length is one of ``lengths``."""
        elems = self.items()
        if len(elems) not in lengths:
            want = " or ".join(str(n) for n in lengths)
            raise self.error(f"expected {want} numbers, got {len(elems)}")
        return np.array([e.number() for e in elems], dtype=np.float64)

    def matrix(self, rows: int, cols: int) -> np.ndarray:
        """A nested list of numbers of shape rows x cols."""
        row_nodes = self.items()
        if len(row_nodes) != rows:
            raise self.error(f"expected a {rows}x{cols} matrix (nested list), "
                             f"got {len(row_nodes)} rows")
        out = np.empty((rows, cols), dtype=np.float64)
        for i, r in enumerate(row_nodes):
            try:
                out[i] = r.vector([cols])
            except ConfigError as exc:
                # the element's own reason (NaN, not a number) beats the row's shape
                if isinstance(r.value(), list) and len(r.value()) == cols:
                    raise r.error(f"row {i} of the {rows}x{cols} matrix: "
                                  f"{exc.message}") from None
                raise r.error(f"expected a {rows}x{cols} matrix: row {i} must have "
                              f"{cols} numbers") from None
        return out


class _LeftOut(yaml.ScalarNode):
    """The place of a list's element left out by :meth:`YamlNode.without` (a null to the
    constructor; :meth:`YamlNode.items` skips it)."""

    def __init__(self, element: yaml.Node) -> None:
        super().__init__("tag:yaml.org,2002:null", "", element.start_mark, element.end_mark)


def _without(node: yaml.Node, key: str, target: str, line: int | None) -> yaml.Node | None:
    """A copy of the mapping ``node`` (at key path ``key``) without the entry at key path
    ``target`` (where two entries have it, the one at ``line``), descending into the entry
    that holds it; None when no entry is or holds ``target``.  A list's element is left out
    of its list (``roles.operator[1]``, a right misspelt: the role keeps its other rights),
    its place kept: the elements after it keep their index in what is told of them."""
    if isinstance(node, yaml.SequenceNode):
        for i, element in enumerate(node.value):
            child = f"{key}[{i}]"
            if child == target or target.startswith((child + ".", child + "[")):
                inner = None if child == target else _without(element, child, target, line)
                elements = list(node.value)
                elements[i] = _LeftOut(element) if inner is None else inner
                return yaml.SequenceNode(node.tag, elements, node.start_mark, node.end_mark,
                                         node.flow_style)
        return None
    if not isinstance(node, yaml.MappingNode):
        return None
    found: int | None = None
    for i, (key_node, _) in enumerate(node.value):
        name = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
        child = f"{key}.{name}" if key else str(name)
        if child == target or target.startswith((child + ".", child + "[")):
            found = i
            if key_node.start_mark.line + 1 == line:
                break
    if found is None:
        return None
    key_node, value_node = node.value[found]
    name = key_node.value
    child = f"{key}.{name}" if key else str(name)
    inner = None if child == target else _without(value_node, child, target, line)
    entries = list(node.value)
    if inner is None:
        del entries[found]
    else:
        entries[found] = (key_node, inner)
    return yaml.MappingNode(node.tag, entries, node.start_mark, node.end_mark,
                            node.flow_style)


def _comma_split(previous: yaml.Node, key: yaml.Node, value: yaml.Node) -> bool:
    """``{length_mm: 300,5}``: YAML reads ``5`` as the next key (with no value); true when
    ``key`` is digits right after the digits of ``previous``'s value, on the same line."""
    return (isinstance(previous, yaml.ScalarNode) and previous.style is None
            and str(previous.value).lstrip("+-").isdigit()
            and isinstance(key, yaml.ScalarNode) and str(key.value).isdigit()
            and isinstance(value, yaml.ScalarNode) and value.value in ("", None)
            and previous.end_mark.line == key.start_mark.line)


def top_keys(root: YamlNode) -> set[str]:
    """The top-level keys of a file that is a mapping (empty otherwise)."""
    value = root.value()
    return {k for k in value if isinstance(k, str)} if isinstance(value, dict) else set()


#: the parser's words for the commonest hand edits, said plainly (its own words kept after)
_PLAIN = (
    ("found character '\\t'", "a tab character: YAML indents with spaces only"),
    ("expected <block end>", "the indentation of this line, or of the line above it, does "
                             "not line up with the lines around it"),
    ("mapping values are not allowed here", "a ':' where no key can start (a value with ': ' "
                                            "in it needs quotes, or the line is indented "
                                            "too far)"),
    ("could not find expected ':'", "a key without its ':' (or a line indented too far)"),
)


#: what the parser was reading when it failed, in the words of what a person typed
_OPENED = {"while parsing a flow mapping": "{ }", "while parsing a flow sequence": "[ ]",
           "while scanning a quoted scalar": "quoted text"}


def _plain(problem: str) -> str:
    """The parser's ``problem`` with plain words before it where it is a common slip."""
    for needle, words in _PLAIN:
        if needle in problem:
            return f"{words} ({problem})"
    return problem


def _type_words(v: Any) -> str:
    """What a YAML value is, in words (a number, a list, ...), not what it says."""
    return {bool: "true/false", int: "number", float: "number", list: "list",
            dict: "mapping"}.get(type(v), type(v).__name__)
