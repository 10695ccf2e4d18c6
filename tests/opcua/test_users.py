"""The OPC UA server's user logins, without a server: the same rules as the screens' logins
(a security review guessed six passwords in 0.6 s and told users' names apart by time)."""

from __future__ import annotations

import logging

import stationd.access as access
from stationd.access import hash_password, password_matches
from stationd.opcua.server import StationUsers

MES_HASH = hash_password("the-mes-password", salt=b"tests-mes-salt!!")


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


def test_wrong_passwords_are_throttled_and_told_with_the_users_name(caplog):
    users = StationUsers({"mes": MES_HASH})
    caplog.set_level(logging.WARNING, logger="stationd.opcua.server")
    assert users.get_user(None).role.name == "Anonymous"
    assert users.get_user(None, "nobody", "guess") is None
    for i in range(5):
        assert users.get_user(None, "mes", f"guess{i}") is None
    # the right password now waits for the window: a guesser gets nothing from trying on
    assert users.get_user(None, "mes", "the-mes-password") is None
    said = [r.getMessage() for r in caplog.records]
    assert "OPC UA: user 'nobody' refused: wrong user or password" in said
    assert said.count("OPC UA: user 'mes' refused: wrong user or password") == 5
    assert said[-1] == "OPC UA: user 'mes' refused: too many wrong passwords"
    other = StationUsers({"mes": MES_HASH})       # (a new server: no wrong password yet)
    user = other.get_user(None, "mes", "the-mes-password")
    assert user is not None and user.name == "mes"


def test_anonymous_clients_may_be_refused_but_not_every_client():
    import pytest

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
