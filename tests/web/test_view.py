"""The view model: events folded into what the operator screen shows."""

from __future__ import annotations

from dataclasses import replace

from stationd.reasons import Reason, Wait, WaitKind, Why
from stationd.station.events import (
    Because,
    ClosingSettled,
    DeviceHealth,
    Localized,
    OperatorChanged,
    ParamsRefusedEvent,
    Refused,
    StateChanged,
    StateReason,
    ToolDisabled,
    VehicleClosed,
    VehicleOpened,
    VehicleReopened,
    WrongBolt,
)
from stationd.web.view import View, fold
from stationd.words import reason_words
from tests.web.scenario import (
    LIFT_LOW,
    VIN,
    fault,
    fault_state,
    opened,
    ran,
    result,
    skipped,
    work,
)

#: the stale-frames refusal as the operator reads it
STALE_812 = ("camera frames too old (812 ms): the cameras or the station's computer fall "
             "behind")


def states(v: View) -> dict[str, str]:
    return {b.bolt: b.state for b in v.bolts.values()}


def test_opened_vehicle_has_pending_bolts_and_counters():
    v = fold(opened())
    assert (v.vin, v.model) == (VIN, "SEDAN")
    assert set(states(v).values()) == {"pending"}
    assert v.counters() == {"total": 4, "done": 0, "nok": 0, "skipped": 0, "held": 0}
    # no frame localized since the station started: it says so (test_view_agree)
    assert v.headline() == "Starting: waiting for the cameras' first frames"
    v.apply(Localized(point_mm=None, tilt_deg=None, reason=NOT_SEEN, candidate=None,
                      distance_mm=None, age_ms=30.0))
    assert v.headline() == "tracking the wrench"


def test_work_marks_ok_nok_selected_tightening_and_next():
    v = fold(opened() + work())
    assert states(v) == {"B1": "ok", "B2": "nok", "B3": "tightening", "B4": "next"}
    assert v.counters()["done"] == 1 and v.counters()["nok"] == 1
    assert v.selected == "B3"
    assert v.headline() == "B3 (pset 1): tighten"
    assert v.wrench is not None and abs(v.wrench["y"] - 299.0) < 1e-9
    last = v.results[0]
    assert last["bolt"] == "B2" and not last["ok"] and last["torque_min"] == 45.0
    j = v.to_json()
    labels = {b["bolt"]: b["label"] for b in j["bolts"]}
    assert labels == {"B1": "OK", "B2": "NOK", "B3": "tighten", "B4": "next"}


def test_fault_shows_device_and_reason_in_large_words():
    v = fold(opened() + work() + fault())
    assert v.state == "fault"
    assert v.headline().startswith("FAULT: lift: no answer")
    assert v.devices["lift"] == {"ok": False, "kind": "timeout",
                                 "reason": "no answer from 10.0.0.7:502 for 2.0 s"}


def test_device_fault_without_fault_state_still_headlines():
    v = fold([*opened(), DeviceHealth(device="cam-a", ok=False, kind="down", reason="no frames")])
    assert v.headline() == "FAULT: cam-a: no frames"
    v.apply(DeviceHealth(device="cam-a", ok=True))
    assert v.headline() == "Starting: waiting for the cameras' first frames"


