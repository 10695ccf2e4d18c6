"""bolts.yaml validation: every error names file, line and key; all errors are collected."""

from __future__ import annotations

import pytest

from db.bolts import Parameters, Window, dump_bolts
from stationd.boltfile import check_bolts, load_bolts
from stationd.errors import ConfigError, InputError
from tests.db.conftest import BASE, EXAMPLE, line_of

B1 = "models.SEDAN.bolts[0]"
B2 = "models.SEDAN.bolts[1]"
B3 = "models.SEDAN.bolts[2]"


@pytest.fixture
def check_text(tmp_path, monkeypatch):
    """``check_text(text, name="b.yaml", **kw)``: the check of a bolt file holding ``text``,
    named ``name`` in the current folder (a temporary one), so its messages start with
    ``b.yaml:LINE:`` as an engineer's relative path would."""
    monkeypatch.chdir(tmp_path)

    def check(text, name="b.yaml", **kw):
        (tmp_path / name).write_text(text)
        return check_bolts(name, **kw)
    return check

# (replace old, by new, the line the error is on (a text on it, after the change), key, message)
CASES = [
    ("target: 25, min: 23", 'target: "25 Nm", min: 23', "25 Nm", f"{B2}.torque.target",
     "expected a number in N m, got the string '25 Nm' (write the number alone"),
    ("target: 25, min: 23", "target: -25, min: 23", "target: -25", f"{B2}.torque.target",
     "-25 N m: must be > 0"),
    ("target: 25, min: 23", "target: 0, min: 0", "target: 0, min: 0", f"{B2}.torque.target",
     "0 N m: must be > 0"),
    ("min: 23, max: 27", "min: -1, max: 27", "min: -1", f"{B2}.torque.min", "must be >= 0"),
    ("target: 25, min: 23, max: 27", "target: 25, min: 23, max: 6000", "max: 6000",
     f"{B2}.torque.max", "above the limit of 5000 N m"),
    ("target: 25, min: 23", "target: 22, min: 23", "target: 22", f"{B2}.torque",
     "target 22 N m is outside [min 23, max 27]"),
    ("target: 25, min: 23, max: 27", "target: 25, min: 27, max: 23", "min: 27",
     f"{B2}.torque", "min 27 N m must be below max 23 N m"),
    ("angle: {target: 30, min: 10, max: 50}", "angle: {target: 30, min: 10, max: 5000}",
     "max: 5000", f"{B2}.angle.max", "above the limit of 3600 deg"),
    ("angle: {target: 30, min: 10, max: 50}", "angle: {target: yes, min: 10, max: 50}",
     "target: yes", f"{B2}.angle.target", "expected a number in deg, got True"),
    ("angle: {target: 30, min: 10, max: 50}", "angle: {target: 30, max: 50}",
     "angle: {target: 30, max: 50}", f"{B2}.angle", "missing key: min"),
    ("angle: {target: 30, min: 10, max: 50}", "angle: 30",
     "angle: 30", f"{B2}.angle", "expected a mapping"),
    ("        name: one\n        position: [0, 0, 0]\n        pset: 1\n      - id: B2",
     "        name: one\n        colour: red\n        position: [0, 0, 0]\n        pset: 1\n"
     "      - id: B2", "colour: red", f"{B1}.colour", "unknown key (accepted: angle, batch"),
    ("psets:\n  - id: 1", "vehicles: 3\npsets:\n  - id: 1", "vehicles: 3", "vehicles",
     "unknown key (accepted: models, psets)"),
    ("    code: 12\n", "    code: 12\n    colour: red\n", "colour: red", "models.SEDAN.colour",
     "unknown key (accepted: bolts, code, description, psets)"),
    ("        name: two\n", "", "- id: B2", B2, "missing key: name"),
    ("        position: [100, 0, 0]\n", "", "- id: B2", B2, "missing key: position"),
    ("position: [100, 0, 0]", 'position: "100, 0, 0"', '"100, 0, 0"', f"{B2}.position",
     "expected [x, y, z] in mm (vehicle frame)"),
    ("position: [100, 0, 0]", "position: [100, 0]", "[100, 0]", f"{B2}.position",
     "expected [x, y, z] in mm (vehicle frame), got 2 values"),
    ("position: [100, 0, 0]", 'position: [100, "0 mm", 0]', "0 mm", f"{B2}.position[1]",
     "expected a number in mm, got the string '0 mm'"),
    ("position: [100, 0, 0]", "position: [100, 0, 20000]", "20000", f"{B2}.position[2]",
     "above the limit of 10000 mm"),
    ("        pset: 1\n      - id: B2", '        pset: "1"\n      - id: B2', 'pset: "1"',
     f"{B1}.pset", "expected an integer, got '1'"),
    ("        pset: 1\n      - id: B2", "        pset: 1000\n      - id: B2", "pset: 1000",
     f"{B1}.pset", "1000 is out of range [0, 999]"),
    ("order: 2", "order: 0", "order: 0", f"{B3}.order", "out of range"),
    ("batch: wheel", "batch: front wheel", "batch: front", f"{B3}.batch",
     "batch 'front wheel': 1-32 letters"),
    ("id: B2", "id: B1", ("id: B1", 1), f"{B2}.id", "duplicate bolt id 'B1' (first at line 13)"),
    ("id: B2", "id: B 2", "id: B 2", f"{B2}.id", "bolt id 'B 2': 1-32 letters"),
    ("id: B2", "id: 2", ("- id: 2", 1), f"{B2}.id", "expected a string, got 2"),
    ("position: [100, 0, 0]", "position: [10, 0, 0]", "[10, 0, 0]", f"{B2}.position",
     "10.0 mm from bolt B1 in X-Y (line 13): bolts must be at least 16 mm apart in X-Y "
     "(twice the matching tolerance of 8 mm)"),
    # one above the other: 30 mm apart in Z, 0 in plan -- the matcher could never tell them apart
    ("position: [100, 0, 0]", "position: [0, 0, 30]", "[0, 0, 30]", f"{B2}.position",
     "0.0 mm from bolt B1 in X-Y (line 13): bolts must be at least 16 mm apart in X-Y"),
    ("  WAGON:\n    bolts:\n      - id: B1\n        name: one\n        position: [0, 0, 0]\n"
     "        pset: 1", "  WAGON:\n    bolts:\n      - id: B1\n        name: one\n"
     "        position: [0, 0, 0]\n        pset: 21", ("pset: 21", 1), "models.WAGON.bolts[0].pset",
     "pset 21 is not defined (define it under 'psets:', globally or in this model)"),
    ("      - id: 21", "      - id: 1\n        torque: {target: 5, min: 4, max: 6}\n"
     "      - id: 21", "      - id: 1", "models.SEDAN.psets[0].id",
     "pset 1 is already defined globally (line 2)"),
    ("models:\n", "  - id: 1\n    torque: {target: 5, min: 4, max: 6}\nmodels:\n",
     ("  - id: 1", 1), "psets[1].id", "duplicate pset 1 (first at line 2)"),
    ("        pset: 1\n      - id: B2", "      - id: B2", "- id: B1", B1,
     "a bolt needs a pset or a torque (or both)"),
    ("        pset: 1\n      - id: B2",
     "        pset: 1\n        torque: {target: 60, min: 45, max: 65}\n      - id: B2",
     "target: 60", f"{B1}.torque", "differs from pset 1's program (target 50, min 45, max 55)"),
    ("  WAGON:\n", "  WAGON:\n    code: 12\n", ("code: 12", 1), "models.WAGON.code",
     "code 12 is also the code of model SEDAN"),
    ("  WAGON:\n", "  WAGON:\n    code: 70000\n", "code: 70000", "models.WAGON.code",
     "70000 is out of range [0, 65535]"),
    ("  WAGON:\n", "  WAGON:\n    psets:\n      - id: 21\n"
     "        torque: {target: 99, min: 90, max: 110}\n", ("- id: 21", 1),
     "models.WAGON.psets[0].id", "pset 21 is defined differently for model SEDAN (line 10)"),
    ("  WAGON:\n    bolts:", "  WAGON 2:\n    bolts:", "WAGON 2", "models.WAGON 2",
     "model name 'WAGON 2'"),
    ("    bolts:\n      - id: B1\n        name: one\n        position: [0, 0, 0]\n"
     "        pset: 1\n", "    bolts: 3\n", "bolts: 3", "models.WAGON.bolts", "expected a list"),
]


