import pytest

from stationd.errors import ConfigError
from stationd.yamlio import MAX_DEPTH, YamlNode


def test_numbers_and_matrix_with_locations():
    n = YamlNode.parse("a: 1.5\nK: [[1, 0, 2], [0, 1, 3], [0, 0, 1]]\n", "f.yaml")
    m = n.mapping(["a", "K"], required=["a"])
    assert m["a"].number() == 1.5
    assert m["K"].matrix(3, 3)[1, 2] == 3


@pytest.mark.parametrize("text,needle", [
    ("a: [1,\n", "f.yaml:2: malformed YAML"),
    ("b: 1\n", "f.yaml:1: b: unknown key (accepted: a)"),
    ("{}\n", "missing key: a"),
    ("a: yes\n", "a: expected a number"),
    ("a: .nan\n", "a: expected a finite number"),
    ("a: 1\na: 2\n", "f.yaml:2: a: duplicate key"),
    ("", "the file is empty"),
])
def test_errors_name_file_line_key(text, needle):
    with pytest.raises(ConfigError) as ei:
        YamlNode.parse(text, "f.yaml").mapping(["a"], required=["a"])["a"].number()
    assert needle in str(ei.value)


@pytest.mark.parametrize("text,needle", [
    # the commonest hand edits, in plain words before the parser's (a line engineer's trial)
    ("tool:\n\tlength_mm: 300\n", "f.yaml:2: malformed YAML: a tab character: YAML indents "
                                    "with spaces only (found character"),
    ("tool:\n  length_mm: 300\n max_tilt_deg: 10\n", "f.yaml:3: malformed YAML: the "
     "indentation of this line, or of the line above it, does not line up with the lines "
     "around it (expected <block end>"),
    ("tool:\n  length_mm: 300\n   max_tilt_deg: 10\n", "f.yaml:3: malformed YAML: a ':' "
     "where no key can start"),
    # an unclosed "{" on line 2 is found on line 3: both said (a line engineer's trial: line
    # 3 alone sent him to a line with nothing wrong on it)
    ("a: 1\nb: {x: 1, y: 2\nc: 3\n", "f.yaml:3: malformed YAML: expected ',' or '}', but "
     "got ':' (in the { } opened at line 2)"),
    ("a:\n  - [1, 2\n  - 3\n", "(in the [ ] opened at line 2)"),
    ("a: 'abc\nb: 2\n", "(in the quoted text opened at line 1)"),
])
def test_a_malformed_file_is_said_in_plain_words(text, needle):
    with pytest.raises(ConfigError) as ei:
        YamlNode.parse(text, "f.yaml")
    assert needle in str(ei.value), str(ei.value)


def test_matrix_shape_error_names_key_and_line():
    n = YamlNode.parse("x: 0\nK: [[1, 2], [3, 4], [5, 6]]\n", "cam.yaml")
    with pytest.raises(ConfigError, match=r"cam.yaml:2: K\[0\]: expected a 3x3 matrix"):
        n.mapping(["x", "K"])["K"].matrix(3, 3)
    # a row of the right length with a NaN says the NaN, not the shape (a sweep)
    n = YamlNode.parse("K: [[.nan, 0, 1], [0, 1, 0], [0, 0, 1]]\n", "cam.yaml")
    with pytest.raises(ConfigError, match=r"K\[0\]: row 0 of the 3x3 matrix: expected a "
                                          r"finite number"):
        n.mapping(["K"])["K"].matrix(3, 3)


def test_range_check():
    n = YamlNode.parse("v: 300\n", "f.yaml").mapping(["v"])["v"]
    with pytest.raises(ConfigError, match="out of range"):
        n.number(lo=0, hi=255)


