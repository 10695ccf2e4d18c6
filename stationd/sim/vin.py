"""Vehicle identification numbers for the simulated line: 17 characters as ISO 3779 writes
them, with the check digit (position 9) that North American VINs carry.

Why real ones: an MES, a line database or a controller that takes a VIN checks its length and
alphabet (no I, O or Q); the demo's vehicles must pass what a plant's systems would demand.
"""

from __future__ import annotations

#: the letters a VIN may use (I, O and Q are never used: they read as 1 and 0)
ALPHABET = "ABCDEFGHJKLMNPRSTUVWXYZ0123456789"
_VALUES = {**{str(d): d for d in range(10)},
           **dict(zip("ABCDEFGH", range(1, 9), strict=True)),
           **dict(zip("JKLMN", range(1, 6), strict=True)), "P": 7, "R": 9,
           **dict(zip("STUVWXYZ", range(2, 10), strict=True))}
_WEIGHTS = (8, 7, 6, 5, 4, 3, 2, 10, 0, 9, 8, 7, 6, 5, 4, 3, 2)
#: a world manufacturer identifier no maker uses ("9" region, letters of this project)
WMI = "9SD"


def check_digit(vin: str) -> str:
    """The check character of a 17-character VIN (its position 9 is ignored)."""
    if len(vin) != 17 or any(c not in ALPHABET for c in vin.upper()):
        raise ValueError(f"not a 17-character VIN: {vin!r}")
    total = sum(_VALUES[c] * w for c, w in zip(vin.upper(), _WEIGHTS, strict=True))
    r = total % 11
    return "X" if r == 10 else str(r)


def is_valid(vin: str) -> bool:
    """Whether ``vin`` has 17 characters of the VIN alphabet and its check digit."""
    try:
        return check_digit(vin) == vin[8]
    except ValueError:
        return False


def make_vin(serial: int, *, model: str = "ST001", year: str = "T", plant: str = "L") -> str:
    """The ``serial``-th vehicle's VIN: WMI, a 5-character model descriptor, the check digit,
    model year, plant and a 6-digit serial number."""
    if not 0 <= serial <= 999_999:
        raise ValueError(f"a serial number has 6 digits, not {serial}")
    body = f"{WMI}{model.upper():<5.5}0{year}{plant}{serial:06d}"
    return body[:8] + check_digit(body) + body[9:]


__all__ = ["ALPHABET", "WMI", "check_digit", "is_valid", "make_vin"]
