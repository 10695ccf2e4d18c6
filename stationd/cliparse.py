"""The command line's parser: argparse, with a usage error said in one line (exit 2) and a
mistyped command or option named with the one it likely meant.

Why a module of its own: the entry point (:mod:`stationd.cli`) builds the commands' parser;
how a parser says a usage error is one subject, tested on its own.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from stationd.logsetup import error_mark

#: bad input: one readable line on stderr (the entry point's exit codes: :mod:`stationd.cli`)
EXIT_BAD_INPUT = 2


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2."""

    #: the command line being read (set by :func:`_main`): a mistyped option is named
    argv: Sequence[str] = ()

    def error(self, message: str) -> NoReturn:
        said = self._missing_command(message) or self._no_such_command(message) or message
        typo = self._mistyped()
        mark = error_mark()
        if message.startswith("unrecognized arguments"):
            # said by the command it was given to; a typo is the whole story (its value was
            # listed as unrecognized too)
            sys.stderr.write(f"{mark}{self._command_prog()}: error: {typo or message} "
                             "(see --help)\n")
        else:
            sys.stderr.write(f"{mark}{self.prog}: error: {typo + '; ' if typo else ''}{said} "
                             "(see --help)\n")
        raise SystemExit(EXIT_BAD_INPUT)

    def _command_prog(self) -> str:
        """The prog of the deepest command the command line names (``stationd demo``), where
        an unrecognized option is reported by the top parser (``stationd``)."""
        return self._command()[0]

    def _command(self) -> tuple[str, argparse.ArgumentParser]:
        """The deepest command the command line names, as typed (``stationd sim lift``, an
        alias of ``sim plc``), and its parser; this one where it names none."""
        words = [t for t in Parser.argv if not t.startswith("-")]
        best: tuple[str, argparse.ArgumentParser] = (self.prog, self)
        depth = 0
        for path, p in self._paths():
            if len(path) > depth and words[:len(path)] == path:
                best, depth = (" ".join([p.prog.split()[0], *path]), p), len(path)
        return best

    def _paths(self) -> list[tuple[list[str], argparse.ArgumentParser]]:
        """Every command under this parser with the words that name it from the top, each
        alias too (an alias's parser is its command's, its prog the command's name)."""
        paths: list[tuple[list[str], argparse.ArgumentParser]] = []
        todo: list[tuple[list[str], argparse.ArgumentParser]] = [(self.prog.split()[1:], self)]
        while todo:
            path, p = todo.pop()
            paths.append((path, p))
            for action in p._actions:
                if isinstance(action, argparse._SubParsersAction):
                    todo.extend(([*path, name], sub) for name, sub in action.choices.items())
        return paths

    def _no_such_command(self, message: str) -> str | None:
        """``stationd stauts``: the command it is likely a typo of, not only the choices."""
        import difflib
        import re

        m = re.match(r"argument (\S+): invalid choice: '([^']*)' \(choose from (.*)\)$",
                     message)
        commands = {a.dest for a in self._actions
                    if isinstance(a, argparse._SubParsersAction)}
        if m is None or m.group(1) not in commands:   # an option's value: argparse's words
            return None
        choices = [c.strip().strip("'") for c in m.group(3).split(",")]
        argv = list(Parser.argv)
        at = next((i for i, t in enumerate(argv) if t == m.group(2)), None)
        if at is not None and at > 0 and argv[at - 1].startswith("--"):
            # ``operator --config S``: the option's value taken for the command
            return (f"a command is missing: {self.prog} {' | '.join(choices)} (its options, "
                    f"{argv[at - 1]} too, come after it)")
        close = difflib.get_close_matches(m.group(2), choices, n=1, cutoff=0.6)
        return None if not close else \
            f"no command {m.group(2)!r} (did you mean {close[0]}?)"

    def _mistyped(self) -> str | None:
        """The first option given that this command does not have, with the one it is
        likely a typo of: ``run --confg X`` said only that --config is required."""
        import difflib

        command = self._command()[1]    # its own options, not every command's
        mine = {o for o in command._option_string_actions if o.startswith("--")}
        known = sorted(mine)
        for token in Parser.argv:
            name = token.split("=", 1)[0]
            if name.startswith("--") and name not in mine:
                close = difflib.get_close_matches(name, known, n=1, cutoff=0.7)
                if close:
                    return f"no option {name} (did you mean {close[0]}?)"
        return None

    def _missing_command(self, message: str) -> str | None:
        """A command given without its subcommand (``stationd config``) is told what to
        type, not ``the following arguments are required: config_command``."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction) and action.dest and \
                    message == f"the following arguments are required: {action.dest}":
                choices = " | ".join(action.choices)
                return f"a command is missing: {self.prog} {choices}"
        return None
