""".ci/bootstrap: one line per step, and a second run does nothing again.  Run on a copy of
the script with stand-ins for apt, dpkg and python on PATH (the real run takes minutes and
the network), so what is tested is the script's own logic and output."""

import os
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PYTHON_STUB = """#!/bin/sh
echo "python3 $*" >> "$LOG"
if [ "$1 $2" = "-m venv" ]; then
    mkdir -p "$3/bin" && cp "$0" "$3/bin/python" && chmod +x "$3/bin/python"
fi
exit 0
"""


NPM_STUB = """#!/bin/sh
echo "npm $*" >> "$LOG"
while [ $# -gt 0 ]; do
    if [ "$1" = "--prefix" ]; then mkdir -p "$2/node_modules/node-opcua"
        touch "$2/node_modules/node-opcua/package.json"; fi
    shift
done
"""


def _stub(bin_dir: Path, name: str, body: str) -> None:
    path = bin_dir / name
    path.write_text(body)
    path.chmod(0o755)


def _run(tree: Path, env: dict[str, str], *args: str) -> list[str]:
    r = subprocess.run(["bash", str(tree / ".ci" / "bootstrap"), *args], capture_output=True,
                       text=True, env=env, timeout=60, check=True)
    return r.stdout.splitlines()


def _machine(tmp_path: Path) -> tuple[Path, Path, dict[str, str]]:
    """A copy of the script, the stand-ins on PATH (as root) and their environment."""
    tree, bin_dir = tmp_path / "tree", tmp_path / "bin"
    (tree / ".ci").mkdir(parents=True)
    bin_dir.mkdir()
    shutil.copy(ROOT / ".ci" / "bootstrap", tree / ".ci" / "bootstrap")
    log = tmp_path / "calls.log"
    _stub(bin_dir, "id", "#!/bin/sh\necho 0\n")  # as root
    _stub(bin_dir, "dpkg", "#!/bin/sh\n[ -f \"$STATE\" ]\n")  # installed once apt-get ran
    _stub(bin_dir, "apt-get", "#!/bin/sh\necho \"apt-get $*\" >> \"$LOG\"\ntouch \"$STATE\"\n")
    _stub(bin_dir, "pkg-config", "#!/bin/sh\nexit 1\n")
    _stub(bin_dir, "python3", PYTHON_STUB)
    _stub(bin_dir, "npm", NPM_STUB)
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin", "LOG": str(log),
           "STATE": str(tmp_path / "installed"), "HOME": str(tmp_path),
           "SYSTEM_PYTHON": str(bin_dir / "python3")}   # as root: the system's Python
    return tree, log, env


def test_bootstrap_prints_a_line_per_step_and_is_idempotent(tmp_path):
    tree, log, env = _machine(tmp_path)
    bin_dir = tmp_path / "bin"
    first = _run(tree, env)
    steps = [line.split("] ", 1)[1] for line in first]
    assert all(line.startswith("bootstrap: [") for line in first)
    assert steps[0] == "apt-get update" and steps[1].startswith("apt-get install python3 ")
    assert steps[2:5] == [f"{bin_dir}/python3 -m venv .venv", "pip install --upgrade pip",
                          "pip install -e .[dev,bench] (numpy, OpenCV, ...: a few minutes the "
                          "first time)"]
    assert steps[-2].startswith("npm install node-opcua@") and steps[-1] == "ready (.venv)"
    calls = log.read_text()
    assert calls.count("apt-get install") == 1 and calls.count("-m venv .venv") == 1
    assert calls.count("npm install") == 1
    second = [line.split("] ", 1)[1] for line in _run(tree, env)]
    assert second[0].startswith("apt: all ") and second[1] == "venv: .venv exists"
    assert second[2] == "python packages: as installed for this pyproject.toml (dev,bench)"
    assert second[3] == "ready (.venv)" and len(second) == 4
    calls = log.read_text()
    assert calls.count("apt-get install") == 1 and calls.count("-m venv .venv") == 1
    assert calls.count("npm install") == 1      # node-opcua is there: not again
    assert os.access(tree / ".venv" / "bin" / "python", os.X_OK)


def test_a_station_pc_gets_the_station_alone(tmp_path):
    """``--station``: the daemon, its commands and sqlite3 for the backups; no browsers, no
    PostgreSQL server, no Node.js, no dev tools (a technician's trial: the tests' set was
    installed on a station PC, a database server started by it)."""
    tree, log, env = _machine(tmp_path)
    steps = [line.split("] ", 1)[1] for line in _run(tree, env, "--station")]
    [install] = [s for s in steps if s.startswith("apt-get install ")]
    packages = install.split()[2:]
    assert "sqlite3" in packages and "gir1.2-aravis-0.8" in packages
    assert not {"chromium", "firefox-esr", "postgresql", "nodejs", "npm"} & set(packages)
    assert "pip install -e . (numpy, OpenCV, ...: a few minutes the first time)" in steps
    assert steps[-1].startswith("ready (.venv, for a station")
    assert "npm" not in log.read_text()
    r = subprocess.run(["bash", str(tree / ".ci" / "bootstrap"), "--stations"],
                       capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 2 and r.stderr.strip() == (
        "bootstrap: unknown option --stations (usage: bootstrap [--station])")
