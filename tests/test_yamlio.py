import pytest

from stationd.errors import ConfigError
from stationd.yamlio import YamlNode


def test_numbers_and_matrix_with_locations():
    n = YamlNode.parse("a: 1.5\nK: [[1, 0, 2], [0, 1, 3], [0, 0, 1]]\n", "f.yaml")
    m = n.mapping(["a", "K"], required=["a"])
    assert m["a"].number() == 1.5
    assert m["K"].matrix(3, 3)[1, 2] == 3


@pytest.mark.parametrize("text,needle", [
    ("a: [1,\n", "f.yaml:2: malformed YAML"),
    ("b: 1\n", "f.yaml:1: b: unknown key (accepted: a)"),
    ("{}\n", "missing key(s): a"),
    ("a: yes\n", "a: expected a number"),
    ("a: .nan\n", "a: expected a finite number"),
    ("a: 1\na: 2\n", "f.yaml:2: a: duplicate key"),
    ("", "the file is empty"),
])
def test_errors_name_file_line_key(text, needle):
    with pytest.raises(ConfigError) as ei:
        YamlNode.parse(text, "f.yaml").mapping(["a"], required=["a"])["a"].number()
    assert needle in str(ei.value)


def test_matrix_shape_error_names_key_and_line():
    n = YamlNode.parse("x: 0\nK: [[1, 2], [3, 4], [5, 6]]\n", "cam.yaml")
    with pytest.raises(ConfigError, match=r"cam.yaml:2: K\[0\]: expected a 3x3 matrix"):
        n.mapping(["x", "K"])["K"].matrix(3, 3)


def test_range_check():
    n = YamlNode.parse("v: 300\n", "f.yaml").mapping(["v"])["v"]
    with pytest.raises(ConfigError, match="out of range"):
        n.number(lo=0, hi=255)


def test_collections_nested_too_deeply_are_one_error_not_a_recursion_crash(tmp_path):
    """PyYAML parses nesting recursively: a file of 5000 nested lists crashed every reader
    (config check, db import, the daemon's reload) with RecursionError."""
    path = tmp_path / "deep.yaml"
    path.write_text("vision: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ConfigError, match="nested too deeply"):
        YamlNode.load(path)
