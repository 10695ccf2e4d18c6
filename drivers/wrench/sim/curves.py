"""The simulated controller's tightening curves: traces from its rundown model, written as
MID 0900 revision 1.

The model: the fastener runs down at a constant speed with a small, slightly rising
prevailing torque, meets the joint at the snug point (a third of the final angle), and from
there the torque rises linearly with the angle to the result's final torque at its final
angle, with a little seeded ripple.  So the torque-angle plot ends on the result's values,
inside the pset's limits for an OK, outside for a NOK.

Written from the specification's table (PROTOCOLS.md and the R2.x layout), apart from the
client's reader (``curve.py``): the torque trace is scaled by a coefficient (PID 02213,
the sample divided by it), the angle trace by a multiplier (PID 02214, the sample multiplied
by it), so both of the reader's ways are exercised; samples are signed 16-bit big-endian.

A trace whose message would pass 9999 bytes is sent in parts (:func:`in_parts`): the data cut
every ``part_size`` bytes (9979 by default, the most a part holds; smaller in tests, so that a
short trace comes in parts too), each piece behind a header of its own with the number of
parts (at most 9) and its part number, 1 first.

MID 0901 (plot parameters, to a session that subscribed to it) and MID 0902 (the result
store's extent, to a MID 0006 asking for it) in revision 1 as the specification's tables lay
them out (``tracedata.py`` names the sources).  The PIDs the simulator puts in a 0901 are
its own numbering (the specification's PID table for plot parameters was not at hand): the
station reads them as opaque fields and uses none.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Iterable

from drivers.wrench.sim.results import NM_PER, TIME, SimRecord

ANGLE, TORQUE = 1, 2
SAMPLES = 240                    # samples per trace
STEP_MS = 2                      # time between samples
TORQUE_COEFFICIENT = 100         # torque sample = N m x 100 (PID 02213: divide by it)
ANGLE_MULTIPLIER = "0.1"         # angle sample = tenths of a degree (PID 02214: multiply)
PART_SIZE = 9999 - 20            # the most data one message (part) carries
MAX_PARTS = 9
#: the simulator's own PIDs for a 0901's limits (not the specification's numbering)
PLOT_PIDS = {"torque_min": "90001", "torque_max": "90002", "angle_min": "90003",
             "angle_max": "90004"}
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
    """MID 0900 revision 1 (header + data, no NUL) for one trace of ``record``, whatever
    its length (:func:`in_parts` cuts one longer than a message)."""
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
    return f"{min(20 + len(data), 9999):04d}{900:04d}001         ".encode("ascii") + data


def in_parts(raw: bytes, part_size: int = PART_SIZE) -> list[bytes]:
    """``raw`` (header + data) as it goes on the wire: itself if its data fits in
    ``part_size`` bytes, else one message per ``part_size`` bytes of data, each with its
    header's number of parts and part number (bytes 19 and 20) set."""
    head, data = raw[:20], raw[20:]
    if len(data) <= part_size:
        return [raw]
    pieces = [data[i:i + part_size] for i in range(0, len(data), part_size)]
    if len(pieces) > MAX_PARTS:
        raise ValueError(f"{len(data)} bytes of data need {len(pieces)} parts of "
                         f"{part_size}: at most {MAX_PARTS}")
    return [f"{20 + len(p):04d}".encode() + head[4:18] + f"{len(pieces)}{k}".encode() + p
            for k, p in enumerate(pieces, 1)]


def _fields(items: Iterable[tuple[str, str]]) -> str:
    parts = [_field(pid, value, "02") for pid, value in items]
    return f"{len(parts):03d}" + "".join(parts)


def mid0901(record: SimRecord) -> bytes:
    """MID 0901 revision 1 for ``record``: its limits as plot parameters (the simulator's
    own PIDs, ``PLOT_PIDS``)."""
    values = {"torque_min": record.torque_min, "torque_max": record.torque_max,
              "angle_min": record.angle_min, "angle_max": record.angle_max}
    data = (f"{record.tightening_id:010d}{record.timestamp.strftime(TIME)}"
            + _fields((PLOT_PIDS[k], str(v)) for k, v in values.items()))
    return f"{20 + len(data):04d}{901:04d}001         ".encode("ascii") + data.encode()


def mid0902(capacity: int, records: list[SimRecord]) -> bytes:
    """MID 0902 revision 1: ``capacity`` and the oldest and newest of ``records`` (the
    controller's store, oldest first; zeros when it is empty)."""
    first, last = (records[0], records[-1]) if records else (None, None)
    stamp = "0000-00-00:00:00:00"
    data = (f"{capacity:010d}"
            f"{first.tightening_id if first else 0:010d}"
            f"{first.timestamp.strftime(TIME) if first else stamp}"
            f"{last.tightening_id if last else 0:010d}"
            f"{last.timestamp.strftime(TIME) if last else stamp}000")
    return f"{20 + len(data):04d}{902:04d}001         ".encode("ascii") + data.encode()
