"""Users, roles, password hashes, sessions and the replay guard of the command channel."""

from __future__ import annotations

import pytest

from stationd.access import (
    AccessConfig,
    LoginThrottle,
    ReplayGuard,
    Sessions,
    hash_password,
    parse_hash,
    verify_password,
)
from stationd.errors import ConfigError
from stationd.station.commands import Right
from stationd.yamlio import YamlNode

HASH = hash_password("correct horse", salt=b"0123456789abcdef")


def test_a_hash_verifies_its_password_only_and_carries_its_parameters():
    assert verify_password("correct horse", HASH)
    assert not verify_password("correct horsf", HASH)
    n, r, p, salt, key = parse_hash(HASH)
    assert (n, r, p, salt, len(key)) == (2 ** 14, 8, 1, b"0123456789abcdef", 32)
    assert hash_password("correct horse") != hash_password("correct horse")   # salted


@pytest.mark.parametrize("text", ["correct horse", "scrypt$16384$8$1$abc", "",
                                  "scrypt$1000$8$1$MDEyMzQ1Njc4OWFiY2RlZg==$" + "A" * 44,
                                  "scrypt$16384$8$1$!!!$" + "A" * 44])
def test_anything_but_a_scrypt_hash_is_refused(text):
    with pytest.raises(ValueError):
        parse_hash(text)


def _access(yaml_text: str) -> AccessConfig:
    return AccessConfig.from_node(YamlNode.parse(yaml_text, "station.yaml"))


def test_users_get_the_rights_of_their_role_and_a_wrong_password_nothing():
    a = _access(f"users:\n  sam: {{role: supervisor, password: '{HASH}'}}\n"
                f"  olga: {{role: operator, password: '{HASH}'}}\n")
    sam = a.issuer("sam", "correct horse", "cli")
    assert sam is not None and sam.rights == {Right.SKIP, Right.REOPEN, Right.RELEASE,
                                              Right.LOOSEN}
    olga = a.issuer("olga", "correct horse", "screen 10.0.0.7")
    assert olga is not None and olga.rights == {Right.SKIP} and olga.source.startswith("screen")
    assert a.issuer("sam", "wrong", "cli") is None
    assert a.issuer("nobody", "correct horse", "cli") is None


def test_roles_written_extend_the_defaults_and_redefine_those_named():
    """The README writes the roles "optional; these are the defaults": a role written is
    added, or redefines the default of its name; the other defaults stay."""
    a = _access(f"roles:\n  lead: [skip, teach]\n  operator: [skip, reopen]\nusers:\n"
                f"  tom: {{role: lead, password: '{HASH}'}}\n"
                f"  sam: {{role: supervisor, password: '{HASH}'}}\n")
    tom = a.issuer("tom", "correct horse", "cli")
    assert tom is not None and tom.rights == {Right.SKIP, Right.TEACH}
    assert a.roles["operator"] == {Right.SKIP, Right.REOPEN}
    assert a.roles["supervisor"] == {Right.SKIP, Right.REOPEN, Right.RELEASE, Right.LOOSEN}
    assert sorted(a.roles) == ["engineer", "lead", "operator", "supervisor"]
    with pytest.raises(ConfigError) as err:
        _access(f"roles:\n  lead: [skip]\nusers:\n  tom: {{role: boss, password: '{HASH}'}}\n")
    assert str(err.value).endswith("'boss' is not one of: operator, supervisor, engineer, lead")


@pytest.mark.parametrize(("text", "message"), [
    ("users:\n  sam: {role: supervisor, password: hunter22}\n", "never the password"),
    (f"users:\n  sam: {{role: king, password: '{HASH}'}}\n", "'king' is not one of"),
    (f"users:\n  sam: {{password: '{HASH}'}}\n", "missing key: role"),
    ("roles:\n  lead: [fly]\n", "'fly' is not one of"),
    ("groups: {}\n", "unknown key"),
    ("operator_required: yes please\n", "expected true or false"),
    ("operator_required: true\n", "operator_required: true needs users"),
    (f"users:\n  sam: {{role: supervisor, password: '{HASH}'}}\noperator_idle_s: 5\n",
     "operator_idle_s"),
])
def test_a_bad_access_section_names_its_line_and_key(text, message):
    with pytest.raises(ConfigError) as err:
        _access(text)
    assert message in str(err.value) and "station.yaml" in str(err.value)


