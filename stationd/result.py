"""The one failure value shared by every stage that can decline to give a result.

A failure is a value with a reason (``Refusal``), never an exception and never ``None``: the
vision, the geometry, the localization and the station all return it, and the station logs the
reason and sends nothing.  This module is a leaf: it imports nothing of the station but its
reasons.
"""

from __future__ import annotations

from dataclasses import dataclass

from stationd.reasons import Reason


@dataclass(frozen=True)
class Refusal:
    """Why a stage gave no result.  Falsy, so ``if not result:`` reads naturally.  ``why``:
    the typed reason where the station acts on its kind (a tilt, pairs that disagree)."""

    reason: str
    why: Reason | None = None
    side: str = ""          # the camera that said it, where one did ("left", "right")

    def __bool__(self) -> bool:
        return False