def test_collections_nested_too_deeply_are_one_error_not_a_recursion_crash(tmp_path):
    """PyYAML parses nesting recursively: a file of 5000 nested lists crashed every reader
    (config check, db import, the daemon's reload) with RecursionError."""
    path = tmp_path / "deep.yaml"
    path.write_text("vision: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ConfigError, match=f"nested more than {MAX_DEPTH} levels"):
        YamlNode.load(path)


@pytest.mark.parametrize("text, line", [
    ("cameras: &a\n  x: *a\n", 2),                       # a mapping holding itself
    ("pairs:\n  - &l [1, *l]\n", 2),                      # a list holding itself
    ("a: &m\n  b:\n    c: [*m]\n", 3),                   # two levels down
])
def test_an_alias_to_a_collection_it_is_inside_of_is_one_error_at_its_line(text, line):
    """A maintenance technician's trial: ``cameras: &a {x: *a}`` crashed every command but
    ``config check`` with PyYAML's ConstructorError, and a reload told it without file or
    line."""
    with pytest.raises(ConfigError, match="names a collection it is inside of") as err:
        YamlNode.parse(text, "anchor.yaml")
    assert err.value.line == line


def test_aliases_that_do_not_hold_themselves_read():
    """An alias used twice, or to a sibling, is no loop."""
    root = YamlNode.parse("base: &b {x: 1}\none: *b\ntwo: [*b, *b]\n", "ok.yaml")
    assert root.value() == {"base": {"x": 1}, "one": {"x": 1}, "two": [{"x": 1}, {"x": 1}]}


@pytest.mark.parametrize("levels", [65, 300])
def test_block_collections_nested_deeper_than_the_limit_are_refused_at_their_line(levels):
    """Block style composes without recursion trouble, but every reader then walks the
    document recursively: 300 levels killed a running daemon's reload with RecursionError."""
    text = "".join("  " * i + f"k{i}:\n" for i in range(levels)) + "  " * levels + "v: 1\n"
    with pytest.raises(ConfigError, match=f"nested more than {MAX_DEPTH} levels") as err:
        YamlNode.parse(text, "deep.yaml")
    assert err.value.line == MAX_DEPTH + 1


def test_nesting_up_to_the_limit_reads():
    levels = MAX_DEPTH - 1
    text = "".join("  " * i + f"k{i}:\n" for i in range(levels)) + "  " * levels + "v: 1\n"
    node = YamlNode.parse(text, "ok.yaml")
    for i in range(levels):
        node = node.mapping([f"k{i}"])[f"k{i}"]
    assert node.mapping(["v"])["v"].number() == 1


# -- issue 19: only regular files are read, and what a file is instead is said -------------

def _load_soon(path, seconds=5.0):
    """YamlNode.load(path) in a thread: a FIFO used to block it until a writer came."""
    import threading

    out: list[BaseException | None] = []

    def run():
        try:
            YamlNode.load(path)
            out.append(None)
        except BaseException as exc:  # handed to the test
            out.append(exc)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(seconds)
    assert out, f"YamlNode.load({path}) did not return within {seconds} s"
    return out[0]


def test_a_fifo_is_refused_at_once_not_waited_on(tmp_path):
    import os

    os.mkfifo(tmp_path / "station.yaml")
    exc = _load_soon(tmp_path / "station.yaml")
    assert isinstance(exc, ConfigError)
    assert str(exc) == f"{tmp_path / 'station.yaml'}: a FIFO, not a file (a YAML file was " \
                       "expected): give the path of a regular file"


def test_a_device_is_refused_at_once_not_read_into_memory():
    exc = _load_soon("/dev/zero")
    assert isinstance(exc, ConfigError) and "/dev/zero: a device, not a file" in str(exc)


def test_a_folder_and_a_huge_file_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="a folder, not a file"):
        YamlNode.load(tmp_path)
    big = tmp_path / "big.yaml"
    with big.open("wb") as f:
        f.truncate(17 * 2**20)    # sparse: nothing written, nothing read
    with pytest.raises(ConfigError, match=r"17825792 bytes: too large for a YAML file \(at most "
                                          r"16 MB\)"):
        YamlNode.load(big)


def test_a_file_under_a_file_or_with_a_name_too_long_is_said_in_words(tmp_path):
    """The system's words were passed on ("cannot read: Not a directory"): which of the
    folders is a file is what to fix."""
    (tmp_path / "afile").write_text("x\n")
    with pytest.raises(ConfigError) as ei:
        YamlNode.load(tmp_path / "afile" / "pair1.yaml")
    assert str(ei.value) == f"{tmp_path / 'afile' / 'pair1.yaml'}: {tmp_path / 'afile'} is a " \
                            "file, not a folder"
    with pytest.raises(ConfigError, match=r"a{300}.yaml: cannot be reached \(file name too "
                                          r"long\)$"):
        YamlNode.load(tmp_path / ("a" * 300 + ".yaml"))


@pytest.mark.parametrize(("data", "message"), [
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "not a text file: it looks like a PNG image (a "
                                             "YAML file was expected)"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF", "it looks like a JPEG image"),
    (b"SQLite format 3\x00\x10\x00", "it looks like an SQLite database"),
    (b"PK\x03\x04\x14\x00", "it looks like a ZIP archive"),
    ("a: 1\n".encode("utf-16"), "UTF-16 text, not UTF-8"),
    (b"a: 1\n\x00\x01\x02", "not a text file: binary data"),
    ("a: 1\nb: caf\u00e9 cr\u00e8me\n".encode("latin-1"),
     "f.yaml:2: not UTF-8 text (Latin-1 or Windows-1252?): 'b: caf\u00e9 cr\u00e8me'; save the "
     "file as UTF-8"),
])
def test_a_file_that_is_not_utf8_text_says_what_it_looks_like(tmp_path, data, message):
    """It said ``'utf-8' codec can't decode byte 0x89 in position 0``."""
    p = tmp_path / "f.yaml"
    p.write_bytes(data)
    with pytest.raises(ConfigError) as ei:
        YamlNode.load(p)
    assert message in str(ei.value) and "codec" not in str(ei.value)


