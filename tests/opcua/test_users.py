"""The OPC UA server's user logins, without a server: the same rules as the screens' logins
where they fit (a security review guessed six passwords in 0.6 s and told users' names apart
by time; a second review locked the MES out with five wrong passwords and stalled the loop
with names never tried)."""

from __future__ import annotations

import logging

import pytest

import stationd.access as access
from stationd.access import hash_password, password_matches
from stationd.opcua.server import CHECKS_BURST, CHECKS_PER_S, StationUsers

MES_HASH = hash_password("the-mes-password", salt=b"tests-mes-salt!!")


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_an_unknown_user_is_checked_against_a_hash_as_a_known_one_is(monkeypatch):
    """An unknown user's password goes through scrypt too (against a dummy hash): its
    refusal cannot be told from a wrong password's by the time it takes."""
    checked = []
    real = access.verify_password
    monkeypatch.setattr(access, "verify_password",
                        lambda pw, stored: checked.append(stored) or real(pw, stored))
    assert not password_matches("anything", None)
    assert not password_matches("wrong", MES_HASH)
    assert password_matches("the-mes-password", MES_HASH)
    assert len(checked) == 3 and checked[0] not in (None, MES_HASH)


def test_password_checks_are_budgeted_not_a_user_locked_out(caplog, monkeypatch):
    """Beyond the budget a login is refused unchecked (no scrypt on the loop); the right
    password gets in once the budget refills: wrong ones cannot keep the MES out for good.
    The journal names the user of a checked refusal, and says the unchecked ones once."""
    checked = []
    real = access.verify_password
    monkeypatch.setattr(access, "verify_password",
                        lambda pw, stored: checked.append(stored) or real(pw, stored))
    clock = Clock()
    users = StationUsers({"mes": MES_HASH}, clock=clock)
    caplog.set_level(logging.WARNING)
    assert users.get_user(None).role.name == "Anonymous"
    assert users.get_user(None, "nobody", "guess") is None
    for i in range(CHECKS_BURST + 10):
        assert users.get_user(None, "mes", f"guess{i}") is None
    assert len(checked) == CHECKS_BURST             # the rest refused unchecked
    assert users.get_user(None, "mes", "the-mes-password") is None    # budget spent
    clock.t += 1.0 / CHECKS_PER_S                    # one check's worth later
    user = users.get_user(None, "mes", "the-mes-password")
    assert user is not None and user.name == "mes"
    said = [r.getMessage() for r in caplog.records]
    assert "OPC UA: user 'nobody' refused: wrong user or password" in said
    assert said.count("OPC UA: user 'mes' refused: wrong user or password") == 1
    assert said.count(f"OPC UA: logins refused unchecked: more than {CHECKS_PER_S} a "
                      "second") == 1
    clock.t += 61.0                                  # a minute on: said again, with the count
    for i in range(CHECKS_BURST + 1):
        users.get_user(None, "mes", f"late{i}")
    said = [r.getMessage() for r in caplog.records]
    assert any(s.startswith("OPC UA: user 'mes' refused: wrong user or password (")
               and "more like it in the last minute" in s for s in said), said


def test_anonymous_clients_may_be_refused_but_not_every_client():
    from stationd.errors import ConfigError
    from stationd.opcua.config import OpcUaConfig
    from stationd.yamlio import YamlNode

    users = StationUsers({"mes": MES_HASH}, anonymous=False)
    assert users.get_user(None) is None
    assert users.get_user(None, "mes", "the-mes-password") is not None
    cfg = OpcUaConfig.from_node(YamlNode.parse(
        f"security: [none]\nanonymous: false\nusers: {{mes: '{MES_HASH}'}}\n"))
    assert not cfg.anonymous and not cfg.on_loopback          # the default 0.0.0.0
    assert OpcUaConfig.from_node(YamlNode.parse(
        "endpoint: opc.tcp://127.0.0.1:4840\nsecurity: [none]\n")).on_loopback
    with pytest.raises(ConfigError, match="false with no users: no client could connect"):
        OpcUaConfig.from_node(YamlNode.parse("security: [none]\nanonymous: false\n"))