def test_a_long_fault_reason_is_cut_in_the_headline_and_whole_in_its_title():
    """A pair's reason carries both cameras' URLs and errors (a newcomer's: 400 characters,
    nine lines of large type over the bolt map): the headline cuts it at a word with an
    ellipsis; its hover title and the devices panel keep it whole."""
    side = ("sim://pair1/{0}: no simulated world for pair 'pair1' (none registered); the "
            "world must call drivers.camera.sim.register_world('pair1', source) first")
    reason = ("stereo sim://pair1/left + sim://pair1/right: no frame from left and right "
              f"within 1 s (left: {side.format('left')}; right: {side.format('right')})")
    for events in ([fault_state(("pair1", reason))],
                   [fault_state(("pair1", reason)),
                    DeviceHealth(device="wrench", ok=False, kind="down", reason="refused")]):
        v = fold([*opened(), DeviceHealth(device="pair1", ok=False, kind="down",
                                          reason=reason), *events])
        head, title = v.headline(), v.headline_title()
        assert head.startswith("FAULT: pair1: stereo sim://pair1/left") and "\u2026" in head
        assert len(head) <= 160 and not head.split("\u2026")[0].endswith(" ")
        assert reason in title and v.to_json()["devices"]["pair1"]["reason"] == reason
        assert ("wrench: see Devices" in head) == (len(events) == 2)
    short = fold([*opened(), DeviceHealth(device="lift", ok=False, kind="timeout",
                                          reason="no answer for 2.0 s")])
    assert short.headline() == short.headline_title() == "FAULT: lift: no answer for 2.0 s"


def test_refusal_blocks_its_bolt_and_is_the_headline_until_a_selection():
    wait = Reason(Why.MUST_WAIT, bolt="B2", wait=Wait(WaitKind.ORDER, order=2, bolts=("B1",)))
    v = fold([*opened(), Refused(reason=wait, bolt="B2")])
    said = "B2 must wait: order 2 needs B1 done first"
    assert states(v)["B2"] == "blocked" and v.bolts["B2"].reason == said
    assert v.headline() == said and v.tone() == "act"
    v.apply(Localized(point_mm=(0.0, 0.0, 0.0), tilt_deg=1.0, reason=None, candidate="B1",
                      distance_mm=0.5, age_ms=30.0, allowed=("B2",)))
    assert states(v)["B2"] == "next"     # the rule now allows it


def test_lost_wrench_is_marked_lost_without_a_position():
    """No crosshair where it was last seen: a grey one left on B47 beside "not in view" was
    read as the wrench on B47 (the map and the panel say the same)."""
    v = fold(opened() + work())
    v.apply(Localized(point_mm=None, tilt_deg=None, reason=Reason(Why.STALE, age_ms=812.0),
                      candidate=None, distance_mm=None, age_ms=400.0))
    assert v.wrench is not None and v.wrench["lost"] and "x" not in v.wrench
    assert v.wrench["reason"] == STALE_812


def test_tool_disabled_returns_selection_to_pending_with_reason():
    v = fold(opened() + work())
    v.apply(ToolDisabled(reason=StateReason(Because.WRENCH_LEFT, bolt="B3"), bolt="B3"))
    assert states(v)["B3"] == "pending"
    assert v.headline() == "wrench left bolt B3"
    v = fold(opened() + work())
    v.apply(ToolDisabled(reason=StateReason(Because.NOT_CONFIRMED, bolt="B3"), bolt="B3",
                         why=Reason(Why.STALE, age_ms=812.0)))
    assert v.headline() == f"wrench not confirmed on bolt B3 ({STALE_812})"


def test_a_nok_rundown_reads_nok_in_the_amber_headline_never_tightened():
    """An operator trial: after four NOKs of B42 the headline read "bolt B42 tightened" in
    the neutral tone each time, as after an OK."""
    for ok, words, tone in ((False, "bolt B3 NOK", "act"), (True, "bolt B3 tightened", "idle")):
        v = fold(opened() + work())
        v.apply(ToolDisabled(reason=StateReason(Because.RUNDOWN, bolt="B3", ok=ok), bolt="B3"))
        v.apply(result("B3", ok, 200))
        assert v.headline() == words and v.tone() == tone, (v.headline(), v.tone())


def test_a_vehicle_opened_again_by_a_reload_keeps_its_last_results():
    v = fold([*opened(), result("B1", True, 100), result("B2", False, 101)])
    v.apply(opened()[-1])                      # the reload's opening of the same vehicle
    assert [(r["bolt"], r["ok"]) for r in v.results] == [("B2", False), ("B1", True)]
    v.apply(replace(opened()[-1], vin="OTHERVIN000000001"))
    assert v.results == []


