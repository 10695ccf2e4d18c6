"""The simulated controller's tightening curves: traces from its rundown model, written as
MID 0900 revision 1.

The model: the fastener runs down at a constant speed with a small, slightly rising
prevailing torque, meets the joint at the snug point (a third of the final angle), and from
there the torque rises linearly with the angle to the result's final torque at its final
angle, with a little seeded ripple.  So the torque-angle plot ends on the result's values,
inside the pset's limits for an OK, outside for a NOK.

Written from the specification's table (PROTOCOLS.md and the R2.x layout), apart from the
client's reader (``op_curve.py``): the torque trace is scaled by a coefficient (PID 02213,
the sample divided by it), the angle trace by a multiplier (PID 02214, the sample multiplied
by it), so both of the reader's ways are exercised; samples are signed 16-bit big-endian.
"""

from __future__ import annotations

import random
import struct

from drivers.wrench.sim_results import NM_PER, TIME, SimRecord

ANGLE, TORQUE = 1, 2
SAMPLES = 240                    # samples per trace
STEP_MS = 2                      # time between samples
TORQUE_COEFFICIENT = 100         # torque sample = N m x 100 (PID 02213: divide by it)
ANGLE_MULTIPLIER = "0.1"         # angle sample = tenths of a degree (PID 02214: multiply)
SNUG = 1 / 3                     # the snug point, as a fraction of the final angle
PREVAIL = 0.04                   # the prevailing torque, as a fraction of the final torque


def trace(record: SimRecord, samples: int = SAMPLES) -> tuple[list[float], list[float]]:
    """(angle in degrees, torque in N m) at each sample of ``record``'s rundown."""
    final_t = record.torque / 100 * NM_PER.get(record.torque_unit, 1.0)
    final_a = max(record.angle_exact, 1.0)
    rng = random.Random(record.tightening_id)  # noqa: S311 - simulation ripple, seeded
    snug_a, snug_t = final_a * SNUG, final_t * PREVAIL * 2
    angles, torques = [], []
    for i in range(samples):
        a = final_a * i / (samples - 1)
        if a <= snug_a:
            t = final_t * PREVAIL + (snug_t - final_t * PREVAIL) * a / snug_a
        else:
            t = snug_t + (final_t - snug_t) * (a - snug_a) / (final_a - snug_a)
        if 0 < i < samples - 1:
            t += rng.gauss(0.0, final_t * 0.006)
        angles.append(a)
        torques.append(max(t, 0.0))
    return angles, torques


def _field(pid: str, value: str, dtype: str = "03", unit: str = "000") -> str:
    return f"{pid}{len(value):03d}{dtype}{unit}0000{value}"


def mid0900(record: SimRecord, trace_type: int, samples: int = SAMPLES) -> bytes:
    """MID 0900 revision 1 (header + data, no NUL) for one trace of ``record``."""
    angles, torques = trace(record, samples)
    if trace_type == TORQUE:
        unit, scale = "001", _field("02213", str(TORQUE_COEFFICIENT))
        raw = [round(t * TORQUE_COEFFICIENT) for t in torques]
    elif trace_type == ANGLE:
        unit, scale = "050", _field("02214", ANGLE_MULTIPLIER)
        raw = [round(a / float(ANGLE_MULTIPLIER)) for a in angles]
    else:
        raise ValueError(f"the simulator makes angle (1) and torque (2) traces, not {trace_type}")
    raw = [min(max(v, -32768), 32767) for v in raw]
    pids = [_field("01000", f"{record.pset:03d}", "01")]      # the pset, as controllers add
    ascii_part = (
        f"{record.tightening_id:010d}{record.timestamp.strftime(TIME)}"
        f"{len(pids):03d}{''.join(pids)}"
        f"{trace_type:02d}01{unit}"                           # trace type, transducer, unit
        f"001{scale}"                                         # parameter data fields
        f"001{1:05d}{samples:05d}{len(str(STEP_MS)):03d}01202{STEP_MS}"   # resolution (ms)
        f"{samples:05d}")
    data = ascii_part.encode("ascii") + b"\x00" + struct.pack(f">{samples}h", *raw)
    return f"{20 + len(data):04d}{900:04d}001         ".encode("ascii") + data