def _mutate(old: str, new: str) -> str:
    assert BASE.count(old) >= 1, old
    if BASE.count(old) > 1:  # the last occurrence (WAGON's) when ambiguous
        i = BASE.rindex(old)
        return BASE[:i] + new + BASE[i + len(old):]
    return BASE.replace(old, new)


def test_base_and_example_are_valid(check_text):
    result = check_text(BASE, "b.yaml")
    assert result.ok and result.table is not None
    sedan = result.table.models[0]
    b1, b2, b3 = sedan.bolts
    assert b1.parameters == Parameters(1, Window(50, 45, 55), Window(30, 15, 60))
    assert b2.parameters == Parameters(None, Window(25, 23, 27), Window(30, 10, 50))
    assert b3.parameters == Parameters(21, Window(120, 110, 130), None)
    assert (b3.order, b3.batch, sedan.code) == (2, "wheel", 12)
    example = load_bolts(EXAMPLE)
    assert example.bolt_count >= 6 and len(example.models) == 2


@pytest.mark.parametrize(("old", "new", "at", "key", "message"), CASES,
                         ids=[c[4][:40] for c in CASES])
def test_each_error_names_file_line_key(old, new, at, key, message, check_text):
    text = _mutate(old, new)
    result = check_text(text, "b.yaml")
    assert result.table is None
    needle, nth = at if isinstance(at, tuple) else (at, 0)
    want = f"b.yaml:{line_of(text, needle, nth)}: {key}: "
    texts = [str(e) for e in result.errors]
    assert any(t.startswith(want) and message in t for t in texts), texts
    assert len(texts) == 1, texts


