"""The bolt table file (bolts.yaml): YAML -> typed, validated values, every error located.

Why a checker that *collects*: a bolt table is written by hand for a whole vehicle model at a
time, so ``stationd config check`` reports every mistake of a file in one run (each with file,
line and dotted key); the importer uses the same checker and refuses the file if any error is
found.  :func:`load_bolts` raises the first error for callers that need only a yes or no.

Numbers are plain numbers in fixed units (positions mm in the vehicle frame, torque N m, angle
degrees): a value such as ``"25 Nm"`` is an error rather than something parsed, so a unit can
never be misread.  A pset is the number of a program held by the tightening controller; its
torque/angle program is defined once, globally or in a model, and bolts refer to it.  Bolts
closer in X-Y than twice the matching tolerance are refused: the station could not tell them
apart (:mod:`db.spacing`, the rule the matcher uses).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import yaml

from db.bolts import BoltSpec, BoltTable, ModelSpec, Parameters, Pset, Window
from db.importer import ImportReport
from db.repository import Repository
from db.spacing import min_spacing_mm, too_close
from drivers.counting import counted, noun
from stationd.errors import ConfigError, InputError
from stationd.filekind import expect
from stationd.yamlio import YamlNode, unknown_key

DEFAULT_TOLERANCE_MM = 8.0   # the matching tolerance; bolts must be twice as far apart
METRES_SPAN_MM = 10.0        # bolts all this near the origin: the table is in metres
#: the least a model's bolts may spread over (the largest extent of their positions along X, Y
#: or Z) in millimetres: a car's chassis written in metres spans a few units (a 5 m car: 5),
#: while two bolts in millimetres are at least twice the matching tolerance apart and a
#: chassis' bolts spread over hundreds of mm, wherever the vehicle frame's origin is
METRES_SPREAD_MM = 10.0
TORQUE_MAX_NM = 5000.0
ANGLE_MAX_DEG = 3600.0       # ten turns
POSITION_MAX_MM = 10_000.0   # |x|, |y|, |z| in the vehicle frame
PSET_MAX = 999               # Open Protocol parameter sets 0-999
MODEL_CODE_MAX = 65_535      # the lift PLC reports the model as a uint16
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.:/+-]{0,31}$")
NAME_RULE = "1-32 letters, digits or _ . : / + -, starting with a letter or digit"

TOP_KEYS = ("psets", "models")
MODEL_KEYS = ("description", "code", "psets", "bolts")
PSET_KEYS = ("id", "name", "torque", "angle")
BOLT_KEYS = ("id", "name", "position", "pset", "torque", "angle", "order", "batch")
WINDOW_KEYS = ("target", "min", "max")

T = TypeVar("T")


@dataclass(frozen=True)
class BoltCheck:
    """The outcome of checking a file: the table when it is valid, else every error."""

    path: str
    table: BoltTable | None
    errors: list[ConfigError] = field(default_factory=list)
    #: valid, but a station with it tightens nothing (no model, a model without bolts), or
    #: two bolts of a model share a name
    warnings: list[ConfigError] = field(default_factory=list)
    #: where each bolt is written ((model, bolt id) -> its entry): the checks of the table
    #: against the station (its controller, its cameras) point at the bolt's own line
    nodes: dict[tuple[str, str], YamlNode] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.errors


def _spread(positions: list[tuple[float, float, float]]) -> float:
    """The largest extent of ``positions`` along X, Y or Z (0 for fewer than two)."""
    if len(positions) < 2:
        return 0.0
    return max(max(p[k] for p in positions) - min(p[k] for p in positions) for k in range(3))


def check_bolts(path: str | Path, *, tolerance_mm: float = DEFAULT_TOLERANCE_MM) -> BoltCheck:
    """Check a bolt file and collect all its errors (a missing or malformed file is one)."""
    try:
        root = YamlNode.load(path)
    except ConfigError as exc:
        return BoltCheck(str(path), None, [exc])
    return _check(root, tolerance_mm)


def load_bolts(path: str | Path, *, tolerance_mm: float = DEFAULT_TOLERANCE_MM) -> BoltTable:
    """The validated table of a file; the file's first error is raised as a ConfigError."""
    result = check_bolts(path, tolerance_mm=tolerance_mm)
    if result.table is None:
        raise result.errors[0]
    return result.table


