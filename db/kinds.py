"""The kinds of rundown and the statuses of a bolt, as the records and reports spell them.

Why a module of their own: the database writes and reads them, the station's core decides
them, and the screens show them; one spelling, importable by all without the schema.

A rundown is a *tightening* or a *loosening* (the controller's result type, Open Protocol MID
0061 parameter 49, where the revision carries it; else what the station sent).  A loosening is
never a bolt done: it undoes what a tightening did.
"""

from __future__ import annotations

TIGHTENING, LOOSENING = "tightening", "loosening"
RUNDOWN_KINDS = (TIGHTENING, LOOSENING)

#: a bolt's status in a vehicle's report: its last tightening OK or NOK, never run down,
#: loosened last (to be tightened again), or to be loosened (a loosen command since its last
#: rundown: the rework a supervisor ordered is not done yet)
OK, NOK, MISSING, LOOSENED, TO_LOOSEN = "ok", "nok", "missing", "loosened", "loosen"
#: never run down because a person skipped it by a command (who and why in the report): not
#: tightened either, but not forgotten, and an export must not say it was
SKIPPED = "skipped"

__all__ = ["LOOSENED", "LOOSENING", "MISSING", "NOK", "OK", "RUNDOWN_KINDS", "SKIPPED",
           "TIGHTENING", "TO_LOOSEN"]