def test_the_operator_options_default_to_tightening_with_nobody_signed_in():
    a = _access(f"users:\n  olga: {{role: operator, password: '{HASH}'}}\n")
    assert (a.operator_required, a.operator_idle_s) == (False, None)
    a = _access(f"users:\n  olga: {{role: operator, password: '{HASH}'}}\n"
                "operator_required: true\noperator_idle_s: 1800\n")
    assert (a.operator_required, a.operator_idle_s) == (True, 1800.0)


def test_sessions_end_idle_and_after_a_shift_and_on_logout():
    now = [0.0]
    s = Sessions(idle_s=60, max_s=600, clock=lambda: now[0])
    who = _access(f"users:\n  sam: {{role: operator, password: '{HASH}'}}\n") \
        .issuer("sam", "correct horse", "cli")
    assert who is not None
    t = s.open(who)
    for _ in range(9):
        now[0] += 59
        assert s.get(t) == who        # kept alive by use
    now[0] += 200
    assert s.get(t) is None           # idle too long
    t = s.open(who)
    for _ in range(12):
        now[0] += 55
    assert s.get(t) is None           # a shift at most
    t = s.open(who)
    s.close(t)
    assert s.get(t) is None and s.get(None) is None and s.get("forged") is None


def test_only_a_fresh_nonce_the_server_issued_passes_once():
    now = [1000.0]
    g = ReplayGuard(window_s=120, clock=lambda: now[0])
    n = g.issue()
    assert g.check(n) is None
    assert "replayed" in (g.check(n) or "")
    assert "unknown" in (g.check("made-up-by-the-client-123") or "")
    old = g.issue()
    now[0] += 121
    assert "stale" in (g.check(old) or "")


def test_wrong_passwords_lock_the_user_out_for_a_while():
    now = [0.0]
    t = LoginThrottle(most=3, window_s=60, clock=lambda: now[0])
    for _ in range(3):
        assert t.blocked("sam") == 0
        t.failed("sam")
    assert t.blocked("sam") == pytest.approx(60) and t.blocked("olga") == 0
    now[0] += 61
    assert t.blocked("sam") == 0
    t.failed("sam")
    t.passed("sam")
    assert t.blocked("sam") == 0


def test_a_removed_user_or_a_changed_role_is_seen_by_a_session():
    a = _access(f"users:\n  sam: {{role: supervisor, password: '{HASH}'}}\n")
    sam = a.issuer("sam", "correct horse", "cli")
    assert sam is not None
    demoted = _access(f"users:\n  sam: {{role: operator, password: '{HASH}'}}\n")
    assert demoted.current(sam) == sam.__class__("sam", frozenset({Right.SKIP}), "cli")
    assert _access("users: {}\n").current(sam) is None


def test_who_has_a_right_by_role_and_by_user():
    """Whom the screens name beside a lock (roles) and whether anyone can release at all
    (users): the roles' rights as written, extending the defaults."""
    cfg = AccessConfig.from_node(YamlNode.parse(
        "roles: {lead: [release]}\nusers:\n"
        f"  olga: {{role: operator, password: '{hash_password('x')}'}}\n"
        f"  lee: {{role: lead, password: '{hash_password('x')}'}}\n", "s.yaml"))
    assert cfg.roles_with(Right.RELEASE) == ["lead", "supervisor"]
    assert cfg.users_with(Right.RELEASE) == ["lee"]
    assert cfg.users_with(Right.TEACH) == []