def test_skip_rework_result_close_and_wrong_bolt():
    v = fold(opened() + work())
    for e in [*skipped("B4", "skipped by supervisor"), *ran("B2", True, 200)]:
        v.apply(e)
    assert states(v)["B4"] == "skipped" and states(v)["B2"] == "ok"
    assert v.counters() == {"total": 4, "done": 2, "nok": 0, "skipped": 1, "held": 0}
    v.apply(VehicleClosed(vin=VIN, missing=("B3",), nok=()))
    assert v.closed == {"vin": VIN, "missing": ["B3"], "skipped": [], "nok": [],
                        "due": []} \
        and v.wrench is None
    assert v.headline() == f"{VIN} closed: missing B3"
    v.apply(WrongBolt(bolt="B1", truth="B2"))
    assert v.headline().startswith("WRONG BOLT")


def test_results_keep_only_the_last_few_and_reopen_resets():
    v = fold(opened())
    for i in range(20):
        v.apply(result("B1", i % 2 == 0, i))
    assert len(v.results) == 8 and v.results[0]["t"] >= v.results[-1]["t"]
    v.apply(VehicleClosed(vin=VIN, missing=("B2", "B3", "B4"), nok=()))
    v.apply(StateChanged(state="waiting for vehicle", reason=StateReason(Because.WAITING_LIFT)))
    v.apply(opened()[-1])                     # back for rework: its visit starts afresh
    assert v.results == [] and states(v)["B1"] == "pending"


def test_controller_refusing_parameters_blocks_the_bolt_and_says_why():
    v = fold(opened())
    v.apply(ParamsRefusedEvent(bolt="B1", reason="pset 1 unknown to the controller"))
    assert states(v)["B1"] == "blocked"
    assert v.headline() == "B1: controller refused the parameters: pset 1 unknown to the controller"


def test_the_headline_says_a_refusal_shared_by_every_pair_once():
    every = Reason(Why.NOT_LOCALIZED, per_pair=tuple(
        (f"pair{k}", "left", "no purple region enclosing a ring in view") for k in range(1, 5)))
    assert reason_words(every) == "no purple region enclosing a ring in view (all 4 pairs)"
    assert reason_words(every, full=True).startswith(
        "pair1: left: no purple region enclosing a ring in view; pair2: left: ")
    mixed = Reason(Why.NOT_LOCALIZED, per_pair=(("pair1", "left", "no purple region in view"),
                                                 ("pair2", "right", "ring cut by the frame")))
    assert reason_words(mixed) == ("pair1: left: no purple region in view; pair2: right: "
                                   "ring cut by the frame")
    v = fold([*opened(), lost(every), Refused(reason=Reason(Why.DONE, bolt="B18"))])
    assert v.headline() == "B18 is already done" and v.tone() == "act"


NOT_SEEN = Reason(Why.NOT_LOCALIZED, per_pair=tuple(
    (f"pair{k}", side, "no purple region enclosing a ring in view")
    for k in range(1, 5) for side in ("left", "right")))


def seen_at(x: float, y: float) -> Localized:
    """A fresh localization near no bolt."""
    return Localized(point_mm=(x, y, 0.0), tilt_deg=1.0, reason=None, candidate=None,
                     distance_mm=None, age_ms=30.0)


def lost(reason: Reason) -> Localized:
    return Localized(point_mm=None, tilt_deg=None, reason=reason, candidate=None,
                     distance_mm=None, age_ms=0.0)


def test_wrench_between_bolts_is_neutral_not_an_alarm():
    v = fold([*opened(), lost(NOT_SEEN), Refused(reason=NOT_SEEN)])
    assert v.tone() == "idle" and v.headline() == "Bring the wrench to a bolt"
    assert v.to_json()["tone"] == "idle"
    # seen, but near no bolt: the same normal state
    v = fold([*opened(), Localized(point_mm=(200.0, 150.0, 0.0), tilt_deg=1.0, reason=None,
                                   candidate="B1", distance_mm=250.0, age_ms=30.0),
              Refused(reason=Reason(Why.NO_BOLT_NEAR, bolt="B1", distance_mm=250.0,
                                    limit=15.0))])
    assert (v.tone(), v.headline()) == ("idle", "Bring the wrench to a bolt")


