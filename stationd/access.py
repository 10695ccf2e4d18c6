"""Who may give the station commands: users and roles from the station file, their passwords
only as scrypt hashes, the screens' sessions and the guard against replayed requests.

Why here and not in the core: authentication is the edges' (a screen's session, the command
line's password); a command reaches the core with the user's name and the rights of their
role (:class:`~stationd.station.commands.Issuer`), and the core checks the right it needs.

The ``access:`` section (optional; without it nobody can give commands)::

    access:
      users:
        sam: {role: supervisor, password: "scrypt$16384$8$1$<salt>$<key>"}
      roles:                          # optional: these are the defaults; a role written
                                      # here gets the rights written, the others keep theirs
        operator: [skip]
        supervisor: [skip, reopen, release, loosen]
        engineer: [skip, reopen, teach, calibrate]
      operator_required: false        # true: no pset is sent while nobody is signed in
      operator_idle_s: 1800           # optional: the operator signed out after this idle

Any user may sign in at the station as its operator (``stationd operator sign-in``, the
operator screen): every rundown is recorded with the operator signed in.

``stationd user hash`` prints the hash of a password typed at its prompt: the file never
holds a password.  scrypt (RFC 7914, Python's ``hashlib``) is a standard key derivation made
to be slow to brute-force; the parameters travel in the hash, so they can be raised later.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import hmac
import secrets
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from stationd.station.commands import Issuer, Right
from stationd.yamlio import YamlNode

SCRYPT_N, SCRYPT_R, SCRYPT_P, KEY_BYTES = 2 ** 14, 8, 1, 32
DEFAULT_ROLES: dict[str, frozenset[Right]] = {
    "operator": frozenset({Right.SKIP}),
    "supervisor": frozenset({Right.SKIP, Right.REOPEN, Right.RELEASE, Right.LOOSEN}),
    "engineer": frozenset({Right.SKIP, Right.REOPEN, Right.TEACH, Right.CALIBRATE}),
}
#: a screen's session ends after this long idle, and after a shift whatever happens, s
SESSION_IDLE_S, SESSION_MAX_S = 30 * 60.0, 12 * 3600.0
#: a command request older (or newer) than this is stale; its nonce is remembered as long, s
REQUEST_WINDOW_S = 120.0


def _b64(b: bytes) -> str:
    return base64.b64encode(b).decode("ascii")


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """``scrypt$N$r$p$salt$key`` (base64): what the station file keeps."""
    salt = salt if salt is not None else secrets.token_bytes(16)
    key = hashlib.scrypt(password.encode(), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P,
                         dklen=KEY_BYTES)
    return f"scrypt${SCRYPT_N}${SCRYPT_R}${SCRYPT_P}${_b64(salt)}${_b64(key)}"


def parse_hash(text: str) -> tuple[int, int, int, bytes, bytes]:
    """The parameters, salt and key of a hash; ``ValueError`` for anything else (a password
    written in the file by mistake among them)."""
    parts = text.split("$")
    if len(parts) != 6 or parts[0] != "scrypt":
        raise ValueError("not a scrypt hash")
    try:
        n, r, p = (int(v) for v in parts[1:4])
        salt = base64.b64decode(parts[4], validate=True)
        key = base64.b64decode(parts[5], validate=True)
    except ValueError:
        raise ValueError("not a scrypt hash") from None
    if n < 2 ** 10 or n & (n - 1) or not 1 <= r <= 64 or not 1 <= p <= 16 \
            or len(salt) < 8 or len(key) < 16:
        raise ValueError("scrypt parameters out of range")
    return n, r, p, salt, key


def verify_password(password: str, stored: str) -> bool:
    """Whether ``password`` is the one ``stored`` was made from (compared in constant time)."""
    n, r, p, salt, key = parse_hash(stored)
    got = hashlib.scrypt(password.encode(), salt=salt, n=n, r=r, p=p, dklen=len(key),
                         maxmem=256 * 1024 * 1024)
    return hmac.compare_digest(got, key)


@dataclass(frozen=True)
class User:
    name: str
    role: str
    password_hash: str


@dataclass(frozen=True)
class AccessConfig:
    """The users and the rights of their roles."""

    users: Mapping[str, User] = field(default_factory=dict)
    roles: Mapping[str, frozenset[Right]] = field(default_factory=lambda: dict(DEFAULT_ROLES))
    #: no parameters are sent while nobody is signed in at the station
    operator_required: bool = False
    #: the operator is signed out after this long without a selection or a rundown, s
    operator_idle_s: float | None = None

    @classmethod
    def from_node(cls, node: YamlNode) -> AccessConfig:
        m = node.mapping(("users", "roles", "operator_required", "operator_idle_s"))
        # the roles written extend the defaults: a default role named there gets the rights
        # written, the others keep theirs (`roles: {lead: [skip]}` did not take away the
        # supervisor, and a user's wrong role was told against every role there is)
        roles = dict(DEFAULT_ROLES)
        for name, item in m["roles"].named("role names to their rights") \
                if "roles" in m else ():
            rights = set()
            for r in item.items():
                rights.add(Right(r.text(tuple(x.value for x in Right))))
            roles[name] = frozenset(rights)
        users = {name: _user(name, item, roles)
                 for name, item in (m["users"].named() if "users" in m else ())}
        required = m["operator_required"].flag() if "operator_required" in m else False
        if required and not users:
            raise m["operator_required"].error(
                "operator_required: true needs users in access.users (nobody could sign in "
                "to tighten)")
        idle = m["operator_idle_s"].number(lo=10.0, hi=24 * 3600.0) \
            if "operator_idle_s" in m else None
        return cls(users, roles, required, idle)

    def roles_with(self, right: Right) -> list[str]:
        """The roles that have ``right`` (whom the screens send an operator to)."""
        return sorted(name for name, rights in self.roles.items() if right in rights)

    def users_with(self, right: Right) -> list[str]:
        """The users whose role has ``right`` (whether anyone can give that command)."""
        return sorted(name for name, u in self.users.items()
                      if right in self.roles.get(u.role, frozenset()))

    def current(self, issuer: Issuer) -> Issuer | None:
        """A logged-in user as this configuration has them now: None when they were removed,
        else with the rights their role has now (a reload changes both)."""
        u = self.users.get(issuer.user)
        if u is None:
            return None
        return Issuer(u.name, self.roles.get(u.role, frozenset()), issuer.source)

    def issuer(self, user: str, password: str, source: str) -> Issuer | None:
        """The user with the rights of their role when the password is theirs, else None
        (an unknown user costs the same time as a wrong password)."""
        u = self.users.get(user)
        if not password_matches(password, u.password_hash if u is not None else None) \
                or u is None:
            return None
        return Issuer(u.name, self.roles.get(u.role, frozenset()), source)


#: what a user of ``access.users`` is written with, both required
USER_KEYS = ("role", "password")


def _user(name: str, item: YamlNode, roles: Mapping[str, frozenset[Right]]) -> User:
    """One user of ``access.users``.  Its role and its password are each checked before
    either is required: ``config check`` reads a section again without the entry it told, and
    a key left out that way is missing, which it does not tell (the user is then left out as
    a whole).  Required first, a user written ``{role: boss, password: hunter22}`` was told
    its role only, its plain-text password at the next check."""
    u = item.mapping(USER_KEYS)
    role = u["role"].text(tuple(roles)) if "role" in u else None
    stored = u["password"].text(secret=True) if "password" in u else None
    if stored is not None:
        try:
            parse_hash(stored)
        except ValueError:
            raise u["password"].error(
                "not a scrypt hash: the file keeps only the hash of a password "
                "(`stationd user hash` prints it), never the password") from None
    if role is None or stored is None:
        item.mapping(USER_KEYS, required=USER_KEYS)   # says which key is missing
    assert role is not None and stored is not None  # noqa: S101 - raised above otherwise
    return User(name, role, stored)


def password_matches(password: str, stored: str | None) -> bool:
    """Whether ``password`` is the one ``stored`` (a scrypt hash) was made from; with no hash
    (an unknown user) it is checked against a dummy one and is False: an unknown user costs
    the same time as a wrong password, so a guesser cannot tell the users' names apart."""
    return verify_password(password, stored if stored is not None else _dummy()) \
        and stored is not None


