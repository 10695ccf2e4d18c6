"""The taught table's comparison with CAD and its text (what ``stationd teach`` writes and the
commissioning screen downloads): the X-Y difference, the flags, parameters kept."""

from __future__ import annotations

import pytest
import yaml

from stationd.taught import compare, table_text

CAD = {"B01": (100.0, 0.0, 5.0), "B02": (200.0, 0.0, 5.0), "B03": (300.0, 0.0, 5.0)}


def test_each_taught_bolt_is_compared_with_cad_and_flagged():
    taught = {"B01": {"position_mm": [103.0, 4.0, 9.0], "dispersion_mm": 0.3},
              "B02": {"position_mm": [290.0, 0.0, 5.0], "dispersion_mm": 0.2},  # moved onto B03
              "B09": {"position_mm": [500.0, 0.0, 5.0], "dispersion_mm": 0.1}}
    got = {c.bolt: c for c in compare(taught, CAD, tolerance_mm=8.0)}
    assert list(got) == ["B01", "B02", "B09"]
    assert got["B01"].difference_mm == pytest.approx(5.0) and not got["B01"].beyond
    assert not got["B01"].neighbours
    assert got["B02"].beyond and got["B02"].neighbours == ("B03",)   # 10 mm < 2 x 8
    assert got["B09"].cad_mm is None and got["B09"].difference_mm is None
    assert got["B09"].to_json()["position_mm"] == [500.0, 0.0, 5.0]


def test_the_table_keeps_every_model_and_parameter_and_moves_only_the_taught_bolts():
    doc = {"psets": [{"id": 1}], "models": {
        "M1": {"bolts": [{"id": "B01", "position": [100.0, 0.0, 5.0], "pset": 1},
                         {"id": "B02", "position": [200.0, 0.0, 5.0], "pset": 1}]},
        "M2": {"bolts": [{"id": "C01", "position": [1.0, 2.0, 3.0], "pset": 1}]}}}
    text = table_text(doc, "M1", {"B02": {"position_mm": [201.04, 0.96, 5.0],
                                          "dispersion_mm": 0.2}})
    assert text.startswith("# taught by stationd teach for M1")
    back = yaml.safe_load(text)
    assert back["models"]["M1"]["bolts"][1] == {"id": "B02", "position": [201.0, 1.0, 5.0],
                                                "pset": 1}
    assert back["models"]["M1"]["bolts"][0]["position"] == [100.0, 0.0, 5.0]
    assert back["models"]["M2"] == doc["models"]["M2"] and back["psets"] == doc["psets"]
    alone = yaml.safe_load(table_text({}, "M1", {"B02": {"position_mm": [1, 2, 3],
                                                         "dispersion_mm": 0.1234}}))
    assert alone == {"model": "M1", "bolts": [{"id": "B02", "position": [1.0, 2.0, 3.0],
                                               "dispersion_mm": 0.123}]}


def test_a_taught_bolt_the_table_does_not_have_is_not_dropped_from_the_taught_table():
    """The commissioning screen's Teach panel takes a typed bolt id (a new bolt of the next
    model year, or a typo): the daemon accepted "Teach B99", listed it taught, and the
    downloaded table (the model's table with the taught positions) left it out without a
    word (a process engineer's trial).  Its measured position is in the file, said as a
    bolt the table does not have (to be added with its parameters)."""
    doc = {"psets": [{"id": 1}], "models": {
        "M1": {"bolts": [{"id": "B01", "position": [100.0, 0.0, 5.0], "pset": 1}]}}}
    text = table_text(doc, "M1", {"B01": {"position_mm": [101.0, 0.0, 5.0],
                                          "dispersion_mm": 0.2},
                                  "B99": {"position_mm": [512.34, 7.0, 5.0],
                                          "dispersion_mm": 0.1}})
    assert "B99" in text and "512.3" in text, text
    back = yaml.safe_load(text)          # still the table to import: B99 is no bolt of it
    assert [b["id"] for b in back["models"]["M1"]["bolts"]] == ["B01"]


def test_a_taught_bolt_id_with_a_line_break_stays_in_its_comment():
    """The Teach panel's bolt id is any text of up to 32 characters (stripped at its ends
    only): one with a line break in it wrote its second line into the taught table as YAML
    (here a second ``models:`` that the import then refused as a duplicate key), not as the
    comment that names the bolt."""
    doc = {"psets": [{"id": 1}], "models": {
        "M1": {"bolts": [{"id": "B01", "position": [100.0, 0.0, 5.0], "pset": 1}]}}}
    text = table_text(doc, "M1", {"B9\nmodels: {}\n#": {"position_mm": [1.0, 2.0, 3.0],
                                                         "dispersion_mm": 0.1}})
    assert all(line.startswith("#") for line in text.split("psets:")[0].splitlines()), text
    assert yaml.safe_load(text) == doc, text
