"""A run builds only its command's group of the parser (:func:`stationd.cli.build_parser`):
the groups must name exactly what their functions add, and a command parsed alone must parse
as it does among all the others."""

from __future__ import annotations

import argparse

import pytest

from stationd import cli


def _commands(parser: argparse.ArgumentParser) -> list[str]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return list(action.choices)


def test_the_groups_name_every_command_in_help_s_order():
    assert _commands(cli.build_parser()) == [n for names, _ in cli._GROUPS for n in names]


@pytest.mark.parametrize("names", [names for names, _ in cli._GROUPS], ids=lambda n: n[0])
def test_a_command_s_parser_holds_its_group_alone(names):
    for name in names:
        assert _commands(cli.build_parser(name)) == list(names)


@pytest.mark.parametrize("argv", [
    ["status", "--json"],
    ["-q", "demo", "--seed", "3"],
    ["sim", "controller", "--port", "0", "--nok-rate", "0.2"],
    ["db", "report", "VIN1", "--db", "sqlite://"],
    ["release", "VIN1", "B1", "--user", "sup", "--comment", "checked"],
    ["calibrate", "check", "--config", "station.yaml"],
    ["demo", "--quiet"],
])
def test_a_command_parsed_alone_parses_as_among_all(argv):
    alone = cli.build_parser(cli.command_word(argv)).parse_args(argv)
    among = cli.build_parser().parse_args(argv)
    assert vars(alone) == vars(among)
    assert cli.command_word(argv) == next(w for w in argv if not w.startswith("-"))


@pytest.mark.parametrize("argv", [
    [], ["-q"], ["--help"], ["-h", "status"], ["--version", "demo"], ["no-such-command"],
    ["-q", "stat"],
])
def test_help_a_version_or_an_unknown_command_builds_them_all(argv):
    assert cli.command_word(argv) is None


def test_an_unknown_command_is_answered_with_every_command(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["no-such-command"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "no-such-command" in err
    for names, _ in cli._GROUPS:
        assert all(name in err for name in names)