def test_tolerance_is_a_parameter_of_the_check(check_text):
    text = BASE.replace("position: [100, 0, 0]", "position: [20, 0, 0]")
    assert check_text(text).ok  # 20 mm >= 2 x 8 mm
    errors = check_text(text, "b.yaml", tolerance_mm=12).errors
    assert [str(e) for e in errors] == [
        f"b.yaml:{line_of(text, '[20, 0, 0]')}: {B2}.position: 20.0 mm from bolt B1 in X-Y "
        "(line 13): bolts must be at least 24 mm apart in X-Y (twice the matching tolerance of "
        "12 mm)"]
    with pytest.raises(InputError, match="tolerance"):
        check_text(text, tolerance_mm=0)


def test_all_errors_of_a_file_are_collected_in_line_order_and_load_raises_the_first(tmp_path):
    text = (BASE.replace("target: 25, min: 23", 'target: "25 Nm", min: 23')
            .replace("id: B2", "id: B1")
            .replace("order: 2", "order: -1")
            .replace("    code: 12\n", "    code: 12\n    colour: red\n    size: 3\n")
            .replace("  WAGON:\n    bolts:\n      - id: B1\n        name: one\n"
                     "        position: [0, 0, 0]\n        pset: 1",
                     "  WAGON:\n    bolts:\n      - id: B1\n        name: one\n"
                     "        position: [0, 0, 0]\n        pset: 7"))
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    result = check_bolts(path)
    lines = [e.line for e in result.errors]
    keys = [e.key for e in result.errors]
    assert keys == ["models.SEDAN.colour", "models.SEDAN.size", f"{B2}.id",
                    f"{B2}.torque.target", f"{B3}.order", "models.WAGON.bolts[0].pset"]
    assert lines == sorted(lines) and all(e.path == str(path) for e in result.errors)
    with pytest.raises(ConfigError) as ei:
        load_bolts(path)
    assert str(ei.value) == str(result.errors[0])
    assert str(ei.value).startswith(f"{path}:{line_of(text, 'colour')}: models.SEDAN.colour:")


@pytest.mark.parametrize(("text", "needle"), [
    ("models: {A: [1,\n", "b.yaml:2: malformed YAML"),
    ("", "b.yaml: the file is empty"),
    ("- 1\n- 2\n", "b.yaml:1: expected a mapping"),
    ("psets: []\n", "b.yaml:1: missing key: models"),
    ("models: [A, B]\n", "b.yaml:1: models: expected a mapping of model name -> model"),
    ("models:\n  A:\n    bolts: []\n  A:\n    bolts: []\n", "b.yaml:4: models.A: duplicate key"),
])
def test_file_level_errors(text, needle, check_text):
    errors = check_text(text, "b.yaml").errors
    assert len(errors) == 1 and str(errors[0]).startswith(needle), errors


def test_missing_file_is_one_error(tmp_path):
    result = check_bolts(tmp_path / "nope.yaml")
    assert [str(e) for e in result.errors] == [f"{tmp_path / 'nope.yaml'}: file not found"]


def test_bolt_may_repeat_its_psets_program_and_complete_it(tmp_path):
    text = BASE.replace("        pset: 21\n",
                        "        pset: 21\n        torque: {target: 120, min: 110, max: 130}\n"
                        "        angle: {target: 10, min: 0, max: 90}\n")
    table = load_bolts_text(tmp_path, text)
    b3 = table.models[0].bolts[2]
    assert b3.parameters == Parameters(21, Window(120, 110, 130), Window(10, 0, 90))


def load_bolts_text(folder, text):
    """The table of a bolt file holding ``text`` (in ``folder``), as the station loads it."""
    path = folder / "b.yaml"
    path.write_text(text)
    return load_bolts(path)


