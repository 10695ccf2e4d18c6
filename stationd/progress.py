"""Progress of long work, on stderr, through tqdm.

Why a wrapper: every long command (calibration views, benchmarks, the demo) shows progress the
same way, and the rules live in one place: bars go to stderr (stdout stays the command's
result, JSON included), and they are off with ``--quiet`` and whenever stderr is not a terminal,
so CI logs and pipes stay clean.  With bars off, :func:`track` is a plain pass-through.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")

_quiet = False


def configure(*, quiet: bool) -> None:
    """Set by the command line once per run (``--quiet``)."""
    global _quiet  # one process-wide switch, set once by main()
    _quiet = quiet


def enabled() -> bool:
    """Bars are shown only to a person: not quiet, and stderr is a terminal."""
    if _quiet:
        return False
    isatty = getattr(sys.stderr, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def track(items: Iterable[T], desc: str, *, total: int | None = None,
          unit: str = "it") -> Iterator[T]:
    """Iterate ``items`` with a bar named ``desc`` when bars are enabled."""
    if not enabled():
        yield from items
        return
    from tqdm import tqdm

    with tqdm(items, desc=desc, total=total, unit=unit, file=sys.stderr, leave=False,
              dynamic_ncols=True) as bar:
        yield from bar


def note(text: str) -> None:
    """A one-line status message (a stage starting) on stderr, only when bars are enabled,
    written so that it does not break a bar in progress."""
    if not enabled():
        return
    from tqdm import tqdm

    tqdm.write(text, file=sys.stderr)
