"""Lint and type checks are part of the test suite, so CI fails when either fails."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool(name: str) -> str:
    path = Path(sys.executable).parent / name
    found = str(path) if path.exists() else shutil.which(name)
    if found is None:
        pytest.fail(f"{name} is not installed (pip install -e '.[dev]')")
    return found


def test_ruff_clean():
    r = subprocess.run([_tool("ruff"), "check", "."], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.timeout(300)
def test_mypy_clean():
    r = subprocess.run([_tool("mypy")], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_layers_hold():
    """import-linter's contracts (pyproject.toml): drivers and db import nothing from stationd,
    vision and geometry nothing from devices, the database or the station; the components of
    stationd in layers without a cycle; runtime code never imports sim or bench."""
    r = subprocess.run([_tool("lint-imports")], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_folders_are_layers_every_layers_contract_exhaustive():
    """Each root package (stationd, drivers, db) has a layers contract over its folders, and
    every layers contract is exhaustive and ignores nothing: a new module or folder must be
    given its place, and no folder is split across two layers (no layer names a module
    inside another package)."""
    import tomllib

    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"][
        "contracts"]
    layered = [c for c in contracts if c["type"] == "layers"]
    assert {"stationd", "drivers", "db"} <= {c["containers"][0] for c in layered}
    for c in layered:
        assert c.get("exhaustive") is True, c["name"]
        assert not c.get("exhaustive_ignores"), c["name"]
        names = [n.strip() for layer in c["layers"] for n in layer.split("|")]
        assert all("." not in n for n in names), c["name"]
    # every folder of more than one module is a layered container of its own (the
    # migrations excepted: Alembic revisions, each after the one it names)
    packages = {".".join(d.relative_to(ROOT).parts) for root in ("stationd", "drivers", "db")
                for d in [ROOT / root, *(ROOT / root).rglob("*")]
                if d.is_dir() and (d / "__init__.py").exists() and "migrations" not in d.parts
                and len([m for m in d.iterdir() if m.name != "__init__.py" and
                         (m.suffix == ".py" or (m / "__init__.py").exists())]) > 1}
    layered_containers = {name for c in layered for name in c["containers"]}
    assert sorted(packages - layered_containers) == []


def test_the_station_opens_every_device_through_the_one_registry():
    """stationd builds and opens devices only through ``drivers.devices`` (one way for every
    kind, one lifecycle); the kinds' own openers are for the drivers' tests."""
    import re

    per_kind = re.compile(r"(?<![.\w])(?<!def )(open_camera|open_lift|open_wrench)\(")
    found = [f"{p.relative_to(ROOT)}:{n}" for p in sorted((ROOT / "stationd").rglob("*.py"))
             for n, line in enumerate(p.read_text().splitlines(), 1) if per_kind.search(line)]
    assert found == []
