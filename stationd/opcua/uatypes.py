"""asyncua's ``ua`` module, untyped for the checker: its annotations use its own NewTypes for
plain ints and strings (``NodeId(Int32, Int16)``) and generate the companion models' classes
at run time, which no checker can see.  Every use of asyncua's types goes through here."""

from typing import Any

from asyncua import ua as _ua

ua: Any = _ua

__all__ = ["ua"]
