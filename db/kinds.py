"""The kinds of rundown and the statuses of a bolt, as the records and reports spell them.

Why a module of their own: the database writes and reads them, the station's core decides
them, and the screens show them; one spelling, importable by all without the schema.

A rundown is a *tightening* or a *loosening* (the controller's result type, Open Protocol MID
0061 parameter 49, where the revision carries it; else what the station sent).  A loosening is
never a bolt done: it undoes what a tightening did.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from enum import StrEnum

TIGHTENING, LOOSENING = "tightening", "loosening"
RUNDOWN_KINDS = (TIGHTENING, LOOSENING)



class BoltStatus(StrEnum):
    """A bolt's status: one spelling for the records and reports, the core's events and the
    screens.  A ``str`` (stored, exported and sent as its value), so a status read back from
    a file or a column compares equal to its member."""

    #: on the vehicle at the station, not run down yet (the screens' "to do")
    PENDING = "pending"
    #: its last tightening OK or NOK
    OK = "ok"
    NOK = "nok"
    #: never run down (a vehicle's report; on an open vehicle the bolt is still to do)
    MISSING = "missing"
    #: loosened last: to be tightened again
    LOOSENED = "loosened"
    #: to be loosened (a loosen command, or the NOK policy, since its last rundown: the
    #: rework ordered is not done yet)
    TO_LOOSEN = "loosen"
    #: never run down because a person skipped it by a command (who and why in the report):
    #: not tightened either, but not forgotten, and an export must not say it was
    SKIPPED = "skipped"


OK, NOK, MISSING, LOOSENED, TO_LOOSEN = (BoltStatus.OK, BoltStatus.NOK, BoltStatus.MISSING,
                                         BoltStatus.LOOSENED, BoltStatus.TO_LOOSEN)
SKIPPED, PENDING = BoltStatus.SKIPPED, BoltStatus.PENDING


def verdict(ok: bool) -> BoltStatus:
    """The status a rundown's OK flag gives its record: one spelling wherever one is stored."""
    return OK if ok else NOK

#: an OK result without a result type (a controller revision that reports none, or a register
#: map without one) whose torque lies outside its bolt's torque window: perhaps no tightening
#: at all (a batch increment reads so at such a revision, an OK of 0 Nm), so never taken for
#: one.  Stored as a controller event under this name (``what``: 32 characters at most), its
#: bolt held until a supervisor checked it on the controller (released, or its outcome
#: entered), also after a restart
NOT_TAKEN = "untyped OK outside torque window"
#: how a held bolt's note begins for such a result (the note of a result that could not be
#: read names that result alone: "tightening 1234", "MID 0061 revision 7")
NOT_TAKEN_NOTE = "an OK result without a result type"
#: a result of a type the station does not know (MID 0061 revision 3+, parameter 49: 0, 9 or
#: more; the specification names 1-8) under a bolt's tool enable: perhaps that bolt's
#: tightening (a controller of a later specification), perhaps none.  Never taken for one,
#: never left open as if nothing was made (an MES's trial: the bolt left open, run down
#: again): stored as a controller event under this name, its bolt held as for
#: :data:`NOT_TAKEN`, published to an MES as a result not decided
UNKNOWN_TYPE_HELD = "unknown result type, not taken"
#: how a held bolt's note begins for such a result
UNKNOWN_TYPE_NOTE = "a result of a type the station does not know"
#: the controller events that are a result an MES is sent and that hold their bolt: perhaps
#: the bolt's tightening, not taken for one
HELD_WITH_RESULT = (NOT_TAKEN, UNKNOWN_TYPE_HELD)
#: a bolt locked by the NOK policy (``max_nok`` NOKs in a row), kept in the command ledger
#: under this kind (user ``station``): the lock stands until a person releases or skips the
#: bolt, whatever the policy says after a reload or a restart (a raised ``max_nok`` read back
#: from the streak alone unlocked it with no one's release)
LOCK = "lock"
#: who and what decided it, in the ledger's user and source columns
LOCK_USER, LOCK_SOURCE = "station", "NOK policy"
#: a command the station refused that would have changed a bolt or a vehicle (a skip, a
#: release, a loosen order, an entered outcome, a reopen), kept in the command ledger under
#: this kind with who gave it and why it was refused (a quality trial: an OK of 5 Nm entered
#: for a 22-28 Nm bolt, refused, was in the journal alone); it changes nothing
REFUSED = "refused"
#: an outcome a person entered for a held bolt, from the controller's screen, kept in the
#: command ledger under this kind with its rundown (``stationd.station.commands.KIND``)
ENTER_OUTCOME = "enter-outcome"
#: the link to the controller went down with the tool enabled for a bolt, and what the
#: controller did meanwhile is not known: stored as a controller event under this name
#: without a result (its note says why), the bolt held until a person checked it
CUT_UNKNOWN = "result unknown after a link cut"
#: a result fetched late because its push was lost (the link up), of the pset of an enable
#: that got no result: it may be that bolt's, which is held for a person (never taken for
#: it: other enables came between), stored as a controller event under this name
LOST_UNKNOWN = "result unknown after a lost push"
#: the station's own controller events that hold a bolt without a result
HELD_WITHOUT_RESULT = (CUT_UNKNOWN, LOST_UNKNOWN)


