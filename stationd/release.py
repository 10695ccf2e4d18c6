"""Which release of stationd runs: its version and, installed from a git checkout (the
README's install: a clone in /opt/stationd), the commit, so that an administrator can tell
the release running after an upgrade (an IT administrator's trial: every release said
"stationd 0.1.0")."""

from __future__ import annotations

import functools
from pathlib import Path

from stationd import __version__

#: the checkout the package runs from (``<checkout>/stationd/release.py``)
CHECKOUT = Path(__file__).resolve().parent.parent


@functools.cache
def release(checkout: Path = CHECKOUT) -> str:
    """``0.1.0`` or ``0.1.0 (git 1860a00c1b2e)``: the commit read from the checkout's
    ``.git`` files (no git program run, none needed by the service); the version alone where
    there is none or it cannot be read."""
    commit = _commit(checkout / ".git")
    return __version__ if commit is None else f"{__version__} (git {commit[:12]})"


def _commit(git: Path) -> str | None:
    """The commit ``HEAD`` names in the repository ``git``: a detached one, a branch's
    loose ref, or its line in ``packed-refs``; None where none is found."""
    try:
        head = (git / "HEAD").read_text().strip()
        if not head.startswith("ref: "):
            return head if _is_sha(head) else None
        ref = head[5:]
        loose = git / ref
        if loose.is_file():
            sha = loose.read_text().strip()
            return sha if _is_sha(sha) else None
        for line in (git / "packed-refs").read_text().splitlines():
            sha, _, name = line.partition(" ")
            if name == ref and _is_sha(sha):
                return sha
    except (OSError, UnicodeDecodeError):
        return None
    return None


def _is_sha(text: str) -> bool:
    return len(text) in (40, 64) and all(c in "0123456789abcdef" for c in text)
