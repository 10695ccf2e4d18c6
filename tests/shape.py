"""The shape of the code in figures, for the README: ``python -m tests.shape``.

Counts by ``ast`` over stationd, drivers and db: the largest modules (lines), classes and
functions (lines from their ``def`` or ``class`` to their last line)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def measure(root: Path) -> dict[str, list[tuple[int, str]]]:
    """The three largest of each: modules, classes, functions."""
    found: dict[str, list[tuple[int, str]]] = {"module": [], "class": [], "function": []}
    for package in ("stationd", "drivers", "db"):
        for path in sorted((root / package).rglob("*.py")):
            text = path.read_text()
            name = str(path.relative_to(root))
            found["module"].append((len(text.splitlines()), name))
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.ClassDef):
                    kind = "class"
                elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    kind = "function"
                else:
                    continue
                size = (node.end_lineno or node.lineno) - node.lineno + 1
                found[kind].append((size, f"{name}:{node.name}"))
    return {k: sorted(v, reverse=True)[:3] for k, v in found.items()}


def main() -> int:
    for kind, largest in measure(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT).items():
        plural = "classes" if kind == "class" else f"{kind}s"
        print(f"largest {plural}: " + ", ".join(f"{name} {n}" for n, name in largest))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
