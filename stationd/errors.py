"""One exception hierarchy for the whole station.

Commands turn a :class:`StationError` into one readable line on stderr and exit code 2;
the daemon turns it into a fault state.  Vision failures are *not* exceptions: a detection
that does not find the marker is a value that carries its reason (see ``vision.types``).
"""

from __future__ import annotations


class StationError(Exception):
    """Base of every error the station reports to a person."""


class InputError(StationError):
    """Bad input: a file that is missing, unreadable, malformed or out of range."""


def printable(text: str, keep: str = "") -> str:
    """``text`` with every character a terminal would act on (ESC, BEL, NUL, a bidirectional
    override...) written as its escape (``\\x1b``), ``keep`` excepted: a key or a file name
    typed with them must not clear the engineer's screen or reorder the line they read."""
    return "".join(c if c.isprintable() or c in keep
                   else c.encode("unicode_escape").decode("ascii") for c in text)


class ConfigError(InputError):
    """A configuration or calibration file is invalid; the message names file, line and key.
    ``missing``: the required keys a mapping lacks, when that is the error (a checker that
    left some entries out tells only the others: ``stationd.configread``)."""

    def __init__(self, message: str, *, path: str | None = None, line: int | None = None,
                 key: str | None = None, missing: tuple[str, ...] = ()) -> None:
        self.path = path
        self.line = line
        self.key = key
        self.missing = missing
        self.message = message   # without the place: what a caller may re-locate
        where = ""
        if path is not None:
            where = printable(path) if line is None else f"{printable(path)}:{line}"
        prefix = f"{where}: " if where else ""
        keypart = f"{printable(key)}: " if key else ""
        super().__init__(f"{prefix}{keypart}{message}")


class ImageError(InputError):
    """An image that cannot be read or has the wrong shape or channel count."""