def test_nobody_signed_in_where_one_is_required_is_said_before_the_wrench_is_brought():
    """A maintenance trial: ``operator_required`` and nobody signed in, the headline said
    "Bring the wrench to a bolt" (the sign-in only on the operator line): the wrench brought
    was refused then.  Said first; signed in, the usual words."""
    v = fold([*opened(), OperatorChanged(None, True), lost(NOT_SEEN), Refused(reason=NOT_SEEN)])
    assert (v.tone(), v.headline()) == ("idle", "Nobody signed in: sign in to tighten")
    v.apply(OperatorChanged("ann", True))
    assert v.headline() == "Bring the wrench to a bolt"
    v = fold([*opened(), OperatorChanged(None, False), lost(NOT_SEEN), Refused(reason=NOT_SEEN)])
    assert v.headline() == "Bring the wrench to a bolt"    # not required: nothing to say


def test_refusals_the_operator_resolves_are_amber_with_the_reason():
    for reason, said in (
            (Reason(Why.STALE, age_ms=812.0), STALE_812),
            (Reason(Why.AMBIGUOUS, bolt="B1", distance_mm=3.0, other="B2", other_mm=4.1),
             "ambiguous: B1 at 3.0 mm, B2 at 4.1 mm"),
            (Reason(Why.TILTED, angle_deg=14.2, limit=10.0), "wrench tilted 14.2 deg (> 10 deg)"),
            (Reason(Why.MUST_WAIT, bolt="B4", wait=Wait(WaitKind.ORDER, order=2, bolts=("B3",))),
             "B4 must wait: order 2 needs B3 done first")):
        # after fresh frames (before them, stale frames are the station starting)
        v = fold([*opened(), seen_at(200.0, 150.0), lost(reason), Refused(reason=reason)])
        assert (v.tone(), v.headline()) == ("act", said), said


def test_fault_is_red_above_any_refusal_and_a_selection_is_go():
    v = fold([*opened(), lost(NOT_SEEN), Refused(reason=NOT_SEEN), *fault()])
    assert v.tone() == "stop" and v.headline().startswith("FAULT: lift")
    assert fold(opened() + work()).tone() == "go"


def test_configured_devices_are_listed_ok_once_started_until_one_reports():
    v = fold([StateChanged(state="starting", reason=StateReason(Because.OPENING))],
             configured=("lift", "wrench", "pair1"))
    health = v.device_health()
    assert list(health) == ["lift", "wrench", "pair1"]
    assert not any(h["ok"] for h in health.values())     # not opened yet: not claimed ok
    v.apply(StateChanged(state="waiting for vehicle", reason=StateReason(Because.WAITING_LIFT)))
    assert all(h["ok"] and not h["reported"] for h in v.device_health().values())
    v.apply(DeviceHealth(device="pair1", ok=False, kind="down", reason="camera 3 gone"))
    got = v.to_json()["devices"]
    assert got["pair1"]["ok"] is False and got["pair1"]["reported"] is True
    assert got["lift"]["ok"] and got["wrench"]["ok"]
    # a reload: the station starts again on its (new) configuration; the last one's reports
    # go (a newcomer's fixed wrench stayed "down ...?foo=1" after the reload that fixed it)
    v.apply(StateChanged(state="starting", reason=StateReason(Because.OPENING)))
    assert not any(h["ok"] or h["reported"] for h in v.device_health().values())
    v.apply(StateChanged(state="waiting for vehicle", reason=StateReason(Because.WAITING_LIFT)))
    assert all(h["ok"] and not h["reported"] for h in v.device_health().values())


