"""Which release runs (:mod:`stationd.release`): the version and the checkout's commit, read
from its ``.git`` files."""

from __future__ import annotations

from pathlib import Path

from stationd import __version__
from stationd.release import release

SHA = "1860a00c1b2e" + "0" * 28


def test_a_branchs_loose_or_packed_ref_and_a_detached_head(tmp_path: Path):
    git = tmp_path / ".git"
    (git / "refs" / "heads").mkdir(parents=True)
    (git / "HEAD").write_text("ref: refs/heads/main\n")
    (git / "packed-refs").write_text(f"# pack-refs with: peeled\n{SHA} refs/heads/main\n")
    assert release.__wrapped__(tmp_path) == f"{__version__} (git 1860a00c1b2e)"
    (git / "refs" / "heads" / "main").write_text("ab" * 20 + "\n")
    assert release.__wrapped__(tmp_path) == f"{__version__} (git abababababab)"
    (git / "HEAD").write_text("cd" * 20 + "\n")
    assert release.__wrapped__(tmp_path) == f"{__version__} (git cdcdcdcdcdcd)"


def test_no_checkout_or_an_unreadable_one_is_the_version_alone(tmp_path: Path):
    assert release.__wrapped__(tmp_path) == __version__
    (tmp_path / ".git").mkdir()
    (tmp_path / ".git" / "HEAD").write_text("ref: refs/heads/gone\n")
    assert release.__wrapped__(tmp_path) == __version__
    (tmp_path / ".git" / "HEAD").write_text("garbage\n")
    assert release.__wrapped__(tmp_path) == __version__
