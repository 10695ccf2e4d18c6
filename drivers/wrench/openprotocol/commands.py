"""The station's commands as Open Protocol messages: select a parameter set (MID 0018),
enable or disable the tool (0043/0042), download the vehicle's identifier (0050).  Pure, no
I/O: each is sent as a command (``Channel.command``: it returns on its MID 0005).

Why apart: what a command says on the wire, and what it is called when it fails ("select
pset 3: ..."), is the protocol's business; waiting for its answer is the channel's.
"""

from __future__ import annotations

from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.message import Message

VIN_LENGTH = 25        # MID 0050 revision 1 carries a 25-character VIN


def select_pset(pset: int) -> tuple[Message, str]:
    """MID 0018 for parameter set ``pset`` (0-999, checked by the caller), and its name."""
    return Message(op.MID_PSET_SELECT, data=f"{pset:03d}".encode()), f"select pset {pset}"


def set_tool(enabled: bool) -> tuple[Message, str]:
    """MID 0043 (enable) or 0042 (disable), and its name."""
    if enabled:
        return Message(op.MID_TOOL_ENABLE), "enable tool"
    return Message(op.MID_TOOL_DISABLE), "disable tool"


def send_vin(vin: str) -> tuple[Message, str]:
    """MID 0050 with ``vin`` padded to its 25 characters, and its name; ValueError for a VIN
    that does not fit (longer, or not printable ASCII)."""
    if len(vin) > VIN_LENGTH or not vin.isascii() or not vin.isprintable():
        raise ValueError(f"VIN must be printable ASCII, at most {VIN_LENGTH} characters: "
                         f"{vin!r}")
    return (Message(op.MID_VIN, data=vin.ljust(VIN_LENGTH).encode("ascii")),
            f"send VIN {vin}")