def test_a_station_waiting_for_its_vehicle_says_so_not_the_last_refusal():
    """After the vehicle left (lift lowered), the last "bring the wrench" refusal no longer
    speaks: the headline is the closed vehicle's summary, then the station's own reason (a
    newcomer saw "Bring the wrench to a bolt" under "waiting for vehicle")."""
    v = fold([*opened(), lost(NOT_SEEN), Refused(reason=NOT_SEEN),
              StateChanged(state="waiting for vehicle", reason=LIFT_LOW)])
    assert v.headline() == "lift not at working height" and v.tone() == ""
    v = fold([*opened(), Refused(reason=NOT_SEEN),
              VehicleClosed(vin=VIN, missing=("B1",), nok=()),
              StateChanged(state="waiting for vehicle", reason=LIFT_LOW)])
    assert v.headline() == f"{VIN} closed: missing B1"
    v = fold([*opened(), Refused(reason=NOT_SEEN),
              StateChanged(state="tracking", reason=StateReason(Because.TRACKING))])
    assert v.headline() == "Bring the wrench to a bolt"      # while tracking it still does


def test_a_closed_vehicle_with_missing_or_nok_bolts_is_an_alarm_and_its_bolts_say_missing():
    """A newcomer saw "SIMVIN... closed: missing B01, ... B50; NOK B04" in the neutral tone
    and 38 bolts still "next": a vehicle that left incomplete is amber, with a NOK red; its
    untightened bolts are "missing"; the headline counts them and names a few."""
    v = fold(opened() + work())          # B1 OK, B2 NOK, B3 tightening, B4 next
    v.apply(VehicleClosed(vin=VIN, missing=("B3", "B4"), nok=("B2",)))
    assert states(v) == {"B1": "ok", "B2": "nok", "B3": "missing", "B4": "missing"}
    assert v.to_json()["bolts"][3]["label"] == "missing"
    assert v.tone() == "nok" and v.headline() == f"{VIN} closed: missing B3, B4; NOK B2"
    v.apply(StateChanged(state="waiting for vehicle", reason=LIFT_LOW))
    assert v.tone() == "nok"             # the closed vehicle still speaks, still red
    v = fold(opened())
    v.apply(VehicleClosed(vin=VIN, missing=("B1",), nok=()))
    assert v.tone() == "missing"
    v = fold(opened())
    v.apply(VehicleClosed(vin=VIN, missing=(), nok=()))
    assert (v.tone(), v.headline()) == ("done", f"{VIN} closed: all bolts OK")


def test_a_bolt_whose_result_is_due_as_the_vehicle_leaves_is_said_due_then_as_recorded():
    """A supervisor's trial: B3 tightening as the lift went down, its NOK before (B2 here)
    and its result still to come: the close says "result due B3" (neither missing nor NOK);
    its OK recorded, then the verdict settled, the close line says what the records do.
    A settled verdict of another vehicle than the one shown changes nothing."""
    v = fold(opened() + work())          # B1 OK, B2 NOK, B3 tightening, B4 next
    v.apply(VehicleClosed(vin=VIN, missing=("B4",), nok=("B2",), due=("B3",)))
    assert states(v)["B3"] == "pending" and states(v)["B4"] == "missing"
    assert v.headline() == f"{VIN} closed: missing B4; NOK B2; result due B3"
    v.apply(result("B3", True, 9))
    v.apply(ClosingSettled(vin=VIN, missing=("B4",), nok=("B2",), settled=("B3",)))
    assert states(v)["B3"] == "ok"
    assert v.headline() == f"{VIN} closed: missing B4; NOK B2"
    v = fold(opened())
    v.apply(VehicleClosed(vin=VIN, missing=("B1", "B2", "B4"), nok=(), due=("B3",)))
    assert v.tone() == "missing"
    v.apply(ClosingSettled(vin=VIN, missing=("B1", "B2", "B3", "B4"), nok=(),
                           settled=("B3",)))     # its result never came
    assert states(v)["B3"] == "missing"
    assert v.headline() == f"{VIN} closed: 4 missing (B1, B2, B3, ...)"
    v.apply(ClosingSettled(vin="OTHER", missing=(), nok=(), settled=("B1",)))
    assert v.headline() == f"{VIN} closed: 4 missing (B1, B2, B3, ...)"


