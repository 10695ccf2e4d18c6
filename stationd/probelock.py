"""A probe's hold on its device (:func:`stationd.lock.probing`), said in its JSON too.

Why a module of its own: ``stationd probe lift|wrench`` and ``stationd probe camera`` take it
alike, and the camera's probe sits below the others' module."""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Iterator

from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.lock import probing


@contextlib.contextmanager
def locked(args: argparse.Namespace, kind: str) -> Iterator[None]:
    """:func:`stationd.lock.probing` for this probe; refused (the device is driven by a daemon
    or another probe), a ``--json`` probe still prints its one object (``ok`` false, the
    refusal in ``error``): a script reading stdout gets an answer, not an empty line, and
    the exit (2) and the line on stderr are the same."""
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(probing(kind, args.url))
        except InputError as exc:
            if args.json:
                sys.stdout.write(strict_json({"device": args.url, "kind": kind, "ok": False,
                                              "error": str(exc)}) + "\n")
            raise
        yield
