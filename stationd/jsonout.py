"""Strict JSON for every command's ``--json`` output.

Why: ``json.dumps`` writes ``NaN`` and ``Infinity`` by default, which is not JSON; strict
readers (jq, JavaScript, most languages' parsers) refuse the whole line.  A value that does not
exist is ``null`` instead, and ``allow_nan=False`` makes one missed here an error in the tests
rather than invalid output in the field.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def strict_json(obj: Any) -> str:
    """One line of strict JSON; non-finite floats (also inside lists and dicts) become null."""
    return json.dumps(finite(obj), allow_nan=False)


def finite(obj: Any) -> Any:
    """``obj`` with every NaN or infinite float replaced by ``None`` (numpy scalars and
    arrays converted to plain values)."""
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    if isinstance(obj, np.generic):
        return finite(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    return obj
