"""The operator signed in at the station on the operator screen's view model: the header's
operator (with whether one is required), the typed refusal "sign in to tighten" as one the
operator acts on (amber), gone once somebody signs in; each last result says who made it."""

from __future__ import annotations

from dataclasses import replace

from stationd.reasons import Reason, Why
from stationd.station.events import Localized, OperatorChange, OperatorChanged, Refused
from stationd.web.view import fold
from tests.web.scenario import opened, result


def _near(bolt: str, x: float) -> Localized:
    return Localized(point_mm=(x, 0.0, 0.0), tilt_deg=1.0, reason=None, candidate=bolt,
                     distance_mm=1.0, age_ms=30.0, allowed=(bolt,))


def test_nobody_signed_in_where_one_is_required_is_an_amber_sign_in_to_tighten():
    nobody = OperatorChanged(None, True, how=OperatorChange.NOBODY)
    v = fold([*opened(), nobody, _near("B2", 400.0),
              Refused(Reason(Why.SIGN_IN, bolt="B2"), "B2")])
    doc = v.to_json()
    assert doc["operator"] == {"user": None, "required": True}
    assert doc["headline"].startswith("sign in to tighten") and doc["tone"] == "act"
    v.apply(OperatorChanged("olga", True, how=OperatorChange.SIGNED_IN))
    doc = v.to_json()
    assert doc["operator"] == {"user": "olga", "required": True}
    assert "sign in" not in doc["headline"] and doc["tone"] != "act"


def test_each_last_result_carries_its_operator():
    r = result("B2", True, 7)
    v = fold([*opened(), OperatorChanged("pia", False, how=OperatorChange.SIGNED_IN),
              replace(r, operator="pia"), result("B3", False, 8)])
    assert [(x["bolt"], x["operator"]) for x in v.to_json()["results"]] == [
        ("B3", None), ("B2", "pia")]
