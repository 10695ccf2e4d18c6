"""What the station does after a NOK: the line's policy, per station, with per-pset and
per-bolt overrides.

Why in the station file and not the bolt table: the policy is how this station's line runs
(how many attempts an operator gets, whether a NOK bolt is skipped, repeated or loosened
first), while the bolt table is the vehicle's engineering data, shared by every station that
tightens that model.

    nok:
      max_nok: 3            # consecutive NOKs on a bolt before it locks (a release unlocks)
      strategy: repeat      # repeat: open again; skip: marked NOK and skipped for the vehicle;
                            # loosen: the loosen pset runs first, then the tightening pset
      loosen_pset: 90       # the controller's program that loosens (needed by ``loosen``)
      count_in_batch: false # a bolt whose last rundown is a NOK counts as tightened for the
                            # sequence (its batch may close, its order's followers go on)
      psets: {125: {max_nok: 1}}
      bolts: {B07: {strategy: loosen, loosen_pset: 91}}

A locked bolt refuses the tool until a user with the ``release`` right releases it (the
operator screen, or ``stationd release VIN BOLT``), with a comment; the release is recorded.

Under ``loosen`` a loosening NOK counts as a NOK of the bolt (towards ``max_nok``: a joint that
does not come loose needs a supervisor) and the bolt still needs its loosening; a loosening OK
neither counts nor clears the count (NOK, loosen, NOK, loosen, NOK locks at ``max_nok`` 3).

A policy that cannot be met is refused with its file and line: ``loosen`` without a loosen pset,
a loosen pset that is the pset it follows, and (:func:`table_errors`, where the bolt tables are
known) overrides naming a pset or a bolt no table has, or a loosen pset some bolt is tightened
with (its "loosening" would be a tightening).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum

from db.bolts import BoltTable
from stationd.errors import ConfigError
from stationd.yamlio import YamlNode


class Strategy(StrEnum):
    """What follows a bolt's NOK: tightened again, skipped (the vehicle goes on without it),
    or loosened with its loosen pset first.  A ``StrEnum``: the station file's word is its
    value, and the status, the journal and the demo's summary print it as before."""

    REPEAT = "repeat"
    SKIP = "skip"
    LOOSEN = "loosen"


STRATEGIES = tuple(s.value for s in Strategy)
DEFAULT_MAX_NOK = 3
PSET_MAX = 999
RULE_KEYS = ("max_nok", "strategy", "loosen_pset", "count_in_batch")


@dataclass(frozen=True)
class NokRule:
    """For one bolt: consecutive NOKs before it locks, what follows a NOK, and the pset that
    loosens it (``strategy`` loosen, and a loosen command)."""

    max_nok: int = DEFAULT_MAX_NOK
    strategy: Strategy = Strategy.REPEAT
    loosen_pset: int | None = None
    #: a NOK counts in the bolt's batch (and order): the sequence goes on without an OK
    count_in_batch: bool = False

    def __post_init__(self) -> None:
        # the word of a file or a test, typed (ValueError for one that is no strategy)
        object.__setattr__(self, "strategy", Strategy(self.strategy))

    def merged(self, node: YamlNode, keys: tuple[str, ...] = RULE_KEYS) -> NokRule:
        """This rule with what ``node`` overrides (refused with its line when it cannot be
        met)."""
        m = node.mapping(keys)
        rule = self
        if "max_nok" in m:
            rule = replace(rule, max_nok=m["max_nok"].integer(lo=1, hi=99))
        if "strategy" in m:
            rule = replace(rule, strategy=Strategy(m["strategy"].text(STRATEGIES)))
        if "loosen_pset" in m:
            rule = replace(rule, loosen_pset=m["loosen_pset"].integer(lo=1, hi=PSET_MAX))
        if "count_in_batch" in m:
            rule = replace(rule, count_in_batch=m["count_in_batch"].flag())
        if rule.strategy is Strategy.LOOSEN and rule.loosen_pset is None:
            raise m.get("strategy", node).error(
                "loosen needs a loosen_pset: the controller's program that loosens the bolt "
                "before it is tightened again")
        return rule


@dataclass(frozen=True)
class NokPolicy:
    """The default rule and its overrides; :meth:`rule` resolves one bolt's."""

    default: NokRule = field(default_factory=NokRule)
    psets: Mapping[int, NokRule] = field(default_factory=dict)
    bolts: Mapping[str, NokRule] = field(default_factory=dict)

    def rule(self, bolt: str, pset: int | None) -> NokRule:
        """The bolt's own rule, else its pset's, else the default."""
        if bolt in self.bolts:
            return self.bolts[bolt]
        if pset is not None and pset in self.psets:
            return self.psets[pset]
        return self.default

    @classmethod
    def from_node(cls, node: YamlNode) -> NokPolicy:
        m = node.mapping((*RULE_KEYS, "psets", "bolts"))
        default = NokRule().merged(node, (*RULE_KEYS, "psets", "bolts"))
        psets: dict[int, NokRule] = {}
        for key, item in _pset_items(m):
            psets[key] = rule = default.merged(item)
            if rule.strategy is Strategy.LOOSEN and rule.loosen_pset == key:
                raise item.error(f"pset {key}: its loosen_pset is the pset itself: the "
                                 "'loosening' would tighten again")
        bolts = {key: default.merged(item) for key, item in _bolt_items(m)}
        return cls(default, psets, bolts)


