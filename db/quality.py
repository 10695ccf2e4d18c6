"""Quality figures from the records: process capability (Cp, Cpk) of torque and angle per bolt
and pset on every measured tightening (OK and NOK), and the NOK rate per day.

Why here: quality engineers asked for them and computed them elsewhere from CSV exports; the
records already hold every value and the limits that applied (the parameter version sent), so
the figures come from one query.  Cp = (USL - LSL) / 6 sigma, Cpk = min(USL - mean, mean -
LSL) / 3 sigma (sample standard deviation); a group with fewer than ``MIN_N`` results, or no
spread, has no figure (None), not a misleading one.  Why NOKs too: the process made them; on
the OK results alone (cut at the limits) a quality engineer's trial read a Cpk of 1.91 for a
bolt whose every measured tightening gave 0.32.  An outcome a person entered is no
measurement: counted apart, never in the figures.

Each group also carries its last ``LAST_N`` results, OK and NOK, and the limits in force
(min, target, max of torque and angle): the screen plots them, because a figure alone hides a
drift towards a limit or a run of NOKs that the eye sees at once.
"""

from __future__ import annotations

import math
from collections import defaultdict, deque
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.kinds import NOK, OK, TIGHTENING
from db.models import Bolt, ProcessParameters, TighteningRecord, Vehicle, VehicleModel

MIN_N = 5    # fewer results than this give no capability figure
LAST_N = 30  # results per group for the screen's plot


def capability(values: list[float], lo: float | None, hi: float | None) -> dict[str, Any]:
    """n, mean, sigma, Cp and Cpk of ``values`` against [lo, hi] (None where not defined)."""
    n = len(values)
    out: dict[str, Any] = {"n": n, "mean": None, "sigma": None, "cp": None, "cpk": None,
                           "lsl": lo, "usl": hi}
    if n == 0:
        return out
    mean = sum(values) / n
    out["mean"] = mean
    if n < MIN_N:
        return out
    sigma = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    out["sigma"] = sigma
    if sigma <= 0 or lo is None or hi is None:
        return out
    out["cp"] = (hi - lo) / (6 * sigma)
    out["cpk"] = min(hi - mean, mean - lo) / (3 * sigma)
    return out


def _limits(lo: float | None, target: float | None, hi: float | None) -> dict[str, Any]:
    return {"min": lo, "target": target, "max": hi}


def _point(rec: TighteningRecord) -> dict[str, Any]:
    """One result for the plot: its values, OK or not, and when it was recorded (UTC, ISO)."""
    return {"torque": None if rec.torque_nm is None else float(rec.torque_nm),
            "angle": None if rec.angle_deg is None else float(rec.angle_deg),
            "ok": rec.status == OK, "at": rec.recorded_at.isoformat(),
            "entered": rec.entered_by is not None}


def spc(s: Session, model: str | None = None, since: datetime | None = None,
        last: int = LAST_N) -> dict[str, Any]:
    """Per bolt and pset (every tightening measured, OK and NOK): torque and angle capability,
    the group's
    last ``last`` results (OK and NOK, oldest first; each says whether it was entered by a
    person) and its limits, the OKs entered (counted apart: not measured); per day: results
    and NOK rate (entered ones too: they are outcomes)."""
    q = (select(TighteningRecord, Bolt.code, VehicleModel.name, ProcessParameters)
         .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
         .join(Vehicle, TighteningRecord.vehicle_id == Vehicle.id)
         .join(VehicleModel, Vehicle.model_id == VehicleModel.id)
         .join(ProcessParameters, TighteningRecord.parameters_id == ProcessParameters.id)
         # tightenings only: a loosening is judged by its loosen program, not these limits
         .where(TighteningRecord.kind == TIGHTENING)
         .order_by(TighteningRecord.recorded_at, TighteningRecord.id))
    if model is not None:
        q = q.where(VehicleModel.name == model)
    if since is not None:
        q = q.where(TighteningRecord.recorded_at >= since)
    # a group per bolt, pset and the limits in force (min, target, max): a parameter change
    # starts a new one, so a plot never mixes results tightened against different limits
    groups: dict[tuple[Any, ...], dict[str, Any]] = {}
    days: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    for rec, bolt, mname, p in s.execute(q):
        day = rec.recorded_at.date().isoformat()
        days[day][0] += 1
        days[day][1] += rec.status == NOK
        limits = (p.torque_min, p.torque_target, p.torque_max,
                  p.angle_min, p.angle_target, p.angle_max)
        g = groups.setdefault((mname, bolt, p.pset, *limits), {
            "torque": [], "angle": [], "limits": limits, "nok": 0, "entered": 0,
            "entered_nok": 0,
            "version": p.version,
            "last": deque(maxlen=max(0, last))})
        g["last"].append(_point(rec))
        g["nok"] += rec.status != OK
        if rec.entered_by is not None:
            # typed in by a person from the controller's screen (its result could not be
            # read): counted, never measured: not in the capability (a new user's trial: an
            # entered 106.7 Nm in a bolt's mean)
            g["entered"] += rec.status == OK
            g["entered_nok"] += rec.status != OK   # in "nok", said apart (not in n)
            continue
        if rec.torque_nm is not None:
            g["torque"].append(float(rec.torque_nm))
        if rec.angle_deg is not None:
            g["angle"].append(float(rec.angle_deg))
    rows = []
    for key, g in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2] or 0,
                                                             kv[1]["version"])):
        mname, bolt, pset = key[:3]
        t_lo, t_aim, t_hi, a_lo, a_aim, a_hi = g["limits"]
        rows.append({"model": mname, "bolt": bolt, "pset": pset, "nok": g["nok"],
                     "entered_ok": g["entered"], "entered_nok": g["entered_nok"],
                     "parameter_version": g["version"],
                     "torque": capability(g["torque"], t_lo, t_hi),
                     "angle": capability(g["angle"], a_lo, a_hi),
                     "limits": {"torque": _limits(t_lo, t_aim, t_hi),
                                "angle": _limits(a_lo, a_aim, a_hi)},
                     "last": list(g["last"])})
    trend = [{"day": d, "results": n, "nok": k, "nok_rate": k / n if n else None}
             for d, (n, k) in sorted(days.items())]
    return {"bolts": rows, "trend": trend}


__all__ = ["LAST_N", "MIN_N", "capability", "spc"]
