"""The generic section reader (stationd.configread): a file's sections parsed by their
components, the first error raised or every error collected, each with file, line and key;
it knows no section of its own (the station's assembly is tests/test_config*.py)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from stationd.configread import (
    SectionReader,
    base_folder,
    existing_file,
    in_order,
    left_out,
    link_note,
    missing_as_written,
    named_items,
    relative_path,
)
from stationd.errors import ConfigError
from stationd.yamlio import YamlNode

KEYS = ("marker", "matching")   # two of a station file's sections, as a file of that kind


@dataclass(frozen=True)
class Limits:
    """A component's section, as a component parses it: ``lo`` and ``hi``, numbers."""

    lo: float = 0.0
    hi: float = 1.0

    @classmethod
    def from_node(cls, node: YamlNode) -> Limits:
        m = node.mapping(("lo", "hi"))
        return cls(*(m[k].number() if k in m else getattr(cls, k) for k in ("lo", "hi")))


def _read(text: str, *, collect: bool) -> tuple[SectionReader, Limits]:
    reader = SectionReader(collect=collect)
    reader.sections(YamlNode.parse(text, "s.yaml"), "station", KEYS)
    return reader, reader.section("matching", Limits(), Limits.from_node)


def test_a_section_is_parsed_by_its_component_and_a_missing_one_is_its_default():
    reader, limits = _read("matching: {lo: 2, hi: 5}\n", collect=False)
    assert limits == Limits(2.0, 5.0) and reader.errors == []
    assert reader.section("marker", "default", Limits.from_node) == "default"
    assert list(reader.top) == ["matching"]


def test_raising_stops_at_the_first_error_of_a_section():
    with pytest.raises(ConfigError, match=r"^s\.yaml:2: matching\.typo: unknown key"):
        _read("matching:\n  typo: 1\n  hi: x\n", collect=False)


def test_collecting_tells_every_error_of_a_section_and_gives_its_default():
    """A typo'd key must not hide a bad value below it: the section is read again without
    the entry told, until it reads or the error is the section's own."""
    reader, limits = _read("matching:\n  typo: 1\n  hi: x\n", collect=True)
    assert limits == Limits()
    assert [(e.line, e.key) for e in reader.errors] == [(2, "matching.typo"), (3, "matching.hi")]
    assert "expected a number" in str(reader.errors[1])


def test_collecting_tells_each_unknown_section_at_its_line_and_reads_the_known_ones():
    reader, limits = _read("colour: red\nmatching: {hi: 3}\nsize: 2\n", collect=True)
    assert limits == Limits(0.0, 3.0)
    assert [(e.line, e.key, str(e).split(": ", 2)[2]) for e in reader.errors] == [
        (1, "colour", "unknown key (accepted: marker, matching)"),
        (3, "size", "unknown key (accepted: marker, matching)")]
    with pytest.raises(ConfigError, match=r"s\.yaml:1: colour: unknown key"):
        _read("colour: red\nmatching: {hi: 3}\n", collect=False)


def test_a_top_level_that_is_no_mapping_is_one_error_and_unreadable():
    reader = SectionReader(collect=True)
    assert reader.sections(YamlNode.parse("- a\n- b\n", "s.yaml"), "station", KEYS) == {}
    assert reader.unreadable and len(reader.errors) == 1
    assert "expected a mapping" in str(reader.errors[0])


def test_a_file_of_another_kind_is_told_in_one_line():
    reader = SectionReader(collect=True)
    with pytest.raises(ConfigError, match="this is a bolt table, not a station file"):
        reader.sections(YamlNode.parse("models: []\npsets: []\n", "s.yaml"), "station", KEYS)


def test_guard_and_refuse_raise_or_record():
    error = YamlNode.parse("a: 1\n", "s.yaml").error("two cameras in one")

    def bad() -> int:
        raise error

    collecting = SectionReader(collect=True)
    assert collecting.guard(7, bad) == 7
    collecting.refuse(error)
    assert collecting.errors == [error, error]
    raising = SectionReader(collect=False)
    with pytest.raises(ConfigError, match="two cameras in one"):
        raising.guard(7, bad)
    with pytest.raises(ConfigError, match="two cameras in one"):
        raising.refuse(error)


def test_an_error_at_an_entry_left_out_is_not_a_second_mistake():
    told = [ConfigError("x", path="s.yaml", line=3, key="access.users.ann")]
    assert left_out(ConfigError("y", key="access.users"), told)
    assert left_out(ConfigError("y", key="access.users.ann"), told)
    assert not left_out(ConfigError("y", key="access.roles"), told)
    assert not left_out(ConfigError("y"), told)