def _pset_items(m: dict[str, YamlNode]) -> list[tuple[int, YamlNode]]:
    out = []
    for key, item in m["psets"].pairs() if "psets" in m else ():
        if isinstance(key, bool) or not isinstance(key, int) or not 1 <= key <= PSET_MAX:
            raise item.error(f"pset {key!r}: a pset number (1-{PSET_MAX})")
        out.append((key, item))
    return out


def _bolt_items(m: dict[str, YamlNode]) -> list[tuple[str, YamlNode]]:
    return m["bolts"].named("names to their rules") if "bolts" in m else []


def table_errors(node: YamlNode, table: BoltTable, source: str) -> list[ConfigError]:
    """What the ``nok:`` section at ``node`` (already read by :meth:`NokPolicy.from_node`)
    names that the bolt tables the station loads (``table``, read from ``source``) do not
    have: an override of a pset no bolt is tightened with and no table defines, of a bolt no
    model has, or a loosen pset some bolt is tightened with.  Each error has its line."""
    m = node.mapping((*RULE_KEYS, "psets", "bolts"))
    bolt_psets: dict[int, str] = {}
    ids: set[str] = set()
    for model in table.models:
        for b in model.bolts:
            ids.add(b.bolt_id)
            if b.parameters.pset is not None:
                bolt_psets.setdefault(b.parameters.pset, f"{b.bolt_id} ({model.name})")
    known = set(bolt_psets) | {p.number for p in table.psets} \
        | {p.number for model in table.models for p in model.psets}
    errors: list[ConfigError] = []
    for number, item in _pset_items(m):
        if number not in known:
            errors.append(item.error(f"pset {number}: no bolt of {source} is tightened with "
                                     "it and no table there defines it"))
    for name, item in _bolt_items(m):
        if name not in ids:
            errors.append(item.error(f"bolt {name}: no model of {source} has it"))
    rules = [node, *(item for _, item in _pset_items(m)), *(item for _, item in _bolt_items(m))]
    for rule in rules:
        given = rule.mapping((*RULE_KEYS, "psets", "bolts")) if rule is node \
            else rule.mapping(RULE_KEYS)
        loosen = given.get("loosen_pset")
        if loosen is not None and loosen.integer() in bolt_psets:
            errors.append(loosen.error(
                f"loosen_pset {loosen.integer()} tightens {bolt_psets[loosen.integer()]} in "
                f"{source}: a loosen pset is a program that loosens, never a bolt's own"))
    return errors


def unused_loosen_psets(node: YamlNode, policy: NokPolicy) -> list[ConfigError]:
    """Warnings (the daemon takes the file) for each ``loosen_pset`` that no bolt's rule
    uses: given where the strategy is ``repeat`` or ``skip`` and no override below takes it
    with ``loosen``.  Why: a line engineer who wrote ``loosen_pset`` under the default
    ``repeat`` read it as "loosen, then tighten again", while the station tightened an
    over-torqued bolt again without loosening it."""
    m = node.mapping((*RULE_KEYS, "psets", "bolts"))
    below = [*policy.psets.values(), *policy.bolts.values()]
    levels: list[tuple[YamlNode, NokRule, list[NokRule]]] = [(node, policy.default, below)]
    levels += [(item, policy.psets[key], []) for key, item in _pset_items(m)]
    levels += [(item, policy.bolts[key], []) for key, item in _bolt_items(m)]
    warnings = []
    for where, rule, inherit in levels:
        given = where.mapping((*RULE_KEYS, "psets", "bolts")) if where is node \
            else where.mapping(RULE_KEYS)
        if "loosen_pset" not in given or rule.strategy is Strategy.LOOSEN:
            continue
        if any(r.strategy is Strategy.LOOSEN and r.loosen_pset == rule.loosen_pset
               for r in inherit):
            continue
        warnings.append(given["loosen_pset"].error(
            f"loosen_pset {rule.loosen_pset} is not used: strategy {rule.strategy} "
            + ("tightens the bolt again after a NOK without loosening it"
               if rule.strategy is Strategy.REPEAT else "skips the bolt after a NOK")
            + " (strategy: loosen loosens it first)"))
    return warnings


__all__ = ["STRATEGIES", "NokPolicy", "NokRule", "table_errors", "unused_loosen_psets"]