def test_a_byte_order_mark_is_not_an_error(tmp_path):
    p = tmp_path / "f.yaml"
    p.write_bytes(b"\xef\xbb\xbfa: 1\n")
    assert YamlNode.load(p).mapping(["a"])["a"].number() == 1


@pytest.mark.parametrize(("text", "message"), [
    ("t: {a: 300,5}\n", "f.yaml:1: t.a: 300,5: a decimal comma? write 300.5 (in {...} a comma "
                        "separates keys)"),
    ("t:\n  a: 300,5\n", "f.yaml:2: t.a: expected a number, got '300,5': a decimal comma? "
                         "write 300.5"),
])
def test_a_decimal_comma_is_told_as_one(text, message):
    """``{length_mm: 300,5}`` said ``key 5 is not a string``."""
    with pytest.raises(ConfigError) as ei:
        YamlNode.parse(text, "f.yaml").mapping(["t"])["t"].mapping(["a"])["a"].number()
    assert str(ei.value) == message


def test_an_exponent_without_a_dot_is_a_number_but_quoted_text_is_not():
    """YAML 1.1 (PyYAML) reads ``1e9`` as text: a person means the number."""
    m = YamlNode.parse("a: 1e9\nb: -2E-3\nc: '1e9'\n", "f.yaml").mapping(["a", "b", "c"])
    assert m["a"].number() == 1e9 and m["b"].number() == -2e-3
    with pytest.raises(ConfigError, match="expected a number, got '1e9'"):
        m["c"].number()


# -- the two parsers: libyaml where PyYAML has it, the pure-Python one for errors ------------
def _graph(node):
    """A node graph as plain data: kind, tag, value or children, style, line and column
    (not a collection's flow style: the parsers mark it differently and nothing reads it)."""
    import yaml

    if isinstance(node, yaml.ScalarNode):
        return ("scalar", node.tag, node.value, node.style, node.start_mark.line,
                node.start_mark.column)
    children = node.value if isinstance(node, yaml.SequenceNode) else \
        [part for pair in node.value for part in pair]
    return (type(node).__name__, node.tag, node.start_mark.line,
            node.start_mark.column, [_graph(c) for c in children])


def _station_files():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "config"
    return sorted(root.rglob("*.yaml"))


def test_libyaml_and_the_pure_python_parser_read_every_shipped_file_alike(monkeypatch):
    """Every YAML file under config/ (the stations, pairs, bolt tables) and the forms the
    readers tell apart (plain, quoted, flow, block, anchors, a decimal comma) read into the
    same graph with either parser: the station reads the same wherever PyYAML lacks
    libyaml."""
    import stationd.yamlio as yamlio

    if yamlio._FAST_LOADER is None:
        pytest.skip("PyYAML without libyaml here: only one parser to compare")
    texts = [p.read_text() for p in _station_files()]
    assert len(texts) >= 10
    texts += ["a: 1e9\nb: '1e9'\nc: \"x\"\nd: [1, 2.5, -3]\ne: {f: 300,5}\n",
              "- &x {a: 1}\n- *x\n- |\n  text\n  more\n- >\n  folded\n- ~\n- yes\n"]
    for text in texts:
        fast = yamlio._compose(text)
        monkeypatch.setattr(yamlio, "_FAST_LOADER", None)
        slow = yamlio._compose(text)
        monkeypatch.undo()
        assert _graph(fast) == _graph(slow)


@pytest.mark.parametrize("text", [
    "a: [1, 2\n", "a: b: c\n", "a:\n\t- 1\n", "{a: 1, a: }\n: x\n", "a: 'open\n",
    "- a\nb: c\n", "a: *nowhere\n",
])
def test_a_malformed_file_is_told_in_the_pure_python_parser_s_words(text, monkeypatch):
    """libyaml's messages differ from PyYAML's own: a file libyaml refuses is parsed again by
    the pure-Python parser, so the error, its words and its line, is the same either way."""
    import stationd.yamlio as yamlio

    with pytest.raises(ConfigError) as fast:
        YamlNode.parse(text, "f.yaml")
    monkeypatch.setattr(yamlio, "_FAST_LOADER", None)
    with pytest.raises(ConfigError) as slow:
        YamlNode.parse(text, "f.yaml")
    assert str(fast.value) == str(slow.value)
    assert str(fast.value).startswith("f.yaml:")


def test_an_unknown_key_says_the_one_meant_where_one_is_close():
    """A newcomer's "pest:" in a bolt table got the list of eight keys to search; the close
    one is said first, a key like none of them gets the list alone."""
    from stationd.yamlio import unknown_key

    keys = ("angle", "batch", "id", "name", "order", "position", "pset", "torque")
    assert unknown_key("pest", keys) == ("unknown key (did you mean pset? accepted: angle, "
                                         "batch, id, name, order, position, pset, torque)")
    assert unknown_key("colour", keys).startswith("unknown key (accepted: angle, ")
