"""What the station does after a NOK: the line's policy, per station, with per-pset and
per-bolt overrides.

Why in the station file and not the bolt table: the policy is how this station's line runs
(how many attempts an operator gets, whether a NOK bolt is skipped or repeated), while the bolt
table is the vehicle's engineering data, shared by every station that tightens that model.

    nok:
      max_nok: 3            # consecutive NOKs on a bolt before it locks (a release unlocks)
      strategy: repeat      # repeat: open again; skip: marked NOK and skipped for the vehicle
      psets: {125: {max_nok: 1}}
      bolts: {B07: {strategy: skip}}

A locked bolt refuses the tool until a user with the ``release`` right releases it (the
operator screen, or ``stationd release VIN BOLT``), with a comment; the release is recorded.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

from stationd.yamlio import YamlNode

STRATEGIES = ("repeat", "skip")
DEFAULT_MAX_NOK = 3


@dataclass(frozen=True)
class NokRule:
    """For one bolt: consecutive NOKs before it locks, and what follows a NOK."""

    max_nok: int = DEFAULT_MAX_NOK
    strategy: str = "repeat"

    def merged(self, node: YamlNode) -> NokRule:
        m = node.mapping(("max_nok", "strategy"))
        rule = self
        if "max_nok" in m:
            rule = replace(rule, max_nok=m["max_nok"].integer(lo=1, hi=99))
        if "strategy" in m:
            rule = replace(rule, strategy=m["strategy"].text(STRATEGIES))
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
        m = node.mapping(("max_nok", "strategy", "psets", "bolts"))
        default = NokRule()
        if "max_nok" in m:
            default = replace(default, max_nok=m["max_nok"].integer(lo=1, hi=99))
        if "strategy" in m:
            default = replace(default, strategy=m["strategy"].text(STRATEGIES))
        psets: dict[int, NokRule] = {}
        for key, item in m["psets"].pairs() if "psets" in m else ():
            if isinstance(key, bool) or not isinstance(key, int) or not 1 <= key <= 999:
                raise item.error(f"pset {key!r}: a pset number (1-999)")
            psets[key] = default.merged(item)
        bolts = {key: default.merged(item)
                 for key, item in (m["bolts"].named("names to their rules")
                                   if "bolts" in m else ())}
        return cls(default, psets, bolts)


__all__ = ["NokPolicy", "NokRule"]