def _check(root: YamlNode, tolerance_mm: float) -> BoltCheck:
    if not (math.isfinite(tolerance_mm) and tolerance_mm > 0):
        raise InputError(f"matching tolerance {tolerance_mm} mm: must be a positive number")
    try:   # one line, not one "unknown key" per section of the wrong kind of file
        expect(root, "bolts", TOP_KEYS)
    except ConfigError as exc:
        return BoltCheck(root.path, None, [exc])
    checker = _Checker(tolerance_mm)
    table = checker.table(root)
    errors = sorted(checker.errors, key=lambda e: e.line or 0)  # stable: same line keeps order
    if errors or table is None:
        return BoltCheck(root.path, None, errors)
    return BoltCheck(root.path, table, [], [*_idle(root, table), *checker.warnings],
                     checker.nodes)


def _idle(root: YamlNode, table: BoltTable) -> list[ConfigError]:
    """What a valid table cannot tighten: no model at all, or a model without a bolt."""
    models = root.mapping(TOP_KEYS).get("models")
    if not table.models:
        return [(models or root).error("no vehicle model: a station with this table "
                                       "tightens nothing")]
    named = dict(models.named()) if models is not None else {}
    return [named.get(m.name, models or root).error(
                f"model {m.name} has no bolt: its vehicles get nothing tightened")
            for m in table.models if not m.bolts]


@dataclass(frozen=True)
class _Item:
    """A parsed pset or bolt with the nodes that later cross-checks point their errors at."""

    node: YamlNode
    keys: dict[str, YamlNode]


@dataclass(frozen=True)
class _Bolt:
    """A bolt as far as it parsed: its id and position take part in the cross-checks even
    when another of its keys is wrong, so one run reports the duplicates and near pairs too."""

    item: _Item
    bolt_id: str | None
    position: tuple[float, float, float] | None
    spec: BoltSpec | None


