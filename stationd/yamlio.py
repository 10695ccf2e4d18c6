"""YAML read into typed values, with errors that name file, line and key.

A thin layer over PyYAML's node graph (``yaml.compose``): every value keeps the line it
came from, so a wrong type, an unknown key or a K that is not 3x3 is reported as
``station.yaml:12: vision.hsv.h: expected two numbers``.  No hidden sources: what is not in
the file is a default written in code, never an environment variable.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from yaml.constructor import SafeConstructor

from stationd.errors import ConfigError

_constructor = SafeConstructor()


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
        try:
            text = p.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ConfigError("file not found", path=str(p)) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"cannot read: {exc}", path=str(p)) from None
        return cls.parse(text, str(p))

    @classmethod
    def parse(cls, text: str, path: str = "<string>") -> YamlNode:
        """Parse YAML text; ``path`` is only used in messages."""
        try:
            node = yaml.compose(text, Loader=yaml.SafeLoader)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line = mark.line + 1 if mark is not None else None
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise ConfigError(f"malformed YAML: {problem}", path=path, line=line) from None
        except RecursionError:   # PyYAML parses nested collections recursively
            raise ConfigError("malformed YAML: collections nested too deeply", path=path
                              ) from None
        if node is None:
            raise ConfigError("the file is empty", path=path)
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

    # -- containers ---------------------------------------------------------------------
    def mapping(self, allowed: Iterable[str], required: Iterable[str] = ()) -> dict[str, YamlNode]:
        """The children of a mapping; unknown keys and missing required keys are errors."""
        if not isinstance(self._node, yaml.MappingNode):
            raise self.error("expected a mapping (key: value)")
        allowed_set = set(allowed)
        out: dict[str, YamlNode] = {}
        for key_node, value_node in self._node.value:
            name = _constructor.construct_object(key_node, deep=True)
            if not isinstance(name, str):
                raise YamlNode(key_node, self.path, self.key).error(f"key {name!r} is not a string")
            child = YamlNode(value_node, self.path, self._child_key(name))
            if name not in allowed_set:
                accepted = ", ".join(sorted(allowed_set))
                raise YamlNode(key_node, self.path, child.key).error(
                    f"unknown key (accepted: {accepted})")
            if name in out:
                raise YamlNode(key_node, self.path, child.key).error("duplicate key")
            out[name] = child
        missing = [k for k in required if k not in out]
        if missing:
            raise self.error(f"missing key(s): {', '.join(missing)}")
        return out

    def pairs(self) -> list[tuple[object, YamlNode]]:
        """The key/value pairs of a mapping whose keys may be any scalar (pset numbers)."""
        if not isinstance(self._node, yaml.MappingNode):
            raise self.error("expected a mapping (key: value)")
        out: list[tuple[object, YamlNode]] = []
        for key_node, value_node in self._node.value:
            key = _constructor.construct_object(key_node, deep=True)
            if any(k == key for k, _ in out):
                raise YamlNode(key_node, self.path, self._child_key(str(key))).error(
                    "duplicate key")
            out.append((key, YamlNode(value_node, self.path, self._child_key(str(key)))))
        return out

    def items(self) -> list[YamlNode]:
        """The elements of a sequence."""
        if not isinstance(self._node, yaml.SequenceNode):
            raise self.error("expected a list")
        return [YamlNode(n, self.path, self._child_key(i)) for i, n in enumerate(self._node.value)]

    # -- scalars ------------------------------------------------------------------------
    def value(self) -> Any:
        """The plain Python value of this node (deep)."""
        return _constructor.construct_object(self._node, deep=True)

    def number(self, *, lo: float = -math.inf, hi: float = math.inf) -> float:
        """A finite number within [lo, hi]."""
        v = self.value()
        if isinstance(v, bool) or not isinstance(v, int | float):
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

    def text(self, choices: Sequence[str] | None = None) -> str:
        v = self.value()
        if not isinstance(v, str):
            raise self.error(f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(f"{v!r} is not one of: {', '.join(choices)}")
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
            except ConfigError:
                raise r.error(f"expected a {rows}x{cols} matrix: row {i} must have "
                              f"{cols} numbers") from None
        return out


#: top-level sections only a bolt table has, and only a station file has (``stationd.config``)
BOLT_ONLY = frozenset({"models", "psets"})
STATION_ONLY = frozenset({"cameras", "pairs", "lift", "wrench", "vision", "marker", "tool"})


def top_keys(root: YamlNode) -> set[str]:
    """The top-level keys of a file that is a mapping (empty otherwise)."""
    value = root.value()
    return {k for k in value if isinstance(k, str)} if isinstance(value, dict) else set()


def file_kind(keys: set[str]) -> str | None:
    """``"bolts"`` for top-level keys of a bolt table, ``"station"`` for a station file's,
    None for anything else: what a file given in the wrong place is said to be."""
    if keys & BOLT_ONLY:
        return "bolts"
    return "station" if keys & STATION_ONLY else None
