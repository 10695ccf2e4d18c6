"""Commands people give the station: typed, with who gave them and from where.

Why typed and through the core: a command (skip a bolt, reopen a vehicle for rework, and the
release, loosen and teach that the process features add) changes what the station will do;
only the core's rules may decide it, on the same path as a device's event, and its answer
(accepted, or refused with a typed :class:`~stationd.reasons.Reason`) goes back to the person.
Authentication is the edge's (the screens' sessions, the command line's password): a command
arrives here with the user's name and the rights of their role, and the core checks the right
the command needs.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from stationd.reasons import Reason


class Right(enum.Enum):
    """What a role may do (``access.roles`` in the station file)."""

    SKIP = "skip"
    REOPEN = "reopen"
    RELEASE = "release"
    LOOSEN = "loosen"
    TEACH = "teach"


@dataclass(frozen=True)
class Issuer:
    """Who gave a command, with the rights of their role, and from where (``screen
    10.0.0.7``, ``cli``)."""

    user: str
    rights: frozenset[Right]
    source: str


@dataclass(frozen=True)
class SkipBolt:
    """Do not tighten ``bolt`` of ``vin`` at this station (it stays missing in the report):
    the operator cannot reach it, a part is missing; ``comment`` says why."""

    vin: str
    bolt: str
    comment: str = ""


@dataclass(frozen=True)
class ReopenVehicle:
    """Reopen the closed vehicle ``vin`` for rework (its records kept)."""

    vin: str
    comment: str = ""


@dataclass(frozen=True)
class ReleaseBolt:
    """Unlock ``bolt`` of ``vin``, locked after too many NOKs in a row (the NOK policy's
    ``max_nok``): it may be tightened again; ``comment`` says why (a supervisor's decision)."""

    vin: str
    bolt: str
    comment: str = ""


Command = SkipBolt | ReopenVehicle | ReleaseBolt

#: the right each command needs
RIGHT: dict[type[Command], Right] = {SkipBolt: Right.SKIP, ReopenVehicle: Right.REOPEN,
                                     ReleaseBolt: Right.RELEASE}
#: the name each command has on the wire (HTTP, the command line) and in the records
KIND: dict[type[Command], str] = {SkipBolt: "skip", ReopenVehicle: "reopen",
                                  ReleaseBolt: "release"}


def skip_note(user: str, comment: str) -> str:
    """Why a skipped bolt is not tightened, as the matcher keeps it."""
    return f"{user}'s command" + (f" ({comment})" if comment else "")


@dataclass(frozen=True)
class Answer:
    """The core's answer to one command: accepted (``reason`` None) or refused with why."""

    request: int
    command: Command
    issuer: Issuer
    reason: Reason | None = None

    @property
    def accepted(self) -> bool:
        return self.reason is None


__all__ = ["KIND", "RIGHT", "Answer", "Command", "Issuer", "ReleaseBolt", "ReopenVehicle",
           "Right", "SkipBolt", "skip_note"]