@functools.cache
def _dummy() -> str:
    """The hash an unknown user's password is checked against: made at the first login, not
    at import (a scrypt costs every command that imports this a tenth of a second)."""
    return hash_password("no such user", salt=b"stationd-dummy-salt")


@dataclass
class _Session:
    issuer: Issuer
    opened: float
    seen: float


class Sessions:
    """The screens' logged-in users, by a random token kept in an HttpOnly cookie; a
    session ends idle after ``idle_s``, and after ``max_s`` in any case."""

    def __init__(self, *, idle_s: float = SESSION_IDLE_S, max_s: float = SESSION_MAX_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.idle_s, self.max_s, self._clock = idle_s, max_s, clock
        self._open: dict[str, _Session] = {}

    def open(self, issuer: Issuer) -> str:
        now = self._clock()
        token = secrets.token_urlsafe(32)
        self._open[token] = _Session(issuer, now, now)
        return token

    def get(self, token: str | None) -> Issuer | None:
        """The session's user, or None (unknown, idle too long, too old)."""
        if not token:
            return None
        now = self._clock()
        for t, old in list(self._open.items()):   # expired ones go
            if now - old.seen > self.idle_s or now - old.opened > self.max_s:
                del self._open[t]
        s = self._open.get(token)
        if s is None:
            return None
        s.seen = now
        return s.issuer

    def close(self, token: str | None) -> None:
        self._open.pop(token or "", None)


class ReplayGuard:
    """Each command request carries a nonce this server issued (``GET /api/nonce``): one it
    never issued, one already used, or one older than ``window_s`` is refused.  The server's
    clock alone decides (a panel PC whose clock is off still works), and a captured request
    cannot be sent again."""

    def __init__(self, window_s: float = REQUEST_WINDOW_S,
                 clock: Callable[[], float] = time.monotonic, most: int = 10_000) -> None:
        self.window_s, self._clock, self._most = window_s, clock, most
        self._issued: dict[str, float] = {}
        self._spent: dict[str, float] = {}

    def issue(self) -> str:
        """A fresh nonce for one request."""
        self._forget()
        while len(self._issued) >= self._most:          # bounded: the oldest goes
            self._issued.pop(next(iter(self._issued)))
        nonce = secrets.token_urlsafe(18)
        self._issued[nonce] = self._clock()
        return nonce

    def check(self, nonce: str) -> str | None:
        """Why the request is refused, or None (then its nonce is spent)."""
        self._forget()
        if nonce in self._spent:
            return "replayed request (this nonce was used)"
        at = self._issued.pop(nonce, None)
        if at is None:
            return "stale or unknown nonce: ask GET /api/nonce for each request"
        self._spent[nonce] = self._clock()
        return None

    def _forget(self) -> None:
        now = self._clock()
        for table in (self._issued, self._spent):
            for n, t in list(table.items()):
                if now - t > self.window_s:
                    del table[n]


class LoginThrottle:
    """Wrong passwords slow a guesser down: after ``most`` failures for one user within
    ``window_s``, that user's logins are refused until the window has passed."""

    def __init__(self, most: int = 5, window_s: float = 60.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.most, self.window_s, self._clock = most, window_s, clock
        self._failed: dict[str, list[float]] = {}

    def blocked(self, user: str) -> float:
        """Seconds until ``user`` may try again (0: now)."""
        now = self._clock()
        recent = [t for t in self._failed.get(user, []) if now - t < self.window_s]
        self._failed[user] = recent
        if len(recent) < self.most:
            return 0.0
        return self.window_s - (now - recent[0])

    def failed(self, user: str) -> None:
        self._failed.setdefault(user, []).append(self._clock())
        if len(self._failed) > 10_000:                    # bounded: guessed names too
            self._failed.pop(next(iter(self._failed)))

    def passed(self, user: str) -> None:
        self._failed.pop(user, None)


__all__ = ["AccessConfig", "LoginThrottle", "ReplayGuard", "Sessions", "User", "hash_password",
           "parse_hash", "verify_password"]
