"""The screens' view model: the typed events folded into the snapshot the operator screen
shows.

Why a pure fold: the screen must show what the daemon decided, not re-decide it; folding the
same events the daemon publishes (no database, no clock, no I/O) makes the view testable
event by event and lets a browser that connects late start from a snapshot, then follow the
same events live.  ``View.apply`` is the only way state changes.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from stationd.reasons import Reason, Why
from stationd.station.core import DATABASE, LOCALIZING
from stationd.station.events import (
    BoltLocked,
    BoltReleased,
    BoltSelected,
    BoltSkipped,
    BoltToLoosen,
    DeviceHealth,
    DeviceIdentified,
    Localized,
    ParamsRefusedEvent,
    ParamsSent,
    Refused,
    ResultRecorded,
    StateChanged,
    StationEvent,
    ToolDisabled,
    ToolEnabled,
    VehicleClosed,
    VehicleOpened,
    WrongBolt,
)
from stationd.words import reason_words

# a bolt's state on the screen; the label is what the operator reads next to the colour
BOLT_LABELS = {
    "pending": "to do", "next": "next", "selected": "selected", "tightening": "tighten",
    "ok": "OK", "nok": "NOK", "skipped": "skipped", "blocked": "blocked",
    "missing": "missing",    # a closed vehicle's bolt left untightened (the daemon's report)
    "loosen": "loosen first",   # its loosen pset goes next (the NOK policy, a loosen command)
    "loosened": "loosened",  # loosened last: its tightening pset goes next
}
# states a bolt can no longer be in once its vehicle closed: nothing is next or selected any
# more on a vehicle that left (the ones the daemon reports missing become "missing")
LIVE_STATES = ("next", "selected", "tightening", "blocked")
NAMES_SHOWN = 3   # bolts named in a closed vehicle's headline; the full list is its title
REASON_SHOWN = 110  # characters of a fault's reason in the headline (whole in its title)
LAST_RESULTS = 8
# refusals the operator must act on (amber): the wrench is seen, something about it or the
# sequence forbids sending; any other refusal while tracking means the wrench is simply not on
# a bolt (between bolts, out of view): a normal state, shown neutral, never as an alarm
ACT_ON = frozenset({Why.STALE, Why.AMBIGUOUS, Why.TILTED, Why.MUST_WAIT, Why.SKIPPED,
                    Why.DONE})
NOT_AT_A_BOLT = "Bring the wrench to a bolt"
TRACKING_STATES = tuple(s.value for s in LOCALIZING)   # where a refusal speaks of the wrench


@dataclass
class BoltState:
    bolt: str
    x_mm: float
    y_mm: float
    pset: int | None
    order: int | None
    batch: str | None
    state: str = "pending"
    reason: str = ""
    torque_nm: float | None = None
    angle_deg: float | None = None
    locked: bool = False        # too many NOKs in a row: a supervisor releases it
    loosen: bool = False        # its loosen pset goes next, before its tightening pset

    def to_json(self) -> dict[str, Any]:
        return {"bolt": self.bolt, "x": self.x_mm, "y": self.y_mm, "pset": self.pset,
                "order": self.order, "batch": self.batch, "state": self.state,
                "label": BOLT_LABELS.get(self.state, self.state), "reason": self.reason,
                "torque_nm": self.torque_nm, "angle_deg": self.angle_deg,
                "locked": self.locked, "loosen": self.loosen}


@dataclass
class View:
    """What the operator screen shows, built from the events in order."""

    state: str = "starting"      # until the daemon says otherwise (it publishes no "starting")
    reason: str = ""
    vin: str | None = None
    model: str | None = None
    rework: bool = False
    bolts: dict[str, BoltState] = field(default_factory=dict)
    wrench: dict[str, Any] | None = None
    refused: str = ""            # why nothing is sent now ("" when parameters may go out)
    act: bool = False            # ... and the operator resolves it (amber), by its kind
    refused_why: Reason | None = None
    devices: dict[str, dict[str, Any]] = field(default_factory=dict)
    identities: dict[str, str] = field(default_factory=dict)   # device -> what it said it is
    results: list[dict[str, Any]] = field(default_factory=list)
    selected: str | None = None
    closed: dict[str, Any] | None = None
    alarm: str = ""              # a wrong bolt reported by the simulation's checker
    # the devices the station was configured with (lift, wrench, each pair), given by the
    # server: the daemon reports a device's health only when it faults or comes back, so a
    # configured device with no report is "ok" once the station is past its start (the daemon
    # tries every device once before its first state; one that fails is reported as a fault)
    configured: tuple[str, ...] = ()
    # the station has tried its devices: the daemon opens the database first and only then
    # every device (``Station.open``), and its core's first state (after ``Started``) comes
    # after that; the one state published before, ``run._open``'s "fault: database" while the
    # database does not open, arrives with the database reported down and does not count
    opened: bool = False

    def apply(self, e: StationEvent) -> None:
        """Fold one event in."""
        if isinstance(e, StateChanged):
            self.state, self.reason = e.state, e.reason
            if e.state == "starting":
                # a station (re)starting on its configuration: the last one's device
                # reports are not about these devices (a reload kept a fixed wrench "down")
                self.devices, self.opened = {}, False
            if e.state != "starting" and self.devices.get(DATABASE, {}).get("ok", True):
                self.opened = True
            if e.state not in TRACKING_STATES:
                # a refusal is about the wrench while tracking: a station waiting for its
                # vehicle (or in fault) says that, not the last vehicle's "bring the wrench"
                self._refuse("")
        elif isinstance(e, DeviceIdentified):
            self.identities[e.device] = e.identity
        elif isinstance(e, DeviceHealth):
            self.devices[e.device] = {"ok": e.ok, "kind": e.kind, "reason": e.reason}
        elif isinstance(e, VehicleOpened):
            self._open(e)
        elif isinstance(e, VehicleClosed):
            self._close(e)
        elif isinstance(e, Localized):
            self._localized(e)
        elif isinstance(e, Refused):
            self._refuse(reason_words(e.reason), e.reason)
            if e.bolt in self.bolts and self.bolts[e.bolt].state in ("pending", "next"):
                self._set(e.bolt, "blocked", self.refused)
        elif isinstance(e, BoltSelected):
            self._unselect()
            self.selected = e.bolt
            self._refuse("")
            self._set(e.bolt, "selected", (f"loosen pset {e.pset}: loosen first" if e.loosen
                                           else f"pset {e.pset}") if e.pset is not None else "")
        elif isinstance(e, ParamsSent):
            self._refuse("")
        elif isinstance(e, ParamsRefusedEvent):
            self._refuse(f"{e.bolt}: controller refused the parameters: {e.reason}", act=True)
            self._set(e.bolt, "blocked", e.reason)
        elif isinstance(e, ToolEnabled):
            self._set(e.bolt, "tightening")
        elif isinstance(e, ToolDisabled):
            b = self.bolts.get(e.bolt or self.selected or "")
            if b is not None and b.state in ("selected", "tightening"):
                self._set(b.bolt, "pending")
            if e.why is not None:
                self._refuse(f"{e.reason} ({reason_words(e.why)})", e.why)
            elif e.reason:
                self._refuse(e.reason)
        elif isinstance(e, BoltSkipped):
            self._set(e.bolt, "skipped", e.reason)
        elif isinstance(e, BoltLocked | BoltReleased) and e.bolt in self.bolts:
            locked = isinstance(e, BoltLocked)
            self.bolts[e.bolt].locked = locked
            self._set(e.bolt, "blocked" if locked else "pending",
                      f"locked after {e.count} NOK in a row: a supervisor releases it"
                      if isinstance(e, BoltLocked) else "")
        elif isinstance(e, BoltToLoosen) and e.bolt in self.bolts:
            self.bolts[e.bolt].loosen = True
            if not self.bolts[e.bolt].locked:
                self._set(e.bolt, "loosen", reason_words(e.reason))
        elif isinstance(e, ResultRecorded):
            self._result(e)
        elif isinstance(e, WrongBolt):
            self.alarm = f"parameters sent for {e.bolt} while the wrench was on {e.truth}"

    def _open(self, e: VehicleOpened) -> None:
        self.vin, self.model, self.rework = e.vin, e.model, e.rework
        self.closed, self.selected, self.wrench, self.refused = None, None, None, ""
        self.results = []
        self.bolts = {b.bolt: BoltState(b.bolt, b.x_mm, b.y_mm, b.pset, b.order, b.batch,
                                        b.status if b.status in BOLT_LABELS else "pending",
                                        loosen=b.status == "loosen")
                      for b in e.bolts}

    def _close(self, e: VehicleClosed) -> None:
        self.closed = {"vin": e.vin, "missing": list(e.missing), "nok": list(e.nok)}
        self.wrench, self.selected = None, None
        if e.vin != self.vin:
            return
        missing = set(e.missing)
        for b in self.bolts.values():
            if b.bolt in missing and b.state != "nok":
                b.state, b.reason = "missing", "not tightened when the vehicle left"
            elif b.state in LIVE_STATES:
                b.state, b.reason = "pending", ""

    def _localized(self, e: Localized) -> None:
        if e.point_mm is None:
            self.wrench = None if self.wrench is None else {
                **self.wrench, "lost": True,
                "reason": reason_words(e.reason, full=True) if e.reason else ""}
        else:
            self.wrench = {"x": e.point_mm[0], "y": e.point_mm[1], "z": e.point_mm[2],
                           "tilt": e.tilt_deg, "candidate": e.candidate,
                           "distance": e.distance_mm, "age_ms": e.age_ms, "lost": False,
                           "reason": reason_words(e.reason) if e.reason else ""}
        allowed = set(e.allowed)
        for b in self.bolts.values():
            if b.state in ("pending", "next", "blocked"):
                want = "next" if b.bolt in allowed else "pending"
                if b.state != "blocked" or want == "next":
                    b.state, b.reason = want, ""

    def _result(self, e: ResultRecorded) -> None:
        if e.vin == self.vin and e.bolt in self.bolts:
            b = self.bolts[e.bolt]
            if e.kind == "loosening":
                b.loosen = b.loosen and not e.ok
                self._set(e.bolt, "loosened" if e.ok else "loosen",
                          "loosened: tighten it again" if e.ok else "loosening NOK")
            else:
                b.loosen = b.loosen and not e.ok
                self._set(e.bolt, "ok" if e.ok else "nok", "" if e.ok else "NOK: rework")
            b.torque_nm, b.angle_deg = e.torque_nm, e.angle_deg
        if self.selected == e.bolt:
            self.selected = None
        self.results.insert(0, {
            "t": e.t, "vin": e.vin, "bolt": e.bolt, "ok": e.ok, "pset": e.pset,
            "torque_nm": e.torque_nm, "torque_min": e.torque_min, "torque_max": e.torque_max,
            "angle_deg": e.angle_deg, "angle_min": e.angle_min, "angle_max": e.angle_max,
            "late": e.late, "kind": e.kind})
        del self.results[LAST_RESULTS:]

    def _refuse(self, words: str, why: Reason | None = None, *, act: bool = False) -> None:
        """Why nothing is sent now, in words, and whether the operator acts on it (its kind,
        or ``act``)."""
        self.refused, self.refused_why = words, why
        self.act = act or (why is not None and why.kind in ACT_ON)

    def _set(self, bolt: str, state: str, reason: str = "") -> None:
        b = self.bolts.get(bolt)
        if b is not None:
            if b.loosen and state == "pending":   # still to be loosened first
                state, reason = "loosen", reason or "loosen first"
            b.state, b.reason = state, reason

    def _unselect(self) -> None:
        for b in self.bolts.values():
            if b.state in ("selected", "tightening"):
                self._set(b.bolt, "pending")

    # -- what the screens read ----------------------------------------------------------
    def counters(self) -> dict[str, int]:
        states = [b.state for b in self.bolts.values()]
        return {"total": len(states), "done": states.count("ok"), "nok": states.count("nok"),
                "skipped": states.count("skipped")}

    def device_health(self) -> dict[str, dict[str, Any]]:
        """Every configured device, then any other that reported: reported health wins; an
        unreported configured device is "opening" ("not opened yet", neutral) until the
        station has tried its devices (``opened``), "ok" after (one that failed reported)."""
        up = self.opened
        out = {d: {"ok": up, "kind": "" if up else "opening",
                   "reason": "" if up else "not opened yet", "reported": False}
               for d in self.configured}
        for d, h in self.devices.items():
            out[d] = {**h, "reported": True}
        for d, who in self.identities.items():
            if d in out:
                out[d]["identity"] = who
        return out

    def tone(self) -> str:
        """How the headline reads: ``stop`` (red: a fault or a wrong bolt, the station
        stops), ``act`` (amber: a refusal the operator resolves: stale, ambiguous, tilted,
        order rule, skipped), ``idle`` (neutral: the wrench is not on a bolt), ``go`` (a bolt
        selected), ``nok`` (red: the vehicle closed with a NOK bolt, with or without missing
        ones: a joint out of its limits left the station, the worse of the two for quality),
        ``missing`` (amber: it closed with bolts not tightened), ``done`` (vehicle finished),
        else "".  ``nok`` is not ``stop``: the station itself is healthy (/healthz stays ok)."""
        if self.alarm or self.state == "fault" or any(not h["ok"]
                                                       for h in self.devices.values()):
            return "stop"
        if self.refused:
            return "act" if self.act else "idle"
        if self.selected is not None:
            return "go"
        if self.closed is not None:
            return ("nok" if self.closed["nok"] else "missing" if self.closed["missing"]
                    else "done")
        c = self.counters()
        if c["total"] and c["done"] == c["total"]:
            return "done"
        return ""

    def headline(self, full: bool = False) -> str:
        """The large words: why nothing is sent, else what to do.  A fault's reason is cut
        to :data:`REASON_SHOWN` characters (``full``: not; the hover title and the devices
        panel have it whole): a pair's reason carries both cameras' URLs and errors, 400
        characters, nine lines of large type over the bolt map on a panel PC."""
        cut = (lambda s: s) if full else _shortened
        faults = [f"{d}: {cut(h['reason'] or h['kind'])}"
                  for d, h in sorted(self.devices.items()) if not h["ok"]]
        if self.alarm:
            return f"WRONG BOLT: {self.alarm}"
        if self.state == "fault" and len(faults) > 1:
            # several devices down: the first in large words, the others named (each one's
            # reason is in the devices panel); the whole list would not fit 3 lines
            others = [d for d, h in sorted(self.devices.items()) if not h["ok"]][1:]
            return f"FAULT: {faults[0]} (and {', '.join(others)}: see Devices)"
        if self.state == "fault":
            return "FAULT: " + (cut(self.reason) or "; ".join(faults) or "see the journal")
        if faults:
            return "FAULT: " + cut("; ".join(faults))
        if self.refused:
            if not self.act and self._not_at_a_bolt():
                return NOT_AT_A_BOLT
            return self.refused
        if self.selected is not None:
            b = self.bolts.get(self.selected)
            pset = f" (pset {b.pset})" if b is not None and b.pset is not None else ""
            return f"{self.selected}{pset}: tighten"
        if self.closed is not None:
            return self._closed_line(NAMES_SHOWN)
        return self.reason or self.state

    def _closed_line(self, shown: int | None) -> str:
        """``VIN closed: 38 missing (B01, B02, B03, ...); NOK B04``: the count and the first
        ``shown`` names (a panel PC fits no 38 names in large type), every name with None."""
        c = self.closed
        assert c is not None  # noqa: S101 - called when closed
        parts = [_named(c["missing"], "missing", shown), _named(c["nok"], "NOK", shown)]
        return f"{c['vin']} closed: " + ("; ".join(x for x in parts if x) or "all bolts OK")

    def headline_title(self) -> str:
        """The headline in full (its hover title): a closed vehicle's every name, a fault's
        whole reason."""
        if self.closed is not None and self.headline() == self._closed_line(NAMES_SHOWN):
            return self._closed_line(None)
        return self.headline(full=True)

    def _not_at_a_bolt(self) -> bool:
        """The wrench is out of view, or seen but near no bolt."""
        w = self.wrench
        near_none = self.refused_why is not None and self.refused_why.kind is Why.NO_BOLT_NEAR
        return w is None or bool(w.get("lost")) or near_none

    def to_json(self) -> dict[str, Any]:
        return {
            "state": self.state, "reason": self.reason, "headline": self.headline(),
            "headline_title": self.headline_title(),
            "tone": self.tone(),
            "refused": self.refused, "alarm": self.alarm,
            "vehicle": None if self.vin is None else {"vin": self.vin, "model": self.model,
                                                      "rework": self.rework},
            "bolts": [b.to_json() for b in self.bolts.values()],
            "selected": self.selected, "wrench": self.wrench, "counters": self.counters(),
            "devices": self.device_health(), "results": self.results, "closed": self.closed,
        }


def _named(names: list[str], what: str, shown: int | None) -> str:
    """``missing B01, B02`` for a few, ``38 missing (B01, B02, B03, ...)`` for more."""
    if not names:
        return ""
    if shown is None or len(names) <= shown:
        return f"{what} {', '.join(names)}"
    return f"{len(names)} {what} ({', '.join(names[:shown])}, ...)"


def fold(events: list[StationEvent] | tuple[StationEvent, ...],
         configured: tuple[str, ...] = ()) -> View:
    """A view built from ``events`` in order (a fresh screen starts from the bus history)."""
    v = View(configured=tuple(configured))
    for e in events:
        v.apply(e)
    return v


def copy_view(v: View) -> View:
    """A shallow-independent copy (tests compare before/after)."""
    return replace(v, bolts={k: replace(b) for k, b in v.bolts.items()},
                   devices=dict(v.devices), results=list(v.results))


def _shortened(text: str, limit: int = REASON_SHOWN) -> str:
    """``text`` cut at the last word boundary before ``limit`` characters, with an ellipsis
    (unchanged when it fits)."""
    if len(text) <= limit:
        return text
    head = text[:limit - 1]
    space = head.rfind(" ")
    return (head[:space] if space > limit // 2 else head).rstrip(" ,;:(") + "\u2026"
