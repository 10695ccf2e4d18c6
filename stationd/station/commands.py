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
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from stationd.reasons import Reason


class Right(enum.Enum):
    """What a role may do (``access.roles`` in the station file)."""

    SKIP = "skip"
    REOPEN = "reopen"
    RELEASE = "release"
    LOOSEN = "loosen"
    TEACH = "teach"
    CALIBRATE = "calibrate"


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


@dataclass(frozen=True)
class EnterOutcome:
    """Resolve ``bolt`` of ``vin``, held because the controller's result could not be read,
    with the outcome a person read on the controller's own screen: ``ok`` (else NOK), its
    ``torque_nm`` and ``angle_deg``.  Recorded as a rundown of its own provenance (entered by
    the user, not measured by the station); OK closes the bolt, NOK counts as a NOK result
    under the NOK policy.  Needs the release right: it is the other way to end a hold;
    ``comment`` says what was checked.  ``loosening`` and ``loosen_pset``: filled in by the
    core when it accepts the command, where the held result came under the bolt's loosen
    pset (that pset, where known): the outcome is then a loosening's, recorded as one (an OK
    loosens the bolt, its tightening pset goes next; a NOK counts as a loosening NOK), never
    a tightening's."""

    vin: str
    bolt: str
    ok: bool
    torque_nm: float
    angle_deg: float
    comment: str = ""
    loosening: bool = False
    loosen_pset: int | None = None


@dataclass(frozen=True)
class LoosenBolt:
    """Reopen ``bolt`` of ``vin`` for rework by loosening it: the bolt is no longer done and
    gets its loosen pset (the NOK policy's ``loosen_pset``) the next time the wrench is on
    it, then its tightening pset again; ``comment`` says why.  Loosening is a right, not a
    free reverse switch: a tightened joint undone without it would pass as tightened."""

    vin: str
    bolt: str
    comment: str = ""


@dataclass(frozen=True)
class TeachStart:
    """Start teach mode for vehicle model ``model``: the normal cycle is off (the tool stays
    off, nothing is sent) while an engineer holds the tool on each bolt in turn."""

    model: str
    comment: str = ""


@dataclass(frozen=True)
class TeachPoint:
    """Measure the bolt end the tool is on now as ``bolt``'s position: the answer carries the
    mean of several steady localizations and their dispersion."""

    bolt: str
    comment: str = ""


@dataclass(frozen=True)
class TeachStop:
    """End teach mode: the normal cycle resumes."""

    comment: str = ""


@dataclass(frozen=True)
class CheckCalibration:
    """Check every pair against the reference markers now (the cameras' calibration check):
    the answer carries each pair's verdict."""

    comment: str = ""


@dataclass(frozen=True)
class SignIn:
    """The issuing user signs in at the station as its operator (the shift's operator: a
    badge, a login): every rundown from now on is recorded with their name, until they sign
    out, another operator signs in or the station's idle time-out ends it.  Any configured
    user may sign themselves in: it grants no right, it says who holds the tool."""

    comment: str = ""


@dataclass(frozen=True)
class SignOut:
    """Nobody is signed in at the station any more (whoever was: ``user``, filled in by the
    core when it accepts the command, so the record names who was signed out).  ``idle_s``:
    the station's own sign-out of an operator idle that long (``comment`` empty: the record's
    comment is its words, :func:`stationd.words.comment_words`, written by the shell)."""

    comment: str = ""
    user: str | None = None
    idle_s: float | None = None


Command = (SkipBolt | ReopenVehicle | ReleaseBolt | EnterOutcome | LoosenBolt | TeachStart
           | TeachPoint | TeachStop | CheckCalibration | SignIn | SignOut)

#: the right each command needs (signing in and out need none: any configured user)
RIGHT: dict[type[Command], Right] = {SkipBolt: Right.SKIP, ReopenVehicle: Right.REOPEN,
                                     ReleaseBolt: Right.RELEASE, LoosenBolt: Right.LOOSEN,
                                     EnterOutcome: Right.RELEASE,
                                     TeachStart: Right.TEACH,
                                     TeachPoint: Right.TEACH, TeachStop: Right.TEACH,
                                     CheckCalibration: Right.CALIBRATE}
#: the name each command has on the wire (HTTP, the command line) and in the records
KIND: dict[type[Command], str] = {SkipBolt: "skip", ReopenVehicle: "reopen",
                                  ReleaseBolt: "release", LoosenBolt: "loosen",
                                  EnterOutcome: "enter-outcome",
                                  TeachStart: "teach-start",
                                  TeachPoint: "teach-point", TeachStop: "teach-stop",
                                  CheckCalibration: "calibration-check",
                                  SignIn: "sign-in", SignOut: "sign-out"}
#: the kinds of command that change a bolt's verdict, given only with their reason (their
#: comment; a quality trial: a NOK bolt released with no word of why): the command line and
#: the screens' API both refuse one without it
WITH_REASON = frozenset(KIND[c] for c in (SkipBolt, ReleaseBolt, LoosenBolt))


@dataclass(frozen=True)
class Answer:
    """The core's answer to one command: accepted (``reason`` None) or refused with why."""

    request: int
    command: Command
    issuer: Issuer
    reason: Reason | None = None
    result: Mapping[str, Any] | None = None   # what a command measured (a taught point)

    @property
    def accepted(self) -> bool:
        return self.reason is None


__all__ = ["KIND", "RIGHT", "WITH_REASON", "Answer", "CheckCalibration", "Command",
           "EnterOutcome", "Issuer", "LoosenBolt", "ReleaseBolt", "ReopenVehicle", "Right",
           "SignIn", "SignOut", "SkipBolt", "TeachPoint", "TeachStart", "TeachStop"]
