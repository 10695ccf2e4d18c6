"""Words of the command line that disagreed with what the station does (issue 30, item 9):
``stationd user hash --help`` did not say where the password is read from; the default
roles written as ``engineer: [skip, reopen, teach]`` while the station gives the engineer
``calibrate`` too (the screens show it); the demo's ``rundowns recorded by operator: operator
23``."""

from __future__ import annotations

import pytest
import yaml

import stationd.access
from stationd.access import DEFAULT_ROLES
from stationd.cli import main
from stationd.demo.station import operator_words


def test_user_hash_help_says_where_the_password_comes_from(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["user", "hash", "--help"])
    assert exit_.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "read from STATIOND_PASSWORD when it is set, else asked twice at a terminal, " \
           "else the first line of standard input" in text


def test_the_roles_written_as_the_defaults_are_the_defaults() -> None:
    """The access section's documented example, whose roles say "these are the defaults"."""
    doc = stationd.access.__doc__ or ""
    block = doc[doc.index("    access:"):doc.index("Any user may sign in")]
    written = yaml.safe_load(block)["access"]["roles"]
    assert {role: set(rights) for role, rights in written.items()} == \
        {role: {r.value for r in rights} for role, rights in DEFAULT_ROLES.items()}


@pytest.mark.parametrize(("operators", "words"), [
    ({"operator": 23}, "23 by user 'operator'"),
    ({"-": 2, "sam": 1, "olga": 4}, "4 by user 'olga', 1 by user 'sam', 2 with nobody "
                                    "signed in"),
])
def test_the_demo_says_whose_rundowns(operators, words) -> None:
    assert operator_words(operators) == \
        f"rundowns recorded, by who was signed in at the station: {words}"
