"""What kind of the station's YAML files a file is, by its top-level keys, and the one line
that says so when a reader is given a file of another kind.

Why: the station's files (a station file, a bolt table, a camera or a pair calibration, a
vehicle registration, the reference points of ``calibrate vehicle``, an HSV range) are all
YAML mappings without a header.  Given in the wrong place, each reader used to stop at the
first key it did not know: a station file given as a pair calibration said ``cameras:
unknown key (accepted: R, T, left, right)``, which names neither what the file is nor what
was expected (issue 19).  Every reader asks :func:`expect` before reading its keys, and
``outfile`` names what an output would replace with the same table.

A file is of a calibration's kind when it has every key that calibration always has (a
``K:`` alone is no camera calibration: ``outfile`` must not replace such a file as one), of a
station file or a bolt table when it has one of their keys.  A reader refuses a file as
another kind only when it has none of the reader's own keys (a file that mixes keys is read,
and its unknown keys are told at their lines).
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass

from stationd.yamlio import YamlNode, top_keys


@dataclass(frozen=True)
class Kind:
    """One kind of file: what it is called, the top-level keys that tell it, and how a
    person recognises it."""

    name: str            # "a station file"
    origin: str          # what writes it, in brackets after the name ("" when people do)
    keys: frozenset[str]
    has: str             # what it looks like, for the one who gave the wrong file
    every: bool = False  # all of ``keys`` make the kind (a calibration); otherwise any one

    def fits(self, keys: set[str]) -> bool:
        """Whether a file with the top-level ``keys`` is of this kind."""
        return self.keys <= keys if self.every else bool(keys & self.keys)


#: every kind, in the order a file with keys of several is named (a bolt table first, as
#: ``db import`` reads it).  The keys are those that tell the kind; each reader's schema
#: stays its own (the station's keys are ``stationd.config.STATION_KEYS``, a superset)
KINDS: dict[str, Kind] = {
    "bolts": Kind("a bolt table", "", frozenset({"psets", "models"}),
                  "a bolt table has models: and psets:"),
    "station": Kind("a station file", "", frozenset({
        "marker", "vision", "cameras", "pairs", "tool", "lift", "wrench", "matching",
        "database", "bolts", "records", "http", "access", "localize", "line", "nok", "opcua"}),
        "a station file names its cameras, pairs, lift and wrench; it may name a bolts: file"),
    "pair": Kind("a stereo pair calibration", "from calibrate stereo",
                 frozenset({"left", "right", "R", "T"}),
                 "a pair calibration has left:, right:, R: and T:, from stationd calibrate "
                 "stereo", every=True),
    "camera": Kind("a camera calibration", "from calibrate camera or stereo",
                   frozenset({"K", "size"}),
                   "a camera calibration has K:, dist: and size:, from stationd calibrate "
                   "camera", every=True),
    "registration": Kind("a vehicle registration", "from calibrate vehicle",
                         frozenset({"A", "t"}),
                         "a vehicle registration has A:, t: and rms_mm:, from stationd "
                         "calibrate vehicle", every=True),
    "points": Kind("a reference points file", "the input of calibrate vehicle",
                   frozenset({"points"}), "a reference points file has points:"),
    "hsv": Kind("an HSV range file", "", frozenset({"hsv"}), "an HSV range file has hsv:"),
}


def described(kind: str) -> str:
    """The kind's name with what writes it: "a stereo pair calibration (from calibrate
    stereo)"."""
    k = KINDS[kind]
    return f"{k.name} ({k.origin})" if k.origin else k.name


def kind_of_keys(keys: set[str]) -> str | None:
    """The kind (a key of :data:`KINDS`) of a file whose top-level keys are ``keys``: the
    first it fits; None when it fits none."""
    for kind, k in KINDS.items():
        if k.fits(keys):
            return kind
    return None


def expect(root: YamlNode, kind: str, accepted: Collection[str]) -> None:
    """Raise, at the file's first line, when ``root`` is a file of another kind than
    ``kind``: it is of another kind and has none of the keys its reader ``accepted``."""
    keys = top_keys(root)
    if keys & set(accepted):
        return
    found = kind_of_keys(keys)
    if found is not None and found != kind:
        raise root.error(f"this is {described(found)}, not {KINDS[kind].name} "
                         f"({KINDS[kind].has})")


__all__ = ["KINDS", "Kind", "described", "expect", "kind_of_keys"]