def test_a_closed_vehicles_skipped_bolts_are_said_skipped_not_missing():
    """The headline said "46 missing (B01, B02, ...)" of a vehicle whose B01 and B02 a person
    skipped, beside the counters' "2 skipped" and the report's 44 missing (a supervisor's
    trial): the core's close names every bolt not done; the skipped ones are said apart."""
    v = fold([*opened(), *skipped("B1", "no nut fitted")])
    v.apply(VehicleClosed(vin=VIN, missing=("B1", "B2", "B3", "B4"), nok=()))
    assert v.headline() == f"{VIN} closed: missing B2, B3, B4; skipped B1"
    assert v.tone() == "missing"
    v = fold([*opened(), *skipped("B1", "x"), *skipped("B2", "y"), *skipped("B3", "z"),
              *skipped("B4", "w")])
    v.apply(VehicleClosed(vin=VIN, missing=("B1", "B2", "B3", "B4"), nok=()))
    assert v.headline() == f"{VIN} closed: 4 skipped (B1, B2, B3, ...)"
    assert v.tone() == "missing"


def test_a_reopened_vehicle_is_no_longer_said_closed():
    """A newcomer reopened the closed vehicle (accepted) and `stationd status` still said
    "VIN closed: 40 missing": reopened, it is said so until it opens at the station."""
    v = fold(opened())
    v.apply(VehicleClosed(vin=VIN, missing=("B1",), nok=()))
    v.apply(StateChanged(state="waiting for vehicle", reason=LIFT_LOW))
    v.apply(VehicleReopened(vin=VIN, user="sam"))
    assert v.closed is None and v.tone() != "missing"
    assert v.headline() == f"{VIN} reopened for rework by sam: it opens when raised at the " \
        "station"
    v2 = fold([*opened(), VehicleReopened(vin="OTHER", user="sam")])
    assert v2.reopened == ("OTHER", "sam")
    # the vehicle on the lift comes first: another one's rework is not its headline
    assert "OTHER" not in v2.headline()
    # none open on the lift (closed, then reopened, then another reopened): said
    v4 = fold([*opened(), VehicleClosed(vin=VIN, missing=(), nok=()),
               VehicleReopened(vin=VIN, user="sam"), VehicleReopened(vin="OTHER", user="kim")])
    assert v4.headline().startswith("OTHER reopened for rework by kim")
    v2.apply(VehicleClosed(vin=VIN, missing=(), nok=()))   # another one closes: said closed
    assert v2.headline() == f"{VIN} closed: all bolts OK"
    v3 = fold([*opened(), VehicleReopened(vin=VIN, user="sam"), *opened()])
    assert v3.reopened is None                         # opened: the usual words again


def test_many_missing_bolts_are_counted_with_a_few_named_and_all_in_the_title():
    names = tuple(f"B{k:02d}" for k in range(1, 51) if k != 4)
    v = fold(opened())
    v.apply(VehicleClosed(vin=VIN, missing=names, nok=("B04",)))
    assert v.headline() == f"{VIN} closed: 49 missing (B01, B02, B03, ...); NOK B04"
    j = v.to_json()
    assert j["headline_title"] == f"{VIN} closed: missing {', '.join(names)}; NOK B04"
    assert j["tone"] == "nok"