def not_taken_note(torque_nm: float | None, tightening_id: int | None) -> str:
    """A held bolt's note for an OK result without a type outside its torque window."""
    torque = "" if torque_nm is None else f", {torque_nm:.1f} Nm"
    which = "" if tightening_id is None else f" (tightening {tightening_id})"
    return f"{NOT_TAKEN_NOTE}{torque} outside the bolt's torque window{which}"


def unknown_type_note(result_type: int | None, tightening_id: int | None) -> str:
    """A held bolt's note for a result of a type the station does not know."""
    which = [f"type {result_type}"] if result_type is not None else []
    which += [f"tightening {tightening_id}"] if tightening_id is not None else []
    return f"{UNKNOWN_TYPE_NOTE} ({', '.join(which)})" if which else UNKNOWN_TYPE_NOTE


def unreadable_note(tightening_id: int | None, mid: int, revision: int) -> str:
    """A held bolt's note for a result that could not be read: which result, by its
    tightening id (the controller's number for every rundown, a loosening's too), else by
    its MID and revision."""
    return f"tightening {tightening_id}" if tightening_id is not None \
        else message_words(mid, revision)


def message_words(mid: int, revision: int) -> str:
    """What an unreadable result came as: ``MID 0061 revision 7``; a register-driven
    controller's (MID 0: no message, its result registers) says so."""
    return f"MID {mid:04d} revision {revision}" if mid else "result registers"


#: how the notes of a hold without a result read (:func:`cut_unknown_note`,
#: :func:`lost_unknown_note`): what the words of a hold tell from a result not read
CUT_NOTE_HEAD = "its result during the link cut not known"
LOST_NOTE_MARK = " may be its own (its push lost, fetched later;"
GAP_NOTE_MARK = "not given by the controller)"
#: the head of a held bolt's note where the controller's newest result could not be read as
#: its enable's late-result window ended (:func:`check_unknown_note`)
CHECK_NOTE_HEAD = "its result not known: the controller's newest result not read as its " \
    "late-result window ended"


def is_unknown_note(note: str | None) -> bool:
    """Whether a held bolt's note is a hold without a result (a link cut's, a lost push's):
    its result was never in hand, not one that could not be read."""
    return note is not None and (note.startswith((CUT_NOTE_HEAD, CHECK_NOTE_HEAD))
                                 or LOST_NOTE_MARK in note or GAP_NOTE_MARK in note)


def cut_unknown_note(why: str, pset: int | None = None, enabled_at: float | None = None
                     ) -> str:
    """A held bolt's note where the tool was enabled for it (with ``pset``, at
    ``enabled_at``, epoch seconds) when the link to the controller went down, and what the
    controller did meanwhile is not known (``why``).  The pset and the time are what the
    supervisor looks for in the controller's result list (a supervisor's trial: the note
    said neither)."""
    note = f"{CUT_NOTE_HEAD}: {why}"
    if enabled_at is None:
        return note
    at = datetime.fromtimestamp(enabled_at, UTC).strftime("%Y-%m-%d %H:%M:%S")
    return note + f"; the tool was enabled{'' if pset is None else f' for pset {pset}'} " \
        f"at {at} UTC"


