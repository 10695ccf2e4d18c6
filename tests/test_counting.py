"""Counts in words: "1 bolt" / "3 bolts", never "3 bolt(s)": drivers' helper (stationd's too)
and db's copy (db imports nothing of drivers), which must say the same."""

from __future__ import annotations

import pytest

import db.counting
import drivers.counting

COPIES = [db.counting, drivers.counting]


@pytest.mark.parametrize("module", COPIES, ids=lambda m: m.__name__)
def test_counted_singular_zero_plural_irregular(module):
    counted = module.counted
    assert counted(1, "bolt") == "1 bolt"
    assert counted(0, "bolt") == "0 bolts"
    assert counted(2, "bolt") == "2 bolts"
    assert counted(1, "NOK result") == "1 NOK result"
    assert counted(12, "NOK result") == "12 NOK results"
    assert counted(1, "entry", "entries") == "1 entry"
    assert counted(0, "entry", "entries") == "0 entries"
    assert counted(3, "entry", "entries") == "3 entries"
    assert counted(-1, "bolt") == "-1 bolts"
    # a float as :g prints it (a limit of 5.0 localizations: "5", not "5.0"); ints in full
    assert counted(1.0, "localization") == "1 localization"
    assert counted(5.0, "localization") == "5 localizations"
    assert counted(1234567, "row") == "1234567 rows"


@pytest.mark.parametrize("module", COPIES, ids=lambda m: m.__name__)
def test_noun_alone_for_lists(module):
    """The noun for a list's length: "missing key: a" / "missing keys: a, b"."""
    noun = module.noun
    assert noun(1, "key") == "key"
    assert noun(0, "key") == "keys"
    assert noun(2, "key") == "keys"
    assert noun(1, "entry", "entries") == "entry"
    assert noun(2, "entry", "entries") == "entries"