@dataclass(frozen=True)
class Person:
    """A component's entry with two required keys, each value checked before either is
    required (``stationd.access``'s users are read so)."""

    role: str
    pin: float

    @classmethod
    def from_node(cls, node: YamlNode) -> Person:
        m = node.mapping(("role", "pin"))
        role = m["role"].text(("operator", "supervisor")) if "role" in m else None
        pin = m["pin"].number() if "pin" in m else None
        if role is None or pin is None:
            node.mapping(("role", "pin"), required=("role", "pin"))
        return cls(str(role), float(pin or 0))


def _people(text: str) -> list[str]:
    reader = SectionReader(collect=True)
    reader.sections(YamlNode.parse(text, "s.yaml"), "station", KEYS)
    reader.section("matching", None, Person.from_node)
    return [str(e) for e in reader.errors]


def test_a_key_missing_as_written_is_told_beside_one_left_out():
    """A user told its wrong role was read again without it, and "missing keys: role, pin"
    was taken for what leaving the role out did: the pin it also lacks was told only once the
    role was fixed."""
    assert _people("matching: {role: boss}\n") == [
        "s.yaml:1: matching.role: 'boss' is not one of: operator, supervisor",
        "s.yaml:1: matching: missing key: pin"]
    assert _people("matching: {role: boss, pin: x}\n") == [
        "s.yaml:1: matching.role: 'boss' is not one of: operator, supervisor",
        "s.yaml:1: matching.pin: expected a number, got 'x'"]
    assert _people("matching: {pin: 1}\n") == ["s.yaml:1: matching: missing key: role"]
    told = [ConfigError("x", key="access.users.ann.role")]
    both = ConfigError("m", key="access.users.ann", missing=("role", "password"))
    assert str(missing_as_written(both, told)) == "access.users.ann: missing key: password"
    assert missing_as_written(ConfigError("m", key="access.users.ann", missing=("role",)),
                              told) is None
    other = ConfigError("m", key="access.users.bob", missing=("role",))
    assert missing_as_written(other, told) is other


def test_errors_in_line_order_then_those_of_the_files_named():
    found = [ConfigError("c", path="s.yaml", line=9), ConfigError("k", path="cal.yaml", line=1),
             ConfigError("a", path="s.yaml", line=2), ConfigError("j", path="other.yaml")]
    assert [e.message for e in in_order(found, "s.yaml")] == ["a", "c", "k", "j"]


def test_relative_paths_are_read_from_the_linked_files_folder(tmp_path: Path):
    """A station file linked from /etc keeps its calibrations beside the file it links to:
    relative paths are read there, and a missing one's message says which folder was read."""
    (tmp_path / "line").mkdir()
    (tmp_path / "etc").mkdir()
    target = tmp_path / "line" / "station.yaml"
    target.write_text("marker: {}\n")
    link = tmp_path / "etc" / "station.yaml"
    link.symlink_to(target)
    assert base_folder(target) == tmp_path / "line" and base_folder(link) == tmp_path / "line"
    assert link_note(target, "the station file") == ""
    note = link_note(link, "the station file")
    assert note == (f" (relative paths are read from {tmp_path / 'line'}, the folder of {target}, "
                    f"which the station file {link} links to)")
    node = YamlNode.parse("bolts: bolts.yaml\n", str(link)).mapping(("bolts",))["bolts"]
    assert relative_path(node, base_folder(link)) == tmp_path / "line" / "bolts.yaml"
    with pytest.raises(ConfigError) as err:
        existing_file(node, base_folder(link), "bolt file", note)
    assert str(err.value) == (f"{link}:1: bolts: bolt file {tmp_path / 'line' / 'bolts.yaml'} "
                              f"does not exist{note}")
    (tmp_path / "line" / "bolts.yaml").write_text("models: []\n")
    assert existing_file(node, base_folder(link), "bolt file") == tmp_path / "line" / "bolts.yaml"
    absolute = YamlNode.parse(f"bolts: {tmp_path}/x.yaml\n").mapping(("bolts",))["bolts"]
    assert relative_path(absolute, base_folder(link)) == tmp_path / "x.yaml"


def test_named_items_need_at_least_one_name():
    m = YamlNode.parse("pairs: {}\ncameras: {a: {url: 'sim://p/left'}}\n", "s.yaml").mapping(
        ("pairs", "cameras"))
    assert [name for name, _ in named_items(m["cameras"])] == ["a"]
    with pytest.raises(ConfigError, match=r"s\.yaml:1: pairs: expected a mapping of names "
                                          r"to their settings"):
        named_items(m["pairs"])