def test_devices_are_not_claimed_ok_while_the_database_keeps_the_station_from_opening_them():
    """run._open publishes the database's fault and a "fault" state before the station has
    tried any device: lift and wrench are "not opened yet", not "ok", until the core's first
    state (published once Station.open has tried them all)."""
    cfg = ("lift", "wrench", "pair1")
    v = fold([], configured=cfg)
    assert v.state == "starting"
    assert {d: h["reason"] for d, h in v.device_health().items()} == {
        d: "not opened yet" for d in cfg}
    down = [DeviceHealth(device="database", ok=False, kind="down", reason="disk I/O error"),
            fault_state(("database", "disk I/O error"))]
    # in either order: the core says its state before the database's health (a
    # technician's trial: that order showed the lift and the controller "ok", never tried)
    for events in (down * 3, down[::-1] * 3):     # retried with backoff
        v = fold(events, configured=cfg)
        health = v.device_health()
        assert not any(health[d]["ok"] for d in cfg) and health["database"]["ok"] is False
        assert health["lift"]["kind"] == "opening"
        assert health["lift"]["reason"] == "not opened yet: the database opens first"
    assert v.to_json()["headline"].startswith("FAULT: database")
    # the database opens; the station tries every device: the wrench does not answer
    v.apply(DeviceHealth(device="database", ok=True))
    v.apply(DeviceHealth(device="wrench", ok=False, kind="refused", reason="connection refused"))
    v.apply(fault_state(("wrench", "connection refused")))
    health = v.device_health()
    assert health["lift"]["ok"] and health["pair1"]["ok"] and not health["wrench"]["ok"]
    # a later database outage does not make the opened devices "not opened yet" again
    v.apply(DeviceHealth(device="database", ok=False, kind="down", reason="locked"))
    v.apply(fault_state(("database", "locked")))
    assert v.device_health()["lift"]["ok"]


def test_what_a_device_said_it_is_goes_with_its_health():
    from stationd.station.events import DeviceIdentified

    v = fold([*opened(), DeviceIdentified(device="wrench", identity="PF6000 (cell 1, "
                                          "channel 1), software 1.2")])
    assert v.device_health()["wrench"]["identity"].startswith("PF6000")
    assert "identity" not in v.device_health().get("lift", {})


def test_a_late_result_of_a_closed_vehicle_leaves_the_next_ones_selection():
    """A result stored late (the database away while the lift went down) of the vehicle that
    left: the next vehicle's selected bolt of the same name stays selected, and the closed
    vehicle's line no longer counts the bolt missing."""
    from dataclasses import replace as _replace

    v = fold(opened())
    v.apply(VehicleClosed(vin=VIN, missing=("B1", "B2"), nok=()))
    assert v.closed is not None and v.closed["missing"] == ["B1", "B2"]
    v.apply(result("B1", True, 7))
    assert v.closed["missing"] == ["B2"] and v.closed["nok"] == []
    nxt = [_replace(e, vin="NEXTVIN0000000001") if isinstance(e, VehicleOpened) else e
           for e in opened()]
    w = fold(nxt + [e for e in work() if type(e).__name__ == "BoltSelected"][-1:])
    assert w.selected == "B3"
    w.apply(result("B3", True, 8))            # the vehicle that left, its B3
    assert w.selected == "B3" and w.headline().startswith("B3")



def test_a_fault_headline_leaves_the_device_s_url_to_the_devices_panel():
    """An operator read "FAULT: wrench: openprotocol://127.0.0.1:14599: reconnect: connection
    refused by 127.0.0.1:14599 (controller off, or…": the URL took the room of the words to
    act on.  The large type leaves it out; the hover title and the devices panel keep it."""
    from stationd.station.events import DeviceHealth

    reason = ("openprotocol://127.0.0.1:14599: reconnect: connection refused by "
              "127.0.0.1:14599 (controller off, or not listening on that port?)")
    v = View()
    v.apply(DeviceHealth("wrench", False, "down", reason))
    assert v.headline() == ("FAULT: wrench: reconnect: connection refused by 127.0.0.1:14599 "
                            "(controller off, or not listening on that port?)")
    assert v.headline_title() == f"FAULT: wrench: {reason}"
    assert v.device_health()["wrench"]["reason"] == reason
