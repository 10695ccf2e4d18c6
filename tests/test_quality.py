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


def test_every_station_module_has_its_place_in_the_component_layers():
    """The components' layers contract lists the station package module by module (its shell
    above the configuration, its core below the screens), so it leaves ``station`` out of its
    exhaustiveness check: a new module of the station must still be placed there."""
    import tomllib

    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"][
        "contracts"]
    (layers,) = [c["layers"] for c in contracts if c.get("containers") == ["stationd"]]
    placed = {name.strip() for layer in layers for name in layer.replace(":", "|").split("|")}
    station = ROOT / "stationd" / "station"
    modules = {f"station.{p.stem}" for p in station.glob("*.py") if p.stem != "__init__"}
    modules |= {f"station.{p.parent.name}" for p in station.glob("*/__init__.py")}
    assert modules - placed == set(), "not placed in the stationd layers contract"