class _Checker:
    """Parses one file, appending every error to ``errors`` instead of stopping at the first."""

    def __init__(self, tolerance_mm: float) -> None:
        self.tolerance_mm = tolerance_mm
        self.errors: list[ConfigError] = []
        self.warnings: list[ConfigError] = []
        self.broken_globals: set[int] = set()  # numbers of global psets defined with errors
        self.nodes: dict[tuple[str, str], YamlNode] = {}   # (model, bolt id) -> its entry

    def fail(self, node: YamlNode, message: str) -> None:
        self.errors.append(node.error(message))

    def guard(self, fn: Callable[[], T]) -> T | None:
        try:
            return fn()
        except ConfigError as exc:
            self.errors.append(exc)
            return None

    def fields(self, node: YamlNode, allowed: Iterable[str], required: Iterable[str] = (),
               unknown_message: Callable[[str], str] | None = None,
               ) -> dict[str, YamlNode] | None:
        """A mapping's children; every unknown key and every missing key is its own error.

        ``YamlNode.mapping`` stops at the first unknown key: its name is added to the accepted
        set and the mapping read again, so each unknown key is reported at its own line (the
        key's line, which ``unknown_message`` can reuse for another complaint about a key).
        """
        allowed_set, unknown = set(allowed), set[str]()
        prefix = f"{node.key}." if node.key else ""
        while True:
            # a key written twice: its error, the first one kept (a pset with an angle line
            # pasted twice was left out, and every bolt using it said "not defined")
            duplicates: list[ConfigError] = []
            try:
                children = node.mapping(allowed_set | unknown, duplicates=duplicates)
                break
            except ConfigError as exc:
                key = exc.key or ""
                name = key[len(prefix):] if key.startswith(prefix) else ""
                if not name or name in allowed_set | unknown:
                    self.errors.append(exc)
                    return None  # not a mapping or a non-string key: stop here
                unknown.add(name)  # listed with the keys of the file only, not the unknown ones
                message = unknown_message(name) if unknown_message is not None \
                    else unknown_key(name, allowed_set)
                self.errors.append(ConfigError(message, path=exc.path, line=exc.line,
                                               key=exc.key))
        self.errors.extend(duplicates)
        missing = [k for k in required if k not in children]
        if missing:
            self.fail(node, f"missing {noun(len(missing), 'key')}: {', '.join(missing)}")
        return {k: v for k, v in children.items() if k not in unknown}

    # -- values -----------------------------------------------------------------------------
    def quantity(self, node: YamlNode, unit: str, lo: float, hi: float, *,
                 above: bool = False) -> float | None:
        """A number in a fixed unit; a string such as "25 Nm" is refused with a hint."""
        v = node.value()
        if isinstance(v, str):
            self.fail(node, f"expected a number in {unit}, got the string {v!r} "
                            f"(write the number alone: the unit is always {unit})")
            return None
        if isinstance(v, bool) or not isinstance(v, int | float):
            self.fail(node, f"expected a number in {unit}, got {v!r}")
            return None
        if not math.isfinite(v):
            self.fail(node, "expected a finite number")
            return None
        if v < lo or (above and v == lo):
            self.fail(node, f"{v:g} {unit}: must be {'>' if above else '>='} {lo:g}")
            return None
        if v > hi:
            self.fail(node, f"{v:g} {unit}: above the limit of {hi:g} {unit}")
            return None
        return float(v)

    def name(self, node: YamlNode, what: str) -> str | None:
        text = self.guard(node.text)
        if text is not None and not NAME_RE.match(text):
            self.fail(node, f"{what} {text!r}: {NAME_RULE}")
            return None
        return text

    def window(self, node: YamlNode, unit: str, hi: float, *, above: bool) -> Window | None:
        m = self.fields(node, WINDOW_KEYS, WINDOW_KEYS)
        if m is None:
            return None
        v = {k: self.quantity(m[k], unit, 0.0, hi, above=above and k == "target")
             for k in WINDOW_KEYS if k in m}
        target, lo, hi_ = v.get("target"), v.get("min"), v.get("max")
        if target is None or lo is None or hi_ is None:
            return None
        if not lo < hi_:
            self.fail(node, f"min {lo:g} {unit} must be below max {hi_:g} {unit}")
            return None
        if not lo <= target <= hi_:
            self.fail(node, f"target {target:g} {unit} is outside "
                            f"[min {lo:g}, max {hi_:g}]")
            return None
        return Window(target, lo, hi_)

    def program(self, m: dict[str, YamlNode]) -> tuple[Window | None, Window | None, bool]:
        """Torque (N m, target > 0) and angle (deg); the flag is False if either was invalid."""
        torque = self.window(m["torque"], "N m", TORQUE_MAX_NM, above=True) \
            if "torque" in m else None
        angle = self.window(m["angle"], "deg", ANGLE_MAX_DEG, above=False) \
            if "angle" in m else None
        return torque, angle, ("torque" in m) == (torque is not None) and \
            ("angle" in m) == (angle is not None)

    def position(self, node: YamlNode) -> tuple[float, float, float] | None:
        try:
            elems: list[YamlNode] | None = node.items()
        except ConfigError:
            elems = None
        if elems is None or len(elems) != 3:
            got = "" if elems is None else f", got {counted(len(elems), 'value')}"
            self.fail(node, f"expected [x, y, z] in mm (vehicle frame){got}")
            return None
        xyz = [self.quantity(e, "mm", -POSITION_MAX_MM, POSITION_MAX_MM) for e in elems]
        x, y, z = xyz
        if x is None or y is None or z is None:
            return None
        return (x, y, z)

    def pset_number(self, node: YamlNode) -> int | None:
        return self.guard(lambda: node.integer(lo=0, hi=PSET_MAX))

    # -- psets and bolts --------------------------------------------------------------------
    def psets(self, node: YamlNode, broken: set[int]) -> list[tuple[Pset, _Item]]:
        """The valid psets of a list; the numbers of invalid ones are added to ``broken`` (so
        the bolts using them are not also told that their pset is undefined)."""
        out: list[tuple[Pset, _Item]] = []
        seen: dict[int, YamlNode] = {}
        for item in self.guard(node.items) or []:
            m = self.fields(item, PSET_KEYS, ("id", "torque"))
            if m is None:
                continue
            number = self.pset_number(m["id"]) if "id" in m else None
            name = self.guard(m["name"].text) if "name" in m else None
            torque, angle, valid = self.program(m)
            if number is None or torque is None or not valid or ("name" in m and name is None):
                if number is not None:
                    broken.add(number)
                continue
            if number in seen:
                self.fail(m["id"], f"duplicate pset {number} (first at line "
                                   f"{seen[number].line})")
                continue
            seen[number] = m["id"]
            out.append((Pset(number, name, torque, angle), _Item(item, m)))
        return out

    def bolt(self, node: YamlNode, programs: dict[int, Pset], broken: set[int]) -> _Bolt | None:
        m = self.fields(node, BOLT_KEYS, ("id", "name", "position"))
        if m is None:
            return None
        bolt_id = self.name(m["id"], "bolt id") if "id" in m else None
        name = self.guard(m["name"].text) if "name" in m else None
        position = self.position(m["position"]) if "position" in m else None
        pset = self.pset_number(m["pset"]) if "pset" in m else None
        torque, angle, valid = self.program(m)
        order = self.guard(lambda: m["order"].integer(lo=1, hi=9999)) if "order" in m else None
        batch = self.name(m["batch"], "batch") if "batch" in m else None
        valid &= all(k not in m or v is not None for k, v in (
            ("pset", pset), ("order", order), ("batch", batch)))
        if "pset" not in m and "torque" not in m:
            self.fail(node, "a bolt needs a pset or a torque (or both)")
            valid = False
        program = programs.get(pset) if pset is not None else None
        if pset is not None and program is None:
            valid = False  # a pset defined with errors was reported where it is defined
            if pset not in broken:
                self.fail(m["pset"], f"pset {pset} is not defined (define it under 'psets:', "
                                     "globally or in this model)")
        if program is not None:
            valid &= self.agrees(m, "torque", torque, program.torque, program.number)
            valid &= self.agrees(m, "angle", angle, program.angle, program.number)
            torque, angle = torque or program.torque, angle or program.angle
        spec = None
        if valid and bolt_id is not None and name is not None and position is not None \
                and torque is not None:
            spec = BoltSpec(bolt_id, name, position, Parameters(pset, torque, angle), order,
                            batch)
        return _Bolt(_Item(node, m), bolt_id, position, spec)

    def agrees(self, m: dict[str, YamlNode], key: str, given: Window | None,
               defined: Window | None, number: int) -> bool:
        """A bolt may repeat its pset's torque or angle, but never contradict it."""
        if given is None or defined is None or given == defined:
            return True
        self.fail(m[key], f"differs from pset {number}'s program (target {defined.target:g}, "
                          f"min {defined.min:g}, max {defined.max:g}): the controller runs "
                          "the pset; give the same values or leave them out")
        return False

    def same_names(self, model: str, bolts: list[_Bolt]) -> None:
        """A warning for each bolt named as one before it in ``model``: the screens, the
        journal and the reports name bolts to people, and two alike are told apart by id
        alone (a line engineer's trial: "bolt 7" given to B07 and B51, taken silently)."""
        first: dict[str, _Bolt] = {}
        for b in bolts:
            if b.spec is None or b.bolt_id is None:
                continue
            seen = first.setdefault(b.spec.name, b)
            if seen is not b:
                self.warnings.append(b.item.keys["name"].error(
                    f"{b.bolt_id}: named {b.spec.name!r} as {seen.bolt_id} (line "
                    f"{seen.item.node.line}) of model {model}: people tell the two apart by "
                    "their id alone"))

    def too_close(self, bolts: list[_Bolt]) -> None:
        """Two bolts nearer in plan than twice the tolerance would both match one wrench
        position (:mod:`db.spacing`, the matcher's metric: X and Y of the vehicle frame).

        Each bolt is reported once, against the nearest bolt before it in the file."""
        placed = [b for b in bolts if b.position is not None]
        limit = min_spacing_mm(self.tolerance_mm)
        span = max((abs(v) for b in placed for v in (b.position or ())), default=0.0)
        if len(placed) >= 2 and 0 < span < METRES_SPAN_MM:
            # a car's bolts lie hundreds of mm apart: every one within a few mm of the origin
            # is a table written in metres (each pair would read as "too close" otherwise)
            self.fail(placed[0].item.keys["position"],
                      f"every bolt position is within {span:g} mm of the vehicle's origin: "
                      "positions in metres? the bolt table's positions are in millimetres")
            return
        spread = _spread([b.position for b in placed if b.position is not None])
        if len(placed) >= 2 and 0 < spread < METRES_SPREAD_MM:
            # the same wherever the origin is (a vehicle frame at the lift's corner, 12 m
            # away): what tells metres is how little the bolts spread, not where they are
            self.fail(placed[0].item.keys["position"],
                      f"the model's {len(placed)} bolts spread over {spread:g} mm only (a "
                      f"chassis' bolts in millimetres spread over hundreds): positions in "
                      "metres? the bolt table's positions are in millimetres")
            return
        for i, j, d in too_close([b.position for b in placed if b.position is not None],
                                 self.tolerance_mm):
            b, a = placed[i], placed[j]
            self.fail(b.item.keys["position"], f"{d:.1f} mm from bolt {a.bolt_id} in X-Y (line "
                      f"{a.item.node.line}): bolts must be at least {limit:g} mm apart in X-Y "
                      f"(twice the matching tolerance of {self.tolerance_mm:g} mm)")

    # -- models and the table -----------------------------------------------------------------
    def model(self, name: str, node: YamlNode, globals_: dict[int, tuple[Pset, _Item]],
              ) -> tuple[ModelSpec, list[tuple[Pset, _Item]], dict[str, YamlNode]] | None:
        m = self.fields(node, MODEL_KEYS, ("bolts",))
        if m is None:
            return None
        description = self.guard(m["description"].text) if "description" in m else None
        code = self.guard(lambda: m["code"].integer(lo=0, hi=MODEL_CODE_MAX)) \
            if "code" in m else None
        own: list[tuple[Pset, _Item]] = []
        broken = set(self.broken_globals)
        for p, pitem in self.psets(m["psets"], broken) if "psets" in m else []:
            if p.number in globals_:
                self.fail(pitem.keys["id"], f"pset {p.number} is already defined globally "
                                            f"(line {globals_[p.number][1].node.line})")
            else:
                own.append((p, pitem))
        programs = {n: p for n, (p, _) in globals_.items()} | {p.number: p for p, _ in own}
        bolts: list[_Bolt] = []
        ids: dict[str, _Bolt] = {}
        items = (self.guard(m["bolts"].items) or []) if "bolts" in m else []
        for item in items:
            bolt = self.bolt(item, programs, broken)
            if bolt is None:
                continue
            if bolt.bolt_id is not None and bolt.bolt_id in ids:
                self.fail(bolt.item.keys["id"], f"duplicate bolt id {bolt.bolt_id!r} (first at "
                                                f"line {ids[bolt.bolt_id].item.node.line})")
                continue
            if bolt.bolt_id is not None:
                ids[bolt.bolt_id] = bolt
                self.nodes[(name, bolt.bolt_id)] = bolt.item.node
            bolts.append(bolt)
        self.same_names(name, bolts)
        self.too_close(bolts)
        spec_ = ModelSpec(name, tuple(b.spec for b in bolts if b.spec is not None),
                          tuple(p for p, _ in own), description, code)
        return spec_, own, m

    def table(self, root: YamlNode) -> BoltTable | None:
        m = self.fields(root, TOP_KEYS, ("models",))
        if m is None:
            return None
        globals_ = {p.number: (p, item) for p, item in self.psets(
            m["psets"], self.broken_globals)} if "psets" in m else {}
        if "models" not in m:
            return None
        node = m["models"]
        try:
            value = node.value()
        except yaml.YAMLError:
            value = None
        if not isinstance(value, dict):
            self.fail(node, "expected a mapping of model name -> model")
            return None
        names = [k for k in value if isinstance(k, str) and NAME_RE.match(k)]
        children = self.fields(node, names,
                               unknown_message=lambda k: f"model name {k!r}: {NAME_RULE}")
        models: list[ModelSpec] = []
        defined: dict[int, tuple[str, Pset, _Item]] = {}
        codes: dict[int, str] = {}
        for name, child in (children or {}).items():
            parsed = self.model(name, child, globals_)
            if parsed is None:
                continue
            model, own, keys = parsed
            models.append(model)
            for p, item in own:  # one controller holds one program per pset number
                other = defined.setdefault(p.number, (name, p, item))
                if other[1] != p:
                    self.fail(item.keys["id"], f"pset {p.number} is defined differently for "
                              f"model {other[0]} (line {other[2].node.line}): the controller "
                              "holds one program per pset; define it once, globally")
            if model.code is not None:
                if model.code in codes:
                    self.fail(keys["code"], f"code {model.code} is also the code of model "
                                            f"{codes[model.code]} (the lift reports one code "
                                            "per model)")
                codes.setdefault(model.code, name)
        return BoltTable(tuple(models), tuple(p for p, _ in globals_.values()))


def import_bolts(repo: Repository, path: str | Path, *,
                 tolerance_mm: float = DEFAULT_TOLERANCE_MM) -> ImportReport:
    """Check the bolt file at ``path`` (every error raised as the first one) and import it into
    ``repo``, all or nothing."""
    return repo.import_bolts(load_bolts(path, tolerance_mm=tolerance_mm), where=str(path))