def test_dump_reads_back_equal(tmp_path):
    for table in (load_bolts_text(tmp_path, BASE), load_bolts(EXAMPLE)):
        text = dump_bolts(table, "a header\nof two lines")
        assert text.startswith("# a header\n# of two lines\n")
        assert load_bolts_text(tmp_path, text) == table


def test_a_pset_with_an_error_is_reported_once_not_at_every_bolt_using_it(check_text):
    text = BASE.replace("target: 50, min: 45, max: 55", 'target: "50 Nm", min: 45, max: 55')
    errors = check_text(text, "b.yaml").errors
    assert [str(e) for e in errors] == [
        "b.yaml:4: psets[0].torque.target: expected a number in N m, got the string '50 Nm' "
        "(write the number alone: the unit is always N m)"]


def test_a_station_file_given_as_a_bolt_table_is_one_error_saying_so():
    """``db import station.yaml`` listed one "unknown key" per section of the station file."""
    from pathlib import Path

    station = Path(__file__).resolve().parents[1] / "config" / "sim" / "station.yaml"
    result = check_bolts(station)
    assert len(result.errors) == 1 and result.table is None
    assert "this is a station file, not a bolt table" in str(result.errors[0])


def test_a_bolt_table_given_as_a_station_file_is_one_error_saying_so():
    from pathlib import Path

    from stationd.config import load_station_config
    from stationd.stationcheck import check_station

    bolts = Path(__file__).resolve().parents[1] / "config" / "sim" / "bolts.yaml"
    with pytest.raises(ConfigError, match="this is a bolt table, not a station file"):
        load_station_config(bolts, station=True)
    errors = check_station(bolts).errors
    assert len(errors) == 1 and "this is a bolt table" in str(errors[0])


def test_a_table_that_tightens_nothing_is_a_warning(check_text):
    """A sweep: `models: {}` and a model without bolts passed config check as "ok, 0
    model(s)" with nothing said."""
    empty = check_text("psets: []\nmodels: {}\n")
    assert empty.ok and [w.line for w in empty.warnings] == [2]
    assert "tightens nothing" in str(empty.warnings[0])
    idle = check_text(
        "psets:\n  - {id: 1, name: a, torque: {target: 10, min: 9, max: 11},\n"
        "     angle: {target: 30, min: 15, max: 60}}\nmodels:\n  M1:\n    bolts: []\n")
    assert idle.ok and len(idle.warnings) == 1 and "model M1 has no bolt" in \
        str(idle.warnings[0])


def test_bolt_positions_in_metres_are_named_so(check_text):
    """A sweep: a table in metres said "1.0 mm from B01 ... at least 16 mm apart" with none
    of the unit hints the station file gets."""
    got = check_text(
        "psets:\n  - {id: 1, name: a, torque: {target: 10, min: 9, max: 11},\n"
        "     angle: {target: 30, min: 15, max: 60}}\nmodels:\n  M1:\n    bolts:\n"
        "      - {id: B01, name: a, position: [1.2, 0.4, 0.0], pset: 1}\n"
        "      - {id: B02, name: b, position: [1.5, 0.4, 0.0], pset: 1}\n")
    texts = [str(e) for e in got.errors]
    assert len(texts) == 1 and "positions in metres?" in texts[0], texts


def test_a_key_written_twice_in_a_pset_is_one_error_not_one_at_every_bolt_using_it(
        check_text):
    """An angle line pasted twice into pset 1 (an engineer changing its window for the next
    model year): ``config check`` said the duplicate key, then "pset 1 is not defined" at
    every bolt using it (18 lines for config/sim's pset 2), where pset 1 is defined."""
    text = BASE.replace("    angle: {target: 30, min: 15, max: 60}\n",
                        "    angle: {target: 30, min: 15, max: 60}\n"
                        "    angle: {target: 30, min: 20, max: 60}\n", 1)
    errors = [str(e) for e in check_text(text).errors]
    assert len(errors) == 1 and "duplicate key" in errors[0], errors


def test_two_bolts_of_a_model_named_alike_is_a_warning_at_the_second(check_text):
    """A line engineer's trial: B51 named "bolt 7" as B07, taken silently; the screens, the
    journal and the reports name bolts to people.  Said at the second one's name, the table
    still valid; the same name in another model is not said."""
    text = BASE.replace("name: three", "name: one", 1)
    assert text != BASE
    result = check_text(text)
    assert result.ok
    [warning] = [w for w in result.warnings if "named" in w.message]
    assert warning.key == f"{B3}.name" and warning.line == line_of(text, "name: one", 1)
    assert warning.message == ("B3: named 'one' as B1 (line "
                               f"{line_of(text, '- id: B1')}) of model SEDAN: people tell the "
                               "two apart by their id alone")
    assert not [w for w in check_text(BASE).warnings if "named" in w.message]
