"""Every file a command writes is written whole or not at all (issue 30, item 8: no
half-written file when Ctrl-C or SIGTERM lands while it is written): through
:func:`stationd.outfile.write_atomic` / ``write_all`` (beside it, synced, renamed), never
with ``Path.write_text``, ``open(..., "w")`` or ``cv2.imwrite`` on the file itself.

Why a scan of the source: the moment a signal lands inside a write is too short to hit from
a test, and the mistake is a line anyone can add (``tune-color`` and the benchmarks' ``--out``
had it); the few writers that may write in place are listed with the reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

STATIOND = Path(__file__).resolve().parents[1] / "stationd"

#: (file, what it writes in place): why that is not a command's output left half-written
ALLOWED = {
    ("outfile.py", "open"): "the atomic writer itself: a temporary file, renamed once whole",
    ("shell/records.py", "imwrite"): "the daemon's evidence crops, each named in its "
                                      "record only once written",
    ("demo/leftovers.py", "write_text"): "the demo's pid file in its own temporary folder "
                                         "(a pid file that does not read leaves the folder)",
    ("bench/soak.py", "write_text"): "the soak's working copies of a station file in its "
                                     "temporary folder, reloaded by the daemon it runs",
}
WRITERS = {"write_text", "write_bytes", "imwrite"}


def _writes(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, what) of each in-place write in a module: a writer method or function, or
    ``open`` / ``fdopen`` / ``Path.open`` with a mode that writes."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) \
            else ""
        if name in WRITERS:
            found.append((node.lineno, name))
        elif name in ("open", "fdopen"):
            modes = [a for a in node.args[1:2] if isinstance(a, ast.Constant)]
            modes += [k.value for k in node.keywords if k.arg == "mode"
                      and isinstance(k.value, ast.Constant)]
            if isinstance(f, ast.Attribute) and f.attr == "open":   # Path.open(mode)
                modes += [a for a in node.args[:1] if isinstance(a, ast.Constant)]
            if any(isinstance(m.value, str) and set(m.value) & set("wax") for m in modes):
                found.append((node.lineno, "open"))
    return found


def test_no_command_writes_a_file_in_place() -> None:
    bad = []
    for path in sorted(STATIOND.rglob("*.py")):
        rel = path.relative_to(STATIOND).as_posix()
        if rel.startswith("sim/"):
            continue    # the simulator's own files (its world's images), no command output
        for line, what in _writes(ast.parse(path.read_text(), str(path))):
            if (rel, what) not in ALLOWED:
                bad.append(f"stationd/{rel}:{line}: {what}")
    assert bad == [], "write these through stationd.outfile.write_atomic: " + ", ".join(bad)


def test_the_scan_finds_what_it_looks_for() -> None:
    """The scan itself: each form it must catch (so an empty result means something)."""
    src = ("Path(p).write_text(t)\nopen(p, 'w')\nopen(p, mode='ab')\np.open('w')\n"
           "os.fdopen(fd, 'wb')\ncv2.imwrite(p, i)\nopen(p)\np.open()\n")
    assert [w for _, w in _writes(ast.parse(src))] == ["write_text", "open", "open", "open",
                                                       "open", "imwrite"]
