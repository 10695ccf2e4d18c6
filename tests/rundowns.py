"""Whole controller results for the tests of the station's core and shell.

Why one maker: the core reads a result's fields as the driver types them (no ``getattr``
with a default), so a test feeds it what a driver would, a :class:`TighteningResult`, not a
namespace with the fields the test thought of."""

from __future__ import annotations

from datetime import datetime

from drivers.wrench.base import ResultType, Status, TighteningResult, TorqueUnit

#: a result's controller time unless a test names one (the controller's naive local clock)
MADE_AT = datetime(2026, 11, 29, 8, 0, 0)


def rundown(tid: int, pset: int, ok: bool = True, *, code: int | None = None,
            rtype: int | None = None, torque_nm: float = 12.0, angle_deg: float = 30.0,
            vin: str = "", when: datetime | None = None, unit: TorqueUnit | None = None,
            clock: bool = True) -> TighteningResult:
    """Result ``tid`` of ``pset``: OK or NOK (its torque LOW), of the type ``code`` (the
    raw type code, MID 0061 parameter 49) or ``rtype`` (a :class:`ResultType`), neither for
    a revision without types; limits around the torque and angle."""
    return TighteningResult(
        ok, torque_nm, angle_deg, Status.OK if ok else Status.LOW, Status.OK, tid, pset, vin,
        when or MADE_AT, torque_nm - 2.0, torque_nm + 2.0, torque_nm, angle_deg - 10.0,
        angle_deg + 10.0, angle_deg, result_type=None if rtype is None else ResultType(rtype),
        result_type_code=code, torque_unit=unit, controller_clock=clock)