def lost_unknown_note(tightening_id: int, pset: int | None, enabled_at: float) -> str:
    """A held bolt's note where a result whose push was lost (``tightening_id``, fetched
    later) is of the pset of its enable (with ``pset`` at ``enabled_at``, epoch seconds) that
    got no result: it may be its own."""
    at = datetime.fromtimestamp(enabled_at, UTC).strftime("%Y-%m-%d %H:%M:%S")
    return (f"tightening {tightening_id}{LOST_NOTE_MARK} other "
            f"enables came between); the tool was enabled"
            f"{'' if pset is None else f' for pset {pset}'} at {at} UTC")


#: the mark of a held bolt's note where a result of another pset came (:func:`other_pset_note`)
OTHER_PSET_MARK = " while its tool was on for pset "


def other_pset_note(tightening_id: int, pset: int, sent: int) -> str:
    """A held bolt's note where a result of another pset (``pset``) than the one sent for it
    (``sent``) came while its tool was on: a rundown with another program, or none of it."""
    return (f"tightening {tightening_id} came under pset {pset}{OTHER_PSET_MARK}{sent}: run "
            "with another program, or not its own")


def check_unknown_note(why: str, pset: int | None, enabled_at: float) -> str:
    """A held bolt's note where its enable (with ``pset`` at ``enabled_at``, epoch seconds)
    got no result in its window and the controller's newest result could not be read then
    (``why``): a rundown whose push was lost may be its own, and nothing else will ask (a
    reviewer: the bolt left open, the tool went on for it again, tightened twice)."""
    at = datetime.fromtimestamp(enabled_at, UTC).strftime("%Y-%m-%d %H:%M:%S")
    return (f"{CHECK_NOTE_HEAD} ({why}): a rundown whose push was lost may be its own; the "
            f"tool was enabled{'' if pset is None else f' for pset {pset}'} at {at} UTC")


def id_span(first: int | None, last: int | None) -> str:
    """Tightening ids from ``first`` to ``last``: ``70061`` or ``70061-70062`` (a gap's, as
    a hold's note and the journal name them)."""
    return str(first) if last is None or first == last else f"{first}-{last}"


def lost_gap_note(span: str, pset: int | None, enabled_at: float) -> str:
    """A held bolt's note where tightenings whose pushes were lost (``span``: "7" or "7-8")
    could not be fetched (the controller no longer has them, or gives none), made after the
    last result heard, and the bolt's enable (with ``pset`` at ``enabled_at``) got no result
    in its window: its own may be among them."""
    at = datetime.fromtimestamp(enabled_at, UTC).strftime("%Y-%m-%d %H:%M:%S")
    which = f"among tightenings {span} (their pushes" if "-" in span \
        else f"tightening {span} (its push"
    return (f"its result may be {which} lost, {GAP_NOTE_MARK}; the tool was enabled"
            f"{'' if pset is None else f' for pset {pset}'} at {at} UTC")


def lost_unknown_id(note: str | None) -> int | None:
    """The tightening id a lost push's hold names (:func:`lost_unknown_note`: the result,
    stored unattributed, that may be the bolt's own, so that the bolt may be tightened
    already); None for the note of another hold."""
    if note is None or LOST_NOTE_MARK not in note:
        return None
    word, _, tid = note.split(LOST_NOTE_MARK, 1)[0].partition(" ")
    return int(tid) if word == "tightening" and tid.isdigit() else None


#: how a link cut's hold says the result it names may be its bolt's own (:func:`cut_own_why`,
#: :func:`ran_again_why`; read back by :func:`held_result_id`)
MAY_BE_ITS_OWN = "may be its own"
#: how :func:`ran_again_why` says a rundown of the pset sent came after the cut's
RAN_AGAIN_OF_ITS_PSET = " of its pset made during the link cut after its rundown "


def cut_own_why(tightening_id: int, why: str) -> str:
    """Why a link cut's bolt is held for tightening ``tightening_id`` (stored unattributed),
    of the pset sent: it may be its own (``why``: the rest, "(not proved by the controller's
    data)", "or B05's, made during the link cut and sent late ...")."""
    return f"tightening {tightening_id} {MAY_BE_ITS_OWN} {why}"


