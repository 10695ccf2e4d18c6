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
        words = [t for t in Parser.argv if not t.startswith("-")]
        best = self.prog
        for p in self._tree():
            named = p.prog.split()[1:]
            if named and words[:len(named)] == named and len(p.prog) > len(best):
                best = p.prog
        return best

    def _tree(self) -> list[argparse.ArgumentParser]:
        """This parser and its subcommands' parsers, theirs too: an option unknown to the
        one that reports it may be a subcommand's, mistyped.  (Walked from here, not kept in
        a list of every parser made: that list grew by the whole tree at every build, and
        each error walked every parser a process, the tests', had ever built.)"""
        tree: list[argparse.ArgumentParser] = []
        todo: list[argparse.ArgumentParser] = [self]
        while todo:
            p = todo.pop()
            if any(p is q for q in tree):    # an alias names its command's parser again
                continue
            tree.append(p)
            for action in p._actions:
                if isinstance(action, argparse._SubParsersAction):
                    todo.extend(action.choices.values())
        return tree

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

        command = self._command_prog()    # its own options, not every command's
        mine = {o for p in self._tree() if p.prog == command
                for o in p._option_string_actions if o.startswith("--")}
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
