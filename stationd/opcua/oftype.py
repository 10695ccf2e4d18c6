"""An event filter's ``OfType`` as OPC UA defines it: the event's type or any subtype of it.

asyncua 2.1.0's server compares the event's type with the one named alone
(``WhereClauseEvaluator``: ``event.EventType == ...``).  The station's results come as its own
subtype of the IJT ``JoiningSystemResultReadyEventType`` (i=1007), so an MES that subscribes
with a where clause ``OfType(JoiningSystemResultReadyEventType)``, as the README and Part 4
(7.7.3: "true if the event is of the type or a subtype") tell it to, got no event at all, and
no error (an MES integrator's trial with node-opcua's ``ofType``; asyncua's own client lists
every subtype itself and so never saw it).  :func:`follow_subtypes` makes the server's
``OfType`` follow the address space's HasSubtype references up from the event's type.  Kept
here, beside the pin (``asyncua==2.1.0``): the one place that changes with asyncua."""

from __future__ import annotations

from typing import Any

from asyncua.server.monitored_item_service import WhereClauseEvaluator

from stationd.opcua.uatypes import ua

#: the HasSubtype reference type (Part 3), followed inversely from a type to its supertype
HAS_SUBTYPE = ua.NodeId(ua.ObjectIds.HasSubtype)
_FOLLOWS = "_stationd_follows_subtypes"


def is_of_type(aspace: Any, event_type: Any, wanted: Any) -> bool:
    """Whether ``event_type`` is ``wanted`` or a subtype of it, in the address space
    ``aspace`` (a type with no supertype there, or a loop, ends the walk)."""
    seen: set[Any] = set()
    current = event_type
    while current is not None and current not in seen:
        if current == wanted:
            return True
        seen.add(current)
        node = aspace.get(current)
        current = None if node is None else next(
            (r.NodeId for r in node.references
             if r.ReferenceTypeId == HAS_SUBTYPE and not r.IsForward), None)
    return False


def follow_subtypes() -> None:
    """Make asyncua's server evaluate ``OfType`` over the subtypes (once per process; every
    other operator as asyncua does)."""
    original = WhereClauseEvaluator._eval_el
    if getattr(original, _FOLLOWS, False):
        return

    def _eval_el(self: Any, index: int, event: Any) -> Any:
        el = self.elements[index]
        if el.FilterOperator == ua.FilterOperator.OfType:
            return is_of_type(self._aspace, event.EventType,
                              self._eval_op(el.FilterOperands[0], event))
        return original(self, index, event)

    setattr(_eval_el, _FOLLOWS, True)
    WhereClauseEvaluator._eval_el = _eval_el  # type: ignore[method-assign]


__all__ = ["HAS_SUBTYPE", "follow_subtypes", "is_of_type"]