def ran_again_why(tightening_id: int, what: str, pset: int | None, after: int) -> str:
    """Why a link cut's bolt is held for tightening ``tightening_id``, ``what`` ("a
    rundown", "a loosening") fetched after the cut's proved rundown ``after``: the tool ran
    again during the cut (``pset``: another program's, None: the pset sent)."""
    which = RAN_AGAIN_OF_ITS_PSET if pset is None \
        else f" of pset {pset} made during the link cut after its rundown "
    return (f"tightening {tightening_id}, {what}{which}{after}, {MAY_BE_ITS_OWN} again or "
            "another bolt's")


def held_result_id(note: str | None) -> int | None:
    """The tightening id a hold names as the result, stored unattributed, that may be the
    bolt's own (so the bolt may be tightened already): a lost push's
    (:func:`lost_unknown_id`), or a link cut's of the pset sent (:func:`cut_own_why`,
    :func:`ran_again_why` of its pset: a supervisor's trial, the release said nothing of the
    OK stored, and the joint was tightened twice); None for the note of another hold."""
    found = lost_unknown_id(note)
    if found is not None or note is None or not note.startswith(CUT_NOTE_HEAD + ": "):
        return found
    word, _, rest = note[len(CUT_NOTE_HEAD) + 2:].partition(" ")
    tid, _, tail = rest.partition(" ")
    tid = tid.rstrip(",")
    same = tail.startswith(MAY_BE_ITS_OWN) or RAN_AGAIN_OF_ITS_PSET in tail
    return int(tid) if word == "tightening" and tid.isdigit() and same else None


def loosening_note(note: str, pset: int | None) -> str:
    """A held bolt's note (``note``: which result) where that result came under the bolt's
    loosen pset: the person who reads it on the controller and enters its outcome is told it
    was a loosening (an OK of it is the bolt loosened, never tightened)."""
    return f"{note}, a loosening" + (f" with loosen pset {pset}" if pset is not None else "")


@dataclass(frozen=True)
class HeldUnder:
    """What a held bolt's result came under, as the records tell it after a reload or a
    restart.  ``loosen``: the tool enable it answered was the bolt's loosen pset (the
    selection stored with the enable says so; None: no enable found for it).  ``pset``: that
    enable's pset, else the result's own as far as it could be read (None: neither).

    Why: an outcome a person enters for the bolt is that result's, a loosening's where the
    loosen pset ran: entered as a tightening, an OK would close a bolt that was only
    loosened."""

    loosen: bool | None = None
    pset: int | None = None


def is_not_taken_note(note: str | None) -> bool:
    """Whether a held bolt's note is a result read but not taken for a tightening (an OK
    without a type outside its window, a type the station does not know, one of another
    pset than the one sent; else: a result not read)."""
    return note is not None and (note.startswith((NOT_TAKEN_NOTE, UNKNOWN_TYPE_NOTE))
                                 or OTHER_PSET_MARK in note)


__all__ = [
    "CHECK_NOTE_HEAD",
    "CUT_NOTE_HEAD",
    "CUT_UNKNOWN",
    "GAP_NOTE_MARK",
    "HELD_WITHOUT_RESULT",
    "HELD_WITH_RESULT",
    "LOOSENED",
    "LOOSENING",
    "LOST_NOTE_MARK",
    "LOST_UNKNOWN",
    "MAY_BE_ITS_OWN",
    "MISSING",
    "NOK",
    "NOT_TAKEN",
    "NOT_TAKEN_NOTE",
    "OK",
    "OTHER_PSET_MARK",
    "PENDING",
    "RAN_AGAIN_OF_ITS_PSET",
    "RUNDOWN_KINDS",
    "SKIPPED",
    "TIGHTENING",
    "TO_LOOSEN",
    "UNKNOWN_TYPE_HELD",
    "UNKNOWN_TYPE_NOTE",
    "BoltStatus",
    "HeldUnder",
    "check_unknown_note",
    "cut_own_why",
    "cut_unknown_note",
    "held_result_id",
    "id_span",
    "is_not_taken_note",
    "is_unknown_note",
    "loosening_note",
    "lost_gap_note",
    "lost_unknown_id",
    "lost_unknown_note",
    "not_taken_note",
    "ran_again_why",
    "unknown_type_note",
    "unreadable_note",
]
